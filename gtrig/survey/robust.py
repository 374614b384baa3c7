"""Bad-reading test: global chi-square test and Baarda's w-test (data snooping).

After a weighted least-squares fit with measurement covariance ``Sigma`` (m, m), Jacobian ``J`` (m, n)
and state covariance ``C = (J^T Sigma^-1 J)^-1``, the residuals ``r = d - f(x)`` have covariance
``Q_r = Sigma - J C J^T``. The w-statistic of reading ``k``,

    w_k = (Sigma^-1 r)_k / sqrt((Sigma^-1 Q_r Sigma^-1)_kk),

is standard normal when reading ``k`` is good, and is the most powerful test of a single gross error in
that reading; it equals the leave-one-out (deleted) standardized residual of a linear model
(W. Baarda, "A testing procedure for use in geodetic networks", 1968). It handles correlated readings,
which arise here because the readings of one point share the reference points' errors.

A typed 3.57 for 3.75, or a reading taken to the wrong point, shows as the largest ``|w|`` once the
global test ``chi2 = r^T Sigma^-1 r`` exceeds its ``1 - alpha`` quantile with ``m - n`` degrees of freedom.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np
from scipy import stats

from gtrig.errors import InputError


@dataclass(frozen=True)
class BadReading:
    """A reading that failed the residual test.

    Attributes
    ----------
    kind : "point" (world point to reference), "network" (world point to world point) or "pose" (robot
        point to world point).
    item : the world point or the pose.
    a, b : reference or other world point (for a point), or robot point and world point (for a pose).
    distance_m : the reading, metres.
    residual_m : reading minus the distance predicted by the fit that includes it, metres.
    error_m : estimated gross error of the reading (its residual against a fit without it), metres.
    w : Baarda's w-statistic.
    source : file and line of the reading.
    """

    kind: str
    item: str
    a: str
    b: str
    distance_m: float
    residual_m: float
    error_m: float
    w: float
    source: str

    def describe(self) -> str:
        if self.kind == "point":
            what = f"point {self.item}, reference {self.a}"
        elif self.kind == "network":
            what = f"point {self.item} to world point {self.a}"
        else:
            what = f"pose {self.item}, robot point {self.a} to world point {self.b}"
        return (
            f"{what}: reading {self.distance_m:.4f} m ({self.source}) fails the residual test "
            f"(w = {self.w:.1f}; it is off by about {self.error_m * 1000:+.0f} mm)"
        )


@dataclass(frozen=True)
class ResidualTest:
    """Global test and w-statistics of one item (a point or a pose).

    Attributes
    ----------
    chi2 : r^T Sigma^-1 r.
    dof : readings minus unknowns.
    p_value : probability of a chi-square at least this large when every reading is good (1 when dof = 0).
    w : (m,) w-statistics (nan where a reading is not checked by the others, e.g. dof = 0).
    error_m : (m,) estimated gross error of every reading, ``(Sigma^-1 r)_k / (Sigma^-1 Q_r Sigma^-1)_kk``
        (Baarda), i.e. its residual against the fit without it (linearised).
    worst : index of the largest |w|, or -1.
    identifiable : the worst reading can be told apart from the others (its w is not perfectly
        correlated with another one's, as it is for every pair when dof = 1).
    """

    chi2: float
    dof: int
    p_value: float
    w: np.ndarray
    error_m: np.ndarray
    worst: int
    identifiable: bool


def residual_test(
    residual: np.ndarray, cov_meas: np.ndarray | None, J: np.ndarray, cov_x: np.ndarray
) -> ResidualTest:
    """Chi-square and w-test of one fit (shapes: residual (m,), cov_meas (m, m), J (m, n), cov_x (n, n)).

    ``cov_meas`` None: the residuals and ``J`` are already whitened (identity covariance); then only the
    diagonal of the residuals' cofactor and one row of it are formed, O(m n^2) instead of O(m^3), which
    is what keeps a network of a thousand readings fast.
    """
    m, n = J.shape
    if m - n <= 0:
        chi2 = float(residual @ (residual if cov_meas is None else np.linalg.solve(cov_meas, residual)))
        return ResidualTest(chi2, m - n, 1.0, np.full(m, np.nan), np.full(m, np.nan), -1, False)
    if cov_meas is None:
        chi2 = float(residual @ residual)
        JC = J @ cov_x
        dM = 1.0 - np.einsum("ij,ij->i", JC, J)
        Sr = residual
        ok = dM > 1e-12

        def m_row(i: int) -> np.ndarray:
            row = -(J @ JC[i])
            row[i] += 1.0
            return row
    else:
        Sinv = np.linalg.inv(cov_meas)
        chi2 = float(residual @ Sinv @ residual)
        M = Sinv @ (cov_meas - J @ cov_x @ J.T) @ Sinv
        dM = np.diag(M).copy()
        Sr = Sinv @ residual
        ok = dM > 1e-12 * np.max(np.abs(np.diag(Sinv))) ** 2

        def m_row(i: int) -> np.ndarray:
            return M[i]
    dof = m - n
    w = np.full(m, np.nan)
    w[ok] = Sr[ok] / np.sqrt(dM[ok])
    err = np.full(m, np.nan)
    err[ok] = Sr[ok] / dM[ok]
    p = float(stats.chi2.sf(chi2, dof))
    if not np.any(ok):
        return ResidualTest(chi2, dof, p, w, err, -1, False)
    worst = int(np.nanargmax(np.abs(w)))
    corr = m_row(worst) / np.sqrt(np.where(ok, dM, np.inf) * dM[worst])
    corr[worst] = 0.0
    identifiable = bool(np.all(np.abs(corr[ok]) < 0.999))
    return ResidualTest(chi2, dof, p, w, err, worst, identifiable)


def triage(
    bad: BadReading,
    test: ResidualTest,
    on_outlier: str,
    n_excluded: int,
    max_exclusions: int,
    unidentifiable_msg: str,
    warnings: list[str],
    log: logging.Logger,
    room_to_exclude: bool = True,
) -> bool:
    """What to do with the worst reading of a failed residual test, by ``on_outlier``.

    Returns True when the reading is to be excluded, False when it is kept (with a warning); raises
    :class:`InputError` when refused, when the bad reading cannot be told apart (``unidentifiable_msg``)
    or when ``max_exclusions`` are spent (or there is no ``room_to_exclude``).
    """
    if on_outlier == "keep":
        msg = f"kept: {bad.describe()}"
        log.warning(msg)
        warnings.append(msg)
        return False
    if on_outlier == "refuse":
        raise InputError(f"{bad.describe()}; check it, or rerun with --on-outlier exclude")
    if not test.identifiable:
        raise InputError(unidentifiable_msg)
    if n_excluded >= max_exclusions or not room_to_exclude:
        raise InputError(
            f"{bad.kind} {bad.item}: still failing the residual test after excluding "
            f"{n_excluded} reading(s): {bad.describe()}"
        )
    return True


def record_exclusion(bad: BadReading, excluded: list[BadReading], warnings: list[str], log: logging.Logger) -> None:
    """Add ``bad`` to ``excluded`` and say so in ``warnings`` and the log (after :func:`triage` said yes)."""
    excluded.append(bad)
    msg = f"excluded: {bad.describe()}"
    log.warning(msg)
    warnings.append(msg)
