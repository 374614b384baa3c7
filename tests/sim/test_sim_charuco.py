"""The simulator's ChArUco board: rendered where the chessboard would be, found where it was put."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

from gtrig import geometry as geo
from gtrig.calib.charuco import CharucoCornerDetector
from gtrig.calib.chessboard import Board, detect_corners
from gtrig.sim import cameras as simcams
from gtrig.sim.config import SimConfig
from gtrig.sim.gtroom import make_scene
from gtrig.sim.render import PinholeCamera
from gtrig.sim.textures import board_object_points, sim_charuco_board


def test_sweep_charuco_corners_match_the_truth_as_closely_as_the_chessboards_with_covariances(
        tmp_path: Path) -> None:
    cfg = SimConfig(seed=0)
    scene = make_scene(0)
    cam = scene.rig_true.cameras[0]
    pc, T_world_cam = PinholeCamera.from_rig(cam), cam.T_world_cam.matrix()
    poses = simcams.sample_intrinsic_poses(pc, T_world_cam, 2, np.random.default_rng(5))
    board = sim_charuco_board()
    charuco = CharucoCornerDetector(board)
    chess = Board(board.squares_x - 1, board.squares_y - 1, board.square_m)
    shared = simcams._StillShared(scene, cfg.camera, 0)
    err_charuco, err_chess = [], []
    nees: list[float] = []
    for k, T in enumerate(poses):
        for is_charuco in (True, False):
            path = tmp_path / f"{k}_{is_charuco}.png"
            simcams._still_frame(shared, (cam, [T], str(path), 0, k, is_charuco))
            grey = cv2.imread(str(path), cv2.IMREAD_GRAYSCALE)
            if is_charuco:
                v = charuco.detect(grey)
                assert v is not None and len(v.ids) == board.n_corners
                # the ChArUco frame's origin is the outer corner, a square before the first inner corner
                P = board.object_points()[v.ids] - [board.square_m, board.square_m, 0.0]
                uv = pc.project(T_world_cam, geo.transform_points(T, P))
                err_charuco.append(np.linalg.norm(v.corners_px - uv, axis=1))
                assert v.cov_px is not None
                d = v.corners_px - uv
                nees.extend(np.einsum("ni,nij,nj->n", d, np.linalg.inv(v.cov_px), d))
            else:
                c = detect_corners(grey, chess)
                assert c is not None
                uv = pc.project(T_world_cam, geo.transform_points(T, board_object_points()))
                # the chessboard's grid is known up to a half turn
                err_chess.append(min(np.linalg.norm(c - uv, axis=1).mean(),
                                     np.linalg.norm(c[::-1] - uv, axis=1).mean()))
    e = np.concatenate(err_charuco)
    # the saddles refined along the strip the markers leave free: measured mean 0.029 px, max 0.079 px, the
    # chessboard's 0.040 px (OpenCV's own ChArUco corners: 2.6x the refined RMS, bench/calib_charuco.py)
    assert e.mean() < 0.04 and e.max() < 0.2, (e.mean(), e.max())
    assert e.mean() < np.mean(err_chess)
    # the stated covariances: median NEES / 2 measured 1.77 on these two views (0.70-0.79 over 48 views)
    assert np.all(np.isfinite(nees)) and 0.3 < np.median(nees) / 2 < 3.0, np.median(nees)


def test_the_sweeps_board_setting_keeps_chessboard_recordings_resumable() -> None:
    from gtrig.sim.recording import _config_key

    # the key of a recording simulated before the setting existed (seed 0, defaults)
    assert _config_key(SimConfig(seed=0)) == "8daed225048552a4"
    assert _config_key(SimConfig(seed=0, calib_board="charuco")) != "8daed225048552a4"
