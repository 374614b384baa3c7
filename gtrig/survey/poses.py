"""Validation robot poses from hand-laser distances between robot points and world points.

Method (AD2.3, "Collection of the validation data"): at every validation pose the operator draws robot
points ``q_a`` (robot frame: the origin and the ends of the x and y axes of a frame fixed to the robot) on
the floor and measures horizontal distances ``d_k = |w_b - (t + R(theta) q_a)| + e_k`` to world points
``w_b``. The pose ``(x, y, theta)`` of the robot frame in the world solves weighted nonlinear least squares
(:func:`scipy.optimize.least_squares`; the seeds iterated an EKF 20 times, i.e. Gauss-Newton).

The world points' covariance (joint, from :mod:`gtrig.survey.points`, or per point from a CSV) and an
optional robot-point sigma are propagated by the Jacobian into the readings' covariance, so readings
sharing a world point are correlated. The result per pose is ``xytheta`` with ``cov_xytheta`` (3 x 3).
Poses are independent given the readings; the correlation between poses through the shared world points
is not reported.

Initial guess: every robot point is trilaterated from its readings, then the rigid transform from the
robot points to those positions is fitted; ``initial`` (the operator's hand-measured pose) and a grid over
the room are added as starts with ``multistart``.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np

from gtrig.errors import ConvergenceError, InputError
from gtrig.io.survey_csv import Distances, NamedPoints, PoseTable
from gtrig.survey import multistart as ms
from gtrig.survey.nls import solve_blocks
from gtrig.survey.points import ON_AMBIGUITY, ON_OUTLIER, circle_intersections
from gtrig.survey.robust import BadReading, record_exclusion, residual_test, triage

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class PoseEstimate:
    """One validation pose.

    Attributes
    ----------
    name : pose name.
    xytheta : (3,) robot frame in the world: metres, metres, radians in [-pi, pi).
    cov_xytheta : (3, 3) covariance (m^2, m rad, rad^2).
    n_readings, chi2, dof, p_value, rms_residual_m, max_abs_residual_m : fit and residual test.
    basin : multi-start outcome (None without multi-start).
    excluded : readings excluded by the residual test.
    """

    name: str
    xytheta: np.ndarray
    cov_xytheta: np.ndarray
    n_readings: int
    chi2: float
    dof: int
    p_value: float
    rms_residual_m: float
    max_abs_residual_m: float
    basin: ms.Basin | None
    excluded: tuple[BadReading, ...]


@dataclass(frozen=True)
class PosesResult:
    """All poses: ``names`` (P,), ``xytheta`` (P, 3), ``cov_xytheta`` (P, 3, 3), details and warnings."""

    names: tuple[str, ...]
    xytheta: np.ndarray
    cov_xytheta: np.ndarray
    poses: tuple[PoseEstimate, ...]
    excluded: tuple[BadReading, ...]
    warnings: tuple[str, ...]

    def as_table(self) -> PoseTable:
        return PoseTable(self.names, self.xytheta, self.cov_xytheta)


def _rot(th: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    return np.cos(th), np.sin(th)


def _batched_model(d: np.ndarray, W: np.ndarray, Q: np.ndarray, w_inv_sigma: np.ndarray) -> ms.BatchedModel:
    """Whitened residuals of one pose for starts X (S, 3); W (m, 2) world points, Q (m, 2) robot points."""

    def model(X: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        c, s = _rot(X[:, 2])
        qx = c[:, None] * Q[None, :, 0] - s[:, None] * Q[None, :, 1]
        qy = s[:, None] * Q[None, :, 0] + c[:, None] * Q[None, :, 1]
        dx = W[None, :, 0] - (X[:, 0:1] + qx)
        dy = W[None, :, 1] - (X[:, 1:2] + qy)
        rng = np.maximum(np.hypot(dx, dy), 1e-9)
        ux, uy = dx / rng, dy / rng
        J = np.stack([-ux, -uy, ux * qy - uy * qx], axis=2)  # d|w - s| / d(x, y, theta)
        return (rng - d) * w_inv_sigma, J * w_inv_sigma[:, None]

    return model


def _kabsch_2d(Q: np.ndarray, P: np.ndarray) -> np.ndarray:
    """(x, y, theta) of the rigid transform mapping robot points Q (n, 2) onto world positions P (n, 2)."""
    qc, pc = Q.mean(axis=0), P.mean(axis=0)
    A, B = Q - qc, P - pc
    th = np.arctan2(
        np.sum(A[:, 0] * B[:, 1] - A[:, 1] * B[:, 0]), np.sum(A[:, 0] * B[:, 0] + A[:, 1] * B[:, 1])
    )
    c, s = np.cos(th), np.sin(th)
    t = pc - np.array([c * qc[0] - s * qc[1], s * qc[0] + c * qc[1]])
    return np.array([t[0], t[1], th])


def _trilaterate_candidates(Wk: np.ndarray, d: np.ndarray) -> np.ndarray:
    """Least-squares positions of one robot point from its world-point readings: best minimum first."""
    near = np.argsort(d)[:4]  # the nearest world points give well-conditioned intersections
    starts = [
        circle_intersections(Wk[a], d[a], Wk[b], d[b]) for i, a in enumerate(near) for b in near[i + 1 :]
    ]
    S = np.vstack([s for s in starts if s.size]) if starts else np.empty((0, 2))
    if S.shape[0] == 0:
        return S

    def model(X: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        diff = X[:, None, :] - Wk[None]
        rng = np.maximum(np.linalg.norm(diff, axis=2), 1e-9)
        return rng - d, diff / rng[..., None]

    X, cost = ms.batched_lm(model, S, iterations=30)
    return np.array([m.x for m in ms.cluster(X, cost, 1e-3)])


def estimate_poses(
    world_points: NamedPoints | tuple[tuple[str, ...], np.ndarray, np.ndarray],
    robot_points: NamedPoints,
    distances: Distances,
    *,
    initial: PoseTable | None = None,
    cov_world_joint: np.ndarray | None = None,
    multistart: bool = True,
    on_ambiguity: str = "refuse",
    on_outlier: str = "exclude",
    alpha: float = 0.001,
    ambiguity_chi2: float = 16.0,
    max_exclusions: int = 2,
    grid_step_m: float = 1.5,
) -> PosesResult:
    """Estimate every validation pose.

    Parameters
    ----------
    world_points : ``(names, xy (N, 2), cov_xy (N, 2, 2))`` world frame, metres (e.g.
        ``(r.names, r.xy, r.cov_xy)`` of a :class:`~gtrig.survey.points.WorldPointsResult`).
    robot_points : points in the robot frame; ``sigma_m`` is their drawing accuracy.
    distances : ``group`` = pose, ``a`` = robot point, ``b`` = world point.
    initial : hand-measured poses, used as extra starts.
    cov_world_joint : (2N, 2N) joint world-point covariance; default block-diagonal from ``cov_xy``.
    multistart, on_ambiguity, on_outlier, alpha, ambiguity_chi2, max_exclusions : as in
        :func:`gtrig.survey.points.estimate_world_points`.
    grid_step_m : spacing of the global grid of starts over the world points' bounding box.
    """
    if on_ambiguity not in ON_AMBIGUITY:
        raise InputError(f"on_ambiguity must be one of {', '.join(ON_AMBIGUITY)}, got {on_ambiguity!r}")
    if on_outlier not in ON_OUTLIER:
        raise InputError(f"on_outlier must be one of {', '.join(ON_OUTLIER)}, got {on_outlier!r}")
    wnames, wxy, cov_world_joint = _world_arrays(world_points, cov_world_joint)
    wi, ri = _reading_indices(wnames, robot_points, distances)
    names = list(dict.fromkeys(distances.group))
    groups = np.array(distances.group)
    _check_observable(names, groups, ri, distances)
    init_map = {} if initial is None else {n: initial.xytheta[i] for i, n in enumerate(initial.names)}
    ctx = dict(wxy=wxy, cov_w=cov_world_joint, Q=robot_points.xy, sig_q=robot_points.sigma_m, wi=wi, ri=ri,
               d=distances.distance_m, sd=distances.sigma_m)
    fit, pose_rows, excluded, warnings = _fit_excluding_outliers(
        names, groups, distances, ctx, init_map, grid_step_m, on_outlier, alpha, max_exclusions)
    out = [_pose_estimate(n, i, fit, pose_rows[i], excluded[n], ctx, init_map, multistart, grid_step_m,
                          ambiguity_chi2, on_ambiguity, warnings) for i, n in enumerate(names)]
    return PosesResult(
        tuple(names),
        np.array([p.xytheta for p in out]).reshape(-1, 3),
        np.array([p.cov_xytheta for p in out]).reshape(-1, 3, 3),
        tuple(out),
        tuple(b for n in names for b in excluded[n]),
        tuple(warnings),
    )


def _world_arrays(world_points: NamedPoints | tuple[tuple[str, ...], np.ndarray, np.ndarray],
                  cov_world_joint: np.ndarray | None) -> tuple[tuple[str, ...], np.ndarray, np.ndarray]:
    """The world points' names, xy (N, 2) and joint covariance (2N, 2N), block-diagonal from each point's
    own when no joint one is given."""
    if isinstance(world_points, NamedPoints):
        wnames, wxy = world_points.names, world_points.xy
        wcov = np.array([np.eye(2) * s**2 for s in world_points.sigma_m])
    else:
        wnames, wxy, wcov = world_points
    N = len(wnames)
    if cov_world_joint is None:
        cov_world_joint = np.zeros((2 * N, 2 * N))
        for i in range(N):
            cov_world_joint[2 * i : 2 * i + 2, 2 * i : 2 * i + 2] = wcov[i]
    return tuple(wnames), wxy, cov_world_joint


def _reading_indices(wnames: tuple[str, ...], robot_points: NamedPoints, distances: Distances
                     ) -> tuple[np.ndarray, np.ndarray]:
    """Each reading's world point and robot point as indices; an unknown name is refused with its line."""
    widx = {n: i for i, n in enumerate(wnames)}
    ridx = robot_points.index()
    wi = np.empty(len(distances.a), dtype=int)
    ri = np.empty(len(distances.a), dtype=int)
    for k in range(len(distances.a)):
        if distances.a[k] not in ridx:
            raise InputError(
                f"{distances.source[k]}: unknown robot point {distances.a[k]!r} "
                f"(robot points: {', '.join(robot_points.names)})"
            )
        if distances.b[k] not in widx:
            raise InputError(
                f"{distances.source[k]}: unknown world point {distances.b[k]!r} "
                f"(world points: {', '.join(wnames)})"
            )
        wi[k], ri[k] = widx[distances.b[k]], ridx[distances.a[k]]
    return wi, ri


