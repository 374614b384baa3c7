"""Joint adjustment of the world points and the validation poses: one network of every hand-laser reading.

The seeds solved the survey in two stages (AD2.3): world points from the readings to the Vframe points,
then each validation pose from the readings of its robot points to the world points, the world points
held. But every pose's readings also measure the world points: at each stop the three robot points see
most of the room, so the 26 stops of a validation session are 26 free stations of a surveyor's network
(Ghilani, *Adjustment Computations*, 6th ed., ch. 16, "free stations" / resection in a network). Adjusted
together, the world points are tied to each other by about 1,200 readings instead of 90, and the poses
inherit that. On the simulated GT room the worst world point of a survey comes down from 1.7 to 1.0 mm
(median over surveys) and every pose's error with it (``bench/survey.py``).

Model (world frame, metres, radians): unknowns are the world points ``P`` (N, 2), the free reference
points ``R`` (their nominal coordinates as priors, ``sigma`` per coordinate), the poses ``(x, y, theta)``
and, when the robot points have a drawing sigma, the offset of every robot point drawn at every pose
(a prior of that sigma: the felt-pen mark is off the true robot point, the same for all readings from
it). Readings are ``|a - b| + e``, ``e ~ N(0, sigma^2)``. Weighted least squares (Levenberg-Marquardt
from the two-stage solution, so the multi-start and the basins of the two stages still decide which
minimum); covariance ``(J^T W J)^-1``; Baarda's w-test over every reading (:mod:`gtrig.survey.robust`).
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np

from gtrig.errors import InputError
from gtrig.io.survey_csv import Distances, NamedPoints
from gtrig.survey.network import point_blocks, solve_whitened
from gtrig.survey.robust import BadReading, ResidualTest, record_exclusion, residual_test, triage


@dataclass(frozen=True)
class JointResult:
    """Outcome of :func:`adjust_jointly`.

    Attributes
    ----------
    points_xy : (N, 2) world points, world frame, metres.
    points_cov_joint : (2N, 2N) their covariance (x1, y1, x2, y2, ...), m^2.
    poses_xytheta : (P, 3) robot frame in the world (m, m, rad in [-pi, pi)).
    poses_cov : (P, 3, 3) covariance of each pose (m^2, m rad, rad^2), marginal over everything else.
    poses_cov_joint : (3P, 3P) the poses' joint covariance (x1, y1, theta1, x2, ...): they share the
        world points, so their errors are correlated.
    reference_xy : (M, 2) adjusted reference points.
    test : global chi-square and w-test over every reading and prior.
    world_active, pose_active : (K,), (L,) readings used, in the order given.
    excluded : readings excluded by this adjustment's residual test.
    """

    points_xy: np.ndarray
    points_cov_joint: np.ndarray
    poses_xytheta: np.ndarray
    poses_cov: np.ndarray
    poses_cov_joint: np.ndarray
    reference_xy: np.ndarray
    test: ResidualTest
    world_active: np.ndarray
    pose_active: np.ndarray
    excluded: tuple[BadReading, ...]

    @property
    def points_cov_xy(self) -> np.ndarray:
        """(N, 2, 2) marginal covariance of every world point."""
        return point_blocks(self.points_cov_joint)


@dataclass(frozen=True)
class _Problem:
    """Index arrays of one adjustment (the active readings only)."""

    n_w: int  # world points
    free: np.ndarray  # (F,) reference points estimated
    R0: np.ndarray  # (M, 2)
    sig_r: np.ndarray  # (M,)
    wa: np.ndarray  # (K,) world point of each world reading
    wb: np.ndarray  # (K,) other end: world point (>= 0) or reference (-1 - j)
    wd: np.ndarray
    ws: np.ndarray
    pp: np.ndarray  # (L,) pose of each pose reading
    pq: np.ndarray  # (L,) robot point
    pw: np.ndarray  # (L,) world point
    pd: np.ndarray
    ps: np.ndarray
    Q: np.ndarray  # (A, 2) robot points, robot frame
    sig_q: np.ndarray  # (A,) drawing sigma of each robot point (0: no offset parameter)
    n_p: int  # poses
    off_index: np.ndarray  # (P, A) column block of each drawn robot point's offset, -1 when none

    @property
    def n_params(self) -> int:
        return 2 * self.n_w + 2 * self.free.size + 3 * self.n_p + 2 * int(np.sum(self.off_index >= 0))

    def unpack(self, z: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        a = 2 * self.n_w
        b = a + 2 * self.free.size
        c = b + 3 * self.n_p
        P = z[:a].reshape(-1, 2)
        R = self.R0.copy()
        R[self.free] = z[a:b].reshape(-1, 2)
        return P, R, z[b:c].reshape(-1, 3), z[c:].reshape(-1, 2)

    def _geometry(self, z: np.ndarray) -> tuple[np.ndarray, ...]:
        P, R, X, O = self.unpack(z)
        end_w = np.where((self.wb >= 0)[:, None], P[np.maximum(self.wb, 0)], R[np.maximum(-1 - self.wb, 0)])
        dw = P[self.wa] - end_w
        c, s = np.cos(X[self.pp, 2]), np.sin(X[self.pp, 2])
        q = self.Q[self.pq]
        qr = np.column_stack([c * q[:, 0] - s * q[:, 1], s * q[:, 0] + c * q[:, 1]])  # R(theta) q
        oi = self.off_index[self.pp, self.pq]
        off = np.where((oi >= 0)[:, None], O[np.maximum(oi, 0)] if O.size else 0.0, 0.0)
        dp = P[self.pw] - (X[self.pp, :2] + qr + off)
        return P, R, X, O, dw, dp, qr, oi

    def resid(self, z: np.ndarray) -> np.ndarray:
        """Whitened residuals: world readings, reference priors, pose readings, robot-point offset priors."""
        _, R, _, O, dw, dp, _, _ = self._geometry(z)
        r_ref = (R[self.free] - self.R0[self.free]) / self.sig_r[self.free, None]
        has = self.off_index >= 0
        sig_o = np.broadcast_to(self.sig_q[None], self.off_index.shape)[has]
        r_off = O / sig_o[:, None] if O.size else np.zeros((0, 2))
        return np.concatenate([
            (np.linalg.norm(dw, axis=1) - self.wd) / self.ws,
            r_ref.ravel(),
            (np.linalg.norm(dp, axis=1) - self.pd) / self.ps,
            r_off.ravel(),
        ])

    def jac(self, z: np.ndarray) -> np.ndarray:
        _, _, _, O, dw, dp, qr, oi = self._geometry(z)
        K, F, L, n_o = self.wd.size, self.free.size, self.pd.size, O.shape[0]
        J = np.zeros((K + 2 * F + L + 2 * n_o, self.n_params))
        col_ref = np.full(self.R0.shape[0], -1)
        col_ref[self.free] = 2 * self.n_w + 2 * np.arange(F)
        col_pose = 2 * self.n_w + 2 * F
        col_off = col_pose + 3 * self.n_p
        # world readings: d|Pa - b| / dPa = u, / db = -u
        u = dw / np.maximum(np.linalg.norm(dw, axis=1, keepdims=True), 1e-12) / self.ws[:, None]
        rows = np.arange(K)
        cb = np.where(self.wb >= 0, 2 * self.wb, col_ref[np.maximum(-1 - self.wb, 0)])
        for c in range(2):
            J[rows, 2 * self.wa + c] += u[:, c]
            ok = cb >= 0
            J[rows[ok], cb[ok] + c] -= u[ok, c]
        # reference priors
        J[K + np.arange(2 * F), 2 * self.n_w + np.arange(2 * F)] = np.repeat(1.0 / self.sig_r[self.free], 2)
        # pose readings: d|W - t - R q - o| / dW = u, / dt = -u, / dtheta = u x (R q) (2D), / do = -u
        v = dp / np.maximum(np.linalg.norm(dp, axis=1, keepdims=True), 1e-12) / self.ps[:, None]
        rows = K + 2 * F + np.arange(L)
        cp = col_pose + 3 * self.pp
        for c in range(2):
            J[rows, 2 * self.pw + c] += v[:, c]
            J[rows, cp + c] -= v[:, c]
        J[rows, cp + 2] = v[:, 0] * qr[:, 1] - v[:, 1] * qr[:, 0]
        has = oi >= 0
        for c in range(2):
            J[rows[has], col_off + 2 * oi[has] + c] -= v[has, c]
        if n_o:
            sig_o = np.broadcast_to(self.sig_q[None], self.off_index.shape)[self.off_index >= 0]
            r0 = K + 2 * F + L
            J[r0 + np.arange(2 * n_o), col_off + np.arange(2 * n_o)] = np.repeat(1.0 / sig_o, 2)
        return J


def _problem(world_names: list[str], references: NamedPoints, world: Distances, w_active: np.ndarray,
             pose_names: list[str], robot_points: NamedPoints, poses: Distances, p_active: np.ndarray) -> _Problem:
    wi = {n: i for i, n in enumerate(world_names)}
    ri = references.index()
    qi = robot_points.index()
    pi = {n: i for i, n in enumerate(pose_names)}
    kw, kp = np.flatnonzero(w_active), np.flatnonzero(p_active)
    for k in kp:
        if poses.b[k] not in wi:
            raise InputError(f"{poses.source[k]}: world point {poses.b[k]!r} is not among the surveyed points")
    sig_q = np.asarray(robot_points.sigma_m, float)
    off = np.full((len(pose_names), len(robot_points.names)), -1)
    used = {(pi[poses.group[k]], qi[poses.a[k]]) for k in kp}
    for j, (p, a) in enumerate(sorted((p, a) for p, a in used if sig_q[a] > 0)):
        off[p, a] = j
    return _Problem(
        n_w=len(world_names), free=np.flatnonzero(references.sigma_m > 0), R0=references.xy,
        sig_r=np.asarray(references.sigma_m, float),
        wa=np.array([wi[world.a[k]] for k in kw], dtype=int),
        wb=np.array([wi[world.b[k]] if world.b[k] in wi else -1 - ri[world.b[k]] for k in kw], dtype=int),
        wd=world.distance_m[kw], ws=world.sigma_m[kw],
        pp=np.array([pi[poses.group[k]] for k in kp], dtype=int),
        pq=np.array([qi[poses.a[k]] for k in kp], dtype=int),
        pw=np.array([wi[poses.b[k]] for k in kp], dtype=int),
        pd=poses.distance_m[kp], ps=poses.sigma_m[kp],
        Q=robot_points.xy, sig_q=sig_q, n_p=len(pose_names), off_index=off,
    )


def adjust_jointly(
    world_names: list[str],
    xy0: np.ndarray,
    references: NamedPoints,
    world_readings: Distances,
    pose_names: list[str],
    xytheta0: np.ndarray,
    robot_points: NamedPoints,
    pose_readings: Distances,
    *,
    world_active: np.ndarray | None = None,
    pose_active: np.ndarray | None = None,
    alpha: float = 0.001,
    on_outlier: str = "exclude",
    max_exclusions: int = 3,
    warnings: list[str] | None = None,
    log: logging.Logger | None = None,
) -> JointResult:
    """Adjust world points, reference points and validation poses together (see the module docstring).

    Parameters
    ----------
    world_names, xy0 : N world point names and their starting coordinates (N, 2) (the two-stage result).
    references : reference points with their sigma per coordinate (0: held fixed).
    world_readings : ``a`` a world point, ``b`` a reference or another world point.
    pose_names, xytheta0 : P pose names and their starting poses (P, 3) (the two-stage result).
    robot_points : robot points in the robot frame, with their drawing sigma.
    pose_readings : ``group`` the pose, ``a`` the robot point, ``b`` the world point.
    world_active, pose_active : readings to use (default all); the two stages' exclusions go here.
    alpha, on_outlier : as :func:`gtrig.survey.points.estimate_world_points`; ``max_exclusions`` counts
        over the whole network (the two stages already excluded what they could pin down).

    Returns
    -------
    JointResult
    """
    log = log or logging.getLogger(__name__)
    warnings = warnings if warnings is not None else []
    wact = np.ones(world_readings.distance_m.size, bool) if world_active is None else np.array(world_active, bool)
    pact = np.ones(pose_readings.distance_m.size, bool) if pose_active is None else np.array(pose_active, bool)
    excluded: list[BadReading] = []
    X0 = np.asarray(xytheta0, float).reshape(-1, 3)
    while True:
        prob = _problem(world_names, references, world_readings, wact, pose_names, robot_points, pose_readings, pact)
        n_off = int(np.sum(prob.off_index >= 0))
        z0 = np.concatenate([np.asarray(xy0, float).ravel(), prob.R0[prob.free].ravel(), X0.ravel(),
                             np.zeros(2 * n_off)])
        x, J, C, r = solve_whitened(prob.resid, prob.jac, z0, "joint survey adjustment")
        test = residual_test(r, None, J, C)
        if test.dof <= 0 or test.p_value >= alpha or test.worst < 0:
            break
        bad, is_world, k = _bad_reading(test, r, prob, references, world_readings, pose_readings, wact, pact)
        if bad is None:  # a prior, not a reading: a reference point or a drawn robot point is off
            msg = _prior_message(test, prob, references, pose_names, robot_points)
            if on_outlier != "keep":
                raise InputError(msg)
            log.warning(msg)
            warnings.append(msg)
            break
        unidentifiable = (f"joint survey adjustment: readings disagree (chi2 {test.chi2:.1f}, {test.dof} dof) "
                          f"but the bad one cannot be told apart; remeasure near {bad.describe()}")
        if not triage(bad, test, on_outlier, len(excluded), max_exclusions, unidentifiable, warnings, log):
            break
        (wact if is_world else pact)[k] = False
        record_exclusion(bad, excluded, warnings, log)
    P, R, X, _ = prob.unpack(x)
    X = X.copy()
    X[:, 2] = (X[:, 2] + np.pi) % (2 * np.pi) - np.pi
    n2 = 2 * len(world_names)
    c0 = n2 + 2 * prob.free.size
    n3 = 3 * len(pose_names)
    cov_joint = C[c0:c0 + n3, c0:c0 + n3]
    pose_cov = np.array([cov_joint[3 * i:3 * i + 3, 3 * i:3 * i + 3] for i in range(len(pose_names))])
    return JointResult(P, C[:n2, :n2], X, pose_cov.reshape(-1, 3, 3), cov_joint, R, test, wact, pact,
                       tuple(excluded))


def _prior_message(test: ResidualTest, prob: _Problem, references: NamedPoints, pose_names: list[str],
                   robot_points: NamedPoints) -> str:
    i = test.worst - prob.wd.size
    w = test.w[test.worst]
    if i < 2 * prob.free.size:
        return (f"reference point {references.names[prob.free[i // 2]]}: its coordinates disagree with the "
                f"readings (w = {w:.1f}); check the reference file")
    j = (i - 2 * prob.free.size - prob.pd.size) // 2
    p, a = (int(v[0]) for v in np.nonzero(prob.off_index == j))
    return (f"pose {pose_names[p]}: robot point {robot_points.names[a]} was drawn off its place (w = {w:.1f}); "
            "check the drawing or its readings")


def _bad_reading(test: ResidualTest, r: np.ndarray, prob: _Problem, references: NamedPoints, world: Distances,
                 poses: Distances, wact: np.ndarray, pact: np.ndarray
                 ) -> tuple[BadReading | None, bool, int]:
    """The reading behind the worst w (None for a reference prior or a robot-point offset prior), whether it
    is a world reading, and its index in its table."""
    K, F2, L = prob.wd.size, 2 * prob.free.size, prob.pd.size
    i = test.worst
    if i < K:
        k = int(np.flatnonzero(wact)[i])
        s = world.sigma_m[k]
        kind = "point" if world.b[k] in references.index() else "network"
        return (BadReading(kind, world.a[k], world.b[k], "", float(world.distance_m[k]), float(r[i] * s),
                           float(test.error_m[i] * s), float(test.w[i]), world.source[k]), True, k)
    if K + F2 <= i < K + F2 + L:
        k = int(np.flatnonzero(pact)[i - K - F2])
        s = poses.sigma_m[k]
        return (BadReading("pose", poses.group[k], poses.a[k], poses.b[k], float(poses.distance_m[k]),
                           float(r[i] * s), float(test.error_m[i] * s), float(test.w[i]), poses.source[k]),
                False, k)
    return None, False, -1


__all__ = ["JointResult", "adjust_jointly"]
