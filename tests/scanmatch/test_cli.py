"""``gtrig scanmatch``: outputs on a small recording, and bad input as one line, exit 2, nothing written."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from gtrig.cli.main import app
from gtrig.io.posetrack import read_pose_track

runner = CliRunner()


def _run(*args: str):  # type: ignore[no-untyped-def]
    return runner.invoke(app, ["scanmatch", *args])


def test_validate_writes_table_and_track(stop_rec, tmp_path):
    rec, truth, _ = stop_rec
    sv = tmp_path / "survey.csv"
    sv.write_text("pose,x,y,theta\n" + "\n".join(f"{k + 1},{p[0] + 0.01},{p[1] - 0.01},{p[2] + 0.01}"
                                                  for k, p in enumerate(truth)) + "\n")
    out = tmp_path / "o" / "poses.csv"
    r = _run("validate", "--recording", str(rec), "--survey", str(sv), "--out", str(out))
    assert r.exit_code == 0, r.output
    assert "stops matched without a manual step" in r.output
    track = read_pose_track(out.with_suffix(".tum"), out.with_name("poses_cov.csv"))
    assert len(track) == len(truth) and track.frame_id == "stop1"
    rows = out.read_text().splitlines()
    assert rows[0].startswith("pose,x,y,theta") and len(rows) == len(truth) + 1


def _copy(rec: Path, tmp: Path) -> Path:
    dst = tmp / "rec"
    shutil.copytree(rec, dst)
    return dst


def _check_refused(r, out: Path, words: str) -> None:  # type: ignore[no-untyped-def]
    assert r.exit_code == 2, r.output
    lines = [x for x in r.output.strip().splitlines() if x.strip()]
    assert len(lines) == 1 and words in lines[0], r.output
    assert "Traceback" not in r.output
    assert not out.exists()
    assert not (out.parent.exists() and any(out.parent.iterdir()))


@pytest.mark.parametrize("case", ["beams", "nan", "stamps"])
def test_bad_scans_refused(stop_rec, tmp_path, case):
    rec = _copy(stop_rec[0], tmp_path)
    f = rec / "validation" / "onboard" / "sick_front.csv"
    lines = f.read_text().splitlines()
    if case == "beams":
        lines = [",".join(x.split(",")[:-1]) for x in lines]
        words = "beams"
    elif case == "nan":
        cells = lines[3].split(",")
        lines[3] = ",".join([cells[0]] + ["nan"] * (len(cells) - 1))
        # a whole stop of empty scans: each scan is refused where it is read
        for k in range(1, len(lines)):
            c = lines[k].split(",")
            lines[k] = ",".join([c[0]] + ["nan"] * (len(c) - 1))
        words = "no valid range"
    else:
        lines[2], lines[3] = lines[3], lines[2]
        words = "does not increase"
    f.write_text("\n".join(lines) + "\n")
    out = tmp_path / "out" / "poses.csv"
    _check_refused(_run("validate", "--recording", str(rec), "--out", str(out)), out, words)


def test_bad_map_refused(stop_rec, tmp_path):
    rec = stop_rec[0]
    init = tmp_path / "init.csv"
    init.write_text("pose,x,y,theta\n1,0,0,0\n")
    out = tmp_path / "out" / "poses.csv"
    m = tmp_path / "m.yaml"
    m.write_text("image: m.pgm\norigin: [0, 0, 0]\n")
    _check_refused(_run("map", "--map", str(m), "--recording", str(rec), "--initial", str(init), "--out", str(out)),
                   out, "resolution")
    m.write_text("image: m.pgm\nresolution: 0.05\norigin: [0, 0, 0]\n")
    (tmp_path / "m.pgm").write_bytes(b"not an image")
    _check_refused(_run("map", "--map", str(m), "--recording", str(rec), "--initial", str(init), "--out", str(out)),
                   out, "does not load")


def test_pairs_on_validation_sequence_with_review(stop_rec, tmp_path):
    rec, truth, _ = stop_rec
    # a guessed trajectory over the stops (TUM): truth displaced by a few centimetres
    iv = np.loadtxt(rec / "validation" / "poses.csv", delimiter=",", skiprows=1)
    tum = tmp_path / "g.tum"
    rows = []
    for (_, a, b), p in zip(iv, truth, strict=True):
        for t in (a - 0.01, b + 0.01):
            h = 0.5 * (p[2] + 0.01)
            rows.append(f"{t:.6f} {p[0] + 0.02:.6f} {p[1]:.6f} 0 0 0 {np.sin(h):.9f} {np.cos(h):.9f}")
    tum.write_text("\n".join(rows) + "\n")
    out = tmp_path / "o" / "relations.csv"
    html = tmp_path / "o" / "review.html"
    r = _run("pairs", "--recording", str(rec), "--sequence", "validation", "--guess", str(tum), "--every", "4",
             "--out", str(out), "--review", str(html))
    assert r.exit_code == 0, r.output
    head = out.read_text().splitlines()[0].split(",")
    assert head[:5] == ["t1", "t2", "dx", "dy", "dtheta"] and "verdict" in head
    raw = out.with_suffix(".relations").read_text().splitlines()
    assert all(len(x.split()) == 8 for x in raw)
    assert html.read_text().count("<figure>") == len(out.read_text().splitlines()) - 1
