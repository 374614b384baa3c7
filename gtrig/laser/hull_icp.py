"""Point-to-line ICP of the visible sides of the robot's rectangular hull, with covariance and degeneracy.

The model is the hull outline (``rig.robot.hull``): four sides in the robot frame. At each iteration
every point is assigned to the nearest side *that faces the scanner which saw it* (a scanner cannot
see the far side of the gown), and the planar pose ``(x, y, theta)`` of the robot in the world is
updated by one Gauss-Newton step on the signed point-to-line distances, Huber-weighted. Unlike the
point-to-point ICP of the seeds (journal paper, section 6, model points along the contour), the
point-to-line residual has no sampling error along a side and converges in two or three iterations.

Covariance. Range noise ``sigma_r`` moves a point along its beam ``u``, hence off the side (normal
``n``) by ``sigma_r |u . n|``; a model error ``sigma_model`` (gown not quite plane, the laser plane cutting
a tilted gown) is added in quadrature. ``cov = (J^T W J)^-1``, scaled up by the a-posteriori variance
factor when the residuals are larger than that noise.

Degeneracy. The fit is flagged, not trusted, when it has few points, when fewer than two sides hold
enough points (one side leaves the position along it free), or when the covariance is wide in any
direction (two parallel sides seen, a short stub of the second side).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from gtrig.rig.models import Hull

_J90 = np.array([[0.0, -1.0], [1.0, 0.0]])


@dataclass(frozen=True)
class HullModel:
    """The hull outline in the robot frame, precomputed for the ICP.

    Attributes
    ----------
    corners_xy : (4, 2) counter-clockwise corners, robot frame, metres.
    normals : (4, 2) outward unit normal of side ``k`` (corner ``k`` to ``k + 1``).
    offsets : (4,) ``normals[k] . corners[k]``: side ``k`` is ``{p : n_k . p = offsets[k]}``.
    tangents : (4, 2) unit direction of side ``k``.
    lengths : (4,) side lengths, metres.
    """

    corners_xy: np.ndarray
    normals: np.ndarray
    offsets: np.ndarray
    tangents: np.ndarray
    lengths: np.ndarray

    @staticmethod
    def from_hull(hull: Hull) -> HullModel:
        return HullModel.from_corners(hull.corners_xy())

    @staticmethod
    def from_corners(corners_xy: np.ndarray) -> HullModel:
        c = np.asarray(corners_xy, dtype=float)
        e = np.roll(c, -1, axis=0) - c
        lengths = np.linalg.norm(e, axis=1)
        t = e / lengths[:, None]
        n = t @ _J90  # (tx, ty) -> (ty, -tx): outward for a counter-clockwise polygon
        return HullModel(c, n, np.einsum("ij,ij->i", n, c), t, lengths)

    @property
    def half_diagonal_m(self) -> float:
        return float(np.max(np.linalg.norm(self.corners_xy - self.corners_xy.mean(axis=0), axis=1)))

    def corners_world(self, xytheta: np.ndarray) -> np.ndarray:
        """Corners (4, 2) in the world at planar pose ``xytheta``."""
        c, s = np.cos(xytheta[2]), np.sin(xytheta[2])
        return self.corners_xy @ np.array([[c, s], [-s, c]]) + xytheta[:2]


@dataclass(frozen=True)
class BeamPoints:
    """Laser points of K frames, each with the frame, scanner and beam it came from: what a hull fit reads.

    Attributes
    ----------
    xy_world : (M, 2) points, world frame, metres.
    frame_index : (M,) frame ``0 .. K-1`` of each point.
    scanner_index : (M,) index into ``scanner_xy_world`` and ``sigma_range_m`` of the scanner that saw
        each point.
    scanner_xy_world : (S, 2) scanner origins, world frame, metres.
    dir_world : (M, 2) unit beam direction of each point in the world x-y plane (sets the noise along a
        side's normal).
    sigma_range_m : (S,) range noise per scanner, metres.

    The arrays are kept as float (indices as ``intp``); ``xy_world`` may be given flat.
    """

    xy_world: np.ndarray
    frame_index: np.ndarray
    scanner_index: np.ndarray
    scanner_xy_world: np.ndarray
    dir_world: np.ndarray
    sigma_range_m: np.ndarray

    def __post_init__(self) -> None:
        p = np.asarray(self.xy_world, dtype=float).reshape(-1, 2)
        fid = np.asarray(self.frame_index, dtype=np.intp)
        sid = np.asarray(self.scanner_index, dtype=np.intp)
        d = np.asarray(self.dir_world, dtype=float)
        S = np.asarray(self.scanner_xy_world, dtype=float)
        sig = np.asarray(self.sigma_range_m, dtype=float)
        m = p.shape[0]
        if fid.shape != (m,) or sid.shape != (m,) or d.shape != (m, 2) or S.ndim != 2 or sig.shape != S.shape[:1]:
            raise ValueError(
                f"BeamPoints: xy_world (M, 2), frame_index (M,), scanner_index (M,), scanner_xy_world (S, 2), "
                f"dir_world (M, 2), sigma_range_m (S,) expected, got {p.shape}, {fid.shape}, {sid.shape}, "
                f"{S.shape}, {d.shape}, {sig.shape}"
            )
        for name, v in (("xy_world", p), ("frame_index", fid), ("scanner_index", sid), ("scanner_xy_world", S),
                        ("dir_world", d), ("sigma_range_m", sig)):
            object.__setattr__(self, name, v)

    @staticmethod
    def one_frame(
        xy_world: np.ndarray, scanner_index: np.ndarray, scanner_xy_world: np.ndarray, dir_world: np.ndarray,
        sigma_range_m: np.ndarray,
    ) -> BeamPoints:
        """The points (M, 2) of a single frame (frame index 0); other arguments as the attributes."""
        p = np.asarray(xy_world, dtype=float).reshape(-1, 2)
        return BeamPoints(p, np.zeros(p.shape[0], dtype=np.intp), scanner_index, scanner_xy_world, dir_world,
                          sigma_range_m)

    def range_variance_m2(self) -> np.ndarray:
        """(M,) range variance of each point's scanner, m^2."""
        return (self.sigma_range_m**2)[self.scanner_index]


@dataclass(frozen=True)
class HullFit:
    """One hull fit.

    Attributes
    ----------
    xytheta : (3,) robot pose in the world: x, y (m), theta (rad).
    cov_xytheta : (3, 3) its covariance (m^2, m rad, rad^2).
    n_points : inliers used.
    side_points : (4,) inliers per hull side.
    n_sides : sides with at least ``min_side_points`` inliers.
    rms_m : root-mean-square point-to-line residual of the inliers, metres.
    chi2_dof : weighted residual sum over degrees of freedom (about 1 when the noise model holds).
    iterations : Gauss-Newton iterations done.
    degenerate : the geometry cannot fix the pose; do not trust ``xytheta``.
    reason : why (empty when not degenerate).
    """

    xytheta: np.ndarray
    cov_xytheta: np.ndarray
    n_points: int
    side_points: np.ndarray
    n_sides: int
    rms_m: float
    chi2_dof: float
    iterations: int
    degenerate: bool
    reason: str = ""


@dataclass(frozen=True)
class IcpSettings:
    """Settings of :func:`fit_hull`.

    Attributes
    ----------
    gate_m : points farther than this from every visible side are ignored.
    huber_k : Huber threshold in sigmas.
    sigma_model_m : model error added in quadrature to each point's noise.
    max_iterations, tol_m, tol_rad : Gauss-Newton stopping rule.
    min_points, min_side_points : degeneracy thresholds on counts.
    max_std_m, max_std_rad : degeneracy thresholds on the covariance.
    prior_std_m, prior_std_rad : a weak prior at the start pose that keeps the normal equations regular.
    end_margin_m : how far beyond a side's ends a point may still belong to it.
    """

    gate_m: float = 0.08
    huber_k: float = 3.0
    sigma_model_m: float = 0.006
    max_iterations: int = 6
    tol_m: float = 1e-4
    tol_rad: float = 1e-4
    min_points: int = 6
    min_side_points: int = 3
    max_std_m: float = 0.015
    max_std_rad: float = np.radians(3.0)
    prior_std_m: float = 2.0
    prior_std_rad: float = 2.0
    end_margin_m: float = 0.03


@dataclass(frozen=True)
class HullFitBatch:
    """Hull fits of K frames at once; field ``f[k]`` is that of :class:`HullFit` for frame ``k``."""

    xytheta: np.ndarray
    cov_xytheta: np.ndarray
    n_points: np.ndarray
    side_points: np.ndarray
    n_sides: np.ndarray
    rms_m: np.ndarray
    chi2_dof: np.ndarray
    iterations: int
    degenerate: np.ndarray
    reasons: tuple[str, ...]

    def __len__(self) -> int:
        return int(self.xytheta.shape[0])

    def item(self, k: int) -> HullFit:
        return HullFit(
            self.xytheta[k].copy(),
            self.cov_xytheta[k].copy(),
            int(self.n_points[k]),
            self.side_points[k].copy(),
            int(self.n_sides[k]),
            float(self.rms_m[k]),
            float(self.chi2_dof[k]),
            self.iterations,
            bool(self.degenerate[k]),
            self.reasons[k],
        )


@dataclass(frozen=True)
class _Linearisation:
    """Point-to-line residuals of M points at given poses: assigned side (M,), inlier mask (M,), signed
    residual (M,) metres, weight (M,) 1/m^2 (0 for outliers), Jacobian rows ``J`` (3 arrays (M,)) with
    respect to the robot pose, and each point's side normal in the world ``nw`` (M, 2)."""

    side: np.ndarray
    inlier: np.ndarray
    r: np.ndarray
    w: np.ndarray
    J: tuple[np.ndarray, np.ndarray, np.ndarray]
    nw: np.ndarray


def _linearise(
    model: HullModel, pts: BeamPoints, var_r: np.ndarray, pose: np.ndarray, gate: float, st: IcpSettings
) -> _Linearisation:
    """Assign each point of ``pts`` to the nearest hull side facing its scanner at ``pose[frame_index]``
    (K, 3) and linearise its residual; ``var_r`` (M,) is each point's range variance
    (:meth:`BeamPoints.range_variance_m2`)."""
    p, fid, sid, S, dir_world = pts.xy_world, pts.frame_index, pts.scanner_index, pts.scanner_xy_world, pts.dir_world
    N, off = model.normals, model.offsets
    Tn, a0 = model.tangents, np.einsum("ij,ij->i", model.tangents, model.corners_xy)
    rows = np.arange(p.shape[0])
    P = pose[fid]
    c, s_ = np.cos(P[:, 2]), np.sin(P[:, 2])
    qx, qy = p[:, 0] - P[:, 0], p[:, 1] - P[:, 1]
    pr = np.column_stack([c * qx + s_ * qy, c * qy - s_ * qx])
    ox, oy = S[sid, 0] - P[:, 0], S[sid, 1] - P[:, 1]
    orr = np.column_stack([c * ox + s_ * oy, c * oy - s_ * ox])
    vis = (orr @ N.T - off) > 0
    sd = pr @ N.T - off
    a = pr @ Tn.T - a0
    over = np.maximum(0.0, np.maximum(-a, a - model.lengths))
    d2 = sd * sd + over * over
    d2[~vis] = np.inf
    k_side = np.argmin(d2, axis=1)
    inl = (d2[rows, k_side] < gate * gate) & (over[rows, k_side] <= st.end_margin_m)
    r = sd[rows, k_side]
    nk = N[k_side]
    nwx = c * nk[:, 0] - s_ * nk[:, 1]
    nwy = s_ * nk[:, 0] + c * nk[:, 1]
    cosi = dir_world[:, 0] * nwx + dir_world[:, 1] * nwy
    # the model error keeps grazing beams from dominating: their weight would otherwise hinge on the
    # very yaw being estimated (through cos i) and bias it
    var = var_r * cosi * cosi + st.sigma_model_m**2
    z2 = r * r / var
    hub = np.where(z2 <= st.huber_k**2, 1.0, st.huber_k / np.sqrt(np.maximum(z2, 1e-24)))
    w = np.where(inl, hub / var, 0.0)
    J = (-nwx, -nwy, nwx * qy - nwy * qx)
    return _Linearisation(k_side, inl, r, w, J, np.column_stack([nwx, nwy]))


def _normal_matrix(fid: np.ndarray, w: np.ndarray, J: tuple[np.ndarray, ...], K: int) -> np.ndarray:
    """Per-frame ``sum w J^T J`` (K, 3, 3), accumulated with ``bincount`` over the frame index (M,)."""
    H = np.zeros((K, 3, 3))
    for i in range(3):
        wi = w * J[i]
        for j in range(i, 3):
            H[:, i, j] = np.bincount(fid, wi * J[j], minlength=K)
            H[:, j, i] = H[:, i, j]
    return H


def fit_hull_batch(
    model: HullModel,
    pts: BeamPoints,
    init_xytheta: np.ndarray,
    settings: IcpSettings = IcpSettings(),
    wide_gate_m: float | None = None,
    min_iterations: int = 0,
) -> HullFitBatch:
    """Fit the hull independently in K frames at once (vectorised over all their points).

    Parameters
    ----------
    model
        The hull outline.
    pts
        M points of K frames seen by S scanners, world frame.
    init_xytheta
        (K, 3) start poses (predicted poses, or acquisition hypotheses).
    settings
        Gates, robust weighting, stopping rule and degeneracy thresholds.
    wide_gate_m
        Gate of the first iteration (default ``2 * settings.gate_m``), to pull in from a rough start.
    min_iterations
        Iterate at least this often (up to ``settings.max_iterations``) before the stopping rule may
        stop: the batch stops when all its frames have converged, so a batch cut into windows iterates
        as the whole one would only if every window does as many iterations (GTlaser's side-bias pass,
        :mod:`gtrig.laser.track`).

    Returns
    -------
    HullFitBatch
    """
    st = settings
    fid = pts.frame_index
    init = np.asarray(init_xytheta, dtype=float).reshape(-1, 3)
    K = init.shape[0]
    M = fid.shape[0]
    pose = init.copy()
    var_r = pts.range_variance_m2()
    prior = np.array([1 / st.prior_std_m**2, 1 / st.prior_std_m**2, 1 / st.prior_std_rad**2])
    wide = 2.0 * st.gate_m if wide_gate_m is None else wide_gate_m
    H = np.zeros((K, 3, 3))
    zero = np.zeros(M)
    lin = _Linearisation(np.zeros(M, dtype=np.intp), np.zeros(M, dtype=bool), zero, zero, (zero, zero, zero),
                         np.zeros((M, 2)))
    it = 0
    for it in range(1, st.max_iterations + 1):  # noqa: B007
        lin = _linearise(model, pts, var_r, pose, wide if it == 1 else st.gate_m, st)
        r, w, J = lin.r, lin.w, lin.J
        H = _normal_matrix(fid, w, J, K)
        # (float: bincount of no points at all is an integer array)
        g = np.column_stack([np.bincount(fid, w * J[i] * r, minlength=K) for i in range(3)]).astype(float)
        H[:, [0, 1, 2], [0, 1, 2]] += prior
        g += prior * (pose - init)
        delta = -np.linalg.solve(H, g[..., None])[..., 0]
        pose = pose + delta
        if (
            it > 1
            and it >= min_iterations
            and np.all(np.hypot(delta[:, 0], delta[:, 1]) < st.tol_m)
            and np.all(np.abs(delta[:, 2]) < st.tol_rad)
        ):
            break
    return _fit_summary(fid, K, pose, H, lin, it, st)


def _fit_summary(fid: np.ndarray, K: int, pose: np.ndarray, H: np.ndarray, lin: _Linearisation, iterations: int,
                 st: IcpSettings) -> HullFitBatch:
    """The K fits from their last linearisation ``lin`` and normal matrices ``H`` (K, 3, 3): inlier counts,
    residuals, the covariance scaled by the variance factor, and why a fit is degenerate."""
    inl, k_side, r, w = lin.inlier, lin.side, lin.r, lin.w
    n_in = np.bincount(fid, inl, minlength=K).astype(int)
    side_points = np.zeros((K, 4), dtype=int)
    np.add.at(side_points, (fid[inl], k_side[inl]), 1)
    n_sides = np.sum(side_points >= st.min_side_points, axis=1)
    ssq = np.bincount(fid, np.where(inl, r * r, 0.0), minlength=K)
    chi2 = np.bincount(fid, w * r * r, minlength=K)
    with np.errstate(invalid="ignore", divide="ignore"):
        rms = np.where(n_in > 0, np.sqrt(ssq / np.maximum(n_in, 1)), np.nan)
        chi2_dof = np.where(n_in > 0, chi2 / np.maximum(n_in - 3, 1), np.nan)
    cov = np.linalg.inv(H)
    inflate = np.where((n_in > 3) & (chi2_dof > 1.0), chi2_dof, 1.0)
    cov = cov * inflate[:, None, None]
    reasons = _degeneracy_reasons(n_in, n_sides, cov, st)
    degenerate = np.array([bool(x) for x in reasons], dtype=bool)
    return HullFitBatch(pose, cov, n_in, side_points, n_sides, rms, chi2_dof, iterations, degenerate, tuple(reasons))


def _degeneracy_reasons(n_in: np.ndarray, n_sides: np.ndarray, cov: np.ndarray, st: IcpSettings) -> list[str]:
    """Why each of K fits cannot be trusted (empty when it can), from its inliers (K,), sides seen (K,) and
    covariance (K, 3, 3)."""
    std_xy = np.sqrt(np.linalg.eigvalsh(cov[:, :2, :2])[:, -1])
    std_th = np.sqrt(cov[:, 2, 2])
    reasons = []
    bad = (n_in < st.min_points) | (n_sides < 2) | (std_xy > st.max_std_m) | (std_th > st.max_std_rad)
    for k in range(len(n_in)):
        if not bad[k]:
            reasons.append("")
        elif n_in[k] < st.min_points:
            reasons.append(f"few points ({n_in[k]})")
        elif n_sides[k] < 2:
            reasons.append("one side seen")
        elif std_xy[k] > st.max_std_m:
            reasons.append(f"weak geometry (position std {1000 * std_xy[k]:.0f} mm)")
        elif std_th[k] > st.max_std_rad:
            reasons.append(f"weak geometry (yaw std {np.degrees(std_th[k]):.2f} deg)")
        else:
            reasons.append("")
    return reasons


def _fit_normal_equations(
    model: HullModel, pts: BeamPoints, xytheta: np.ndarray, st: IcpSettings
) -> tuple[_Linearisation, np.ndarray]:
    """The fit of ``pts`` linearised at ``xytheta`` (K, 3) and its (K, 3, 3) normal matrix with the prior, as
    the sensitivities need them."""
    pose = np.asarray(xytheta, dtype=float).reshape(-1, 3)
    lin = _linearise(model, pts, pts.range_variance_m2(), pose, st.gate_m, st)
    H = _normal_matrix(pts.frame_index, lin.w, lin.J, pose.shape[0])
    H[:, [0, 1, 2], [0, 1, 2]] += [1 / st.prior_std_m**2, 1 / st.prior_std_m**2, 1 / st.prior_std_rad**2]
    return lin, H


def scanner_sensitivity(
    model: HullModel,
    pts: BeamPoints,
    xytheta: np.ndarray,
    settings: IcpSettings = IcpSettings(),
) -> np.ndarray:
    """How the fitted robot poses move with the scanners' calibrated poses, to first order.

    A scanner ``s`` moved by ``dc_s = (dx, dy, dphi)`` (world frame, about its own origin ``t_s``) moves
    each of its points by ``(dx, dy) + dphi * J90 (p - t_s)``; the least-squares pose then moves by
    ``-H^-1 sum_i w_i J_i^T (dr_i / dc_s)``, with the assignments and weights of the fit at ``xytheta``.
    The scanners' calibration errors are common to all frames, so this propagates the calibration
    covariance into each pose (:func:`gtrig.laser.track.track_frames`): ``A Sigma_cal A^T``.

    Parameters
    ----------
    model, pts
        As in :func:`fit_hull_batch`; M points of K frames, S scanners.
    xytheta
        (K, 3) the fitted poses (x, y m; theta rad).
    settings
        The fit's settings (gate, weights).

    Returns
    -------
    (K, 3, 3 S) ``d xytheta_k / d (x_s, y_s, theta_s)``, scanner blocks in scanner order; zero for
    frames without points.
    """
    lin, H = _fit_normal_equations(model, pts, xytheta, settings)
    B = _scanner_pulls(pts, lin, H.shape[0], lin.J)
    return -np.linalg.solve(H, B)


def _scanner_pulls(pts: BeamPoints, lin: _Linearisation, K: int, rows: Sequence[np.ndarray]) -> np.ndarray:
    """(K, R, 3 S) ``sum_i w_i rows[a]_i (dr_i / dc_s)`` per frame: the derivative of the right-hand sides
    whose per-point factors are ``rows`` (R arrays (M,)) by the scanners' planar poses ``c_s`` (moved
    about their own origins ``pts.scanner_xy_world[s]``)."""
    p, fid, sid, S = pts.xy_world, pts.frame_index, pts.scanner_index, pts.scanner_xy_world
    n_s = S.shape[0]
    lever = p - S[sid]
    Jc = (lin.nw[:, 0], lin.nw[:, 1], lin.nw[:, 1] * lever[:, 0] - lin.nw[:, 0] * lever[:, 1])
    cell = fid * n_s + sid
    B = np.zeros((K, len(rows), n_s, 3))
    for i, row in enumerate(rows):
        wi = lin.w * row
        for j in range(3):
            B[:, i, :, j] = np.bincount(cell, wi * Jc[j], minlength=K * n_s).reshape(K, n_s)
    return B.reshape(K, len(rows), 3 * n_s)


def _side_bias_cross(fid: np.ndarray, d: np.ndarray, lin: _Linearisation, K: int
                     ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Each point's side-bias factor ``c = -(n . u)`` (M,), its frame-and-side cell ``fid * 4 + side`` (M,)
    and the pose-bias block ``H_pb`` (K, 3, 4) ``sum w J c`` per frame and side
    (:func:`side_bias_normal_equations`)."""
    c = -(lin.nw[:, 0] * d[:, 0] + lin.nw[:, 1] * d[:, 1])
    cell = fid * 4 + lin.side
    H_pb = np.zeros((K, 3, 4))
    for i in range(3):
        H_pb[:, i, :] = np.bincount(cell, lin.w * lin.J[i] * c, minlength=K * 4).reshape(K, 4)
    return c, cell, H_pb


def side_bias_normal_equations(
    model: HullModel,
    pts: BeamPoints,
    xytheta: np.ndarray,
    settings: IcpSettings,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The fits' normal equations extended by a range bias of each hull side, linearised at ``xytheta``.

    A dark fabric returns weaker pulses that a scanner ranges long, a light one short (a few
    millimetres between black and white, centimetres on glossy or very dark cloth): a point seen on
    side ``k`` lies ``beta_k`` farther along its beam ``u`` than the fabric. Correcting it by
    ``-beta_k u`` changes its residual by ``c = -(n . u) beta_k``, so each frame's least squares in
    ``(pose, beta)`` has the blocks below (weights, gates and side assignments of the fit at ``xytheta``).

    Parameters
    ----------
    As :func:`scanner_sensitivity`.

    Returns
    -------
    H_pp : (K, 3, 3) ``sum w J J^T`` with the fit's weak prior.
    H_pb : (K, 3, 4) ``sum w J c`` per side.
    H_bb : (K, 4) ``sum w c^2`` per side (the block is diagonal: a point lies on one side).
    g_p : (K, 3) ``sum w J r``.
    g_b : (K, 4) ``sum w c r`` per side.
    Residuals in metres, pose in (m, m, rad), biases in metres.
    """
    lin, H = _fit_normal_equations(model, pts, xytheta, settings)
    K = H.shape[0]
    fid = pts.frame_index
    c, cell, H_pb = _side_bias_cross(fid, pts.dir_world, lin, K)
    H_bb = np.bincount(cell, lin.w * c * c, minlength=K * 4).reshape(K, 4)
    g_p = np.column_stack([np.bincount(fid, lin.w * lin.J[i] * lin.r, minlength=K) for i in range(3)])
    g_b = np.bincount(cell, lin.w * c * lin.r, minlength=K * 4).reshape(K, 4)
    return H, H_pb, H_bb, g_p.astype(float), g_b


def side_bias_scanner_pull(
    model: HullModel,
    pts: BeamPoints,
    xytheta: np.ndarray,
    settings: IcpSettings,
) -> np.ndarray:
    """How each frame's reduced side-bias equations (:func:`gtrig.laser.side_bias.reduced_normal_equations`)
    move with the scanners' calibrated poses, to first order.

    A scanner error ``dc`` moves the frame's right-hand sides by ``B_p dc`` (pose rows) and ``B_b dc``
    (side rows, the residuals' factor ``c = -(n . u)`` of :func:`side_bias_normal_equations`); with the
    pose eliminated, ``u`` moves by ``(B_b - H_pb^T H_pp^-1 B_p) dc``. Summed over a sequence, this is how
    much of a calibration error the sides' range bias estimate takes up (an error that moves the points
    along their beams on one side looks like that side's bias).

    Parameters
    ----------
    As :func:`scanner_sensitivity`.

    Returns
    -------
    (K, 4, 3 S) ``d u_k / d (x_s, y_s, theta_s)`` (m / m, m / rad), sides in the hull's order.
    """
    lin, H = _fit_normal_equations(model, pts, xytheta, settings)
    K = H.shape[0]
    c, _, H_pb = _side_bias_cross(pts.frame_index, pts.dir_world, lin, K)
    B_p = _scanner_pulls(pts, lin, K, lin.J)
    B_b = _scanner_pulls(pts, lin, K, [np.where(lin.side == k, c, 0.0) for k in range(4)])
    return B_b - np.einsum("kia,kij->kaj", H_pb, np.linalg.solve(H, B_p))


def assigned_sides(model: HullModel, pts: BeamPoints, xytheta: np.ndarray, settings: IcpSettings) -> np.ndarray:
    """(M,) the hull side each point is assigned to by the fit at ``xytheta`` (arguments as
    :func:`scanner_sensitivity`): the nearest side facing its scanner."""
    lin, _ = _fit_normal_equations(model, pts, xytheta, settings)
    return lin.side


def side_bias_sensitivity(
    model: HullModel,
    pts: BeamPoints,
    xytheta: np.ndarray,
    settings: IcpSettings,
) -> np.ndarray:
    """How the fitted robot poses move with a range bias of each hull side, to first order.

    Every point on side ``k`` seen ``b_k`` too far along its beam ``u`` moves its residual by
    ``b_k (n . u)``, and the least-squares pose by ``-H^-1 sum_i w_i J_i^T (n_i . u_i)`` over that
    side's points (:func:`side_bias_normal_equations`: ``H^-1 H_pb``). The bias stays with the side
    while the robot moves, so smoothing cannot average it out; :func:`gtrig.laser.track.track_frames`
    estimates it over the sequence (:mod:`gtrig.laser.side_bias`) and adds what is left of its
    uncertainty as ``A C A^T`` after smoothing.

    Parameters
    ----------
    As :func:`scanner_sensitivity`.

    Returns
    -------
    (K, 3, 4) ``d xytheta_k / d b_side`` (m/m, rad/m), sides in the hull's order; zero for frames
    without points.
    """
    H, H_pb, _, _, _ = side_bias_normal_equations(model, pts, xytheta, settings)
    return np.linalg.solve(H, H_pb)


def fit_hull(
    model: HullModel,
    xy_world: np.ndarray,
    scanner_index: np.ndarray,
    scanner_xy_world: np.ndarray,
    dir_world: np.ndarray,
    sigma_range_m: np.ndarray,
    init_xytheta: np.ndarray,
    settings: IcpSettings = IcpSettings(),
    wide_gate_m: float | None = None,
) -> HullFit:
    """Fit the hull to the points of one frame by point-to-line ICP from ``init_xytheta``.

    Parameters are those of :func:`fit_hull_batch` for a single frame, its points given as the
    attributes of :class:`BeamPoints`: ``xy_world`` (M, 2), ``scanner_index`` (M,), ``scanner_xy_world``
    (S, 2), ``dir_world`` (M, 2), ``sigma_range_m`` (S,); ``init_xytheta`` (3,).
    """
    pts = BeamPoints.one_frame(xy_world, scanner_index, scanner_xy_world, dir_world, sigma_range_m)
    return fit_hull_batch(model, pts, np.asarray(init_xytheta, dtype=float)[None], settings, wide_gate_m).item(0)
