"""Bad input on the command line: one line naming the option or file, exit code 2, nothing written,
and no input ever overwritten."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from gtrig.cli.main import app

runner = CliRunner()

REF = {"O": (0.0, 0.0), "A": (0.0, 2.5), "B": (2.5, 0.0), "C": (2.5, 2.5)}
PTS = {"1": (1.0, 1.5), "2": (3.0, 1.0), "3": (1.5, 3.5)}


@pytest.fixture()
def survey(tmp_path: Path) -> dict[str, Path]:
    rng = np.random.default_rng(0)
    ref = tmp_path / "ref.csv"
    ref.write_text("name,x,y,sigma\n" + "".join(f"{n},{x},{y},0.0005\n" for n, (x, y) in REF.items()))
    d = tmp_path / "d.csv"
    rows = [f"{p},{r},{np.hypot(px - rx, py - ry) + rng.normal(0, 0.0005):.7f},0.00075\n"
            for p, (px, py) in PTS.items() for r, (rx, ry) in REF.items()]
    d.write_text("point,reference,distance,sigma\n" + "".join(rows))
    return {"ref": ref, "d": d, "dir": tmp_path}


def _fails_cleanly(args: list[str], *must_name: str) -> str:
    r = runner.invoke(app, args)
    assert r.exit_code == 2, r.output
    lines = [x for x in r.output.splitlines() if x.strip()]
    assert len(lines) == 1 and lines[0].startswith("error:"), r.output
    assert "Traceback" not in r.output
    for m in must_name:
        assert m in lines[0], lines[0]
    return lines[0]


def test_survey_points_works(survey):
    out = survey["dir"] / "points.csv"
    r = runner.invoke(app, ["survey", "points", "--reference", str(survey["ref"]), "--distances",
                            str(survey["d"]), "--out", str(out)])
    assert r.exit_code == 0, r.output
    assert out.read_text().count("\n") == 4


@pytest.mark.parametrize(("sigma", "why"), [("nan", "finite"), ("-1", "> 0"), ("0", "> 0"),
                                            ("2", "millimetres"), ("inf", "finite")])
def test_survey_sigma_checked_first(survey, sigma, why):
    out = survey["dir"] / "points.csv"
    _fails_cleanly(["survey", "points", "--reference", str(survey["ref"]), "--distances", str(survey["d"]),
                    "--out", str(out), "--sigma", sigma], "--sigma", why)
    assert not out.exists()


def test_output_equal_to_input_refused(survey):
    before = survey["d"].read_bytes()
    _fails_cleanly(["survey", "points", "--reference", str(survey["ref"]), "--distances", str(survey["d"]),
                    "--out", str(survey["d"])], "overwrite an input")
    assert survey["d"].read_bytes() == before


@pytest.mark.parametrize("where", ["folder", "under_file"])
def test_unusable_output_paths(survey, where):
    d = survey["dir"]
    (d / "afile").write_text("x")
    (d / "afolder").mkdir()
    out = {"folder": d / "afolder", "under_file": d / "afile" / "points.csv"}[where]
    _fails_cleanly(["survey", "points", "--reference", str(survey["ref"]), "--distances", str(survey["d"]),
                    "--out", str(out)], str(out))


@pytest.mark.parametrize(("opt", "val", "why"), [("--step", "1e-9", "--step"), ("--margin", "1e6", "--margin"),
                                                 ("--step", "nan", "finite")])
def test_predict_refuses_huge_grids_at_once(survey, opt, val, why):
    d = survey["dir"]
    pts = d / "points.csv"
    pts.write_text("name,x,y\n" + "".join(f"{n},{x},{y}\n" for n, (x, y) in {**REF, **PTS}.items()))
    rp = d / "rp.csv"
    rp.write_text("name,x,y\nO,0,0\nX,0.5,0\nY,0,0.5\n")
    _fails_cleanly(["survey", "predict", "--points", str(pts), "--robot-points", str(rp), opt, val], why)


def test_predict_grid_limit_in_the_library():
    from gtrig.errors import InputError
    from gtrig.survey.predict import predict_pose_uncertainty

    W = np.array([[0.0, 0.0], [10.0, 0.0], [0.0, 10.0]])
    with pytest.raises(InputError, match="cells"):
        predict_pose_uncertainty(W, None, np.array([[0, 0], [0.5, 0]]), 0.002, step_m=0.001)
