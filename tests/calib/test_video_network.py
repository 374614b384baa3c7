"""The camera network from a hand-held ChArUco board, on simulated corners with known camera poses."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from gtrig import geometry as geo
from gtrig.calib.charuco import CharucoBoard, CharucoView
from gtrig.calib.video_detect import VideoDetections
from gtrig.calib.video_network import calibrate_video_network, project, relative_poses
from gtrig.io.camfile import CameraIntrinsics
from gtrig.io.video import frame_timing

BOARD = CharucoBoard(6, 8, 0.04, 0.03, "DICT_5X5_100")
K = np.array([[700.0, 0, 640], [0, 700, 360], [0, 0, 1]])
DIST = np.array([0.05, -0.1, 0.001, -0.001, 0.0])
LENS = CameraIntrinsics((1280, 720), K, DIST)



def _scene(rng: np.random.Generator, noise_px: float) -> tuple[dict[str, VideoDetections], dict[str, np.ndarray]]:
    eyes = {"a": [1.2, 0, 0.3], "b": [0, 1.2, 0.4], "c": [-1.1, 0.2, 0.2]}
    T_world_cam = {n: geo.look_at(np.array(e), np.zeros(3)) for n, e in eyes.items()}
    P = BOARD.object_points()
    views: dict[str, list[tuple[int, CharucoView]]] = {n: [] for n in eyes}
    for inst in range(40):
        R = Rotation.from_rotvec(rng.normal(0, 0.6, 3)).as_matrix()
        T_world_board = geo.make_T(R, rng.normal(0, 0.15, 3)) @ geo.make_T(np.eye(3), -P.mean(axis=0))
        for n, T in T_world_cam.items():
            T_cb = geo.inv_T(T) @ T_world_board
            Xc = P @ T_cb[:3, :3].T + T_cb[:3, 3]
            normal_c = T_cb[:3, 2]
            if np.any(Xc[:, 2] < 0.2) or abs(normal_c @ (Xc.mean(axis=0) / np.linalg.norm(Xc.mean(axis=0)))) < 0.3:
                continue
            uv = project(Xc, K, DIST) + rng.normal(0, noise_px, (len(P), 2))
            inside = (uv[:, 0] > 0) & (uv[:, 0] < 1279) & (uv[:, 1] > 0) & (uv[:, 1] < 719)
            ids = np.flatnonzero(inside & (rng.random(len(P)) > 0.2))  # partial corner sets
            if len(ids) >= 6:
                views[n].append((inst, CharucoView(ids, uv[ids])))
    dets = {}
    for n, vs in views.items():
        inst = np.array([i for i, _ in vs])
        dets[n] = VideoDetections(n, (1280, 720), 40, inst, inst / 6.0, inst, tuple(v for _, v in vs))
    return dets, T_world_cam


def test_network_recovers_simulated_cameras_with_consistent_covariance() -> None:
    rng = np.random.default_rng(5)
    dets, T_world_cam = _scene(rng, noise_px=0.3)
    res = calibrate_video_network(dets, {n: LENS for n in dets}, BOARD, "a")
    assert res.rms_px_all == pytest.approx(0.3 * np.sqrt(2), rel=0.15)  # per corner: both axes
    sig = np.sqrt(np.diag(res.cov))
    for k, n in enumerate(res.order):
        T_true = geo.inv_T(T_world_cam["a"]) @ T_world_cam[n]
        err_pos = res.T_ref_cam[n][:3, 3] - T_true[:3, 3]
        assert np.linalg.norm(err_pos) < 0.003  # 3 mm at 1.2-1.7 m with 0.3 px noise
        assert np.all(np.abs(err_pos) < 5 * np.maximum(sig[6 * k + 3: 6 * k + 6], 1e-5))
    base = {(p.cam_a, p.cam_b): p for p in relative_poses(res)}
    true_ab = np.linalg.norm((geo.inv_T(T_world_cam["a"]) @ T_world_cam["b"])[:3, 3])
    assert abs(base[("a", "b")].baseline_m - true_ab) < 5 * base[("a", "b")].sigma_baseline_m + 1e-4


def test_frame_timing_of_regular_stamps_has_no_gaps() -> None:
    ft = frame_timing(np.arange(100) / 30.0)
    assert (ft.n_dropped, ft.n_duplicated) == (0, 0) and ft.period_s == pytest.approx(1 / 30)


def test_lens_sigma_widens_the_pose_covariance_by_the_solution_sensitivity() -> None:
    """One uncertain parameter (cam b's fx) adds the rank-one ``a a^T sigma^2``, ``a`` the poses' shift per pixel
    of fx, which re-solving with a shifted fx measures."""
    rng = np.random.default_rng(7)
    dets, _ = _scene(rng, noise_px=0.3)
    sigma_fx = 4.0
    uncertain = replace(LENS, extra={"std_honest": {"fx": sigma_fx}})
    cams = {"a": LENS, "b": uncertain, "c": LENS}
    held = calibrate_video_network(dets, cams, BOARD, "a", lens_uncertainty=False)
    full = calibrate_video_network(dets, cams, BOARD, "a")
    added = np.sqrt(np.clip(np.diag(full.cov - held.cov), 0, None))
    shifted_lens = replace(LENS, camera_matrix=LENS.camera_matrix + np.diag([sigma_fx, 0.0, 0.0]))
    shifted = calibrate_video_network(dets, {**cams, "b": shifted_lens}, BOARD, "a", lens_uncertainty=False)
    for k, n in enumerate(held.order):
        T0, T1 = geo.inv_T(held.T_ref_cam[n]), geo.inv_T(shifted.T_ref_cam[n])
        moved = np.abs(np.concatenate([Rotation.from_matrix(T1[:3, :3] @ T0[:3, :3].T).as_rotvec(),
                                       T1[:3, 3] - T0[:3, 3]]))
        assert np.max(moved) > 1e-4  # fx of 4 px moves the cameras measurably
        np.testing.assert_allclose(added[6 * k: 6 * k + 6], moved, rtol=0.15, atol=2e-6)
