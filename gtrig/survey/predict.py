"""Expected pose uncertainty over the room for a layout of world points (planning where they go).

At every cell of a grid and for ``n_headings`` headings, the pose covariance of the survey is the
Cramer-Rao bound ``(J^T Sigma^-1 J)^-1`` of :mod:`gtrig.survey.poses` with readings from every robot point
to every world point within ``max_range_m`` (hand-laser sigma plus the world points' covariance,
propagated). The map keeps the worst heading: ``sigma_pos_m`` = sqrt of the largest eigenvalue of the
position block, ``sigma_theta_rad``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from gtrig.errors import InputError


@dataclass(frozen=True)
class UncertaintyMap:
    """Grid ``x_m`` (nx,), ``y_m`` (ny,); ``sigma_pos_m`` and ``sigma_theta_rad`` (ny, nx), nan where fewer
    than 3 readings are possible."""

    x_m: np.ndarray
    y_m: np.ndarray
    sigma_pos_m: np.ndarray
    sigma_theta_rad: np.ndarray


#: the largest map :func:`predict_pose_uncertainty` computes (a 100 m room at 3 cm steps)
MAX_CELLS = 10_000_000


def predict_pose_uncertainty(
    world_xy: np.ndarray,
    world_cov_xy: np.ndarray,
    robot_xy: np.ndarray,
    sigma_m: float,
    *,
    step_m: float = 0.25,
    margin_m: float = 0.0,
    n_headings: int = 8,
    max_range_m: float = 30.0,
) -> UncertaintyMap:
    """Pose uncertainty map over the bounding box of the world points (+ ``margin_m``).

    Parameters
    ----------
    world_xy : (N, 2) world points, world frame, metres; world_cov_xy : (N, 2, 2) their covariance.
    robot_xy : (A, 2) robot points, robot frame.
    sigma_m : hand-laser standard deviation.
    """
    W = np.asarray(world_xy, dtype=float)
    if W.shape[0] < 2 or robot_xy.shape[0] < 2:
        raise InputError("the prediction needs at least 2 world points and 2 robot points")
    if not (np.isfinite(step_m) and step_m > 0):
        raise InputError(f"step must be a positive number of metres, got {step_m:g}")
    if not (np.isfinite(margin_m) and margin_m >= 0):
        raise InputError(f"margin must be a non-negative number of metres, got {margin_m:g}")
    lo, hi = W.min(axis=0) - margin_m, W.max(axis=0) + margin_m
    cells = float(np.prod(np.floor((hi - lo) / step_m) + 1))
    if cells > MAX_CELLS:
        raise InputError(f"a grid of {cells:.3g} cells (step {step_m:g} m, margin {margin_m:g} m) is more than "
                         f"the {MAX_CELLS:.0e} a map may have: use a larger step or a smaller margin")
    xs = np.arange(lo[0], hi[0] + 1e-9, step_m)
    ys = np.arange(lo[1], hi[1] + 1e-9, step_m)
    gx, gy = np.meshgrid(xs, ys)
    P = np.column_stack([gx.ravel(), gy.ravel()])  # (G, 2)
    worst_pos = np.zeros(P.shape[0])
    worst_th = np.zeros(P.shape[0])
    var_w = np.asarray(world_cov_xy, dtype=float)
    for th in np.linspace(0, 2 * np.pi, n_headings, endpoint=False):
        c, s = np.cos(th), np.sin(th)
        q = robot_xy @ np.array([[c, s], [-s, c]])  # rotated robot points (A, 2)
        S = P[:, None, :] + q[None]  # (G, A, 2)
        diff = W[None, None] - S[:, :, None, :]  # (G, A, N, 2)
        rng = np.linalg.norm(diff, axis=3)
        u = diff / np.maximum(rng, 1e-9)[..., None]
        ok = (rng > 0.05) & (rng < max_range_m)
        # Jacobian rows (G, A, N, 3); readings treated as independent with variance sigma^2 + u^T C_w u
        dth = u[..., 0] * q[None, :, None, 1] - u[..., 1] * q[None, :, None, 0]
        J = np.concatenate([-u, dth[..., None]], axis=3)  # d|w - s| / d(x, y, theta), as in poses.py
        var = sigma_m**2 + np.einsum("gani,nij,ganj->gan", u, var_w, u)
        wgt = np.where(ok, 1.0 / var, 0.0)
        info = np.einsum("gani,gan,ganj->gij", J, wgt, J)
        n_ok = ok.reshape(ok.shape[0], -1).sum(axis=1)
        good = (n_ok >= 3) & (np.linalg.cond(info) < 1e12)
        cov = np.full_like(info, np.nan)
        cov[good] = np.linalg.inv(info[good])
        ev = np.linalg.eigvalsh(np.nan_to_num(cov[:, :2, :2]))
        sp = np.where(good, np.sqrt(np.maximum(ev[:, -1], 0)), np.nan)
        st = np.where(good, np.sqrt(np.abs(cov[:, 2, 2])), np.nan)
        worst_pos = np.fmax(worst_pos, sp) if th > 0 else sp
        worst_th = np.fmax(worst_th, st) if th > 0 else st
    return UncertaintyMap(xs, ys, worst_pos.reshape(gx.shape), worst_th.reshape(gx.shape))
