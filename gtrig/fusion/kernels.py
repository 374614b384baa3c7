"""Compiled per-factor kernels shared by both estimators (the EKF + RTS and the batch MAP solve).

One place defines what each factor predicts and its Jacobian, so that the two estimators smooth the same
factors. Every function works on one factor and small dense blocks (d <= 6), in explicit loops, because
LAPACK calls on 3 x 3 matrices cost more than the arithmetic (numba, ``cache=True``).

State of node i: ``X[i] = (x, y, yaw)`` (odometry process, d = 3) or ``(x, y, yaw, vx, vy, wz)``
(constant velocity, d = 6), world frame, metres and radians, yaw unwrapped along the chain.
Global parameters (odometry only, p = 3): ``K = (k_dist, k_turn, k_curv)``: the true robot-frame increment
is ``(k_dist * u_x, k_dist * u_y, k_turn * u_yaw + k_curv * u_x)`` for an odometry increment ``u``
(distance scale, turn-rate scale and the curvature a right/left wheel radius difference adds, rad/m;
Borenstein and Feng's systematic odometry errors).

Fix models (``kind``): 0 = planar pose ``(x, y, yaw)``; 1 = position ``(x, y)`` of a point at
``lever_xy`` in the robot frame (a GPS antenna, a prism). A fix at stamp t between nodes i and i+1 sees
the pose linearly interpolated at ``alpha = (t - t_i) / (t_{i+1} - t_i)``: the fix enters at its own
stamp, no resampling.
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

KIND_POSE = 0
KIND_POSITION = 1

_jit = nb.njit(cache=True, fastmath=False, nogil=True)


@_jit
def wrap(a: float) -> float:
    return (a + math.pi) % (2.0 * math.pi) - math.pi


@_jit
def chol_factor(A: np.ndarray, L: np.ndarray) -> bool:
    """``L`` (n, n, zeroed by the caller) = the lower Cholesky factor of a small symmetric ``A`` (n, n);
    False, ``L`` left part-filled, if ``A`` is not positive definite."""
    n = A.shape[0]
    for j in range(n):
        s = A[j, j]
        for k in range(j):
            s -= L[j, k] * L[j, k]
        if not s > 0.0:
            return False
        L[j, j] = math.sqrt(s)
        for i in range(j + 1, n):
            t = A[i, j]
            for k in range(j):
                t -= L[i, k] * L[j, k]
            L[i, j] = t / L[j, j]
    return True


@_jit
def chol_inv(A: np.ndarray, out: np.ndarray) -> bool:
    """``out = A^{-1}`` for a small symmetric positive-definite ``A`` (Cholesky); False if not PD."""
    n = A.shape[0]
    L = np.zeros((n, n))
    if not chol_factor(A, L):
        return False
    # inverse of L, then L^-T L^-1
    Li = np.zeros((n, n))
    for j in range(n):
        Li[j, j] = 1.0 / L[j, j]
        for i in range(j + 1, n):
            t = 0.0
            for k in range(j, i):
                t -= L[i, k] * Li[k, j]
            Li[i, j] = t / L[i, i]
    for i in range(n):
        for j in range(i + 1):
            t = 0.0
            for k in range(i, n):
                t += Li[k, i] * Li[k, j]
            out[i, j] = t
            out[j, i] = t
    return True


@_jit
def fix_predict(q: np.ndarray, kind: int, lever: np.ndarray, h: np.ndarray, Jq: np.ndarray) -> int:
    """What a fix of ``kind`` sees from the planar pose ``q = (x, y, yaw)``: ``h`` (3,), ``Jq`` (3, 3)
    (rows past the fix's dimension are zero); returns the dimension m."""
    for a in range(3):
        for b in range(3):
            Jq[a, b] = 0.0
    if kind == KIND_POSE:
        h[0] = q[0]
        h[1] = q[1]
        h[2] = q[2]
        Jq[0, 0] = 1.0
        Jq[1, 1] = 1.0
        Jq[2, 2] = 1.0
        return 3
    c = math.cos(q[2])
    s = math.sin(q[2])
    h[0] = q[0] + c * lever[0] - s * lever[1]
    h[1] = q[1] + s * lever[0] + c * lever[1]
    h[2] = 0.0
    Jq[0, 0] = 1.0
    Jq[1, 1] = 1.0
    Jq[0, 2] = -s * lever[0] - c * lever[1]
    Jq[1, 2] = c * lever[0] - s * lever[1]
    return 2


@_jit
def fix_residual(Xa: np.ndarray, Xb: np.ndarray, alpha: float, kind: int, z: np.ndarray, lever: np.ndarray,
                 r: np.ndarray, Jq: np.ndarray, q: np.ndarray, h: np.ndarray) -> int:
    """Residual ``r = h(q) - z`` (yaw wrapped) of a fix between two node states; ``Jq`` is d r / d q, the
    interpolated pose's Jacobian (multiply by 1 - alpha and alpha for the two nodes); ``q``, ``h`` (3,)
    are work buffers; returns m."""
    for a in range(3):
        q[a] = (1.0 - alpha) * Xa[a] + alpha * Xb[a]
    m = fix_predict(q, kind, lever, h, Jq)
    for a in range(3):
        r[a] = h[a] - z[a]
    if kind == KIND_POSE:
        r[2] = wrap(r[2])
    else:
        r[2] = 0.0
    return m


@_jit
def odo_predict(x: np.ndarray, K: np.ndarray, u: np.ndarray, f: np.ndarray, F: np.ndarray, G: np.ndarray) -> None:
    """Odometry motion: ``f`` (3,) the next pose from ``x`` (3,) and parameters ``K`` (3,) under the
    robot-frame increment ``u`` (3,); ``F`` (3, 6) = d f / d (x, K); ``G`` (3, 3) maps robot-frame noise
    to the world."""
    c = math.cos(x[2])
    s = math.sin(x[2])
    ax = K[0] * u[0]
    ay = K[0] * u[1]
    f[0] = x[0] + c * ax - s * ay
    f[1] = x[1] + s * ax + c * ay
    f[2] = x[2] + K[1] * u[2] + K[2] * u[0]
    for a in range(3):
        for b in range(6):
            F[a, b] = 0.0
        for b in range(3):
            G[a, b] = 0.0
    F[0, 0] = 1.0
    F[1, 1] = 1.0
    F[2, 2] = 1.0
    F[0, 2] = -s * ax - c * ay
    F[1, 2] = c * ax - s * ay
    F[0, 3] = c * u[0] - s * u[1]
    F[1, 3] = s * u[0] + c * u[1]
    F[2, 4] = u[2]
    F[2, 5] = u[0]
    G[0, 0] = c
    G[0, 1] = -s
    G[1, 0] = s
    G[1, 1] = c
    G[2, 2] = 1.0


@_jit
def odo_residual(Xa: np.ndarray, Xb: np.ndarray, K: np.ndarray, u: np.ndarray, r: np.ndarray,
                 Ja: np.ndarray, Jb: np.ndarray, Jk: np.ndarray) -> None:
    """Residual of an odometry increment in the robot frame of node a: ``R(yaw_a)^T (p_b - p_a) - k_d u_xy``
    and ``yaw_b - yaw_a - k_t u_yaw - k_c u_x``; Jacobians (3, 3) on both nodes and (3, 3) on K."""
    c = math.cos(Xa[2])
    s = math.sin(Xa[2])
    dx = Xb[0] - Xa[0]
    dy = Xb[1] - Xa[1]
    r[0] = c * dx + s * dy - K[0] * u[0]
    r[1] = -s * dx + c * dy - K[0] * u[1]
    r[2] = (Xb[2] - Xa[2]) - K[1] * u[2] - K[2] * u[0]
    for a in range(3):
        for b in range(3):
            Ja[a, b] = 0.0
            Jb[a, b] = 0.0
            Jk[a, b] = 0.0
    Ja[0, 0] = -c
    Ja[0, 1] = -s
    Ja[0, 2] = -s * dx + c * dy
    Ja[1, 0] = s
    Ja[1, 1] = -c
    Ja[1, 2] = -c * dx - s * dy
    Ja[2, 2] = -1.0
    Jb[0, 0] = c
    Jb[0, 1] = s
    Jb[1, 0] = -s
    Jb[1, 1] = c
    Jb[2, 2] = 1.0
    Jk[0, 0] = -u[0]
    Jk[1, 0] = -u[1]
    Jk[2, 1] = -u[2]
    Jk[2, 2] = -u[0]


@_jit
def cv_residual(Xa: np.ndarray, Xb: np.ndarray, dt: float, r: np.ndarray, Ja: np.ndarray, Jb: np.ndarray) -> None:
    """Constant velocity (white-noise acceleration): ``p_b - p_a - v_a dt`` and ``v_b - v_a`` (6,)."""
    for a in range(6):
        for b in range(6):
            Ja[a, b] = 0.0
            Jb[a, b] = 0.0
    for a in range(3):
        r[a] = Xb[a] - Xa[a] - Xa[3 + a] * dt
        r[3 + a] = Xb[3 + a] - Xa[3 + a]
        Ja[a, a] = -1.0
        Ja[a, 3 + a] = -dt
        Ja[3 + a, 3 + a] = -1.0
        Jb[a, a] = 1.0
        Jb[3 + a, 3 + a] = 1.0


@_jit
def huber(s2: float, k: float) -> tuple[float, float]:
    """Huber loss of a squared whitened norm ``s2``: (rho, weight); quadratic inside ``k`` sigma."""
    if k <= 0.0 or s2 <= k * k:
        return s2, 1.0
    s = math.sqrt(s2)
    return 2.0 * k * s - k * k, k / s
