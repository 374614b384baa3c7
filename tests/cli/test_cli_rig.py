"""CLI smoke tests: one-line errors and exit codes, never a traceback."""

from __future__ import annotations

from pathlib import Path

from typer.testing import CliRunner

from gtrig.cli.main import app
from gtrig.rig import dump_rig
from gtrig.sim.gtroom import make_scene

runner = CliRunner()


def test_rig_check_ok(tmp_path: Path) -> None:
    dump_rig(make_scene(0).rig_nominal, tmp_path / "rig.yaml")
    r = runner.invoke(app, ["rig", "check", str(tmp_path / "rig.yaml")])
    assert r.exit_code == 0, r.output
    assert "valid rig 'gtroom'" in r.output
    assert "cam3" in r.output and "laser3" in r.output


def test_rig_check_error_is_one_line(tmp_path: Path) -> None:
    p = tmp_path / "rig.yaml"
    dump_rig(make_scene(0).rig_nominal, p)
    p.write_text(p.read_text().replace("side_m: 0.156", "side_m: 156.0", 1))
    r = runner.invoke(app, ["rig", "check", str(p)])
    assert r.exit_code == 2
    lines = [x for x in r.output.splitlines() if x.strip()]
    assert len(lines) == 1 and lines[0].startswith("error:"), r.output
    assert "side_m" in lines[0] and "millimetres" in lines[0]
    assert "Traceback" not in r.output


def test_version() -> None:
    r = runner.invoke(app, ["--version"])
    assert r.exit_code == 0 and "gtrig" in r.output
