"""Camera image sets: sequences, calibration sets, hand-held survey."""

from __future__ import annotations

import cv2
import numpy as np
import pytest
import yaml

from gtrig import geometry as geo
from gtrig.io.frames import read_frame_index
from gtrig.io.tum import read_tum
from gtrig.rig.models import Pose
from gtrig.sim import gtroom
from gtrig.sim.cameras import (
    _markers_in_view,
    handheld_camera,
    render_sequence,
    write_calibration_sets,
    write_handheld_set,
)
from gtrig.sim.config import SimConfig
from gtrig.sim.motion import RobotMotion
from gtrig.sim.render import PinholeCamera
from gtrig.sim.textures import board_object_points


@pytest.fixture(scope="module")
def scene() -> gtroom.Scene:
    return gtroom.make_scene(0)


def _robot_in_view_pose(scene: gtroom.Scene, cam_index: int) -> np.ndarray:
    cam = scene.rig_true.cameras[cam_index]
    pc, T = PinholeCamera.from_rig(cam), cam.T_world_cam.matrix()
    for p in gtroom.VALIDATION_POSES:
        uv = pc.project(T, scene.T_world_robot(*p)[:3, 3][None])
        if np.all((uv > 150) & (uv < np.array(pc.size) - 150)):
            return p
    raise AssertionError("no validation pose in view")


def test_sequence_same_bytes_any_worker_count(scene, tmp_path):
    p = _robot_in_view_pose(scene, 1)
    # the robot drives through the frames: motion blur is exercised
    motion = RobotMotion(np.array([0.0, 1.0]), np.array([p, p + [0.3, 0.0, 0.2]]), scene.floor)
    stamps = np.array([0.1, 0.2, 0.3])
    cfg1 = SimConfig(workers=1)
    cfg2 = SimConfig(workers=2)
    cam = scene.rig_true.cameras[1]
    w1 = render_sequence(scene, cam, motion, stamps, tmp_path / "a", cfg1, seed=5)
    w2 = render_sequence(scene, cam, motion, stamps, tmp_path / "b", cfg2, seed=5)
    for k in range(3):
        name = f"{k:06d}.png"
        assert (tmp_path / "a" / name).read_bytes() == (tmp_path / "b" / name).read_bytes()
    idx = read_frame_index(tmp_path / "a")
    np.testing.assert_allclose(idx.stamps_s, w1, atol=1e-6)
    np.testing.assert_array_equal(w1, w2)
    assert np.all(np.abs(w1 - stamps) < 0.045) and np.any(w1 != stamps)  # jittered, still ordered
    img = idx.read(0)
    assert img.shape == (768, 1024) and img.dtype == np.uint8
    # a different seed changes the noise only
    render_sequence(scene, cam, motion, stamps[:1], tmp_path / "c", cfg1, seed=6)
    other = cv2.imread(str(tmp_path / "c" / "000000.png"), cv2.IMREAD_GRAYSCALE)
    diff = np.abs(other.astype(int) - img.astype(int))
    assert 0 < diff.mean() < 4


def test_calibration_sets(scene, tmp_path):
    cam_cfg = SimConfig().camera.model_copy(update={"noise_sigma": 0.0, "defocus_sigma_px": 0.0})
    cfg = SimConfig(n_intrinsic_views=3, n_pair_views=2, n_world_board_views=1, workers=2, camera=cam_cfg)
    truth = write_calibration_sets(scene, tmp_path, cfg)
    nominal = yaml.safe_load((tmp_path / "calib" / "boards.yaml").read_text())
    assert nominal["squares"] == [10, 6] and nominal["inner_corners"] == [9, 5]
    assert nominal["square_m"] == pytest.approx(0.1)
    stored = yaml.safe_load((tmp_path / "truth" / "boards.yaml").read_text())
    assert stored["T_board1_board2"] == truth["T_board1_board2"]
    assert sorted(truth["pairs"]) == ["cam0-cam1", "cam1-cam2", "cam2-cam3"]
    assert truth["world_board"], "some camera must see the world board"
    objp = board_object_points()
    for cam in scene.rig_true.cameras:
        files = sorted((tmp_path / "calib" / "intrinsics" / cam.name).glob("*.png"))
        assert len(files) == 3
    # every board is found where the truth projects it (blur- and noise-free)
    checks = [(scene.rig_true.cameras[2], tmp_path / "calib" / "intrinsics" / "cam2" / "000001.png",
               Pose(**truth["intrinsics"]["cam2"][1]["T_cam_board"]).matrix())]
    entry = truth["pairs"]["cam1-cam2"][0]
    pair_img = tmp_path / "calib" / "pairs" / "cam1-cam2" / "cam2" / "000000.png"
    checks.append((scene.rig_true.cameras[2], pair_img, Pose(**entry["T_cam2_board2"]).matrix()))
    for cam, path, T_cam_board in checks:
        g = cv2.imread(str(path), cv2.IMREAD_GRAYSCALE)
        ok, found = cv2.findChessboardCorners(g, (9, 5))
        assert ok, path
        found = cv2.cornerSubPix(g, found, (5, 5), (-1, -1),
                                 (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_COUNT, 50, 1e-3)).reshape(-1, 2)
        pc = PinholeCamera.from_rig(cam)
        truth_uv = geo.project_points(geo.transform_points(T_cam_board, objp), pc.K, pc.dist)
        if np.linalg.norm(found[0] - truth_uv[0]) > np.linalg.norm(found[0] - truth_uv[-1]):
            found = found[::-1]
        assert np.max(np.linalg.norm(found - truth_uv, axis=1)) < 0.15  # 8-bit quantised


def test_handheld_set(scene, tmp_path):
    cfg = SimConfig(n_handheld_views=4, workers=2)
    poses = write_handheld_set(scene, tmp_path, cfg)
    traj = read_tum(tmp_path / "truth" / "handheld.tum")
    np.testing.assert_allclose(traj.matrices(), np.stack(poses), atol=1e-8)
    doc = yaml.safe_load((tmp_path / "handheld" / "camera.yaml").read_text())
    assert doc["image_size"] == [1600, 1200]
    cam = handheld_camera()
    x, y, th = 0.36, 2.0, 0.4
    T_world_robot = scene.T_world_robot(x, y, th)
    together: dict[int, int] = {}
    for k, T in enumerate(poses):
        img = cv2.imread(str(tmp_path / "handheld" / "images" / f"{k:06d}.png"), cv2.IMREAD_GRAYSCALE)
        assert img.shape == (1200, 1600)
        seen = _markers_in_view(scene, cam, T, T_world_robot)
        assert len(seen) >= 2
        for i in seen:
            together[i] = together.get(i, 0) + 1
    assert set(together) == {m.id for m in scene.rig_true.robot.markers}
    assert min(together.values()) >= 2
