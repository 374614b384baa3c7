"""A robust start for the chain: where the odometry's frame sits in the world.

Each pose fix gives one candidate ``T_world_odom = T_world_robot(fix) * T_odom_robot(t)^-1``; the candidate
with the most others within 5 cm and 3 deg wins and its agreeing candidates are averaged, so a flipped or
turned first fix cannot start the filter. Position-only fixes are aligned by a 2-D Procrustes fit of the
seen point's odometry track to them (trimmed once), which needs the robot to move.
"""

from __future__ import annotations

import numpy as np

from gtrig.errors import InputError
from gtrig.geometry import wrap_angle


def _compose(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(..., 3) planar poses a * b."""
    c, s = np.cos(a[..., 2]), np.sin(a[..., 2])
    return np.stack([a[..., 0] + c * b[..., 0] - s * b[..., 1], a[..., 1] + s * b[..., 0] + c * b[..., 1],
                     a[..., 2] + b[..., 2]], axis=-1)


def _inverse(a: np.ndarray) -> np.ndarray:
    c, s = np.cos(a[..., 2]), np.sin(a[..., 2])
    return np.stack([-c * a[..., 0] - s * a[..., 1], s * a[..., 0] - c * a[..., 1], -a[..., 2]], axis=-1)


def odom_in_world(pose_z: np.ndarray, odo_at_fix: np.ndarray, pos_z: np.ndarray, odo_at_pos: np.ndarray,
                  lever_xy: np.ndarray, tol_m: float = 0.05, tol_rad: float = np.deg2rad(3.0)) -> np.ndarray:
    """``T_world_odom`` (x, y, yaw) from the first fixes.

    Parameters
    ----------
    pose_z : (A, 3) pose fixes; odo_at_fix : (A, 3) odometry poses at their stamps.
    pos_z : (B, 2) position fixes; odo_at_pos : (B, 3) odometry poses at their stamps; lever_xy : (B, 2).
    tol_m, tol_rad : agreement between candidates.
    """
    if len(pose_z):
        cand = _compose(pose_z, _inverse(odo_at_fix))  # (A, 3)
        dp = np.hypot(cand[:, None, 0] - cand[None, :, 0], cand[:, None, 1] - cand[None, :, 1])
        dth = np.abs(wrap_angle(cand[:, None, 2] - cand[None, :, 2]))
        agree = (dp < tol_m) & (dth < tol_rad)
        best = int(np.argmax(agree.sum(axis=1)))
        sel = cand[agree[best]]
        th = cand[best, 2] + np.mean(wrap_angle(sel[:, 2] - cand[best, 2]))
        return np.array([np.median(sel[:, 0]), np.median(sel[:, 1]), th])
    if len(pos_z) < 3:
        raise InputError("fusion: fewer than three fixes at the start of a segment; nothing to anchor it")
    c, s = np.cos(odo_at_pos[:, 2]), np.sin(odo_at_pos[:, 2])
    src = odo_at_pos[:, :2] + np.column_stack([c * lever_xy[:, 0] - s * lever_xy[:, 1],
                                               s * lever_xy[:, 0] + c * lever_xy[:, 1]])
    if np.ptp(src, axis=0).max() < 0.5:
        raise InputError("fusion: position-only fixes while the robot moves less than 0.5 m: its heading is "
                         "unobservable at the start of a segment")
    keep = np.ones(len(src), bool)
    for _ in range(2):
        ms, mz = src[keep].mean(0), pos_z[keep].mean(0)
        H = (src[keep] - ms).T @ (pos_z[keep] - mz)
        U, _, Vt = np.linalg.svd(H)
        R = Vt.T @ np.diag([1.0, np.sign(np.linalg.det(Vt.T @ U.T))]) @ U.T
        t = mz - R @ ms
        res = np.hypot(*(pos_z - (src @ R.T + t)).T)
        keep = res <= max(3.0 * np.median(res), 1e-6)
    return np.array([t[0], t[1], np.arctan2(R[1, 0], R[0, 0])])
