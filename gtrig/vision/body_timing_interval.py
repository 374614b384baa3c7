"""The timing fit's interval: a Bartlett sandwich over instants, debiased and given its degrees of freedom.

The fit (:mod:`gtrig.vision.body_timing`) solves a few timing parameters from a few dozen instants, each
instant's whitened residuals ``e_g`` (pose projected out) and timing columns ``X_g``. Its error is
``N^-1 sum_g X_g^T eps_g`` (``N = sum_g X_g^T X_g``). The sandwich estimates the middle from the fitted
residuals' scores ``s_g = X_g^T e_g``, weighting the products of instants ``k`` apart by Bartlett's
``1 - k / (lags + 1)``: neighbouring instants share poses through their local motions.

Two things make that estimate too small and too variable for a few dozen instants, both worse for a drift
than for an offset. The fit zeroes the scores' sum, so the products of neighbours come out negative on
average even where the true scores are independent: with 40 instants and ``lags`` 6 the Bartlett middle of
a drift falls to about 0.6 of its value at the true timing. And the drift's columns grow with the time
from the recording's midpoint, the image speed and the residuals' spread (an exposure that wanders from
its frame time shifts the points by their speed times the wander), so a handful of fast instants at the
recording's ends carry most of the estimate and of its middle: the middle has the few degrees of
freedom of those instants, not of all.

Both are computed from the design rather than tuned: under a working model in which the instants' errors
are independent, each with the variance of its own residuals (``sigma_g^2 = |e_g|^2 / (n_g - 6)``, ``n_g``
its whitened residuals), the Bartlett middle of a parameter ``c`` is the quadratic form ``a^T W a`` of
``a_g = u_g^T e_g`` (``u_g = X_g N^-1 c``, ``W`` the Bartlett weights), with expectation ``E = tr(W B)``
and variance ``2 tr(W B W B)``, ``B`` the covariance of ``a`` (``e = M eps`` with ``M`` the fit's
residual maker); the parameter's variance under the same model is ``V = c^T N^-1 X^T S X N^-1 c``. The
sandwich is scaled by ``V / E`` and its degrees of freedom are Satterthwaite's ``E^2 / tr(W B W B)``;
the interval's half width is Student's quantile at those degrees of freedom times the sigma. This is Bell
and McCaffrey's small-sample correction of a clustered sandwich, with the clusters' Bartlett band in place
of a block-diagonal middle. On simulated board videos with drifting offsets and 16.7 ms of unstamped
exposure jitter (``bench/body_timing.py``, 40 seeds) the drifts' 95 % intervals covered 89.2 % with
Kiefer and Vogelsang's fixed-b critical value (which assumes evenly spread scores) and 94.2 % with this.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from scipy.stats import t as student_t


def bartlett_weights(index: np.ndarray, lags: int) -> np.ndarray:
    """(G, G) Bartlett weights ``max(0, 1 - |index_a - index_b| / (lags + 1))`` of instants at positions
    ``index`` (G,) in the track."""
    gap = np.abs(index[:, None] - index[None, :]).astype(float)
    return np.clip(1.0 - gap / (lags + 1.0), 0.0, None)


def sandwich_covariance(columns: Sequence[np.ndarray], residuals: Sequence[np.ndarray], index: np.ndarray,
                        lags: int) -> tuple[np.ndarray, np.ndarray]:
    """The Bartlett sandwich covariance of a least-squares estimate over instants, debiased (module docstring),
    and each parameter's degrees of freedom.

    Parameters
    ----------
    columns : per instant, (n_g, p) whitened columns of the parameters (nuisance projected out).
    residuals : per instant, (n_g,) whitened residuals at the estimate (nuisance projected out).
    index : (G,) the instants' positions in the track (neighbours ``k`` apart share errors up to ``lags``).
    lags : the Bartlett band's half width, instants.

    Returns
    -------
    cov : (p, p) the sandwich ``N^-1 M N^-1``, each parameter's row and column scaled by its ``sqrt(V / E)``.
    dof : (p,) each parameter's Satterthwaite degrees of freedom.
    """
    N_inv = np.linalg.inv(sum(X.T @ X for X in columns))
    W = bartlett_weights(np.asarray(index), lags)
    scores = np.array([X.T @ e for X, e in zip(columns, residuals, strict=True)])  # (G, p)
    cov = N_inv @ (scores.T @ W @ scores) @ N_inv
    var_g = np.array([e @ e / max(len(e) - 6, 1) for e in residuals])
    N_var = sum(v * X.T @ X for v, X in zip(var_g, columns, strict=True))
    p = N_inv.shape[0]
    scale, dof = np.ones(p), np.full(p, np.inf)
    for j in range(p):
        u = [X @ N_inv[:, j] for X in columns]
        F = np.array([X.T @ uj for X, uj in zip(columns, u, strict=True)])  # (G, p): u_g^T X_g
        FNF = F @ N_inv @ F.T
        B = (np.diag(var_g * np.array([uj @ uj for uj in u])) - var_g[:, None] * FNF - FNF * var_g[None, :]
             + F @ N_inv @ N_var @ N_inv @ F.T)
        WB = W @ B
        expected, spread = float(np.trace(WB)), float(np.sum(WB * WB.T))
        if expected > 0 and spread > 0:
            scale[j] = np.sqrt(max(float(N_inv[:, j] @ N_var @ N_inv[:, j]), 0.0) / expected)
            dof[j] = expected**2 / spread
    return cov * np.outer(scale, scale), dof


def quantile_factor(dof: np.ndarray, level: float = 0.95) -> np.ndarray:
    """(p,) Student's two-sided ``level`` quantile at ``dof`` over the normal one: the factor that turns a
    sigma with ``dof`` degrees of freedom into one whose 1.96 is a 95 % interval."""
    q = 0.5 + level / 2
    return np.asarray(student_t.ppf(q, np.asarray(dof, float)) / student_t.ppf(q, np.inf))
