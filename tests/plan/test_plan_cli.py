"""``gtrig plan``: writes its files, and refuses bad input in one line without writing anything."""

from __future__ import annotations

import numpy as np
import pytest
from typer.testing import CliRunner

from gtrig.cli.main import app
from gtrig.io.plan import read_plan_csv
from gtrig.rig.load import dump_rig
from gtrig.sim.gtroom import make_scene

runner = CliRunner()
AREA = "-1,0;2,0;2,4;-1,4"


@pytest.fixture(scope="module")
def rig_file(tmp_path_factory):
    p = tmp_path_factory.mktemp("rig") / "rig.yaml"
    dump_rig(make_scene(0).rig_nominal, p)
    return p


def test_plan_writes_its_files(rig_file, tmp_path):
    out = tmp_path / "plan"
    r = runner.invoke(app, ["plan", str(rig_file), "--out", str(out), "--area", AREA, "--grid-m", "0.5",
                            "--headings", "4"])
    assert r.exit_code == 0, r.output
    assert "target 1 mm / 0.05 deg" in r.output
    for f in ("plan_grid.csv", "plan.html", "summary.txt", "target.png", "sigma_fused.png", "coverage.png"):
        assert (out / f).stat().st_size > 0
    t = read_plan_csv(out / "plan_grid.csv")
    assert t.xytheta.shape[0] % 4 == 0 and t.xytheta.shape[0] >= 4 * 40
    assert np.isfinite(t.sigma_xy_m["fused"]).mean() > 0.9
    assert "data:image/png;base64," in (out / "plan.html").read_text()


def test_plan_suggests_a_camera(rig_file, tmp_path):
    out = tmp_path / "s"
    r = runner.invoke(app, ["plan", str(rig_file), "--out", str(out), "--area", AREA, "--grid-m", "0.5",
                            "--headings", "2", "--suggest", "cameras:1", "--suggest-positions", "4",
                            "--target-mm", "3", "--target-deg", "0.1"])
    assert r.exit_code == 0, r.output
    assert "suggested camera suggested1" in r.output
    from gtrig.rig.load import load_rig

    assert [c.name for c in load_rig(out / "rig_suggested.yaml").cameras][-1] == "suggested1"
    assert (out / "target_suggested.png").stat().st_size > 0


def test_plan_suggests_a_camera_and_a_scanner(rig_file, tmp_path):
    out = tmp_path / "s2"
    r = runner.invoke(app, ["plan", str(rig_file), "--out", str(out), "--area", AREA, "--grid-m", "0.5",
                            "--headings", "2", "--suggest", "cameras:1,scanners:1", "--suggest-positions", "4",
                            "--target-mm", "3", "--target-deg", "0.1"])
    assert r.exit_code == 0, r.output
    assert "suggested camera suggested1" in r.output and "suggested scanner suggested_laser1" in r.output
    from gtrig.rig.load import load_rig

    rig = load_rig(out / "rig_suggested.yaml")
    assert rig.cameras[-1].name == "suggested1" and rig.laser_scanners[-1].name == "suggested_laser1"


def test_plan_on_a_path(rig_file, tmp_path):
    tum = tmp_path / "p.tum"
    tum.write_text("".join(f"{i:.1f} {0.1 * i:.3f} 2.0 0 0 0 0 1\n" for i in range(10)))
    r = runner.invoke(app, ["plan", str(rig_file), "--out", str(tmp_path / "o"), "--path", str(tum)])
    assert r.exit_code == 0, r.output
    assert read_plan_csv(tmp_path / "o" / "plan_grid.csv").xytheta.shape[0] == 10


@pytest.mark.parametrize("args, expect", [
    (["--grid-m", "0"], "--grid-m"),
    (["--headings", "0"], "--headings"),
    (["--area", "0,0;1"], "--area vertex 2"),
    (["--area", "0,0;1,1;2,2"], "no area"),
    (["--area", AREA, "--sunlit", "0,0;1"], "--sunlit vertex 2"),
    (["--area", AREA, "--sunlit", "0,0;1,1;2,2"], "--sunlit: the polygon has no area"),
    (["--target-mm", "-1"], "--target-mm"),
    (["--clock-sigma-ms", "-1"], "--clock-sigma-ms"),
    (["--clock-sigma-ms", "nan"], "--clock-sigma-ms"),
    (["--path", "nothere.tum"], "nothere.tum"),
    (["--area", AREA, "--path", "x.tum"], "exclude each other"),
    (["--suggest", "lidars:1"], "--suggest"),
    (["--suggest", "cameras:1,cameras:2"], "--suggest"),
    (["--suggest", "scanners:1", "--suggest-scanner-height", "2"], "does not cut the hull"),
])
def test_plan_refuses_bad_input_in_one_line(rig_file, tmp_path, args, expect):
    out = tmp_path / "o"
    r = runner.invoke(app, ["plan", str(rig_file), "--out", str(out), *args])
    assert r.exit_code == 2, r.output
    lines = [x for x in r.output.splitlines() if x.strip()]
    assert len(lines) == 1 and lines[0].startswith("error:") and expect in lines[0], r.output
    assert "Traceback" not in r.output
    assert not out.exists() or not any(out.iterdir())


def test_plan_refuses_a_missing_rig(tmp_path):
    r = runner.invoke(app, ["plan", str(tmp_path / "none.yaml"), "--out", str(tmp_path / "o")])
    assert r.exit_code == 2 and r.output.startswith("error:") and "none.yaml" in r.output
