"""World points by trilateration from hand-laser distances to uncertain reference points.

Method (AD2.3, "Determination of the coordinates of the world-points"): each world point ``p`` (2,) is
at distance ``d_k = |p - r_k| + e_k`` from reference point ``r_k``, with hand-laser noise
``e_k ~ N(0, sigma_k^2)``. The seeds solved this with an EKF iterated 20 times, which is Gauss-Newton on
the same model; here it is weighted nonlinear least squares (:func:`scipy.optimize.least_squares`).

The reference points are uncertain (isotropic ``sigma_r`` per coordinate, from the reference file). Their
error is propagated by the Jacobian: the readings of one point have covariance
``Sigma = diag(sigma_k^2) + U Sigma_r U^T`` with ``U`` the unit lines of sight, which is equivalent to
augmenting the state with the reference points for the marginal of one point. Across points the shared
reference errors correlate the estimates; :attr:`WorldPointsResult.cov_joint` carries that correlation
(first-order propagation ``d p_i / d r``), and the pose survey uses it.

Every point is solved from every pairwise intersection of its circles (and, with ``multistart``, from
rings of starts up to 2 m away); distinct minima are reported and a second minimum that fits nearly as
well (mirror solution about collinear references) is refused or flagged, never silently dropped.

Readings between two world points (the ``reference`` column naming a world point) make the survey a
network: the trilateration above gives the starts, the ambiguity check and the per-point triage, then
:func:`gtrig.survey.network.adjust_network` adjusts all points and reference points together.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, replace
from itertools import combinations

import numpy as np

from gtrig.errors import ConvergenceError, InputError
from gtrig.io.survey_csv import Distances, NamedPoints, PointsTable
from gtrig.survey import multistart as ms
from gtrig.survey.network import NetworkResult, adjust_network
from gtrig.survey.nls import solve_blocks
from gtrig.survey.robust import BadReading, record_exclusion, residual_test, triage

log = logging.getLogger(__name__)

ON_AMBIGUITY = ("refuse", "warn")
ON_OUTLIER = ("exclude", "refuse", "keep")


@dataclass(frozen=True)
class PointEstimate:
    """One world point.

    Attributes
    ----------
    name : world point name.
    xy : (2,) world frame (the frame of the reference points), metres.
    cov_xy : (2, 2) covariance, m^2 (hand-laser and reference-point errors).
    n_readings : readings used.
    chi2, dof, p_value : global residual test.
    rms_residual_m, max_abs_residual_m : of the readings used.
    basin : multi-start outcome (None without multi-start).
    alternatives : other minima found, as (x, y, chi2).
    excluded : readings excluded by the residual test.
    """

    name: str
    xy: np.ndarray
    cov_xy: np.ndarray
    n_readings: int
    chi2: float
    dof: int
    p_value: float
    rms_residual_m: float
    max_abs_residual_m: float
    basin: ms.Basin | None
    alternatives: tuple[tuple[float, float, float], ...]
    excluded: tuple[BadReading, ...]


@dataclass(frozen=True)
class WorldPointsResult:
    """All world points.

    Attributes
    ----------
    names : N names, in order of first appearance in the distances.
    xy : (N, 2) world frame, metres.
    cov_xy : (N, 2, 2) marginal covariances, m^2.
    cov_joint : (2N, 2N) joint covariance (x1, y1, x2, y2, ...), including the correlation through the
        shared reference points.
    points : per-point details.
    excluded : all excluded readings.
    warnings : messages also sent to the log.
    network : the network adjustment, when the readings include some between world points (then
        ``xy`` and the covariances are its result, and each point's chi2 is that of its trilateration).
    """

    names: tuple[str, ...]
    xy: np.ndarray
    cov_xy: np.ndarray
    cov_joint: np.ndarray
    points: tuple[PointEstimate, ...]
    excluded: tuple[BadReading, ...]
    warnings: tuple[str, ...]
    network: NetworkResult | None = None

    def as_table(self) -> PointsTable:
        return PointsTable(self.names, self.xy, self.cov_xy)


def circle_intersections(c1: np.ndarray, r1: float, c2: np.ndarray, r2: float) -> np.ndarray:
    """The two intersections (2, 2) of two circles; the two nearest points when they do not meet."""
    v = c2 - c1
    D = float(np.linalg.norm(v))
    if D < 1e-9:
        return np.empty((0, 2))
    a = (r1 * r1 - r2 * r2 + D * D) / (2 * D)
    h = np.sqrt(max(r1 * r1 - a * a, 0.0))
    e = v / D
    n = np.array([-e[1], e[0]])
    m = c1 + a * e
    return np.array([m + h * n, m - h * n])


def _reading_cov(
    xy: np.ndarray, R: np.ndarray, ref_idx: np.ndarray, sigma_d: np.ndarray, sigma_r: np.ndarray
) -> np.ndarray:
    """Covariance (m, m) of the readings of one point at ``xy``: hand laser plus reference points."""
    diff = xy - R
    u = diff / np.linalg.norm(diff, axis=1, keepdims=True)
    same = ref_idx[:, None] == ref_idx[None, :]
    return np.diag(sigma_d**2) + same * (u @ u.T) * (sigma_r[ref_idx] ** 2)[:, None]


def _batched_model(d: np.ndarray, R: np.ndarray, w_inv_sigma: np.ndarray) -> ms.BatchedModel:
    def model(X: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        diff = X[:, None, :] - R[None]
        rng = np.maximum(np.linalg.norm(diff, axis=2), 1e-9)
        r = (rng - d) * w_inv_sigma
        J = diff / rng[..., None] * w_inv_sigma[:, None]
        return r, J

    return model


def _group(
    references: NamedPoints, distances: Distances
) -> tuple[list[str], list[np.ndarray], np.ndarray, np.ndarray]:
    """World point names, rows per point, reference index per row (-1 for a reading to a world point)
    and the mask of the readings between world points."""
    ref_index = references.index()
    names: list[str] = []
    for p in distances.a:
        if p not in names:
            names.append(p)
    ref_idx = np.full(len(distances.a), -1, dtype=int)
    for k, (p, b) in enumerate(zip(distances.a, distances.b, strict=True)):
        if p in ref_index:
            raise InputError(
                f"{distances.source[k]}: {p!r} is a reference point, not a world point to survey"
            )
        if b in ref_index:
            ref_idx[k] = ref_index[b]
        elif b == p:
            raise InputError(f"{distances.source[k]}: a reading from point {p!r} to itself")
        elif b not in names:
            raise InputError(
                f"{distances.source[k]}: unknown reference point {b!r} for point {p!r} "
                f"(reference points: {', '.join(references.names)}; a reading to another world point "
                "needs that point's own readings too)"
            )
    network = ref_idx < 0
    rows = [np.flatnonzero((np.array(distances.a) == n) & ~network) for n in names]
    return names, rows, ref_idx, network


def _check_counts(name: str, rows: np.ndarray, ref_idx: np.ndarray, distances: Distances) -> None:
    n_ref = len(set(ref_idx[rows].tolist()))
    if rows.size < 2 or n_ref < 2:
        where = distances.source[rows[0]] if rows.size else distances.source[distances.a.index(name)]
        raise InputError(
            f"point {name}: {rows.size} distance(s) to {n_ref} reference point(s), at least 2 "
            f"reference points needed for its 2 unknowns ({where})"
        )


def estimate_world_points(
    references: NamedPoints,
    distances: Distances,
    *,
    multistart: bool = True,
    on_ambiguity: str = "refuse",
    on_outlier: str = "exclude",
    alpha: float = 0.001,
    ambiguity_chi2: float = 16.0,
    max_exclusions: int = 1,
) -> WorldPointsResult:
    """Trilaterate every world point from its distances to the reference points.

    Parameters
    ----------
    references : reference points, world frame, with their sigma per coordinate (metres).
    distances : world distances (``a`` = world point, ``b`` = reference point or another world point,
        ``sigma_m`` = hand laser).
    multistart : also start from rings 0.1 to 2 m around the solution and report the basin.
    on_ambiguity : "refuse" (raise :class:`ConvergenceError`) or "warn" when a second minimum fits
        within ``ambiguity_chi2`` of the best.
    on_outlier : what to do with a reading failing the residual test at level ``alpha``: "exclude" it
        with a warning, "refuse" (raise :class:`InputError` naming it), or "keep" it with a warning.
    max_exclusions : readings that may be excluded per point.

    Returns
    -------
    WorldPointsResult
    """
    if on_ambiguity not in ON_AMBIGUITY:
        raise InputError(f"on_ambiguity must be one of {', '.join(ON_AMBIGUITY)}, got {on_ambiguity!r}")
    if on_outlier not in ON_OUTLIER:
        raise InputError(f"on_outlier must be one of {', '.join(ON_OUTLIER)}, got {on_outlier!r}")
    names, rows_all, ref_idx_all, network = _group(references, distances)
    for n, rows in zip(names, rows_all, strict=True):
        _check_counts(n, rows, ref_idx_all, distances)
    active = ~network
    excluded: dict[str, list[BadReading]] = {n: [] for n in names}
    warnings: list[str] = []
    fit = _fit_excluding_outliers(
        references, distances, names, active, ref_idx_all, excluded, warnings,
        alpha=alpha, on_outlier=on_outlier, max_exclusions=max_exclusions,
    )
    points = [
        _point_estimate(
            fit, i, n, tuple(excluded[n]), warnings, multistart=multistart, on_ambiguity=on_ambiguity,
            ambiguity_chi2=ambiguity_chi2,
        )
        for i, n in enumerate(names)
    ]
    all_excl = tuple(b for n in names for b in excluded[n])
    xy, cov, cov_joint = np.array(fit["xy"]), np.array(fit["cov"]), fit["cov_joint"]
    net = None
    if network.any():
        # the trilateration above gave the starts, the ambiguity check and the per-point triage;
        # the network adjusts all points together with every reading left
        net = adjust_network(
            names, xy, references, distances.subset(active | network), alpha=alpha, on_outlier=on_outlier,
            max_exclusions=max_exclusions, warnings=warnings, log=log,
        )
        xy, cov, cov_joint = net.xy, net.cov_xy, net.cov_joint
        points = [replace(p, xy=xy[i], cov_xy=cov[i]) for i, p in enumerate(points)]
        all_excl = all_excl + net.excluded
    return WorldPointsResult(
        tuple(names), xy, cov, cov_joint, tuple(points), all_excl, tuple(warnings), net
    )


def _fit_excluding_outliers(
    references: NamedPoints,
    distances: Distances,
    names: list[str],
    active: np.ndarray,
    ref_idx_all: np.ndarray,
    excluded: dict[str, list[BadReading]],
    warnings: list[str],
    *,
    alpha: float,
    on_outlier: str,
    max_exclusions: int,
) -> dict:
    """Fit every point, drop the worst reading of each point failing the residual test, refit until none does.

    ``active`` (readings used) is cleared in place for each excluded reading, which is appended to
    ``excluded[name]``; warnings are appended to ``warnings``. Returns the last fit (see :func:`_fit`).
    """
    while True:
        fit = _fit(references, distances, names, active, ref_idx_all)
        changed = False
        for i, n in enumerate(names):
            t, rows = fit["tests"][i], fit["rows"][i]
            if t.dof <= 0 or t.p_value >= alpha:
                continue
            k = rows[t.worst] if t.worst >= 0 else rows[0]
            bad = BadReading(
                "point",
                n,
                distances.b[k],
                "",
                float(distances.distance_m[k]),
                float(fit["residuals"][i][t.worst]),
                float(t.error_m[t.worst]),
                float(t.w[t.worst]),
                distances.source[k],
            )
            unidentifiable = (
                f"point {n}: readings disagree (chi2 {t.chi2:.1f}, {t.dof} dof, p {t.p_value:.1e}) "
                f"but with {rows.size} readings the bad one cannot be told apart; remeasure "
                f"({distances.source[rows[0]]})"
            )
            if not triage(bad, t, on_outlier, len(excluded[n]), max_exclusions, unidentifiable, warnings, log):
                continue
            rest = np.setdiff1d(rows, [k])
            if len(set(ref_idx_all[rest].tolist())) < 2:
                raise InputError(f"{bad.describe()}; excluding it would leave too few readings")
            active[k] = False
            record_exclusion(bad, excluded[n], warnings, log)
            changed = True
        if not changed:
            return fit


def _point_estimate(
    fit: dict,
    i: int,
    name: str,
    excluded: tuple[BadReading, ...],
    warnings: list[str],
    *,
    multistart: bool,
    on_ambiguity: str,
    ambiguity_chi2: float,
) -> PointEstimate:
    """Point ``i`` of ``fit`` as a record, after checking that no other minimum fits nearly as well.

    A second minimum within ``ambiguity_chi2`` of the best raises :class:`ConvergenceError` with
    ``on_ambiguity="refuse"``, or is logged and appended to ``warnings`` with ``"warn"``.
    """
    rows, t, res = fit["rows"][i], fit["tests"][i], fit["residuals"][i]
    x = fit["xy"][i]
    alts = [m for m in fit["minima"][i] if np.max(np.abs(m.x - x)) > 1e-2]
    basin = None
    if multistart:
        basin = ms.analyse(fit["models"][i], x, np.empty((0, 2)), ambiguity_chi2=ambiguity_chi2)
        for m in basin.alternatives:
            if all(np.max(np.abs(m.x - a.x)) > 1e-3 for a in alts):
                alts.append(m)
    alts.sort(key=lambda m: m.chi2)
    xd, cd = ms.batched_lm(fit["models"][i], x[None])
    chi2_diag = float(cd[0])  # the alternatives' chi2 leave out the readings' correlations too
    close = [m for m in alts if m.chi2 - chi2_diag < ambiguity_chi2]
    if close:
        m = close[0]
        msg = (
            f"point {name}: two solutions fit the distances: ({x[0]:.4f}, {x[1]:.4f}) chi2 {chi2_diag:.2f} "
            f"and ({m.x[0]:.4f}, {m.x[1]:.4f}) chi2 {m.chi2:.2f} (mirror about the reference points?)"
        )
        if on_ambiguity == "refuse":
            raise ConvergenceError(
                f"{msg}; add a distance to a reference point off their line, or rerun "
                "with --on-ambiguity warn"
            )
        log.warning(msg + "; kept the better one")
        warnings.append(msg)
    return PointEstimate(
        name=name,
        xy=x,
        cov_xy=fit["cov"][i],
        n_readings=int(rows.size),
        chi2=t.chi2,
        dof=t.dof,
        p_value=t.p_value,
        rms_residual_m=float(np.sqrt(np.mean(res**2))),
        max_abs_residual_m=float(np.max(np.abs(res))),
        basin=basin,
        alternatives=tuple((float(m.x[0]), float(m.x[1]), float(m.chi2)) for m in alts),
        excluded=excluded,
    )


def _fit(
    references: NamedPoints,
    distances: Distances,
    names: list[str],
    active: np.ndarray,
    ref_idx_all: np.ndarray,
) -> dict:
    """One joint fit of all points with the ``active`` readings."""
    R_all = references.xy
    sig_r = references.sigma_m
    rows = [np.flatnonzero((np.array(distances.a) == n) & active) for n in names]
    d_all, sd_all = distances.distance_m, distances.sigma_m
    # starts: all pairwise circle intersections, solved at once with the readings' diagonal weights
    x0, minima, models = [], [], []
    for r in rows:
        R, d, ri = R_all[ref_idx_all[r]], d_all[r], ref_idx_all[r]
        w_inv_sigma0 = 1.0 / np.sqrt(sd_all[r] ** 2 + sig_r[ri] ** 2)
        starts = [
            circle_intersections(R[a], d[a], R[b], d[b])
            for a, b in combinations(range(r.size), 2)
            if ri[a] != ri[b]
        ]
        S = np.vstack(starts)
        X, cost = ms.batched_lm(_batched_model(d, R, w_inv_sigma0), S)
        mins = ms.cluster(X, cost, 1e-3)
        x0.append(mins[0].x)
    order = np.concatenate(rows)
    offsets = np.cumsum([0] + [r.size for r in rows])
    Rk, dk, sdk, rik = R_all[ref_idx_all[order]], d_all[order], sd_all[order], ref_idx_all[order]
    pidx = np.repeat(np.arange(len(rows)), [r.size for r in rows])

    def resid(z: np.ndarray) -> np.ndarray:
        P = z.reshape(-1, 2)[pidx]
        return np.linalg.norm(P - Rk, axis=1) - dk

    def jac(z: np.ndarray) -> np.ndarray:
        P = z.reshape(-1, 2)[pidx]
        diff = P - Rk
        u = diff / np.linalg.norm(diff, axis=1, keepdims=True)
        J = np.zeros((order.size, z.size))
        J[np.arange(order.size), 2 * pidx] = u[:, 0]
        J[np.arange(order.size), 2 * pidx + 1] = u[:, 1]
        return J

    def covs(z: np.ndarray) -> list[np.ndarray]:
        P = z.reshape(-1, 2)
        return [
            _reading_cov(
                P[i],
                Rk[offsets[i] : offsets[i + 1]],
                rik[offsets[i] : offsets[i + 1]],
                sdk[offsets[i] : offsets[i + 1]],
                sig_r,
            )
            for i in range(len(rows))
        ]

    z = solve_blocks(resid, jac, np.concatenate(x0), covs, what="world points")
    P = z.reshape(-1, 2)
    Sig = covs(z)
    r_all = -resid(z)
    J_all = jac(z)
    n = len(rows)
    nref = R_all.shape[0]
    A_blocks, B = [], np.zeros((2 * n, 2 * nref))
    cov, tests, residuals = [], [], []
    for i in range(n):
        sl = slice(offsets[i], offsets[i + 1])
        J = J_all[sl, 2 * i : 2 * i + 2]
        Si = np.linalg.inv(Sig[i])
        C = np.linalg.inv(J.T @ Si @ J)
        C = 0.5 * (C + C.T)
        cov.append(C)
        tests.append(residual_test(r_all[sl], Sig[i], J, C))
        residuals.append(r_all[sl])
        A = C @ J.T @ Si
        A_blocks.append(A @ np.diag(sdk[sl] ** 2) @ A.T)
        # d p_i / d r_j = A (-d f / d r_j) = A u  (f = |p - r|, d f / d r = -u)
        for k_local, k in enumerate(range(offsets[i], offsets[i + 1])):
            j = rik[k]
            B[2 * i : 2 * i + 2, 2 * j : 2 * j + 2] += np.outer(A[:, k_local], J[k_local])
        models.append(_batched_model(dk[sl], Rk[sl], 1.0 / np.sqrt(np.diag(Sig[i]))))
        # minima from the pairwise starts, re-ranked with the full weights
        minima.append(_minima_from_starts(models[-1], Rk[sl], dk[sl], rik[sl]))
    cov_joint = np.zeros((2 * n, 2 * n))
    for i in range(n):
        cov_joint[2 * i : 2 * i + 2, 2 * i : 2 * i + 2] = A_blocks[i]
    cov_joint += B @ np.kron(np.diag(sig_r**2), np.eye(2)) @ B.T
    cov_joint = 0.5 * (cov_joint + cov_joint.T)
    return {
        "xy": list(P),
        "cov": cov,
        "tests": tests,
        "residuals": residuals,
        "rows": [order[offsets[i] : offsets[i + 1]] for i in range(n)],
        "minima": minima,
        "models": models,
        "cov_joint": cov_joint,
    }


def _minima_from_starts(
    model: ms.BatchedModel, R: np.ndarray, d: np.ndarray, ri: np.ndarray
) -> list[ms.Minimum]:
    starts = [
        circle_intersections(R[a], d[a], R[b], d[b])
        for a, b in combinations(range(d.size), 2)
        if ri[a] != ri[b]
    ]
    X, cost = ms.batched_lm(model, np.vstack(starts))
    r, J = model(X)
    grad = np.linalg.norm(np.matmul(r[:, None, :], J)[:, 0], axis=1)
    keep = grad < 1e-4 * (1 + np.sqrt(cost))
    return ms.cluster(X[keep], cost[keep], 1e-3)
