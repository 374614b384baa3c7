"""What GTlaser's smoother leaves of one scan's noise: the steady-state Rauch-Tung-Striebel smoother.

GTlaser fits every frame of the fixed scanners with the hull ICP, then smooths each track with a
white-noise model of ``order`` integrators (:func:`gtrig.smoothing.rts_smooth_varying`). Far from a
track's ends and with frames at a steady rate, the smoothed variance of each of x, y and yaw settles to
a fixed share of the frame's own variance ``r``; for a process noise of spectral density ``q`` and a
frame interval ``dt`` that share depends only on ``lam = q dt^(2 order - 1) / r`` (scale the state's
units and time). It is computed once per order on a log grid of ``lam`` (the filter's discrete
algebraic Riccati equation, then the smoother's steady-state Lyapunov equation) and interpolated.
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np
from scipy.linalg import solve_discrete_are, solve_discrete_lyapunov

from gtrig.smoothing import white_noise_model

#: the range of ``lam`` tabulated (``lam`` outside it is clipped to it)
LAM_RANGE = (1e-18, 1e6)
_N_TABLE = 121


def _steady_share(lam: float, order: int) -> float:
    """Smoothed over measured variance of one axis, measurement variance 1, unit time step."""
    F, Q = white_noise_model(np.ones(1), np.full(3, lam), order)
    idx = [3 * i for i in range(order)]  # the x axis's pose, velocity, ... (the axes are independent)
    Fx, Qx = F[0][np.ix_(idx, idx)], Q[0][np.ix_(idx, idx)]
    H = np.zeros((1, order))
    H[0, 0] = 1.0
    P_pred = solve_discrete_are(Fx.T, H.T, Qx, np.eye(1))
    gain = P_pred @ H.T / (H @ P_pred @ H.T + 1.0)
    P_filt = P_pred - gain @ H @ P_pred
    C = P_filt @ Fx.T @ np.linalg.inv(P_pred)
    P_smooth = solve_discrete_lyapunov(C, P_filt - C @ P_pred @ C.T)
    return float(P_smooth[0, 0])


@lru_cache(maxsize=4)
def _table(order: int) -> tuple[np.ndarray, np.ndarray]:
    log_lam = np.linspace(np.log10(LAM_RANGE[0]), np.log10(LAM_RANGE[1]), _N_TABLE)
    share = np.array([_steady_share(10.0**x, order) for x in log_lam])
    return log_lam, np.log10(np.minimum(share, 1.0))


def smoothed_share(lam: np.ndarray, order: int) -> np.ndarray:
    """The steady-state smoothed variance over one frame's variance (same shape as ``lam``, in (0, 1]).

    Parameters
    ----------
    lam : process noise spectral density times ``dt^(2 order - 1)`` over the frame's variance, any shape.
    order : 2 (white acceleration) or 3 (white jerk), as the smoother's.
    """
    x, y = _table(order)
    ll = np.log10(np.clip(np.asarray(lam, dtype=float), 10.0 ** x[0], 10.0 ** x[-1]))
    return np.minimum(10.0 ** np.interp(ll, x, y), 1.0)


def smoothed_covariance(cov_frame: np.ndarray, qd_xytheta: np.ndarray, dt_s: float, order: int) -> np.ndarray:
    """Steady-state smoothed covariance (K, 3, 3) of frames whose own covariance is ``cov_frame`` (K, 3, 3):
    each axis's standard deviation scaled by the square root of its :func:`smoothed_share` (correlations
    kept), for process noise spectral densities ``qd_xytheta`` (3,) of x, y, yaw and frames ``dt_s`` apart."""
    var = np.diagonal(cov_frame, axis1=1, axis2=2)
    with np.errstate(divide="ignore", invalid="ignore"):
        lam = np.asarray(qd_xytheta, dtype=float) * dt_s ** (2 * order - 1) / var
    d = np.sqrt(smoothed_share(np.where(np.isfinite(lam), lam, LAM_RANGE[1]), order))
    return cov_frame * d[:, :, None] * d[:, None, :]
