""""Within 3 sigma" for an n-D error under its covariance: the test, the rate a correct covariance
gives, and how far a run's rate may stray from it by chance.

In 1-D, +/- 3 sigma holds 99.73 % of a Gaussian. In n-D "within 3 sigma" has three readings, and a
correct covariance passes each at a different rate:

* ``region``: inside the ellipsoid that holds the same 99.73 % (``d^2 <= chi2_n.ppf(0.9973)``: 11.83 in
  2-D, 14.16 in 3-D): 99.73 % whatever n; the n-D meaning of "3 sigma" used for the acceptance;
* ``axes``: each coordinate within 3 of its own sigmas: 0.9973^n for uncorrelated axes (99.19 % in
  3-D), a little more when they are correlated (computed from the covariances);
* ``d3``: Mahalanobis distance ``d <= 3``: 98.89 % in 2-D, 97.07 % in 3-D.

How far the rate of N errors may stray: N independent errors give a binomial spread; errors correlated
in time (RTK errors wander over seconds) are fewer independent samples, and their exceedances come in
clusters, so the spread is much wider. It is drawn by Monte Carlo for a
first-order Gauss-Markov error of a given time constant sampled at the run's own stamps
(:func:`correlated_rates`).
"""

from __future__ import annotations

from typing import Literal

import numpy as np
from scipy import stats

Test = Literal["region", "axes", "d3"]
P_3SIGMA = float(stats.chi2.cdf(9.0, 1))  # 0.99730


def mahalanobis2(err: np.ndarray, cov: np.ndarray) -> np.ndarray:
    """(N,) ``e^T C^-1 e`` of errors (N, n) under covariances (N, n, n)."""
    return np.einsum("ni,ni->n", err, np.linalg.solve(cov, err[..., None])[..., 0])


def within(err: np.ndarray, cov: np.ndarray, test: Test = "region") -> np.ndarray:
    """(N,) bool: each error (N, n) inside its covariance's (N, n, n) 3-sigma by ``test`` (module docstring)."""
    n = err.shape[1]
    if test == "axes":
        return np.all(np.abs(err) <= 3.0 * np.sqrt(np.diagonal(cov, axis1=1, axis2=2)), axis=1)
    limit = 9.0 if test == "d3" else float(stats.chi2.ppf(P_3SIGMA, n))
    return mahalanobis2(err, cov) <= limit


def _inside_draws(z: np.ndarray, cov: np.ndarray, test: Test) -> np.ndarray:
    """(N, K) bool: unit-Gaussian draws z (N, K, n) coloured by ``chol(cov)`` (N, n, n), inside by ``test``."""
    n = cov.shape[1]
    if test != "axes":  # d^2 of chol(C) z under C is |z|^2
        return np.sum(z * z, axis=-1) <= (9.0 if test == "d3" else float(stats.chi2.ppf(P_3SIGMA, n)))
    e = np.einsum("nij,nkj->nki", np.linalg.cholesky(cov), z)
    sig = np.sqrt(np.diagonal(cov, axis1=1, axis2=2))
    return np.all(np.abs(e) <= 3.0 * sig[:, None, :], axis=-1)


def expected_rate(cov: np.ndarray, test: Test = "region", n_samples: int = 400_000,
                  rng: np.random.Generator | None = None) -> float:
    """The rate a correct covariance gives: exact for ``region`` and ``d3``; for ``axes``, Gaussian
    errors drawn from ``cov`` (N, n, n), about ``n_samples`` in all (binomial sd 1.4e-4 at 99.2 %)."""
    n = cov.shape[1]
    if test == "region":
        return P_3SIGMA
    if test == "d3":
        return float(stats.chi2.cdf(9.0, n))
    rng = rng or np.random.default_rng(0)
    draws = max(1, -(-n_samples // cov.shape[0]))
    return float(_inside_draws(rng.standard_normal((cov.shape[0], draws, n)), cov, "axes").mean())


def binomial_interval(n: int, p: float, level: float = 0.95) -> tuple[float, float]:
    """Central ``level`` interval of the rate of ``n`` independent trials of probability ``p``."""
    lo, hi = stats.binom.interval(level, n, p)
    return float(lo / n), float(hi / n)


def correlated_rates(stamps_s: np.ndarray, cov: np.ndarray, tau_s: float, test: Test = "region",
                     n_draws: int = 1000, rng: np.random.Generator | None = None) -> np.ndarray:
    """(n_draws,) rates a correct covariance gives when the errors wander in time.

    Each draw is a unit-variance first-order Gauss-Markov process of time constant ``tau_s`` (per
    axis, independent) sampled at ``stamps_s`` (N,) (gaps included: correlation ``exp(-dt / tau)``),
    coloured by ``chol(cov)`` (N, n, n); the test is applied to it as to the real errors. Their
    quantiles are the spread of a run's rate; the share at or below a run's rate is its p-value.
    """
    rng = rng or np.random.default_rng(0)
    N, n = cov.shape[:2]
    a = np.exp(-np.diff(stamps_s) / tau_s)
    z = np.empty((N, n_draws, n))
    z[0] = rng.standard_normal((n_draws, n))
    w = rng.standard_normal((N - 1, n_draws, n))
    for i in range(1, N):  # the recursion is sequential in time, vectorised over draws and axes
        z[i] = a[i - 1] * z[i - 1] + np.sqrt(1.0 - a[i - 1] ** 2) * w[i - 1]
    return _inside_draws(z, cov, test).mean(axis=0)
