"""Did a camera move between two recordings? The seeds' two procedures (AD2.3, "Verification of the
steadiness of the camera network"):

1. **Image comparison.** The same camera's image before and after is registered with ECC (Evangelidis
   and Psarakis, "Parametric image alignment using enhanced correlation coefficient maximization", PAMI
   2008; ``cv2.findTransformECC``, homography model, on a Gaussian-smoothed image); the image shift is the
   largest displacement the homography gives over a grid of image points (pixels). A static scene is
   assumed (people and the robot out of view).
2. **Board re-localisation.** A chessboard left at (or put back on) the same marked place is located in
   the before and the after image (PnP); its corners' 3D displacement in the camera frame is the
   camera's apparent motion in millimetres, and the relative pose gives the camera's rotation.

A camera is flagged when the image shift exceeds ``shift_px`` or the board moved by more than
``move_mm`` (or turned by more than ``turn_deg``).
"""

from __future__ import annotations

import logging
import os
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from gtrig import geometry as geo
from gtrig.calib.anchor import board_pose
from gtrig.calib.chessboard import Board, detect_corners, list_images, read_grey
from gtrig.errors import ConvergenceError, InputError

log = logging.getLogger(__name__)

SHIFT_PX = 0.3
MOVE_MM = 0.8
TURN_DEG = 0.02


def image_shift_px(before: np.ndarray, after: np.ndarray, smooth_px: float = 1.0) -> float:
    """Largest displacement (pixels) over the image of the homography that maps ``before`` onto
    ``after`` (ECC registration)."""
    if before.shape != after.shape:
        raise InputError(
            f"before and after images differ in size: {before.shape[::-1]} vs {after.shape[::-1]}"
        )
    a = cv2.GaussianBlur(before.astype(np.float32), (0, 0), smooth_px)
    b = cv2.GaussianBlur(after.astype(np.float32), (0, 0), smooth_px)
    H = np.eye(3, dtype=np.float32)
    crit = (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 200, 1e-7)
    try:
        _, H = cv2.findTransformECC(a, b, H, cv2.MOTION_HOMOGRAPHY, crit, None, 5)  # type: ignore[call-overload]  # stubs: no None mask
    except cv2.error as e:
        raise ConvergenceError(f"image registration failed: {str(e).splitlines()[-1].strip()}") from None
    h, w = before.shape[:2]
    u, v = np.meshgrid(np.linspace(0, w - 1, 9), np.linspace(0, h - 1, 7))
    p = np.column_stack([u.ravel(), v.ravel(), np.ones(u.size)])
    q = p @ H.astype(float).T
    q = q[:, :2] / q[:, 2:]
    return float(np.max(np.linalg.norm(q - p[:, :2], axis=1)))


@dataclass(frozen=True)
class BoardShift:
    """Board re-localisation: ``move_mm`` the largest corner displacement in the camera frame,
    ``turn_deg`` the rotation of the relative pose, ``reproj_px`` the corners' median image shift."""

    move_mm: float
    turn_deg: float
    reproj_px: float


def board_shift(
    K: np.ndarray, dist: np.ndarray, before: np.ndarray, after: np.ndarray, board: Board
) -> BoardShift:
    """Locate the board in both images and measure how much it moved relative to the camera."""
    cb, ca = detect_corners(before, board), detect_corners(after, board)
    if cb is None or ca is None:
        raise InputError(
            f"no {board.cols}x{board.rows} chessboard in the {'before' if cb is None else 'after'} image"
        )
    if np.median(np.linalg.norm(cb - ca, axis=1)) > np.median(np.linalg.norm(cb - ca[::-1], axis=1)):
        ca = ca[::-1].copy()  # same physical corners (half-turn ambiguity of the grid)
    Tb, _ = board_pose(K, dist, cb, board)
    Ta, _ = board_pose(K, dist, ca, board)
    P = board.object_points()
    d = geo.transform_points(Ta, P) - geo.transform_points(Tb, P)
    _, rot = geo.pose_error(Ta, Tb)
    return BoardShift(
        float(np.max(np.linalg.norm(d, axis=1)) * 1000),
        float(np.degrees(rot)),
        float(np.median(np.linalg.norm(ca - cb, axis=1))),
    )


@dataclass(frozen=True)
class SteadyResult:
    """Per camera and image name: the image shift (px), the board shift (or None), and the verdict."""

    camera: str
    image: str
    shift_px: float
    board: BoardShift | None
    moved: bool


def check_steady(
    before_dir: str | os.PathLike[str],
    after_dir: str | os.PathLike[str],
    cameras: dict[str, tuple[np.ndarray, np.ndarray]],
    board: Board | None,
    *,
    shift_px: float = SHIFT_PX,
    move_mm: float = MOVE_MM,
    turn_deg: float = TURN_DEG,
) -> list[SteadyResult]:
    """Compare ``before_dir/<cam>/<n>`` with ``after_dir/<cam>/<n>`` for every camera present in both.

    Parameters
    ----------
    cameras : {name: (camera_matrix (3, 3), dist_coeffs)} from the calibrated rig.
    board : the chessboard for re-localisation, or None for image comparison only.
    """
    b_root, a_root = Path(before_dir), Path(after_dir)
    for r in (b_root, a_root):
        if not r.is_dir():
            raise InputError(f"{r}: no such folder")
    out: list[SteadyResult] = []
    for cam in sorted(cameras):
        if not (b_root / cam).is_dir() or not (a_root / cam).is_dir():
            continue
        bm = {p.stem: p for p in list_images(b_root / cam)}
        am = {p.stem: p for p in list_images(a_root / cam)}
        common = sorted(set(bm) & set(am))
        if not common:
            raise InputError(f"{a_root / cam}: no image name in common with {b_root / cam}")
        K, dist = cameras[cam]
        for stem in common:
            ib, ia = read_grey(bm[stem]), read_grey(am[stem])
            s = image_shift_px(ib, ia)
            bs = None
            if board is not None and detect_corners(ib, board) is not None:
                bs = board_shift(K, dist, ib, ia, board)
            moved = s > shift_px or (bs is not None and (bs.move_mm > move_mm or bs.turn_deg > turn_deg))
            out.append(SteadyResult(cam, bm[stem].name, s, bs, moved))
            if moved:
                log.warning(
                    "camera %s moved: image shift %.2f px%s",
                    cam,
                    s,
                    "" if bs is None else f", board moved {bs.move_mm:.2f} mm / {bs.turn_deg:.3f} deg",
                )
    if not out:
        raise InputError(f"{b_root} and {a_root}: no camera folder in common with the rig")
    return out