def _check_observable(names: list[str], groups: np.ndarray, ri: np.ndarray, distances: Distances) -> None:
    """Every pose needs three readings from two robot points or more (x, y and theta)."""
    for n in names:
        rows = np.flatnonzero(groups == n)
        if rows.size < 3:
            raise InputError(
                f"pose {n}: {rows.size} distance(s), at least 3 needed for its 3 unknowns "
                f"(x, y, theta) ({distances.source[rows[0]]})"
            )
        if len(set(ri[rows].tolist())) < 2:
            raise InputError(
                f"pose {n}: readings from one robot point only; theta is not observable "
                f"({distances.source[rows[0]]})"
            )


def _fit_excluding_outliers(names: list[str], groups: np.ndarray, distances: Distances, ctx: dict,
                            init_map: dict, grid_step_m: float, on_outlier: str, alpha: float,
                            max_exclusions: int) -> tuple[dict, list[np.ndarray], dict[str, list[BadReading]],
                                                          list[str]]:
    """Fit every pose, drop the worst reading of a pose whose readings fail the chi-square test at
    ``alpha`` (as ``on_outlier`` and ``max_exclusions`` allow), and fit again until none is dropped."""
    active = np.ones(len(distances.a), dtype=bool)
    excluded: dict[str, list[BadReading]] = {n: [] for n in names}
    warnings: list[str] = []
    x_prev: dict[str, np.ndarray] = {}
    while True:
        pose_rows = [np.flatnonzero((groups == n) & active) for n in names]
        x0 = [x_prev[n] if n in x_prev else _initial_guess(n, r, ctx, init_map.get(n), grid_step_m)
              for n, r in zip(names, pose_rows, strict=True)]
        fit = _fit(pose_rows, np.array(x0), ctx)
        x_prev = {n: fit["x"][i] for i, n in enumerate(names)}
        changed = False
        for i, n in enumerate(names):
            t, r = fit["tests"][i], pose_rows[i]
            if t.dof <= 0 or t.p_value >= alpha:
                continue
            k = r[t.worst] if t.worst >= 0 else r[0]
            bad = BadReading(
                "pose",
                n,
                distances.a[k],
                distances.b[k],
                float(distances.distance_m[k]),
                float(fit["residuals"][i][t.worst]),
                float(t.error_m[t.worst]),
                float(t.w[t.worst]),
                distances.source[k],
            )
            unidentifiable = (
                f"pose {n}: readings disagree (chi2 {t.chi2:.1f}, {t.dof} dof) but the bad one "
                f"cannot be told apart; remeasure ({distances.source[r[0]]})"
            )
            if not triage(bad, t, on_outlier, len(excluded[n]), max_exclusions, unidentifiable, warnings, log,
                          room_to_exclude=r.size - 1 >= 3):
                continue
            active[k] = False
            record_exclusion(bad, excluded[n], warnings, log)
            changed = True
        if not changed:
            return fit, pose_rows, excluded, warnings


