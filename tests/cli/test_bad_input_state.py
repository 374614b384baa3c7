"""Bad input that is not a refusal on the command line: a corrupt GTvision checkpoint (reported and
restarted, never trusted), a verb whose second output fails (neither output written, the previous ones
kept), results that were wrong while the exit code was 0 (TUM files paired by row; a moved camera called
steady under NaN thresholds), and the error printer itself (markup, exit codes)."""

from __future__ import annotations

import json
import logging
from pathlib import Path

import numpy as np
import pytest
from bad_input_kit import refused, runner

from gtrig.cli.main import app
from gtrig.errors import FormatError, InputError
from gtrig.vision.sequence import _scan_checkpoint


def _load_checkpoint(path: Path, key: str) -> tuple[dict[str, dict[int, tuple[object, ...]]], int]:
    """The detections of every good line of the checkpoint (by camera and row) and its good length."""
    dets: dict[str, dict[int, tuple[object, ...]]] = {}
    good = _scan_checkpoint(path, key, lambda at, cam, got: dets.setdefault(cam, {}).update(got))
    return dets, good


@pytest.mark.parametrize(("text", "rows"), [
    ("{not json\n", 0),                                          # a torn or foreign header
    ("[1, 2, 3]\n", 0),                                          # JSON of the wrong type
    ('{"key": 5}\n', 0),                                         # a header without a key string
    ('{"key": "K"}\n{"camera": "a", "frames": [[0, []]]}\n{"camera": 3, "frames": "x"}\n'
     '{"camera": "a", "frames": [[2, []]]}\n', 1),              # a damaged line: stop there
    ('{"key": "K"}\n{"camera": "a", "frames": [[0, []]]}\n[1]\n', 1),
    ('{"key": "K"}\n{"camera": "a", "frames": 7}\n', 0),
    ('{"key": "K"}\n{"camera": "a", "frames": [[0, [[3, [[0, 0]], [[1]]]]]]}\n', 0),  # a view of the wrong shape
    ('{"key": "K"}\n{"camera": "a", "frames": [[0, []]]}', 0),  # a last line cut before its end
    ('{"key": "K"}\n\x00\x01\x02\n', 0),
])
def test_corrupt_checkpoint_is_restarted_not_trusted(tmp_path: Path, caplog: pytest.LogCaptureFixture,
                                                     text: str, rows: int) -> None:
    ck = tmp_path / "v.tum.checkpoint.jsonl"
    ck.write_text(text, encoding="utf-8", errors="surrogateescape")
    with caplog.at_level(logging.WARNING):
        dets, good = _load_checkpoint(ck, "K")
    assert sum(len(v) for v in dets.values()) == rows
    assert all(isinstance(v, tuple) for d in dets.values() for v in d.values())
    assert good <= len(text.encode("utf-8", "surrogateescape"))


def test_checkpoint_of_another_run_is_refused(tmp_path: Path) -> None:
    ck = tmp_path / "v.tum.checkpoint.jsonl"
    ck.write_text('{"key": "other"}\n')
    with pytest.raises(InputError, match="checkpoint of another run"):
        _load_checkpoint(ck, "K")


def test_survey_adjust_second_output_failing_writes_neither(d: Path, tmp_path: Path,
                                                            monkeypatch: pytest.MonkeyPatch) -> None:
    import gtrig.io.survey_csv as sc
    import gtrig.survey.recording  # noqa: F401  (imported first under the patch, it would keep `fail`)

    o = tmp_path / "o"
    o.mkdir()
    (o / "points.csv").write_text("previous points\n")

    def fail(*args: object, **kwargs: object) -> None:
        raise PermissionError(13, "Permission denied", str(o / "poses.csv"))

    monkeypatch.setattr(sc, "write_poses", fail)
    args = ["survey", "adjust", "--reference", str(d / "ref.csv"), "--distances", str(d / "d.csv"),
            "--robot-points", str(d / "rp.csv"), "--pose-distances", str(d / "pd.csv"),
            "--out-points", str(o / "points.csv"), "--out-poses", str(o / "poses.csv")]
    r = runner.invoke(app, args)
    lines = [x for x in r.output.splitlines() if x.startswith("error:")]
    assert r.exit_code in (2, 3) and len(lines) == 1 and "Traceback" not in r.output, r.output
    # neither output: the previous points are kept, no poses and no temporary
    assert (o / "points.csv").read_text() == "previous points\n"
    assert sorted(p.name for p in o.iterdir()) == ["points.csv"]


