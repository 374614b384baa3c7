"""The mean NEES / dof interval covers honest covariances at its level and flags a covariance four times too small."""

import numpy as np

from gtrig.evaluate.compare import mean_nees_interval


def test_interval_covers_honest_and_flags_quarter_covariance() -> None:
    rng = np.random.default_rng(3)
    n, dof, trials = 12, 3, 4000
    lo, hi = mean_nees_interval(n, dof)
    C = np.diag([4e-6, 9e-6, 1e-4])
    e = rng.multivariate_normal(np.zeros(dof), C, size=(trials, n))
    honest = np.einsum("tni,ij,tnj->tn", e, np.linalg.inv(C), e).mean(axis=1) / dof
    inside = np.mean((honest >= lo) & (honest <= hi))
    assert abs(inside - 0.95) < 0.015
    quarter = honest * 4  # the same errors judged with C / 4
    assert np.mean((quarter >= lo) & (quarter <= hi)) < 0.01
