"""Compiled (numba) projection of robot-frame corners through each corner's own camera, with the
Jacobian in the robot pose's world-frame perturbation: the arithmetic of
:func:`gtrig.vision.projection.project_pose` in one pass over the corners.

A frame holds a few to a few dozen corners; written with numpy arrays, each of the forty-odd operations of
the lens model costs more in call overhead than in arithmetic, and the robust fit projects ten to
twenty times per instant.
"""

from __future__ import annotations

import numba as nb
import numpy as np

# one signature, compiled (or loaded from the cache) when the module is imported: any layout of the
# arrays is taken, and the workers forked from a process that imported it never load it again; the inputs
# are typed read-only, which writable arrays match too (a rig's arrays may be frozen)
_I1, _I2, _I3 = (nb.types.Array(nb.float64, d, "A", readonly=True) for d in (1, 2, 3))
_F1, _F2, _F3 = nb.float64[:], nb.float64[:, :], nb.float64[:, :, :]
_SIGNATURE = nb.void(_I2, _I2, _I1, _I3, _I2, _I1, _I1, _I1, _I1, _I1, _I2, nb.boolean, _F2, _F1, _F3)


@nb.njit(_SIGNATURE, cache=True, fastmath=False, nogil=True)
def project_pose_into(p_robot: np.ndarray, R: np.ndarray, t: np.ndarray, R_cw: np.ndarray, t_cw: np.ndarray,
                      fx: np.ndarray, fy: np.ndarray, skew: np.ndarray, cx: np.ndarray, cy: np.ndarray,
                      dist: np.ndarray, jacobian: bool, uv: np.ndarray, z_cam: np.ndarray, J: np.ndarray) -> None:
    """Fill ``uv`` (N, 2) pixels, ``z_cam`` (N,) depths (m) and, when ``jacobian``, ``J`` (N, 2, 6)
    d uv / d xi for the robot at ``(R, t)`` (``T_world_robot``).

    Parameters
    ----------
    p_robot : (N, 3) corners in the robot frame, m.
    R, t : (3, 3), (3,) the robot pose in the world.
    R_cw, t_cw : (N, 3, 3), (N, 3) each corner's camera, ``T_cam_world``.
    fx, fy, skew, cx, cy : (N,) each corner's camera intrinsics, pixels.
    dist : (N, 8) OpenCV's k1, k2, p1, p2, k3, k4, k5, k6.
    """
    n = p_robot.shape[0]
    q = np.empty(3)
    pw = np.empty(3)
    pc = np.empty(3)
    Jp = np.empty((2, 3))
    JR = np.empty((2, 3))
    for i in range(n):
        for r in range(3):
            q[r] = R[r, 0] * p_robot[i, 0] + R[r, 1] * p_robot[i, 1] + R[r, 2] * p_robot[i, 2]
            pw[r] = q[r] + t[r]
        for r in range(3):
            pc[r] = R_cw[i, r, 0] * pw[0] + R_cw[i, r, 1] * pw[1] + R_cw[i, r, 2] * pw[2] + t_cw[i, r]
        iz = 1.0 / pc[2]
        x = pc[0] * iz
        y = pc[1] * iz
        k1, k2, p1, p2, k3 = dist[i, 0], dist[i, 1], dist[i, 2], dist[i, 3], dist[i, 4]
        k4, k5, k6 = dist[i, 5], dist[i, 6], dist[i, 7]
        r2 = x * x + y * y
        a = 1 + r2 * (k1 + r2 * (k2 + r2 * k3))
        b = 1 + r2 * (k4 + r2 * (k5 + r2 * k6))
        rad = a / b
        xd = x * rad + 2 * p1 * x * y + p2 * (r2 + 2 * x * x)
        yd = y * rad + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y
        uv[i, 0] = fx[i] * xd + skew[i] * yd + cx[i]
        uv[i, 1] = fy[i] * yd + cy[i]
        z_cam[i] = pc[2]
        if not jacobian:
            continue
        da = k1 + r2 * (2 * k2 + 3 * k3 * r2)
        db = k4 + r2 * (2 * k5 + 3 * k6 * r2)
        drad = (da * b - a * db) / (b * b)  # d rad / d r2
        dxd_dx = rad + 2 * x * x * drad + 2 * p1 * y + 6 * p2 * x
        dxd_dy = 2 * x * y * drad + 2 * p1 * x + 2 * p2 * y
        dyd_dx = 2 * x * y * drad + 2 * p1 * x + 2 * p2 * y
        dyd_dy = rad + 2 * y * y * drad + 6 * p1 * y + 2 * p2 * x
        d00 = fx[i] * dxd_dx + skew[i] * dyd_dx
        d01 = fx[i] * dxd_dy + skew[i] * dyd_dy
        d10 = fy[i] * dyd_dx
        d11 = fy[i] * dyd_dy
        # d uv / d p_cam: the distortion's 2 x 2 times d(x, y) / d p_cam
        Jp[0, 0], Jp[0, 1], Jp[0, 2] = d00 * iz, d01 * iz, d00 * (-x * iz) + d01 * (-y * iz)
        Jp[1, 0], Jp[1, 1], Jp[1, 2] = d10 * iz, d11 * iz, d10 * (-x * iz) + d11 * (-y * iz)
        for r in range(2):
            for c in range(3):
                JR[r, c] = Jp[r, 0] * R_cw[i, 0, c] + Jp[r, 1] * R_cw[i, 1, c] + Jp[r, 2] * R_cw[i, 2, c]
            J[i, r, 0], J[i, r, 1], J[i, r, 2] = JR[r, 0], JR[r, 1], JR[r, 2]
            # cross(q, JR[r]) = -JR[r] @ skew(q)
            J[i, r, 3] = q[1] * JR[r, 2] - q[2] * JR[r, 1]
            J[i, r, 4] = q[2] * JR[r, 0] - q[0] * JR[r, 2]
            J[i, r, 5] = q[0] * JR[r, 1] - q[1] * JR[r, 0]


@nb.njit(nb.void(_I3, _I3, _F3), cache=True, fastmath=False, nogil=True)
def whiten_into(sqrt_info: np.ndarray, J: np.ndarray, out: np.ndarray) -> None:
    """Fill ``out`` (N, 2, K) with ``L_n^T @ J_n`` for ``sqrt_info`` L (N, 2, 2) and ``J`` (N, 2, K): each sum
    started at zero and taken in the order of the rows of ``J``, as numpy's ``einsum("nji,njk->nik")``
    takes it, so that both give the same bits."""
    n, _, m = J.shape
    for i in range(n):
        for r in range(2):
            for c in range(m):
                acc = 0.0
                acc += sqrt_info[i, 0, r] * J[i, 0, c]
                acc += sqrt_info[i, 1, r] * J[i, 1, c]
                out[i, r, c] = acc
