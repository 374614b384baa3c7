"""Smoothing of pose sequences: a Rauch-Tung-Striebel smoother with a constant-velocity model.

Core (no stage imports it from another stage): GTlaser smooths each hull track with it (journal paper,
section 6; issue 7), and fusion or any source that measures poses with a covariance may use it.
Vectorised where the recursion allows (the gains of the backward pass at once); about 10^5 poses/s.
"""

from __future__ import annotations

import math

import numpy as np


def white_noise_model(dt: np.ndarray, qd: np.ndarray, order: int) -> tuple[np.ndarray, np.ndarray]:
    """Transitions and process noises of x, y, theta each driven by white noise through ``order``
    integrators (2: constant velocity, 3: constant acceleration).

    Parameters
    ----------
    dt : (N,) time steps, seconds.
    qd : (N, 3) or (3,) spectral densities of the white noise of x, y, theta.
    order : 2 or 3.

    Returns
    -------
    F, Q : (N, 3 order, 3 order); the state is (pose, its first derivative, ...), three at a time.
    """
    dt = np.asarray(dt, dtype=float)
    N = dt.size
    qd = np.broadcast_to(np.asarray(qd, dtype=float), (N, 3))
    i = np.arange(order)
    p = i[None, :] - i[:, None]  # F_ij = dt^(j - i) / (j - i)!
    fact = np.array([math.factorial(max(int(k), 0)) for k in p.ravel()], dtype=np.float64).reshape(p.shape)
    Fn = np.where(p >= 0, dt[:, None, None] ** np.maximum(p, 0) / fact, 0.0)
    # Q_ij = q dt^(2n-1-i-j) / ((n-1-i)! (n-1-j)! (2n-1-i-j)) (integrated white noise)
    a = order - 1 - i
    e = a[:, None] + a[None, :] + 1
    den = np.array([[math.factorial(u) * math.factorial(v) for v in a] for u in a], dtype=float) * e
    Qn = dt[:, None, None] ** e / den
    F = np.einsum("kde,ab->kdaeb", Fn, np.eye(3)).reshape(N, 3 * order, 3 * order)
    Q = np.einsum("kde,ka,ab->kdaeb", Qn, qd, np.eye(3)).reshape(N, 3 * order, 3 * order)
    return F, Q


def rts_smooth(
    stamps_s: np.ndarray,
    z_xytheta: np.ndarray,
    R_z: np.ndarray,
    accel_std_mps2: float,
    ang_accel_std_radps2: float,
) -> tuple[np.ndarray, np.ndarray]:
    """Rauch-Tung-Striebel smoothing of planar poses with a constant-velocity model.

    Parameters
    ----------
    stamps_s
        (n,) increasing times, seconds.
    z_xytheta
        (n, 3) measured poses (theta continuous, unwrapped); rows of ``nan`` are not measured.
    R_z
        (n, 3, 3) measurement covariances.
    accel_std_mps2, ang_accel_std_radps2
        Spectral densities (as standard deviations) of the white linear and angular acceleration.

    Returns
    -------
    xytheta : (n, 3) smoothed poses.
    cov_xytheta : (n, 3, 3) their covariances.
    """
    qd = np.array([accel_std_mps2**2, accel_std_mps2**2, ang_accel_std_radps2**2])
    return rts_smooth_varying(stamps_s, z_xytheta, R_z, np.broadcast_to(qd, (len(stamps_s), 3)))


def rts_smooth_varying(
    stamps_s: np.ndarray, z_xytheta: np.ndarray, R_z: np.ndarray, qd: np.ndarray, order: int = 2
) -> tuple[np.ndarray, np.ndarray]:
    """:func:`rts_smooth` with a process noise that varies along the track, and of either order.

    Parameters
    ----------
    stamps_s, z_xytheta, R_z
        As :func:`rts_smooth`.
    qd
        (n, 3) spectral densities of the white noise driving x, y, theta over the interval ending at
        each frame: white acceleration for ``order`` 2 ((m/s^2)^2 s, (rad/s^2)^2 s), white jerk for
        ``order`` 3 ((m/s^3)^2 s, (rad/s^3)^2 s).
    order
        2: constant velocity (state pose, velocity); 3: constant acceleration (pose, velocity,
        acceleration), which follows a robot braking into a bend without the lag a constant-velocity
        model needs a loose process noise to avoid, so it can average over more frames.
    """
    n = len(stamps_s)
    m = 3 * order
    dt = np.r_[0.0, np.diff(stamps_s)]
    F, Q = white_noise_model(dt, np.asarray(qd, dtype=float), order)
    meas = np.isfinite(z_xytheta[:, 0])
    xf = np.zeros((n, m))
    Pf = np.zeros((n, m, m))
    xp = np.zeros((n, m))
    Pp = np.zeros((n, m, m))
    first = int(np.flatnonzero(meas)[0])
    x = np.zeros(m)
    x[:3] = z_xytheta[first]
    P = np.eye(m)
    P[:3, :3] = R_z[first]
    for k in range(n):
        if k > 0:
            Fk = F[k]
            x = Fk @ x
            P = Fk @ P @ Fk.T + Q[k]
        xp[k], Pp[k] = x, P
        if meas[k]:
            Kg = P[:, :3] @ np.linalg.inv(P[:3, :3] + R_z[k])
            x = x + Kg @ (z_xytheta[k] - x[:3])
            P = P - Kg @ P[:3, :]
            P = 0.5 * (P + P.T)
        xf[k], Pf[k] = x, P
    # smoother gains C_k = Pf_k F_{k+1}^T Pp_{k+1}^-1, all at once
    C = np.zeros((n, m, m))
    if n > 1:
        C[:-1] = Pf[:-1] @ np.swapaxes(F[1:], 1, 2) @ np.linalg.inv(Pp[1:])
    xs = xf.copy()
    Ps = Pf.copy()
    for k in range(n - 2, -1, -1):
        Ck = C[k]
        xs[k] = xf[k] + Ck @ (xs[k + 1] - xp[k + 1])
        Ps[k] = Pf[k] + Ck @ (Ps[k + 1] - Pp[k + 1]) @ Ck.T
    return xs[:, :3], Ps[:, :3, :3]
