"""Compiled (numba) loops of the evaluation's per-pose arithmetic: one pass per metric, no (n, 4) temporaries.

The NumPy expressions they replace (gtrig.evaluate.quat) allocate a dozen 10^6-element arrays per product,
and at 10^6 poses the page faults of those allocations cost more than the arithmetic. Quaternions are
``xyzw`` (scalar last), positions metres, angles radians; the formulas are those of gtrig.evaluate.quat.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit


@njit(cache=True, inline="always")
def _mul(ax: float, ay: float, az: float, aw: float, bx: float, by: float, bz: float, bw: float
         ) -> tuple[float, float, float, float]:
    """Hamilton product ``a b``."""
    return (aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw,
            aw * bw - ax * bx - ay * by - az * bz)


@njit(cache=True, inline="always")
def _angle(x: float, y: float, z: float, w: float) -> float:
    """Rotation angle in [0, pi] of a unit quaternion: ``2 atan2(|v|, |w|)``."""
    return 2.0 * math.atan2(math.sqrt(x * x + y * y + z * z), abs(w))


@njit(cache=True, inline="always")
def _rotate_inv(q: np.ndarray, i: int, vx: float, vy: float, vz: float) -> tuple[float, float, float]:
    """``R(q_i)^T v`` (quat.rotate's formula with the vector part negated)."""
    ux, uy, uz, w = -q[i, 0], -q[i, 1], -q[i, 2], q[i, 3]
    tx = 2.0 * (uy * vz - uz * vy)
    ty = 2.0 * (uz * vx - ux * vz)
    tz = 2.0 * (ux * vy - uy * vx)
    return (vx + w * tx + (uy * tz - uz * ty),
            vy + w * ty + (uz * tx - ux * tz),
            vz + w * tz + (ux * ty - uy * tx))


@njit(cache=True)
def ape_errors(q_gt: np.ndarray, t_gt: np.ndarray, q_est: np.ndarray, t_est: np.ndarray
               ) -> tuple[np.ndarray, np.ndarray]:
    """``(|t_est - t_gt|, angle(q_est^-1 q_gt))`` per pose: (n,) metres and radians."""
    n = q_gt.shape[0]
    trans = np.empty(n)
    angle = np.empty(n)
    for i in range(n):
        dx = t_est[i, 0] - t_gt[i, 0]
        dy = t_est[i, 1] - t_gt[i, 1]
        dz = t_est[i, 2] - t_gt[i, 2]
        trans[i] = math.sqrt(dx * dx + dy * dy + dz * dz)
        x, y, z, w = _mul(-q_est[i, 0], -q_est[i, 1], -q_est[i, 2], q_est[i, 3],
                          q_gt[i, 0], q_gt[i, 1], q_gt[i, 2], q_gt[i, 3])
        angle[i] = _angle(x, y, z, w)
    return trans, angle


@njit(cache=True)
def rpe_errors(q_gt: np.ndarray, t_gt: np.ndarray, q_est: np.ndarray, t_est: np.ndarray, delta: int
               ) -> tuple[np.ndarray, np.ndarray]:
    """evo's RPE over the pairs ``(k delta, (k + 1) delta)``: ``(|t_P - t_Q|, angle(R_Q^-1 R_P))`` per pair,
    with ``Q = Q_i^-1 Q_j`` (GT) and ``P = P_i^-1 P_j`` (estimate)."""
    m = max((q_gt.shape[0] - 1) // delta, 0)
    trans = np.empty(m)
    angle = np.empty(m)
    for k in range(m):
        i = k * delta
        j = i + delta
        gx, gy, gz, gw = _mul(-q_gt[i, 0], -q_gt[i, 1], -q_gt[i, 2], q_gt[i, 3],
                              q_gt[j, 0], q_gt[j, 1], q_gt[j, 2], q_gt[j, 3])
        ex, ey, ez, ew = _mul(-q_est[i, 0], -q_est[i, 1], -q_est[i, 2], q_est[i, 3],
                              q_est[j, 0], q_est[j, 1], q_est[j, 2], q_est[j, 3])
        qx, qy, qz = _rotate_inv(q_gt, i, t_gt[j, 0] - t_gt[i, 0], t_gt[j, 1] - t_gt[i, 1], t_gt[j, 2] - t_gt[i, 2])
        px, py, pz = _rotate_inv(q_est, i, t_est[j, 0] - t_est[i, 0], t_est[j, 1] - t_est[i, 1],
                                 t_est[j, 2] - t_est[i, 2])
        trans[k] = math.sqrt((px - qx) ** 2 + (py - qy) ** 2 + (pz - qz) ** 2)
        x, y, z, w = _mul(-gx, -gy, -gz, gw, ex, ey, ez, ew)
        angle[k] = _angle(x, y, z, w)
    return trans, angle


@njit(cache=True)
def transform_poses(scale: float, R: np.ndarray, t: np.ndarray, r: np.ndarray, xyz: np.ndarray, q: np.ndarray
                    ) -> tuple[np.ndarray, np.ndarray]:
    """Poses moved by a similarity: positions ``s R p_i + t`` (R (3, 3), t (3,)) and rotations ``r q_i`` (r the
    quaternion of R), renormalised with the scalar part made non-negative. (n, 3) and (n, 4) out."""
    n = q.shape[0]
    p_out = np.empty((n, 3))
    q_out = np.empty((n, 4))
    for i in range(n):
        x, y, z = xyz[i, 0], xyz[i, 1], xyz[i, 2]
        for k in range(3):
            p_out[i, k] = scale * (R[k, 0] * x + R[k, 1] * y + R[k, 2] * z) + t[k]
        a, b, c, d = _mul(r[0], r[1], r[2], r[3], q[i, 0], q[i, 1], q[i, 2], q[i, 3])
        s = math.sqrt(a * a + b * b + c * c + d * d)
        if d < 0:
            s = -s
        q_out[i, 0] = a / s
        q_out[i, 1] = b / s
        q_out[i, 2] = c / s
        q_out[i, 3] = d / s
    return p_out, q_out


@njit(cache=True)
def heading_cos_sin(q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(n,) ``cos`` and ``sin`` of the heading (the body x axis projected on the world x-y plane) of unit
    quaternions, without the angle: ``(R00, R10) / |(R00, R10)|``; ``(1, 0)`` for a body x axis straight up."""
    n = q.shape[0]
    c = np.empty(n)
    s = np.empty(n)
    for i in range(n):
        x, y, z, w = q[i, 0], q[i, 1], q[i, 2], q[i, 3]
        r00 = 1.0 - 2.0 * (y * y + z * z)
        r10 = 2.0 * (x * y + w * z)
        h = math.hypot(r00, r10)
        if h > 0:
            c[i] = r00 / h
            s[i] = r10 / h
        else:
            c[i] = 1.0
            s[i] = 0.0
    return c, s