def test_tum_files_are_paired_by_stamp_not_by_row(d: Path, tmp_path: Path) -> None:
    ref = np.loadtxt(d / "ref.tum")
    est = ref.copy()
    est[:, 1] += 0.001
    half = tmp_path / "half.tum"  # every other row dropped: still 1 mm errors, not a path's length
    np.savetxt(half, est[::2], fmt="%.6f")
    r = runner.invoke(app, ["evaluate", "poses", "--reference", str(d / "ref.tum"), "--estimate", str(half),
                            "--format", "csv", "--per-pose"])
    assert r.exit_code == 0, r.output
    errs = [abs(float(line.split(",")[1])) for line in r.output.splitlines()[1:]
            if line and line[0].isdigit() and line.count(",") == 4]
    assert errs and max(errs) == pytest.approx(0.001, abs=1e-6)
    shifted = tmp_path / "shifted.tum"  # every stamp a million seconds later: nothing pairs, no "0 error"
    est[:, 0] += 1e6
    np.savetxt(shifted, est, fmt="%.6f")
    refused(["evaluate", "poses", "--reference", str(d / "ref.tum"), "--estimate", str(shifted)], d,
            tmp_path / "o", 2, ["no pair"])


def test_rig_check_refuses_nan_where_a_number_is_meant(d: Path, tmp_path: Path) -> None:
    import yaml

    doc = yaml.safe_load((d / "rig.yaml").read_text())
    for where in (("cameras", 0, "T_world_cam", "xyz", 0), ("laser_scanners", 1, "rate_hz"),
                  ("robot", "hull", "length_m")):
        bad = yaml.safe_load((d / "rig.yaml").read_text())
        node = bad
        for k in where[:-1]:
            node = node[k]
        node[where[-1]] = float("nan")
        p = tmp_path / f"rig_{where[0]}.yaml"
        p.write_text(yaml.safe_dump(bad))
        refused(["rig", "check", str(p)], d, tmp_path / "o", 2, [str(p)])
    assert doc  # the valid rig itself passes
    r = runner.invoke(app, ["rig", "check", str(d / "rig.yaml")])
    assert r.exit_code == 0, r.output


def test_usage_errors_are_one_line(d: Path, tmp_path: Path) -> None:
    line = refused(["survey", "points", "--reference"], d, tmp_path / "o", 2, ["--reference"])
    assert "Usage" not in line
    r = runner.invoke(app, ["survey"])  # a group alone still shows its help
    assert "Usage" in r.output


def test_json_state_of_sim_written_by_sim_is_accepted(tmp_path: Path) -> None:
    from gtrig.sim.recording import STEPS, _read_state

    p = tmp_path / "state.json"
    p.write_text(json.dumps({"config": "abc", "done": [STEPS[0][0]]}))
    assert _read_state(p)["done"] == [STEPS[0][0]]


def test_images_beyond_the_size_limit_refused(d: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    import gtrig.io.frames as frames

    # the 64-megapixel limit, lowered under this 64 x 48 px image (a real 20000 x 20000 px one costs 400 MB)
    monkeypatch.setattr(frames, "MAX_IMAGE_PIXELS", 1000)
    refused(["markers", "detect", str(d / "images" / "0.png"), "--family", "artoolkitplus_simple", "--out",
             str(tmp_path / "o" / "det.json")], d, tmp_path / "o", 2, [str(d / "images" / "0.png"), "megapixels"])
    with pytest.raises(FormatError, match="megapixels"):
        frames.read_image(d / "images" / "0.png")
