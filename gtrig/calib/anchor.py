"""Locating a chessboard in one calibrated camera (PnP) and anchoring a camera to the world.

``board_pose`` solves the planar PnP with IPPE (Collins and Bartoli, "Infinitesimal plane-based pose
estimation", IJCV 2014), which returns both planar solutions, then refines the better one with
Levenberg-Marquardt on the reprojection error (``cv2.solvePnPRefineLM``). ``anchor_camera`` is the seeds'
world anchoring (AD2.3: the pattern laid on the floor in a known pose relative to the GTV frame):
``T_world_cam = T_world_board @ inv(T_cam_board)``, averaged on SE(3) over the views.
"""

from __future__ import annotations

from collections.abc import Sequence

import cv2
import numpy as np

from gtrig import geometry as geo
from gtrig.calib.chessboard import Board, flip_half_turn
from gtrig.calib.se3avg import PoseMean, mean_pose
from gtrig.errors import ConvergenceError, InputError


def board_pose(
    K: np.ndarray, dist: np.ndarray, corners_px: np.ndarray, board: Board
) -> tuple[np.ndarray, float]:
    """Pose ``T_cam_board`` (4, 4) of a detected board and its reprojection RMS (pixels)."""
    P = board.object_points()
    uv = np.asarray(corners_px, dtype=np.float64).reshape(-1, 1, 2)
    K = np.asarray(K, dtype=float)
    dist = np.asarray(dist, dtype=float).ravel()
    try:
        n, rvecs, tvecs, errs = cv2.solvePnPGeneric(P, uv, K, dist, flags=cv2.SOLVEPNP_IPPE)
    except cv2.error as e:
        raise ConvergenceError(f"PnP failed: {str(e).splitlines()[-1].strip()}") from None
    if n == 0:
        raise ConvergenceError("PnP found no pose for the board")
    best = int(np.argmin(np.asarray(errs).ravel()))
    rvec, tvec = rvecs[best].copy(), tvecs[best].copy()
    rvec, tvec = cv2.solvePnPRefineLM(P, uv, K, dist, rvec, tvec)
    T = geo.make_T(cv2.Rodrigues(rvec)[0], tvec.ravel())
    res = geo.project_points(geo.transform_points(T, P), K, dist) - uv.reshape(-1, 2)
    return T, float(np.sqrt(np.mean(np.sum(res**2, axis=1))))


def pose_distance(T_a: np.ndarray, T_b: np.ndarray, metres_per_rad: float = 1.0) -> float:
    """A scalar distance between two poses: rotation angle (rad) x ``metres_per_rad`` + translation (m)."""
    dt, dr = geo.pose_error(T_a, T_b)
    return dr * metres_per_rad + dt


def oriented_board_pose(
    K: np.ndarray, dist: np.ndarray, corners_px: np.ndarray, board: Board, T_cam_board_expected: np.ndarray
) -> tuple[np.ndarray, np.ndarray, float]:
    """Resolve the half-turn ambiguity of a grid against an expected pose.

    Returns the corners in the order consistent with ``T_cam_board_expected``, the pose and its RMS.
    """
    T0, e0 = board_pose(K, dist, corners_px, board)
    flipped = flip_half_turn(corners_px)
    T1, e1 = board_pose(K, dist, flipped, board)
    if pose_distance(T1, T_cam_board_expected) < pose_distance(T0, T_cam_board_expected):
        return flipped, T1, e1
    return np.asarray(corners_px), T0, e0


def anchor_camera(
    K: np.ndarray,
    dist: np.ndarray,
    views: Sequence[np.ndarray],
    board: Board,
    T_world_board: np.ndarray,
    T_world_cam_nominal: np.ndarray | None = None,
) -> tuple[PoseMean, list[np.ndarray]]:
    """``T_world_cam`` from views of a board at a known world pose.

    Parameters
    ----------
    views : corner arrays (N, 2), pixels.
    T_world_board : (4, 4) the board's known pose in the world.
    T_world_cam_nominal : the believed camera pose, to resolve the grid's half-turn ambiguity.

    Returns
    -------
    The SE(3) mean of the per-view estimates, and the (re-ordered) corners of each view.
    """
    if not views:
        raise InputError("no view of the world board")
    Ts, ordered = [], []
    for c in views:
        if T_world_cam_nominal is not None:
            c, T_cam_board, _ = oriented_board_pose(
                K, dist, c, board, geo.inv_T(T_world_cam_nominal) @ T_world_board
            )
        else:
            T_cam_board, _ = board_pose(K, dist, c, board)
        Ts.append(T_world_board @ geo.inv_T(T_cam_board))
        ordered.append(c)
    return mean_pose(np.array(Ts)), ordered