def _pose_estimate(n: str, i: int, fit: dict, rows: np.ndarray, excluded: list[BadReading], ctx: dict,
                   init_map: dict, multistart: bool, grid_step_m: float, ambiguity_chi2: float,
                   on_ambiguity: str, warnings: list[str]) -> PoseEstimate:
    """Pose ``n``'s estimate, its fit statistics and, with ``multistart``, the other basins' analysis; a
    second pose that fits as well is refused (``on_ambiguity="refuse"``) or warned of."""
    x, t, res = fit["x"][i], fit["tests"][i], fit["residuals"][i]
    basin = None
    if multistart:
        extra = _global_starts(ctx["wxy"][np.unique(ctx["wi"][rows])], grid_step_m)
        if n in init_map:
            extra = np.vstack([extra, init_map[n]])
        basin = ms.analyse(fit["models"][i], x, extra, radii=(0.1, 0.25, 0.5, 1.0),
                           ambiguity_chi2=ambiguity_chi2, angle_index=2)
        if basin.ambiguous:
            m = basin.alternatives[0]
            msg = (
                f"pose {n}: two poses fit the distances: ({x[0]:.4f}, {x[1]:.4f}, {x[2]:.4f}) "
                f"and ({m.x[0]:.4f}, {m.x[1]:.4f}, {m.x[2]:.4f}) chi2 {m.chi2:.2f}"
            )
            if on_ambiguity == "refuse":
                raise ConvergenceError(f"{msg}; add readings to other world points, or rerun with --on-ambiguity warn")
            log.warning(msg + "; kept the better one")
            warnings.append(msg)
    return PoseEstimate(n, x, fit["cov"][i], int(rows.size), t.chi2, t.dof, t.p_value,
                        float(np.sqrt(np.mean(res**2))), float(np.max(np.abs(res))), basin, tuple(excluded))


