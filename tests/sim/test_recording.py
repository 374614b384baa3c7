"""`gtrig sim` end to end on a tiny recording: the documented layout, resume, refusal, CLI."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from gtrig.cli.main import app
from gtrig.errors import InputError
from gtrig.io.frames import read_frame_index, read_image
from gtrig.io.recording import summarize
from gtrig.io.scans import read_scans
from gtrig.io.tum import read_tum
from gtrig.rig import load_rig
from gtrig.sim.config import SimConfig
from gtrig.sim.recording import STEPS, simulate


def tiny(seed: int = 0) -> SimConfig:
    return SimConfig.quick_defaults(seed).model_copy(update={
        "run_duration_s": 1.0, "static_pose_s": 0.1, "background_s": 0.3, "n_intrinsic_views": 3,
        "n_pair_views": 2, "n_handheld_views": 2, "workers": 1,
    })


@pytest.fixture(scope="module")
def rec(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("rec")
    simulate(tiny(), out)
    return out


def test_layout(rec: Path) -> None:
    rig = load_rig(rec / "rig.yaml")
    truth = load_rig(rec / "truth" / "rig.yaml")
    assert rig != truth  # the operator's belief is not the truth
    for cam in rig.cameras:
        idx = read_frame_index(rec / "run" / "cameras" / cam.name)
        assert len(idx) >= 9 and idx.read(0).shape == (768, 1024)
        assert (rec / "calib" / "intrinsics" / cam.name).is_dir()
    for s in rig.laser_scanners:
        log = read_scans(rec / "run" / "lasers" / f"{s.name}.csv", s)
        assert log.ranges_m.shape[1] == 180 and len(log.stamps_s) >= 70
        assert (rec / "background" / "lasers" / f"{s.name}.csv").is_file()
    run = read_tum(rec / "truth" / "run.tum")
    assert run.stamps_s[-1] - run.stamps_s[0] == pytest.approx(1.0, abs=0.01)
    assert len(read_tum(rec / "truth" / "validation.tum")) == 26
    for f in ("reference_points", "world_distances", "robot_points", "pose_distances"):
        assert (rec / "survey" / f"{f}.csv").is_file()
    assert (rec / "run" / "odometry.csv").is_file()
    kinds = {s.what.split()[0] for s in summarize(rec)}
    assert {"run", "validation", "background", "calib", "survey"} <= kinds


def test_resume_and_refusal(rec: Path, tmp_path: Path) -> None:
    # every step is recorded: a second call with the same settings writes nothing new
    before = {p: p.stat().st_mtime_ns for p in rec.rglob("*.csv")}
    assert simulate(tiny(), rec) == {}
    assert before == {p: p.stat().st_mtime_ns for p in rec.rglob("*.csv")}
    with pytest.raises(InputError, match="other settings"):
        simulate(tiny(seed=1), rec)
    (tmp_path / "x.txt").write_text("mine")
    with pytest.raises(InputError, match="not empty"):
        simulate(tiny(), tmp_path)
    assert len(STEPS) == 8  # the map step (gtrig.sim.map) is the eighth


def test_same_seed_same_truth(rec: Path, tmp_path: Path) -> None:
    cfg = tiny().model_copy(update={"n_intrinsic_views": 3})
    out = tmp_path / "again"
    simulate(cfg, out)
    for rel in ("truth/run.tum", "survey/pose_distances.csv", "run/lasers/laser0.csv", "run/odometry.csv"):
        assert (rec / rel).read_bytes() == (out / rel).read_bytes(), rel
    a = read_frame_index(rec / "run" / "cameras" / "cam1").read(3)
    b = read_frame_index(out / "run" / "cameras" / "cam1").read(3)
    assert np.array_equal(a, b)


def test_cli_errors_are_one_line(tmp_path: Path) -> None:
    r = CliRunner().invoke(app, ["sim", "--scenario", "warehouse", "--out", str(tmp_path / "r"), "--quick"])
    assert r.exit_code == 2 and "unknown scenario 'warehouse'" in r.output and "Traceback" not in r.output


def _same(a: Path, b: Path, rel: str) -> bool:
    return (a / rel).read_bytes() == (b / rel).read_bytes()


def _image_difference(a: Path, b: Path, rel: str) -> np.ndarray:
    return read_image(a / rel).astype(float) - read_image(b / rel).astype(float)


def test_a_noise_draw_keeps_the_geometry_and_redraws_the_measurements(rec: Path, tmp_path: Path) -> None:
    out = tmp_path / "draw1"
    simulate(tiny().model_copy(update={"noise_draw": 1}), out)
    # the scene, rig, paths, board and hand-held poses, clock offsets and odometry errors are the seed's
    for rel in ["rig.yaml", "calib/boards.yaml", "survey/reference_points.csv", "survey/robot_points.csv",
                *(str(p.relative_to(rec)) for p in (rec / "truth").iterdir())]:
        assert _same(rec, out, rel), rel
    # every measurement's noise is drawn anew, with the statistics of the seed's own
    rig = load_rig(rec / "rig.yaml")
    sc = rig.laser_scanners[0]
    r0 = read_scans(rec / "background" / "lasers" / f"{sc.name}.csv", sc).ranges_m
    r1 = read_scans(out / "background" / "lasers" / f"{sc.name}.csv", sc).ranges_m
    both = np.isfinite(r0) & np.isfinite(r1)
    # the same static room and people, two draws of 1 cm range noise: their difference has sd sqrt(2) cm
    assert both.sum() > 2000 and 0.0125 < float(np.std((r1 - r0)[both])) < 0.016
    d = _image_difference(rec, out, "run/cameras/cam1/000003.png")
    assert 1.5 < float(np.std(d)) < 4.5 and abs(float(np.mean(d))) < 0.1
    w0, w1 = (np.loadtxt(p / "survey" / "world_distances.csv", delimiter=",", skiprows=1, usecols=2)
              for p in (rec, out))
    assert 0.0008 < float(np.std(w1 - w0)) < 0.00135  # two draws of the hand laser's 0.75 mm
    o0, o1 = (np.loadtxt(p / "run" / "odometry.csv", delimiter=",", skiprows=1) for p in (rec, out))
    assert np.array_equal(o0[:, 0], o1[:, 0]) and not np.array_equal(o0[:, 1:4], o1[:, 1:4])
    assert float(np.abs(o1[:, 1:3] - o0[:, 1:3]).max()) < 0.01  # wheel slip only: millimetres over the run
    assert not _same(rec, out, "calib/intrinsics/cam0/000000.png")


def test_a_calibration_noise_draw_redraws_the_calibration_images_only(rec: Path, tmp_path: Path) -> None:
    out = tmp_path / "calib_draw"
    simulate(tiny().model_copy(update={"noise_draw": 2, "noise_redrawn": "calibration"}), out)
    for rel in ("run/lasers/laser0.csv", "run/odometry.csv", "survey/world_distances.csv",
                "run/cameras/cam1/000003.png", "run/cameras/cam1/timestamps.csv"):
        assert _same(rec, out, rel), rel
    d = _image_difference(rec, out, "calib/intrinsics/cam0/000000.png")
    assert 1.5 < float(np.std(d)) < 4.5
    assert not _same(rec, out, "handheld/images/000000.png")
