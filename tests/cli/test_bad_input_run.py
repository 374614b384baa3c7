"""Refusals inside ``gtrig run`` and ``gtrig demo``: a stage that refuses its input ends the run with one
``error: <stage>: ...`` line naming the file or field and the refusal's exit code (2, or 3 for no
convergence), never a crash log; a run configuration out of range is refused at load, before any work."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import typer
import yaml
from bad_input_kit import _rig_doc, refused, runner

from gtrig.cli.common import handle_errors
from gtrig.cli.main import app
from gtrig.errors import ConvergenceError


def _laser_recording(root: Path, beams_off: int) -> Path:
    """A recording holding only what the laser stage reads: scans of ``beams_off`` more beams than the
    rig's scanners have (0: as many)."""
    rec = root / "rec"
    doc = _rig_doc()
    rec.mkdir(parents=True)
    (rec / "rig.yaml").write_text(yaml.safe_dump(doc, sort_keys=False))
    for part in ("background", "run"):
        for sc in doc["laser_scanners"]:
            n = sc["beams"] + beams_off
            f = rec / part / "lasers" / f"{sc['name']}.csv"
            f.parent.mkdir(parents=True, exist_ok=True)
            f.write_text("timestamp," + ",".join(f"r_{i}" for i in range(n)) + "\n"
                         + "".join(f"{t:.3f}," + ",".join(["2.5"] * n) + "\n" for t in np.arange(0, 0.5, 0.1)))
    (rec / "calib").mkdir()
    (rec / "calib" / "laser_object.yaml").write_text("objects:\n- name: box\n  corners_xy: [[0, 0], [0.6, 0], "
                                                      "[0.6, 0.4], [0, 0.4]]\n")
    return rec


def _camera_recording(root: Path, poses: str = "1,0.0,1.0\n", rig_size: bool = False) -> Path:
    """A recording holding what GTvision reads: the validation stops ``poses``, one blank image per camera
    and sequence, 64 x 48 where the rig's cameras say otherwise (``rig_size``: the rig's size)."""
    import cv2

    rec = root / "rec"
    doc = _rig_doc()
    rec.mkdir(parents=True)
    (rec / "rig.yaml").write_text(yaml.safe_dump(doc, sort_keys=False))
    (rec / "validation").mkdir()
    (rec / "validation" / "poses.csv").write_text("pose,start_s,end_s\n" + poses)
    for seq in ("validation", "run"):
        for cam in doc["cameras"]:
            d = rec / seq / "cameras" / cam["name"]
            d.mkdir(parents=True)
            w, h = cam["resolution"] if rig_size else (64, 48)
            cv2.imwrite(str(d / "0.png"), np.full((h, w), 128, np.uint8))
            (d / "timestamps.csv").write_text("frame,stamp_s,file\n0,0.5,0.png\n")
    return rec


def _lines(output: str) -> list[str]:
    return [x for x in output.splitlines() if x.strip()]