def _global_starts(W: np.ndarray, step: float) -> np.ndarray:
    lo, hi = W.min(axis=0), W.max(axis=0)
    xs = np.arange(lo[0], hi[0] + 1e-9, step)
    ys = np.arange(lo[1], hi[1] + 1e-9, step)
    ths = np.linspace(-np.pi, np.pi, 8, endpoint=False)
    g = np.array(np.meshgrid(xs, ys, ths, indexing="ij")).reshape(3, -1).T
    return g


def _initial_guess(
    name: str, rows: np.ndarray, ctx: dict, hand: np.ndarray | None, step: float
) -> np.ndarray:
    wxy, Q, wi, ri, d = ctx["wxy"], ctx["Q"], ctx["wi"], ctx["ri"], ctx["d"]
    Wk, Qk, dk = wxy[wi[rows]], Q[ri[rows]], d[rows]
    starts = []
    # trilaterate each robot point; all combinations of their candidate positions, then Kabsch
    cands, qs = [], []
    for a in np.unique(ri[rows]):
        sel = ri[rows] == a
        if sel.sum() >= 2:
            c = _trilaterate_candidates(Wk[sel], dk[sel])
            if c.size:
                cands.append(c[:2])
                qs.append(Q[a])
    if len(cands) >= 2:
        import itertools

        for combo in itertools.product(*cands):
            starts.append(_kabsch_2d(np.array(qs), np.array(combo)))
    if hand is not None:
        starts.append(np.asarray(hand, dtype=float))
    if not starts:
        starts = list(_global_starts(Wk, step))
    S = np.array(starts)
    S[:, 2] = (S[:, 2] + np.pi) % (2 * np.pi) - np.pi
    w_inv_sigma = 1.0 / ctx["sd"][rows]
    X, cost = ms.batched_lm(_batched_model(dk, Wk, Qk, w_inv_sigma), S, angle_index=2)
    return X[int(np.argmin(cost))]


