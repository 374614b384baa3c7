"""The pipeline's runner with small stand-in stages: typed hand-over, declarations checked, reuse keyed on
code, options, recording and upstream, ``--from``, ``--stages``, interruption, one-line refusals."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from gtrig.config import RunConfig, config_from_dict
from gtrig.errors import ConfigError, ConvergenceError, InputError
from gtrig.pipeline import AccuracyRow, Stage, StageInput, StageOutput
from gtrig.pipeline.runner import run_stages
from gtrig.rig import dump_rig
from gtrig.rig.models import Hull, Rig, Robot
from gtrig.trajectory import PoseTrack


@pytest.fixture()
def rec(tmp_path: Path) -> Path:
    r = tmp_path / "rec"
    (r / "survey").mkdir(parents=True)
    (r / "survey" / "readings.csv").write_text("a,b\n1,2\n")
    (r / "run").mkdir()
    (r / "run" / "scans.csv").write_text("t\n0\n")
    dump_rig(Rig(robot=Robot(hull=Hull(length_m=0.78, width_m=0.57, z_min_m=0.05, z_max_m=0.55))), r / "rig.yaml")
    return r


class Calls:
    def __init__(self) -> None:
        self.names: list[str] = []
        self.fail: dict[str, BaseException] = {}


def make_stages(calls: Calls) -> tuple[Stage, ...]:
    def first(inp: StageInput) -> StageOutput:
        calls.names.append("first")
        if "first" in calls.fail:
            raise calls.fail["first"]
        # the rig is there from the start (the recording's nominal one)
        assert inp.products.rig is not None and inp.products.rig.robot.hull.length_m == 0.78
        (inp.out / "first.txt").write_text("1\n")
        return StageOutput({"survey": ("points", 3)}, rows=(AccuracyRow("first", "value", 1.0, "m"),),
                           outputs=("first.txt",))

    def second(inp: StageInput) -> StageOutput:
        calls.names.append("second")
        if "second" in calls.fail:
            raise calls.fail["second"]
        assert inp.products.survey == ("points", 3)  # the object itself, not a file to read again
        gap = inp.config.laser.track.max_gap_s
        track = PoseTrack.from_xytheta(np.arange(3.0), np.zeros((3, 3)), cov=np.tile(np.eye(3), (3, 1, 1)),
                                       source="toy")
        return StageOutput({"tracks/toy": track}, checks=(AccuracyRow("second", "gap", gap, "s", "<= 1", gap <= 1),))

    def third(inp: StageInput) -> StageOutput:
        calls.names.append("third")
        assert len(inp.products.tracks["toy"]) == 3
        return StageOutput()

    return (
        Stage("first", "first stage", first, produces=("survey",), reads=("survey/readings.csv",), section="survey"),
        Stage("second", "second stage", second, consumes=("survey",), produces=("tracks/toy",),
              reads=("run/scans.csv",), section="laser"),
        Stage("third", "third stage", third, consumes=("tracks/toy",)),
    )


def test_products_handed_on_and_finished_stages_reused(rec: Path, tmp_path: Path) -> None:
    calls = Calls()
    stages = make_stages(calls)
    out = tmp_path / "out"
    r1 = run_stages(stages, rec, out)
    assert calls.names == ["first", "second", "third"] and not r1.skipped and r1.exit_code == 0
    assert r1.products.tracks["toy"].source == "toy" and (out / "accuracy.csv").is_file()
    assert (out / "run.yaml").is_file() and (out / "summary.csv").is_file()
    calls.names.clear()
    r2 = run_stages(stages, rec, out)
    assert calls.names == [] and r2.reused == ("first", "second", "third")
    assert r2.rows == r1.rows and r2.checks == r1.checks  # the table of a reused stage is its own
    # --from reruns that stage and every later one
    run_stages(stages, rec, out, from_stage="second")
    assert calls.names == ["second", "third"]
    # an option of a stage's section reruns it and what consumes its products, not the stages before
    calls.names.clear()
    r3 = run_stages(stages, rec, out, config_from_dict({"laser": {"track": {"max_gap_s": 0.5}}}))
    assert calls.names == ["second", "third"] and r3.checks[0].value == 0.5
    # a changed input file in the recording reruns the stages that read it and those downstream
    calls.names.clear()
    (rec / "survey" / "readings.csv").write_text("a,b\n1,3\n")
    run_stages(stages, rec, out, config_from_dict({"laser": {"track": {"max_gap_s": 0.5}}}))
    assert calls.names == ["first", "second", "third"]
    # a deleted output: that stage is not finished any more
    calls.names.clear()
    (out / "first.txt").unlink()
    run_stages(stages, rec, out, config_from_dict({"laser": {"track": {"max_gap_s": 0.5}}}))
    assert calls.names[0] == "first"


def test_truth_appearing_reruns_every_stage(rec: Path, tmp_path: Path) -> None:
    calls = Calls()
    stages = make_stages(calls)
    run_stages(stages, rec, tmp_path / "out")
    (rec / "truth").mkdir()
    (rec / "truth" / "run.tum").write_text("0 0 0 0 0 0 0 1\n")
    calls.names.clear()
    run_stages(stages, rec, tmp_path / "out")
    assert calls.names == ["first", "second", "third"]


def test_interrupted_run_resumes_after_the_last_finished_stage(rec: Path, tmp_path: Path) -> None:
    calls = Calls()
    stages = make_stages(calls)
    calls.fail["second"] = KeyboardInterrupt()
    with pytest.raises(KeyboardInterrupt):
        run_stages(stages, rec, tmp_path / "out")
    calls.names.clear()
    calls.fail.clear()
    r = run_stages(stages, rec, tmp_path / "out")
    assert calls.names == ["second", "third"] and r.reused == ("first",)


def test_only_some_stages(rec: Path, tmp_path: Path) -> None:
    calls = Calls()
    stages = make_stages(calls)
    r = run_stages(stages, rec, tmp_path / "out", only=["first"])
    assert calls.names == ["first"] and set(r.skipped) == {"second", "third"}
    calls.names.clear()
    r = run_stages(stages, rec, tmp_path / "out", only=["second", "third"])
    assert calls.names == ["second", "third"] and r.reused == ("first",)  # what they need, from its last run
    with pytest.raises(ConfigError, match="unknown stage 'fourth'; the stages are first, second, third"):
        run_stages(stages, rec, tmp_path / "out", only=["fourth"])
    with pytest.raises(ConfigError, match="--from: unknown stage"):
        run_stages(stages, rec, tmp_path / "out", from_stage="zeroth")


def test_a_refusing_stage_skips_its_consumers_and_sets_the_exit_code(rec: Path, tmp_path: Path) -> None:
    calls = Calls()
    stages = make_stages(calls)
    calls.fail["first"] = ConvergenceError("survey: two minima fit the readings")
    r = run_stages(stages, rec, tmp_path / "out")
    assert calls.names == ["first"] and r.exit_code == 3
    assert r.skipped["first"] == "survey: two minima fit the readings"
    assert r.skipped["second"] == "needs survey, which no earlier stage produced"
    assert "needs tracks/toy" in r.skipped["third"]


def test_missing_part_of_the_recording_names_stage_and_file(rec: Path, tmp_path: Path) -> None:
    calls = Calls()
    (rec / "run" / "scans.csv").unlink()
    with pytest.raises(InputError) as e:
        run_stages(make_stages(calls), rec, tmp_path / "out")
    msg = str(e.value)
    assert "\n" not in msg and "stage second" in msg and str(rec / "run" / "scans.csv") in msg
    assert calls.names == [] and not (tmp_path / "out" / "accuracy.csv").exists()  # refused before any stage
    # without that stage, the rest runs
    r = run_stages(make_stages(calls), rec, tmp_path / "out", only=["first"])
    assert calls.names == ["first"] and r.exit_code == 0


def test_not_a_recording(tmp_path: Path) -> None:
    (tmp_path / "empty").mkdir()
    with pytest.raises(InputError, match="not a recording"):
        run_stages(make_stages(Calls()), tmp_path / "empty", tmp_path / "out")


def test_stage_declarations_are_checked(rec: Path, tmp_path: Path) -> None:
    with pytest.raises(ValueError, match="'trax/x' is not a product"):
        Stage("bad", "bad", lambda inp: StageOutput(), consumes=("trax/x",))
    sneaky = Stage("sneaky", "sneaky", lambda inp: StageOutput({"survey": 1}), produces=("tracks/x",))
    with pytest.raises(ValueError, match="does not declare"):
        run_stages((sneaky,), rec, tmp_path / "out", RunConfig())


def _rig_stages() -> tuple[Stage, ...]:
    def hull(inp: StageInput, **kw: float) -> StageOutput:
        rig = inp.products.rig
        assert rig is not None
        robot = rig.robot.model_copy(update={"hull": rig.robot.hull.model_copy(update=kw)})
        return StageOutput({"rig": rig.model_copy(update={"robot": robot})})

    return (Stage("length", "length", lambda inp: hull(inp, length_m=0.80), produces=("rig",)),
            Stage("width", "width", lambda inp: hull(inp, width_m=0.60), produces=("rig",)))


def test_a_run_leaving_out_a_calibration_keeps_the_earlier_rig(rec: Path, tmp_path: Path) -> None:
    """A run of some calibration stages alone does not write the recording's nominal values over what the
    others calibrated before; on a fresh output it writes what it has."""
    from gtrig.rig import load_rig

    out = tmp_path / "out"
    run_stages(_rig_stages(), rec, out)
    hull = load_rig(out / "rig.calibrated.yaml").robot.hull
    assert (hull.length_m, hull.width_m) == (0.80, 0.60)
    r = run_stages(_rig_stages(), rec, out, only=["length"], reuse=False)
    assert "width" in r.skipped
    assert load_rig(out / "rig.calibrated.yaml").robot.hull.width_m == 0.60
    run_stages(_rig_stages(), rec, tmp_path / "fresh", only=["length"])
    hull = load_rig(tmp_path / "fresh" / "rig.calibrated.yaml").robot.hull
    assert (hull.length_m, hull.width_m) == (0.80, 0.57)