def test_a_stage_refusing_its_input_inside_run_is_one_error_line(tmp_path: Path,
                                                                  monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("GTRIG_LOG_DIR", str(tmp_path))
    rec = _laser_recording(tmp_path, beams_off=-1)
    r = runner.invoke(app, ["run", "--recording", str(rec), "--out", str(tmp_path / "out"), "--stages", "laser"])
    assert r.exit_code == 2, r.output
    errors = [x for x in _lines(r.output) if x.startswith("error:")]
    assert len(errors) == 1, r.output
    assert errors[0].startswith("error: laser: ") and "laser0.csv" in errors[0] and "beams" in errors[0], errors
    assert "unexpected" not in r.output and "Traceback" not in r.output, r.output
    assert not list(tmp_path.glob("gtrig-crash-*.log"))
    assert not any(x.startswith("skipped") and "laser:" in x for x in _lines(r.output)), r.output


def test_images_of_another_size_than_the_rig_says_refused_before_detection(tmp_path: Path) -> None:
    rec = _camera_recording(tmp_path)
    r = runner.invoke(app, ["run", "--recording", str(rec), "--out", str(tmp_path / "out"), "--stages", "vision"])
    assert r.exit_code == 2, r.output
    errors = [x for x in _lines(r.output) if x.startswith("error:")]
    assert len(errors) == 1 and errors[0].startswith("error: vision: "), r.output
    assert "0.png: a 64 x 48 image, but the rig's cameras." in errors[0] and ".resolution is " in errors[0], errors
    assert not (tmp_path / "out" / "gt_vision_validation.checkpoint").exists()


@pytest.mark.parametrize("poses", ["1,5.0,2.0\n", "1,0.0,nan\n"])
def test_validation_stops_that_are_not_intervals_refused_naming_the_line(tmp_path: Path, poses: str) -> None:
    rec = _camera_recording(tmp_path, "# stop 0\n0,0.0,1.0\n" + poses, rig_size=True)
    r = runner.invoke(app, ["run", "--recording", str(rec), "--out", str(tmp_path / "out"), "--stages", "vision"])
    assert r.exit_code == 2, r.output
    errors = [x for x in _lines(r.output) if x.startswith("error:")]
    assert errors == [f"error: vision: {rec}/validation/poses.csv:4: start_s {poses.split(',')[1]} and end_s "
                      f"{poses.split(',')[2].strip()} are not an interval (finite, start before end)"], r.output


def test_no_marker_in_view_is_said_once_not_as_a_share_of_nothing(tmp_path: Path) -> None:
    """Blank images: the stops are not localized (a warning); the share of the instants with a marker in
    view cannot be measured, and is no second warning."""
    rec = _camera_recording(tmp_path, rig_size=True)
    out = tmp_path / "out"
    r = runner.invoke(app, ["run", "--recording", str(rec), "--out", str(out), "--stages", "vision"])
    assert r.exit_code == 0, r.output
    warned = [x for x in _lines(r.output) if x.startswith("warning")]
    assert "warning GTvision: validation, poses localized is 0 of 1 (expected all)" in warned, r.output
    assert not any("marker in view" in w for w in warned), warned
    from gtrig.pipeline import read_accuracy_csv

    checks = read_accuracy_csv(out / "summary.csv")
    assert checks[("GTvision", "validation, instants with no marker in view")] == 1
    assert np.isnan(checks[("GTvision", "validation, instants with a marker in view, localized")])


def test_demo_reports_a_refusing_stage_as_one_error_line(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """The demo's own path after the run (its stages are the run's): the refusal's line and exit code 3."""
    import gtrig.pipeline as pipeline
    import gtrig.sim.recording as sim_recording
    from gtrig.pipeline import PipelineResult

    monkeypatch.setenv("GTRIG_LOG_DIR", str(tmp_path))
    why = "cameras: the network did not converge"
    monkeypatch.setattr(sim_recording, "simulate", lambda cfg, rec, on_step=None: rec.mkdir(parents=True))
    monkeypatch.setattr(pipeline, "run", lambda *a, **k: PipelineResult(
        (), {}, {"cameras": why}, exit_code=ConvergenceError.exit_code, refused={"cameras": why}))
    monkeypatch.setattr("gtrig.io.recording.summarize", lambda rec: [])
    monkeypatch.setattr("gtrig.cli.demo._scanmatch_validate", lambda rec, results: None)
    monkeypatch.setattr("gtrig.report.write_report", lambda *a, **k: tmp_path / "report.html")
    r = runner.invoke(app, ["demo", "--out", str(tmp_path / "demo"), "--quick"])
    assert r.exit_code == 3, r.output
    assert [x for x in _lines(r.output) if x.startswith("error:")] == [f"error: cameras: {why}"], r.output
    assert not list(tmp_path.glob("gtrig-crash-*.log")) and "unexpected" not in r.output


@pytest.mark.parametrize(("text", "field"), [
    ("laser: {track: {max_gap_s: -1}}\n", "laser.track.max_gap_s: Input should be greater than 0"),
    ("laser: {track: {icp: {gate_m: .nan}}}\n", "laser.track.icp.gate_m: Input should be a finite number"),
    ("laser: {track: {chunk_frames: 0}}\n", "laser.track.chunk_frames: Input should be greater than or equal to 1"),
    ("laser: {track: {smoother_order: 5}}\n", "laser.track.smoother_order"),
    ("markers: {options: {view_p: 1.5}}\n", "markers.options.view_p: Input should be less than 1"),
    ("vision: {sync_tol_s: .inf}\n", "vision.sync_tol_s: Input should be a finite number"),
    ("fusion: {max_gap_s: 0}\n", "fusion.max_gap_s: Input should be greater than 0"),
])
def test_run_configuration_out_of_range_refused_before_any_work(tmp_path: Path, text: str, field: str) -> None:
    rec = _laser_recording(tmp_path / "inputs", beams_off=0)
    (tmp_path / "inputs" / "run.yaml").write_text(text)
    line = refused(["run", "--recording", str(rec), "--out", "{o}/results", "--config", "{d}/run.yaml"],
                   tmp_path / "inputs", tmp_path / "o", must=[field, "{d}/run.yaml"])
    assert not (tmp_path / "o" / "results").exists(), line


def test_the_default_configuration_is_within_its_ranges() -> None:
    from gtrig.config import RunConfig

    assert RunConfig.model_validate(RunConfig().model_dump()) == RunConfig()


@pytest.mark.parametrize("code", [0, 1, 3])
def test_a_verbs_own_exit_code_is_kept_without_a_crash_log(capsys: pytest.CaptureFixture[str], tmp_path: Path,
                                                            monkeypatch: pytest.MonkeyPatch, code: int) -> None:
    """``calib check`` and ``calib steady`` end a failed verdict with ``typer.Exit(1)``: that exit code, no
    ``unexpected`` line."""
    monkeypatch.setenv("GTRIG_LOG_DIR", str(tmp_path))

    @handle_errors
    def verb() -> None:
        raise typer.Exit(code)

    with pytest.raises(SystemExit) as e:
        verb()
    assert e.value.code == code
    assert capsys.readouterr().err == ""
    assert not list(tmp_path.glob("gtrig-crash-*.log"))