def _pose_cov(x: np.ndarray, rows: np.ndarray, ctx: dict) -> np.ndarray:
    """Covariance of the readings of one pose at ``x``: hand laser, world points (joint), robot points."""
    wxy, Q, wi, ri = ctx["wxy"], ctx["Q"], ctx["wi"], ctx["ri"]
    c, s = np.cos(x[2]), np.sin(x[2])
    q = Q[ri[rows]]
    S = x[:2] + np.column_stack([c * q[:, 0] - s * q[:, 1], s * q[:, 0] + c * q[:, 1]])
    diff = wxy[wi[rows]] - S
    u = diff / np.linalg.norm(diff, axis=1, keepdims=True)
    m = rows.size
    Vw = np.zeros((m, 2 * wxy.shape[0]))
    Vw[np.arange(m), 2 * wi[rows]] = u[:, 0]
    Vw[np.arange(m), 2 * wi[rows] + 1] = u[:, 1]
    same_q = ri[rows][:, None] == ri[rows][None, :]
    return (
        np.diag(ctx["sd"][rows] ** 2)
        + Vw @ ctx["cov_w"] @ Vw.T
        + same_q * (u @ u.T) * (ctx["sig_q"][ri[rows]] ** 2)[:, None]
    )


def _fit(rows: list[np.ndarray], x0: np.ndarray, ctx: dict) -> dict:
    wxy, Q, wi, ri, d = ctx["wxy"], ctx["Q"], ctx["wi"], ctx["ri"], ctx["d"]
    order = np.concatenate(rows)
    offsets = np.cumsum([0] + [r.size for r in rows])
    pidx = np.repeat(np.arange(len(rows)), [r.size for r in rows])
    Wk, Qk, dk = wxy[wi[order]], Q[ri[order]], d[order]
    M = order.size

    def parts(z: np.ndarray) -> tuple[np.ndarray, ...]:
        X = z.reshape(-1, 3)[pidx]
        c, s = np.cos(X[:, 2]), np.sin(X[:, 2])
        qx = c * Qk[:, 0] - s * Qk[:, 1]
        qy = s * Qk[:, 0] + c * Qk[:, 1]
        dx, dy = Wk[:, 0] - X[:, 0] - qx, Wk[:, 1] - X[:, 1] - qy
        return dx, dy, np.hypot(dx, dy), qx, qy

    def resid(z: np.ndarray) -> np.ndarray:
        return parts(z)[2] - dk

    def jac(z: np.ndarray) -> np.ndarray:
        dx, dy, rng, qx, qy = parts(z)
        ux, uy = dx / rng, dy / rng
        J = np.zeros((M, z.size))
        a = np.arange(M)
        J[a, 3 * pidx] = -ux
        J[a, 3 * pidx + 1] = -uy
        J[a, 3 * pidx + 2] = ux * qy - uy * qx
        return J

    def covs(z: np.ndarray) -> list[np.ndarray]:
        Z = z.reshape(-1, 3)
        return [_pose_cov(Z[i], rows[i], ctx) for i in range(len(rows))]

    z = solve_blocks(resid, jac, x0.ravel(), covs, what="validation poses")
    Sig = covs(z)
    r_all, J_all = -resid(z), jac(z)
    X = z.reshape(-1, 3).copy()
    X[:, 2] = (X[:, 2] + np.pi) % (2 * np.pi) - np.pi
    cov, tests, residuals, models = [], [], [], []
    for i in range(len(rows)):
        sl = slice(offsets[i], offsets[i + 1])
        J = J_all[sl, 3 * i : 3 * i + 3]
        Si = np.linalg.inv(Sig[i])
        C = np.linalg.inv(J.T @ Si @ J)
        C = 0.5 * (C + C.T)
        cov.append(C)
        tests.append(residual_test(r_all[sl], Sig[i], J, C))
        residuals.append(r_all[sl])
        models.append(_batched_model(dk[sl], Wk[sl], Qk[sl], 1.0 / np.sqrt(np.diag(Sig[i]))))
    return {"x": list(X), "cov": cov, "tests": tests, "residuals": residuals, "models": models}
