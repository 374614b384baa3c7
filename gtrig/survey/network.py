"""Network adjustment of the world points: readings between world points as well as to reference points.

The seeds measured every world point from the four Vframe points only (AD2.3, "Determination of the
coordinates of the world-points"). A point far from the 2.5 m Vframe square is then seen along nearly
parallel lines of sight, and its error across them is the reading error magnified by about distance over
baseline (2.5x at 6 m: 1.6 mm per coordinate with a 0.75 mm hand laser). Readings between the world
points themselves, as a surveyor closes a network, tie the far points to each other around the room and
bring that error down to about the reading error (``docs/simulator.md`` measures it).

Model: the unknowns are the world points ``P`` (N, 2) and the reference points ``R`` (M, 2), world frame,
metres. Every reading is ``d = |a - b| + e``, ``e ~ N(0, sigma^2)``, with ``a`` a world point and ``b`` a
reference or another world point. The reference points enter with their nominal coordinates as prior
pseudo-readings of standard deviation ``sigma_r`` per coordinate (a reference point with ``sigma_r = 0``
is held fixed). Weighted least squares; the covariance ``(J^T W J)^-1`` of the world points then includes
the reference points' uncertainty and the correlations between points. Bad readings are found by Baarda's
w-test over the whole network (:mod:`gtrig.survey.robust`).
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares

from gtrig.errors import ConvergenceError, InputError
from gtrig.io.survey_csv import Distances, NamedPoints
from gtrig.survey.robust import BadReading, ResidualTest, record_exclusion, residual_test, triage


@dataclass(frozen=True)
class NetworkResult:
    """Outcome of :func:`adjust_network`.

    Attributes
    ----------
    xy : (N, 2) world points, world frame, metres.
    cov_joint : (2N, 2N) covariance of (x1, y1, x2, y2, ...), m^2, reference-point errors included.
    reference_xy : (M, 2) adjusted reference points, metres.
    test : global chi-square and w-test over all readings and the reference-point priors.
    active : (K,) readings used, in the order given.
    excluded : readings excluded by the residual test.
    """

    xy: np.ndarray
    cov_joint: np.ndarray
    reference_xy: np.ndarray
    test: ResidualTest
    active: np.ndarray
    excluded: tuple[BadReading, ...]

    @property
    def cov_xy(self) -> np.ndarray:
        """(N, 2, 2) marginal covariance of every world point, m^2."""
        return point_blocks(self.cov_joint)


def point_blocks(cov_joint: np.ndarray) -> np.ndarray:
    """The (N, 2, 2) diagonal blocks of a (2N, 2N) covariance over (x1, y1, x2, y2, ...)."""
    n = cov_joint.shape[0] // 2
    i = np.arange(n)
    return cov_joint.reshape(n, 2, n, 2)[i, :, i]


@dataclass(frozen=True)
class _Problem:
    ia: np.ndarray  # (K,) world point index of a
    ib: np.ndarray  # (K,) index of b: world point (>= 0) or reference point (-1 - j)
    d: np.ndarray
    s: np.ndarray
    free: np.ndarray  # (F,) indices of the reference points being estimated
    R0: np.ndarray  # (M, 2) nominal reference points
    sig_r: np.ndarray  # (M, 2) per coordinate
    n: int  # world points

    def unpack(self, z: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        P = z[: 2 * self.n].reshape(-1, 2)
        R = self.R0.copy()
        R[self.free] = z[2 * self.n :].reshape(-1, 2)
        return P, R

    def ends(self, P: np.ndarray, R: np.ndarray) -> np.ndarray:
        return np.where((self.ib >= 0)[:, None], P[np.maximum(self.ib, 0)], R[np.maximum(-1 - self.ib, 0)])

    def resid(self, z: np.ndarray) -> np.ndarray:
        """Whitened residuals: readings, then the priors of the free reference points."""
        P, R = self.unpack(z)
        rng = np.linalg.norm(P[self.ia] - self.ends(P, R), axis=1)
        prior = (R[self.free] - self.R0[self.free]) / self.sig_r[self.free]
        return np.concatenate([(rng - self.d) / self.s, prior.ravel()])

    def jac(self, z: np.ndarray) -> np.ndarray:
        P, R = self.unpack(z)
        K, F = self.d.size, self.free.size
        diff = P[self.ia] - self.ends(P, R)
        u = diff / np.maximum(np.linalg.norm(diff, axis=1, keepdims=True), 1e-12) / self.s[:, None]
        col_of_ref = np.full(self.R0.shape[0], -1)
        col_of_ref[self.free] = self.n + np.arange(F)
        col_b = np.where(self.ib >= 0, self.ib, col_of_ref[np.maximum(-1 - self.ib, 0)])
        J = np.zeros((K + 2 * F, 2 * (self.n + F)))
        rows = np.arange(K)
        for c in range(2):
            J[rows, 2 * self.ia + c] += u[:, c]
            has_b = col_b >= 0
            J[rows[has_b], 2 * col_b[has_b] + c] -= u[has_b, c]
        J[K:, 2 * self.n :] = np.diag(1.0 / self.sig_r[self.free].ravel())
        return J


def _problem(
    names: list[str], references: NamedPoints, readings: Distances, active: np.ndarray
) -> _Problem:
    p_index = {n: i for i, n in enumerate(names)}
    r_index = references.index()
    idx = np.flatnonzero(active)
    ia = np.array([p_index[readings.a[k]] for k in idx], dtype=int)
    ib = np.array(
        [p_index[readings.b[k]] if readings.b[k] in p_index else -1 - r_index[readings.b[k]] for k in idx],
        dtype=int,
    )
    free = np.flatnonzero(references.sigma_m > 0)
    sig_r = np.repeat(references.sigma_m[:, None], 2, axis=1)
    return _Problem(ia, ib, readings.distance_m[idx], readings.sigma_m[idx], free, references.xy, sig_r, len(names))


def adjust_network(
    names: list[str],
    xy0: np.ndarray,
    references: NamedPoints,
    readings: Distances,
    *,
    alpha: float = 0.001,
    on_outlier: str = "exclude",
    max_exclusions: int = 1,
    warnings: list[str] | None = None,
    log: logging.Logger | None = None,
) -> NetworkResult:
    """Adjust all world points together from readings to reference points and between world points.

    Parameters
    ----------
    names : N world point names (the order of ``xy0`` and of the result).
    xy0 : (N, 2) starting points, world frame, metres (the per-point trilateration).
    references : reference points with their sigma per coordinate.
    readings : ``a`` a world point, ``b`` a reference point or another world point; ``sigma_m`` of the
        hand laser.
    alpha, on_outlier, max_exclusions : as in :func:`gtrig.survey.points.estimate_world_points`;
        ``max_exclusions`` counts per world point.
    warnings : list the messages are appended to.

    Returns
    -------
    NetworkResult
    """
    log = log or logging.getLogger(__name__)
    warnings = warnings if warnings is not None else []
    active = np.ones(readings.distance_m.size, dtype=bool)
    excluded: list[BadReading] = []
    per_point = {n: 0 for n in names}
    while True:
        prob = _problem(names, references, readings, active)
        x, J, C, r = _solve(prob, xy0)
        test = residual_test(r, None, J, C)
        if test.dof <= 0 or test.p_value >= alpha or test.worst < 0:
            break
        K = prob.d.size
        if test.worst >= K:
            _reference_disagrees(references.names[prob.free[(test.worst - K) // 2]], test, on_outlier, warnings, log)
            break
        k = int(np.flatnonzero(active)[test.worst])
        bad = _bad_reading(readings, k, references, float(r[test.worst]), test)
        unidentifiable = (
            f"world point network: readings disagree (chi2 {test.chi2:.1f}, {test.dof} dof) but the bad one "
            f"cannot be told apart; remeasure near {bad.describe()}"
        )
        # a reading to another world point spends that point's allowance too
        n_excl = max(per_point[readings.a[k]], per_point.get(readings.b[k], 0))
        if not triage(bad, test, on_outlier, n_excl, max_exclusions, unidentifiable, warnings, log):
            break
        active[k] = False
        per_point[readings.a[k]] += 1
        if readings.b[k] in per_point:
            per_point[readings.b[k]] += 1
        record_exclusion(bad, excluded, warnings, log)
    P, R = prob.unpack(x)
    n2 = 2 * len(names)
    return NetworkResult(P, C[:n2, :n2], R, test, active, tuple(excluded))


def _solve(prob: _Problem, xy0: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """:func:`solve_whitened` of ``prob`` from the world points ``xy0`` (N, 2) and the nominal reference
    points (the solution holds the world points, then the free reference points, metres)."""
    z0 = np.concatenate([np.asarray(xy0, float).ravel(), prob.R0[prob.free].ravel()])
    return solve_whitened(prob.resid, prob.jac, z0, "world point network: least squares")


def solve_whitened(resid: Callable[[np.ndarray], np.ndarray], jac: Callable[[np.ndarray], np.ndarray],
                   z0: np.ndarray, what: str) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Least squares (Levenberg-Marquardt) of the whitened residuals ``resid`` (K,) with Jacobian ``jac``
    (K, U) from ``z0`` (U,): the solution, the Jacobian there, the covariance ``(J^T J)^-1``
    (symmetrised) and the negated residuals. ``what`` names the problem when it does not converge."""
    res = least_squares(resid, z0, jac=jac, method="lm", xtol=1e-12, ftol=1e-12, gtol=1e-12)
    if res.status <= 0 or not np.all(np.isfinite(res.x)):
        raise ConvergenceError(f"{what} did not converge ({res.message})")
    J = jac(res.x)
    C = np.linalg.inv(J.T @ J)
    C = 0.5 * (C + C.T)
    return res.x, J, C, -resid(res.x)


def _reference_disagrees(name: str, test: ResidualTest, on_outlier: str, warnings: list[str],
                         log: logging.Logger) -> None:
    """A reference point's prior is the worst residual: an error, or with ``on_outlier="keep"`` a warning."""
    msg = (
        f"reference point {name}: its coordinates disagree with the readings "
        f"(w = {test.w[test.worst]:.1f}); check the reference file"
    )
    if on_outlier != "keep":
        raise InputError(msg)
    log.warning(msg)
    warnings.append(msg)


def _bad_reading(readings: Distances, k: int, references: NamedPoints, r_whitened: float,
                 test: ResidualTest) -> BadReading:
    """Reading ``k``, the worst of the w-test, as a :class:`BadReading` (residual and estimated error in
    metres)."""
    s = readings.sigma_m[k]
    return BadReading(
        "point" if readings.b[k] in references.index() else "network",
        readings.a[k],
        readings.b[k],
        "",
        float(readings.distance_m[k]),
        float(r_whitened * s),
        float(test.error_m[test.worst] * s),
        float(test.w[test.worst]),
        readings.source[k],
    )
