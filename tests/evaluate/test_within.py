""""Within 3 sigma" in n-D (gtrig.evaluate.within): each test's rate for a correct covariance, the
spread of that rate for independent and for time-correlated errors, and an understated covariance
caught."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import stats

from gtrig.evaluate.within import P_3SIGMA, binomial_interval, correlated_rates, expected_rate, mahalanobis2, within


def _covs(n: int, rng: np.random.Generator) -> np.ndarray:
    A = rng.normal(size=(n, 3, 3)) * [0.01, 0.02, 0.03]
    return A @ np.swapaxes(A, 1, 2) + 1e-6 * np.eye(3)


@pytest.mark.parametrize("test", ["region", "axes", "d3"])
def test_a_correct_covariance_gives_the_expected_rate(test: str) -> None:
    rng = np.random.default_rng(1)
    C = _covs(40_000, rng)
    e = np.einsum("nij,nj->ni", np.linalg.cholesky(C), rng.standard_normal((40_000, 3)))
    p = expected_rate(C, test)  # type: ignore[arg-type]
    lo, hi = binomial_interval(40_000, p, 0.999)
    assert lo <= within(e, C, test).mean() <= hi  # type: ignore[arg-type]
    assert {"region": P_3SIGMA, "d3": stats.chi2.cdf(9, 3)}.get(test, p) == p
    if test == "axes":  # correlated axes pass more often than 0.9973^3
        assert 0.9973**3 - 1e-3 < p < 0.9973


def test_mahalanobis_of_whitened_errors() -> None:
    rng = np.random.default_rng(2)
    C = _covs(5, rng)
    z = rng.standard_normal((5, 3))
    e = np.einsum("nij,nj->ni", np.linalg.cholesky(C), z)
    assert np.allclose(mahalanobis2(e, C), np.sum(z**2, axis=1))


def test_correlated_errors_spread_the_rate_and_an_understated_covariance_is_caught() -> None:
    rng = np.random.default_rng(3)
    t = np.arange(0, 200, 0.2)  # 1000 fixes at 5 Hz
    C = np.tile(np.diag([1e-4, 2e-4, 4e-4]), (t.size, 1, 1))
    white = correlated_rates(t, C, 1e-3, "region", n_draws=400, rng=rng)  # independent errors
    wander = correlated_rates(t, C, 8.0, "region", n_draws=400, rng=rng)
    assert abs(white.mean() - P_3SIGMA) < 1e-3 and abs(wander.mean() - P_3SIGMA) < 2e-3
    lo, hi = binomial_interval(t.size, P_3SIGMA)
    assert lo - 1e-9 <= np.quantile(white, 0.05) and np.quantile(white, 0.95) <= hi + 1e-9
    assert np.std(wander) > 3 * np.std(white)  # fewer independent samples, clustered exceedances
    # errors 1.5 times larger than the stated covariance: below what even wandering errors give
    z = np.random.default_rng(4).standard_normal((t.size, 3))
    e = 1.5 * np.einsum("nij,nj->ni", np.linalg.cholesky(C), z)
    assert np.mean(wander <= within(e, C).mean()) < 0.01
