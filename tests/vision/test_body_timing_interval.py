"""The timing fit's debiased Bartlett sandwich and its degrees of freedom (gtrig.vision.body_timing_interval),
on least-squares problems of the timing fit's shape whose truth is known: 40 instants, each with 16 whitened
rows less a 6-parameter pose projected out, an offset-like column and a drift-like one (the first times the
time from the midpoint), the instants' speeds spread as a hand's are."""

from __future__ import annotations

import numpy as np

from gtrig.vision.body_timing_interval import bartlett_weights, quantile_factor, sandwich_covariance

LAGS = 6


def _design(rng: np.random.Generator, n_instants: int = 40, rows: int = 16
            ) -> tuple[list[np.ndarray], list[np.ndarray], np.ndarray]:
    """Per instant the (rows, 2) columns and the (rows, rows) projector removing a random pose, and the
    instants' speeds (log-normal)."""
    t = np.linspace(-1.0, 1.0, n_instants)
    speed = np.exp(rng.normal(0.0, 0.8, n_instants))
    columns, projectors = [], []
    for g in range(n_instants):
        P = rng.normal(size=(rows, 6))
        Q = np.eye(rows) - P @ np.linalg.pinv(P)
        x = rng.normal(size=rows) * speed[g]
        columns.append(Q @ np.c_[x, x * t[g]])
        projectors.append(Q)
    return columns, projectors, speed


def _draws(rng: np.random.Generator, columns: list[np.ndarray], projectors: list[np.ndarray],
           sigma: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """``n`` noise draws (instant ``g``'s rows with sigma ``sigma[g]``): the estimates (n, 2), their sandwich
    variances (n, 2) and degrees of freedom (n, 2), and the raw Bartlett sandwich's variances (n, 2)."""
    N_inv = np.linalg.inv(sum(X.T @ X for X in columns))
    index = np.arange(len(columns))
    W = bartlett_weights(index, LAGS)
    est, var, dof, raw = [], [], [], []
    for _ in range(n):
        eps = [Q @ rng.normal(0.0, s, len(Q)) for Q, s in zip(projectors, sigma, strict=True)]
        theta = N_inv @ sum(X.T @ e for X, e in zip(columns, eps, strict=True))
        res = [e - X @ theta for X, e in zip(columns, eps, strict=True)]
        cov, d = sandwich_covariance(columns, res, index, LAGS)
        S = np.array([X.T @ e for X, e in zip(columns, res, strict=True)])
        est.append(theta)
        var.append(np.diag(cov))
        dof.append(d)
        raw.append(np.diag(N_inv @ S.T @ W @ S @ N_inv))
    return np.array(est), np.array(var), np.array(dof), np.array(raw)


def test_sandwich_unbiased_and_its_spread_as_its_degrees_of_freedom_say() -> None:
    """Independent instants of equal noise: the scaled sandwich's mean is the estimate's true variance (the
    raw Bartlett middle's falls well short: the fit zeroes the scores' sum), and its relative variance is
    Satterthwaite's ``2 / dof``."""
    rng = np.random.default_rng(2)
    columns, projectors, _ = _design(rng)
    true_var = np.diag(np.linalg.inv(sum(X.T @ X for X in columns)))
    _, var, dof, raw = _draws(rng, columns, projectors, np.ones(len(columns)), 400)
    # measured (600 draws) 0.94 and 0.93 +- 0.03; raw 0.6-0.7
    assert np.all(np.abs(var.mean(0) / true_var - 1) < 0.12), var.mean(0) / true_var
    assert np.all(raw.mean(0) / true_var < 0.8), raw.mean(0) / true_var
    # measured relative variance 0.60 and 0.47 against 2 / dof 0.49 and 0.46
    rel = var.var(0) / var.mean(0) ** 2
    assert np.all(np.abs(rel / (2 / dof.mean(0)) - 1) < 0.4), (rel, 2 / dof.mean(0))
    assert np.all(dof < len(columns)) and np.all(dof > 1)


def test_intervals_cover_where_fast_instants_are_noisier() -> None:
    """Each instant's noise grows with its speed (an exposure wandering from its frame time): the scaled
    sandwich with Student's quantile at its degrees of freedom covers the truth 95 % of the time or a little
    more; the raw Bartlett sandwich with the normal quantile does not."""
    rng = np.random.default_rng(1)
    columns, projectors, speed = _design(rng)
    est, var, dof, raw = _draws(rng, columns, projectors, 0.3 + 0.5 * speed, 400)
    cover = np.mean(np.abs(est) < 1.96 * np.sqrt(var) * quantile_factor(dof), axis=0)
    cover_raw = np.mean(np.abs(est) < 1.96 * np.sqrt(raw), axis=0)
    # measured (2000 draws) 97.0 % and 97.9 %; raw 75.8 % and 70.4 %
    assert np.all((cover > 0.93) & (cover < 0.995)), cover
    assert np.all(cover_raw < 0.85), cover_raw


def test_quantile_factor_is_student_over_normal() -> None:
    """1 at infinite degrees of freedom; 12.706 / 1.960 at one."""
    f = quantile_factor(np.array([np.inf, 1.0, 30.0]))
    assert f[0] == 1.0 and abs(f[1] - 12.7062 / 1.95996) < 1e-3 and 1.0 < f[2] < 1.05
