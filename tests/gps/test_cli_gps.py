"""``gtrig gps``: outputs on a good log; bad input gives one line, exit code 2 and nothing written."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from gtrig.cli.main import app
from gtrig.io.posetrack import read_pose_track

from ._nmea_text import GGA, GST, cs

runner = CliRunner()


def _run(tmp: Path, log: Path, *extra: str):
    return runner.invoke(app, ["gps", "--log", str(log), "--out", str(tmp / "o" / "gps.tum"),
                               "--covariance", str(tmp / "o" / "gps_cov.csv"), "--report", str(tmp / "o" / "r.json"),
                               *extra])


def _good_log(p: Path, n: int = 20) -> Path:
    rows = []
    for k in range(n):
        t = f"1200{0.2 * k:05.2f}"
        rows += [f"{1223121600.0 + 0.2 * k:.6f}, " + cs(GGA.format(t=t, q=4)), cs(GST.format(t=t))]
    p.write_text("\n".join(rows) + "\n")
    return p


def test_good_log_writes_track_covariance_report_and_plots(tmp_path: Path) -> None:
    log = _good_log(tmp_path / "ok.log")
    r = _run(tmp_path, log, "--frame", "utm", "--plot", str(tmp_path / "o"))
    assert r.exit_code == 0, r.output
    tr = read_pose_track(tmp_path / "o" / "gps.tum", tmp_path / "o" / "gps_cov.csv")
    assert len(tr) == 20 and tr.cov_kind == "xyz" and tr.frame_id == "utm"
    assert np.allclose(tr.xyz, 0.0, atol=1e-6)  # one position, subtracted
    rep = json.loads((tmp_path / "o" / "r.json").read_text())
    assert rep["kept"] == 20 and rep["lines"]["total"] == 40
    assert (tmp_path / "o" / "gps_coverage.png").stat().st_size > 1000
    md = (tmp_path / "o" / "r.md").read_text()  # the summary `gtrig report` shows
    assert "| rtk_fixed | 100.0% |" in md and "(gps_coverage.png)" in md


def _bad_inputs(tmp: Path) -> dict[str, tuple[Path, str, list[str]]]:
    empty = tmp / "empty.log"
    empty.write_text("")
    binary = tmp / "bin.log"
    binary.write_bytes(bytes(range(256)) * 8)
    fields = tmp / "fields.log"
    fields.write_text("\n".join(cs("GPGGA,1200%05.2f,4530.3,N,00909.9,E,4,8,0.9" % (0.2 * k)) for k in range(5)) + "\n")
    lat = tmp / "lat.log"
    lat.write_text(cs("GPGGA,120000.00,9130.36844637,N,00909.97033083,E,4,8,0.9,129.0,M,48.0,M,1.0,0000") + "\n")
    nofix = tmp / "float.log"
    nofix.write_text("\n".join(cs(GGA.format(t=f"1200{0.2 * k:05.2f}", q=5)) for k in range(5)) + "\n")
    return {"empty": (empty, "empty log", []), "binary": (binary, "binary", []),
            "fields": (fields, "fields, expected 14", []), "latitude": (lat, "latitude out of range", []),
            "no fix asked": (nofix, "no fix of the kind asked", []),
            "bad option": (nofix, "--frame", ["--frame", "ecef"]),
            "bad origin": (nofix, "--origin", ["--origin", "95,9,0"])}


@pytest.mark.parametrize("case", ["empty", "binary", "fields", "latitude", "no fix asked", "bad option", "bad origin"])
def test_bad_input_one_line_exit_2_nothing_written(tmp_path: Path, case: str) -> None:
    log, expect, extra = _bad_inputs(tmp_path)[case]
    r = _run(tmp_path, log, *extra)
    assert r.exit_code == 2, r.output
    lines = [x for x in r.output.splitlines() if x.strip()]
    assert len(lines) == 1 and lines[0].startswith("error:") and expect in lines[0], r.output
    assert "Traceback" not in r.output
    assert not (tmp_path / "o").exists() or not any((tmp_path / "o").iterdir())


def test_smoothing_with_odometry_through_the_verb(tmp_path: Path) -> None:
    from gtrig.sim.outdoor import OutdoorParams, simulate_outdoor

    rec = tmp_path / "rec"
    simulate_outdoor(rec, seed=0, params=OutdoorParams(duration_s=240.0))
    r = _run(tmp_path, rec / "gps" / "gps.log", "--clock", "utc", "--odometry", str(rec / "odometry" / "odometry.csv"),
             "--antenna-lever-arm=-0.2,0.05,0.6")
    assert r.exit_code == 0, r.output
    tr = read_pose_track(tmp_path / "o" / "gps.tum", tmp_path / "o" / "gps_cov.csv")
    assert tr.cov_kind == "xyyaw" and tr.source == "gps+odometry"
    rep = json.loads((tmp_path / "o" / "r.json").read_text())["smoothed"]
    assert rep["bridged"] > 0 and rep["ok"] > 0 and rep["poses"] == len(tr)
    # a horizontal lever arm without odometry has no heading to turn it with: refused
    r2 = _run(tmp_path / "x", rec / "gps" / "gps.log", "--antenna-lever-arm=-0.2,0.05,0.6")
    assert r2.exit_code == 2 and "needs --odometry" in r2.output
