"""``gtrig calib``: a check's truth CSV may not name an image outside ``--images`` (the line is named,
nothing is read); the calibrated rig and its report are written all or none."""

from __future__ import annotations

import errno
from pathlib import Path

import numpy as np
import pytest
import yaml
from bad_input_kit import _rig_doc, refused, runner, snapshot

from gtrig.cli.main import app


@pytest.fixture(scope="module")
def inputs(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A rig, ``images/<cam>/0.png`` (no board in it), and an image beside ``images/`` that no check may read."""
    import cv2

    d = tmp_path_factory.mktemp("calib_inputs")
    doc = _rig_doc()
    (d / "rig.yaml").write_text(yaml.safe_dump(doc, sort_keys=False))
    cam = doc["cameras"][0]["name"]
    (d / "images" / cam).mkdir(parents=True)
    cv2.imwrite(str(d / "images" / cam / "0.png"), np.full((48, 64), 128, np.uint8))
    cv2.imwrite(str(d / "outside.png"), np.full((48, 64), 128, np.uint8))
    head = "camera,image,x,y,z\n"
    (d / "ok.csv").write_text(f"{head}{cam},0.png,1,2,0.7\n")
    (d / "up.csv").write_text(f"{head}{cam},0.png,1,2,0.7\n{cam},../../outside.png,1,2,0.7\n")
    (d / "up_win.csv").write_text(f"{head}{cam},..\\..\\outside.png,1,2,0.7\n")
    (d / "absolute.csv").write_text(f"{head}# a comment\n{cam},{d / 'outside.png'},1,2,0.7\n")
    return d


@pytest.mark.parametrize(("csv", "line"), [("up.csv", 3), ("up_win.csv", 2), ("absolute.csv", 3)])
def test_calib_check_refuses_an_image_outside_the_images_folder(inputs: Path, tmp_path: Path,
                                                                 csv: str, line: int) -> None:
    refused(["calib", "check", "--rig", "{d}/rig.yaml", "--images", "{d}/images", "--truth", f"{{d}}/{csv}"],
            inputs, tmp_path / "o", must=[f"{{d}}/{csv}:{line}:", "outside the images folder"])


def test_calib_check_reads_an_image_inside_the_images_folder(inputs: Path, tmp_path: Path) -> None:
    """The same table with a plain name gets as far as the image (which holds no board)."""
    refused(["calib", "check", "--rig", "{d}/rig.yaml", "--images", "{d}/images", "--truth", "{d}/ok.csv"],
            inputs, tmp_path / "o", must=["0.png", "no 9x5 chessboard found"])


def _fake_calibration(monkeypatch: pytest.MonkeyPatch) -> None:
    """``calibrate_recording`` replaced by its result on the nominal rig (the writing is what is tested)."""
    import gtrig.calib.recording as recording
    from gtrig.rig import load_rig

    monkeypatch.setattr(recording, "calibrate_recording", lambda rec, estimate_k3=False: (
        load_rig(Path(rec) / "rig.yaml"), recording.CalibrationReport({}, None)))  # type: ignore[arg-type]
    monkeypatch.setattr(recording.CalibrationReport, "texts",
                        lambda self: {"calibration_report.md": "# report\n", "calibration_report.yaml": "a: 1\n"})


def _calibrated_before(o: Path, inputs: Path) -> Path:
    (o / "rec").mkdir(parents=True)
    (o / "rec" / "rig.yaml").write_text((inputs / "rig.yaml").read_text())
    (o / "rec" / "rig.calibrated.yaml").write_text("# the previous calibration\n")
    return o / "rec"


def test_calib_recording_report_in_the_way_is_refused_before_the_work(inputs: Path, tmp_path: Path,
                                                                      monkeypatch: pytest.MonkeyPatch) -> None:
    _fake_calibration(monkeypatch)

    def setup(o: Path) -> None:
        _calibrated_before(o, inputs)
        (o / "rec" / "calibration_report.yaml").mkdir()

    refused(["calib", "recording", "{o}/rec"], inputs, tmp_path / "o", setup=setup,
            must=["{o}/rec/calibration_report.yaml", "is a folder"])


def test_calib_recording_report_not_written_leaves_the_previous_rig(inputs: Path, tmp_path: Path,
                                                                    monkeypatch: pytest.MonkeyPatch) -> None:
    """The disk fills while the report is written: the previous calibrated rig stays, no file is new."""
    _fake_calibration(monkeypatch)
    rec = _calibrated_before(tmp_path, inputs)
    before = snapshot(tmp_path)
    write_text = Path.write_text

    def full_disk(self: Path, text: str, *a: object, **k: object) -> int:
        if "calibration_report.yaml" in self.name:
            raise OSError(errno.ENOSPC, "No space left on device", str(self))
        return write_text(self, text, *a, **k)  # type: ignore[arg-type]

    monkeypatch.setattr(Path, "write_text", full_disk)
    r = runner.invoke(app, ["calib", "recording", str(rec)])
    monkeypatch.undo()
    assert r.exit_code == 2 and "No space left on device" in r.output, r.output
    assert snapshot(tmp_path) == before
    # and with room on the disk, all three are written together
    _fake_calibration(monkeypatch)
    r = runner.invoke(app, ["calib", "recording", str(rec)])
    assert r.exit_code == 0, r.output
    from gtrig.rig import load_rig

    assert load_rig(rec / "rig.calibrated.yaml") == load_rig(rec / "rig.yaml")
    assert (rec / "calibration_report.md").read_text() == "# report\n"
