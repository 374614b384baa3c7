"""The run configuration: the stages' own defaults, partial YAML overrides, one line for a bad file."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import pytest
import yaml
from typer.testing import CliRunner

from gtrig.cli.main import app
from gtrig.config import RunConfig, apply_to_dataclass, load_config, write_config
from gtrig.errors import ConfigError
from gtrig.laser.track import TrackSettings
from gtrig.markers.robotcal.calibrate import RobotCalOptions
from gtrig.rig import dump_rig
from gtrig.rig.models import Hull, Rig, Robot
from gtrig.vision.covariance import UNCALIBRATED_MARKERS
from gtrig.vision.estimate import VisionOptions

runner = CliRunner()


def test_defaults_are_the_stages_own() -> None:
    cfg = RunConfig()
    assert cfg.overrides() == {}
    assert apply_to_dataclass(cfg.laser.track, TrackSettings()) == TrackSettings()
    assert apply_to_dataclass(cfg.markers.options, RobotCalOptions()) == RobotCalOptions()
    v = VisionOptions(rig_uncertainty=UNCALIBRATED_MARKERS)
    assert apply_to_dataclass(cfg.vision.options, v) is v  # nothing changed: the very same options
    # every scalar field of the dataclasses is configurable, with its default
    for f in dataclasses.fields(TrackSettings):
        if f.name != "icp":
            assert getattr(cfg.laser.track, f.name) == f.default, f.name


def test_partial_yaml_overrides(tmp_path: Path) -> None:
    p = tmp_path / "run.yaml"
    p.write_text("laser:\n  track:\n    max_gap_s: 0.4\n    icp: {gate_m: 0.1}\nvision: {detector: aruco}\n")
    cfg = load_config(p)
    st = apply_to_dataclass(cfg.laser.track, TrackSettings())
    assert st.max_gap_s == 0.4 and st.icp.gate_m == 0.1
    assert st.lost_after == TrackSettings().lost_after and st.icp.huber_k == TrackSettings().icp.huber_k
    assert cfg.vision.detector == "aruco" and cfg.survey == RunConfig().survey
    # the effective configuration written next to the results reads back as the same configuration
    write_config(cfg, tmp_path / "out" / "run.yaml")
    assert load_config(tmp_path / "out" / "run.yaml") == cfg
    assert yaml.safe_load((tmp_path / "out" / "run.yaml").read_text())["laser"]["track"]["max_gap_s"] == 0.4


@pytest.mark.parametrize(("text", "expect"), [
    ("laser:\n  trak: {max_gap_s: 1}\n", "laser.trak: unknown key"),
    ("laser:\n  track: {max_gap_s: soon}\n", "laser.track.max_gap_s: Input should be a valid number"),
    ("vision: {detector: sift}\n", "vision.detector: Input should be 'auto', 'gtrig' or 'aruco'"),
    ("workers: -1\n", "workers: Input should be greater than or equal to 0"),
    ("- 1\n- 2\n", "expected a mapping of sections"),
    ("laser: [\n", "not valid YAML"),
])
def test_bad_configuration_is_one_line(tmp_path: Path, text: str, expect: str) -> None:
    p = tmp_path / "run.yaml"
    p.write_text(text)
    with pytest.raises(ConfigError) as e:
        load_config(p)
    assert expect in str(e.value) and str(p) in str(e.value) and "\n" not in str(e.value)


def test_cli_print_config_and_bad_inputs(tmp_path: Path) -> None:
    r = runner.invoke(app, ["run", "--print-config"])
    assert r.exit_code == 0, r.output
    assert RunConfig.model_validate(yaml.safe_load(r.output)) == RunConfig()
    r = runner.invoke(app, ["run", "--print-config", "--workers", "3"])
    assert yaml.safe_load(r.output)["workers"] == 3
    # a recording with only its rig: the first stage asked for names what it lacks
    only_rig = tmp_path / "only_rig"
    hull = Hull(length_m=0.78, width_m=0.57, z_min_m=0.05, z_max_m=0.55)
    dump_rig(Rig(robot=Robot(hull=hull)), only_rig / "rig.yaml")
    r = runner.invoke(app, ["run", "--recording", str(only_rig), "--out", str(tmp_path / "o2")])
    assert r.exit_code == 2 and "stage survey needs" in r.output and "reference_points.csv" in r.output, r.output
    assert len([ln for ln in r.output.splitlines() if ln.strip()]) == 1
    r = runner.invoke(app, ["run", "--recording", str(only_rig), "--out", str(tmp_path / "o2"), "--stages", "laser"])
    assert r.exit_code == 2 and "stage laser needs" in r.output and "lasers" in r.output, r.output
    bad = tmp_path / "bad.yaml"
    bad.write_text("survey: {alpha: 2}\n")
    (tmp_path / "folder").mkdir()
    for args, expect in (
        (["--config", str(bad)], "survey.alpha: Input should be less than 1"),
        (["--config", str(tmp_path / "none.yaml")], "no such file"),
        ([], "not a recording (no rig.yaml"),
        (["--stages", "survey,teleport"], "unknown stage 'teleport'"),
    ):
        r = runner.invoke(app, ["run", "--recording", str(tmp_path / "folder"), "--out", str(tmp_path / "o"), *args])
        assert r.exit_code == 2, (args, r.output)
        lines = [ln for ln in r.output.splitlines() if ln.strip()]
        assert len(lines) == 1 and expect in r.output and "Traceback" not in r.output, r.output
