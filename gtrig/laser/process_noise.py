"""The smoother's process noise chosen by maximum likelihood on the track's own innovations.

A constant-velocity smoother is only as right as its white-acceleration spectral density: too small
and it lags through the bends of a fast robot (errors the covariance does not admit), too large and
it averages little. The robot's accelerations differ from run to run (a cart pushed at 0.3 m/s, a
robot braking from 1.5 m/s before a turn), so the density is estimated per track: the forward Kalman
filter is run for a grid of linear and angular densities at once, and the pair whose innovations are
most likely (Gaussian log-likelihood, Mehra 1970; Bar-Shalom, Li and Kirubarajan 2001, section 5.2)
is kept. The filter is the predict/update of :func:`gtrig.smoothing.rts_smooth`, batched over the
grid, so a whole track costs about one pass per grid row.
"""

from __future__ import annotations

import numpy as np

from gtrig.smoothing import SMOOTH_BLOCK_FRAMES, white_noise_model


def innovation_loglik(
    stamps_s: np.ndarray,
    z_xytheta: np.ndarray,
    R_z: np.ndarray,
    q_lin: np.ndarray,
    q_ang: np.ndarray,
    order: int = 2,
) -> np.ndarray:
    """Log-likelihood of a track's measurements under the constant-velocity model, for every pair of
    spectral densities.

    Parameters
    ----------
    stamps_s : (n,) increasing times, seconds.
    z_xytheta : (n, 3) measured poses (theta unwrapped); rows of ``nan`` are not measured.
    R_z : (n, 3, 3) measurement covariances.
    q_lin : (A,) linear white-acceleration densities, (m/s^2)^2 s.
    q_ang : (B,) angular ones, (rad/s^2)^2 s.
    order : 2, the constant-velocity model; 3, constant acceleration (densities then of the white
        jerk, (m/s^3)^2 s and (rad/s^3)^2 s).

    Returns
    -------
    (A, B) log-likelihoods (up to a common constant).
    """
    return innovation_loglik_terms(stamps_s, z_xytheta, R_z, q_lin, q_ang, order).sum(axis=0)


def innovation_loglik_terms(
    stamps_s: np.ndarray,
    z_xytheta: np.ndarray,
    R_z: np.ndarray,
    q_lin: np.ndarray,
    q_ang: np.ndarray,
    order: int = 2,
) -> np.ndarray:
    """Per-frame terms (n, A, B) of :func:`innovation_loglik` (zero where a frame is not measured,
    and at the first measured frame)."""
    A, B = len(q_lin), len(q_ang)
    qd_grid = np.zeros((A, B, 3))
    qd_grid[..., 0] = qd_grid[..., 1] = np.asarray(q_lin, dtype=float)[:, None]
    qd_grid[..., 2] = np.asarray(q_ang, dtype=float)[None, :]
    qd = qd_grid.reshape(-1, 3)
    G = qd.shape[0]
    m = 3 * order
    meas = np.flatnonzero(np.isfinite(z_xytheta[:, 0]))
    terms = np.zeros((len(stamps_s), G))
    if meas.size < 3:
        return terms.reshape(-1, A, B)
    first = meas[0]
    x = np.zeros((G, m))
    x[:, :3] = z_xytheta[first]
    P = np.tile(np.eye(m), (G, 1, 1))
    P[:, :3, :3] = R_z[first]
    dts = np.diff(stamps_s[meas])
    axis = np.tile(np.arange(3), order)
    W = SMOOTH_BLOCK_FRAMES  # the steps' transitions made a block at a time (a track's would be ~1.3 kB a step)
    for n_k, k in enumerate(meas[1:]):
        if n_k % W == 0:
            Fs, _ = white_noise_model(dts[n_k:n_k + W], np.zeros(3), order)
            _, Qunit = white_noise_model(dts[n_k:n_k + W], np.ones(3), order)  # per unit density, axis by axis
        F = Fs[n_k % W]
        x = x @ F.T
        Qg = Qunit[n_k % W][None] * np.sqrt(qd[:, axis][:, :, None] * qd[:, axis][:, None, :])
        P = F @ P @ F.T + Qg
        S = P[:, :3, :3] + R_z[k]
        Si = np.linalg.inv(S)
        nu = z_xytheta[k] - x[:, :3]
        terms[k] = -0.5 * (np.einsum("gi,gij,gj->g", nu, Si, nu) + np.linalg.slogdet(S)[1])
        K = P[:, :, :3] @ Si
        x = x + np.einsum("gij,gj->gi", K, nu)
        P = P - K @ P[:, :3, :]
        P = 0.5 * (P + np.swapaxes(P, 1, 2))
    return terms.reshape(-1, A, B)


def ml_process_noise(
    stamps_s: np.ndarray,
    z_xytheta: np.ndarray,
    R_z: np.ndarray,
    accel_std_grid_mps2: np.ndarray,
    ang_accel_std_grid_radps2: np.ndarray,
    order: int = 2,
) -> tuple[float, float]:
    """The (linear, angular) white-acceleration standard deviations, among the grids (A,) and (B,),
    whose innovations are most likely (:func:`innovation_loglik`)."""
    a = np.asarray(accel_std_grid_mps2, dtype=float)
    b = np.asarray(ang_accel_std_grid_radps2, dtype=float)
    ll = innovation_loglik(stamps_s, z_xytheta, R_z, a**2, b**2, order)
    i, j = np.unravel_index(int(np.argmax(ll)), ll.shape)
    return float(a[i]), float(b[j])


def local_ml_process_noise(
    stamps_s: np.ndarray,
    z_xytheta: np.ndarray,
    R_z: np.ndarray,
    accel_std_grid_mps2: np.ndarray,
    ang_accel_std_grid_radps2: np.ndarray,
    window_s: float,
    order: int = 2,
) -> tuple[np.ndarray, np.ndarray]:
    """Per-frame (n,) linear and angular white-acceleration standard deviations: at each frame, the
    grid pair whose innovations within ``window_s`` (centred) are most likely. A robot cruising and
    then braking into a bend gets a stiff model on the straight and a loose one in the bend."""
    a = np.asarray(accel_std_grid_mps2, dtype=float)
    b = np.asarray(ang_accel_std_grid_radps2, dtype=float)
    terms = innovation_loglik_terms(stamps_s, z_xytheta, R_z, a**2, b**2, order)  # (n, A, B)
    shape = terms.shape[1:]
    c = np.zeros((len(terms) + 1,) + shape)
    np.cumsum(terms, axis=0, out=c[1:])
    del terms
    t = np.asarray(stamps_s, dtype=float)
    lo = np.searchsorted(t, t - window_s / 2, side="left")
    hi = np.searchsorted(t, t + window_s / 2, side="right")
    best = np.zeros(len(t), dtype=np.intp)
    for k0 in range(0, len(t), SMOOTH_BLOCK_FRAMES):  # the windows' sums a block at a time
        k1 = k0 + SMOOTH_BLOCK_FRAMES
        best[k0:k1] = np.argmax((c[hi[k0:k1]] - c[lo[k0:k1]]).reshape(len(lo[k0:k1]), -1), axis=1)
    i, j = np.unravel_index(best, shape)
    return a[i], b[j]
