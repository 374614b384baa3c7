"""Smoothing of pose sequences: a Rauch-Tung-Striebel smoother with a constant-velocity model.

Core (no stage imports it from another stage): GTlaser smooths each hull track with it (journal paper,
section 6; issue 7), and fusion or any source that measures poses with a covariance may use it.
Vectorised where the recursion allows (the gains of the backward pass at once); about 10^5 poses/s.
"""

from __future__ import annotations

import numpy as np


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
    n = len(stamps_s)
    qd = np.array([accel_std_mps2**2, accel_std_mps2**2, ang_accel_std_radps2**2])
    dt = np.r_[0.0, np.diff(stamps_s)]
    F = np.tile(np.eye(6), (n, 1, 1))
    F[:, [0, 1, 2], [3, 4, 5]] = dt[:, None]
    Q = np.zeros((n, 6, 6))
    Q[:, [0, 1, 2], [0, 1, 2]] = qd * dt[:, None] ** 3 / 3
    Q[:, [0, 1, 2], [3, 4, 5]] = Q[:, [3, 4, 5], [0, 1, 2]] = qd * dt[:, None] ** 2 / 2
    Q[:, [3, 4, 5], [3, 4, 5]] = qd * dt[:, None]
    meas = np.isfinite(z_xytheta[:, 0])
    xf = np.zeros((n, 6))
    Pf = np.zeros((n, 6, 6))
    xp = np.zeros((n, 6))
    Pp = np.zeros((n, 6, 6))
    first = int(np.flatnonzero(meas)[0])
    x = np.r_[z_xytheta[first], 0.0, 0.0, 0.0]
    P = np.zeros((6, 6))
    P[:3, :3] = R_z[first]
    P[3:, 3:] = np.eye(3)
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
    C = np.zeros((n, 6, 6))
    if n > 1:
        C[:-1] = Pf[:-1] @ np.swapaxes(F[1:], 1, 2) @ np.linalg.inv(Pp[1:])
    xs = xf.copy()
    Ps = Pf.copy()
    for k in range(n - 2, -1, -1):
        Ck = C[k]
        xs[k] = xf[k] + Ck @ (xs[k + 1] - xp[k + 1])
        Ps[k] = Pf[k] + Ck @ (Ps[k + 1] - Pp[k + 1]) @ Ck.T
    return xs[:, :3], Ps[:, :3, :3]
