"""``gtrig evaluate slam`` and ``compare``: outputs, and one clear line with exit code 2 for bad input."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from gtrig.cli.main import app
from gtrig.io.posetrack import write_pose_track
from gtrig.trajectory import PoseTrack

runner = CliRunner()
D = Path(__file__).resolve().parents[2] / ".." / "shared" / "data"
B25 = D / "rawseeds" / "Bicocca_2009-02-25b"


def _track(t0: float = 0.0, n: int = 300, scale_t: float = 1.0) -> PoseTrack:
    t = t0 + np.arange(n) * 0.05
    xy = np.column_stack([2 * np.cos(0.2 * t), np.sin(0.4 * t), 0.2 * t + np.pi / 2])
    cov = np.tile(np.diag([1e-6, 1e-6, 1e-6]), (n, 1, 1))
    return PoseTrack.from_xytheta(t * scale_t, xy, cov=cov, source="sim")


def _fail(args: list[str], needle: str) -> None:
    res = runner.invoke(app, args)
    assert res.exit_code == 2, res.output
    assert "Traceback" not in res.output and needle in res.output, res.output
    errors = [ln for ln in res.output.splitlines() if ln.startswith("error:")]
    assert len(errors) == 1 and needle in errors[0], res.output


def test_bad_inputs(tmp_path: Path) -> None:
    gt = tmp_path / "gt.tum"
    write_pose_track(_track(), gt, tmp_path / "gt_cov.csv")
    late = tmp_path / "late.tum"
    write_pose_track(_track(t0=1000.0), late)
    ns = tmp_path / "ns.tum"
    write_pose_track(_track(scale_t=1e9), ns)
    odd = tmp_path / "est.xyz"
    odd.write_text("0 0 0\n")
    _fail(["evaluate", "slam", "--gt", str(gt), "--estimate", str(odd)], "not a trajectory in any known format")
    _fail(["evaluate", "slam", "--gt", str(gt), "--estimate", str(late)], "no common time span")
    _fail(["evaluate", "slam", "--gt", str(gt), "--estimate", str(ns)], "time unit mismatch")
    rel = tmp_path / "r.relations"
    rel.write_text("5000 5001 0.1 0 0 0 0 0\n")
    _fail(["evaluate", "slam", "--gt", str(gt), "--estimate", str(gt), "--relations", str(rel)], "relations")
    _fail(["evaluate", "slam", "--gt", str(gt), "--estimate", str(gt), "--format-in", "euroc"], "asked for")
    bad = tmp_path / "bad.tum"
    bad.write_text("0 1 2 3\n")
    _fail(["evaluate", "slam", "--gt", str(gt), "--estimate", str(bad)], "bad.tum:1")


def test_self_is_perfect_json(tmp_path: Path) -> None:
    gt = tmp_path / "gt.tum"
    write_pose_track(_track(), gt, tmp_path / "gt_cov.csv")
    res = runner.invoke(app, ["evaluate", "slam", "--gt", str(gt), "--estimate", str(gt), "--format", "json",
                              "--align", "none"])
    assert res.exit_code == 0, res.output
    out = json.loads(res.stdout)
    assert out["evo"]["APE trans"]["rmse"] < 1e-9 and out["pairing"]["interpolate-gt"]["matched"] == 300
    assert out["association"]["chosen"] == "auto"
    assert out["gt-aware"]["indistinguishable from GT"]["verdict"] == 1.0


@pytest.mark.skipif(not B25.is_dir(), reason="RAWSEEDS data missing")
def test_rawseeds_cli_and_compare(tmp_path: Path) -> None:
    res = runner.invoke(app, ["evaluate", "slam", "--gt", str(B25 / "Bicocca_2009-02-25b-GROUNDTRUTH.csv"),
                              "--estimate", str(B25 / "SOLUTION_GraphSLAM_Laser.csv"), "--relations",
                              str(B25 / "Bicocca_2009-02-25b.relations"), "--metrics", "rawseeds", "--align", "se2",
                              "--format", "csv", "--plot", str(tmp_path / "fig")])
    assert res.exit_code == 0, res.output
    assert "rawseeds,T-RPE,value" in res.output and "evo," not in res.output
    assert len(list((tmp_path / "fig").glob("*.png"))) >= 3
    res = runner.invoke(app, ["evaluate", "compare", "--a", str(B25 / "Bicocca_2009-02-25b-GROUNDTRUTH.csv"),
                              "--b", str(B25 / "Bicocca_2009-02-25b-GT-extended.csv"), "--align", "se2",
                              "--max-gap", "1", "--format", "csv"])
    assert res.exit_code == 0, res.output
    assert "APE trans,rmse" in res.output
