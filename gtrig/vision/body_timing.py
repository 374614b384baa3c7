"""Each camera's time offset, and a rolling shutter's line delay, from a tracked body's motion.

A camera whose image of an instant was exposed ``tau`` seconds after the instant's stamp sees the body moved
by its velocity times ``tau``: each point's pixels move by ``g tau``, ``g`` the point's image velocity
(the pose Jacobian times the body's world-frame twist). The exposure time of a point in camera ``c``'s
image is modelled as

    tau = (t_image - t_instant) + delta_c + kappa_c (t_image - t_mid) + rho_c (row - h / 2)

with ``t_image`` the image's stamp (the frame-time file's), ``delta_c`` the camera's unknown offset from its
stamps at ``t_mid`` (relative to a reference camera, whose offset is 0: only differences are observable),
``kappa_c`` its drift (seconds per second, optional: a camera whose exposures slide against the host's
frame stamps, by a clock skew or a changing stamping latency) and ``rho_c`` its line delay (seconds per
image row; 0 for a global shutter). ``t_mid`` is the midpoint of the tracked instants' stamps, where the
offsets and their drifts are least correlated. At each instant seen by two cameras or more the pose is a
nuisance: its six parameters are projected out of that instant's residuals, and ``delta``, ``kappa``,
``rho`` solved by least squares over all instants. The body's motion about an instant is the polynomial
through its pose and up to three neighbours' on each side (:func:`local_motion`; one on each side at
least, so instants at the ends of the track or after a gap are left out); each point is moved along it to
its exposure time (Gauss-Newton on the timing). The tracked poses blend cameras exposed tens of
milliseconds apart: they are refitted at their instants' stamps with the estimated timing, and the
polynomials and timing solved again.

The interval is the larger of two covariances: the residuals' variance factor times the inverse normal
matrix (residuals independent), and a sandwich whose middle is the per-instant scores' autocovariance over
neighbouring instants (Newey-West, Bartlett weights), debiased for the fit's zeroing of the scores' sum
and widened to Student's quantile at its degrees of freedom, both computed from the instants' columns and
residuals (:mod:`gtrig.vision.body_timing_interval`: a few fast instants carry most of a drift, and a few
dozen instants estimate that middle). What the timing model leaves out acts instant by
instant and not point by point: a velocity error moves every point of an instant together, a webcam whose
exposure wanders from its frame times by a few milliseconds from frame to frame shifts all of that
image's points along their motion, and neighbouring instants share poses and the hand's motion. The
sandwich sees these through the residuals' correlation; the variance factor does not.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace

import numpy as np
from scipy.spatial.transform import Rotation

from gtrig.vision.body import BodyOptions, BodyPose, PointBody, stack_body
from gtrig.vision.body_timing_interval import quantile_factor, sandwich_covariance
from gtrig.vision.body_track import BodyInstant
from gtrig.vision.observations import CameraGeometry
from gtrig.vision.projection import project_pose


@dataclass(frozen=True)
class CameraTiming:
    """The cameras' exposure timing.

    Attributes
    ----------
    reference : the camera whose offset is 0.
    cameras : the cameras, in the order of ``offset_s``, ``drift_s_per_s`` and ``line_delay_s``.
    offset_s, sigma_offset_s : (C,) each camera's offset from its stamps minus the reference's, seconds, at
        ``mid_s``.
    drift_s_per_s, sigma_drift_s_per_s : (C,) the offsets' rate of change, seconds per second (1e-6 is one
        ppm; nan when not estimated).
    line_delay_s, sigma_line_delay_s : (C,) seconds per image row (nan when not estimated).
    mid_s : the time (frame-time clock, seconds) the offsets refer to; span_s : (first, last) stamp of the
        instants used.
    rms_px : {"stamps": residual RMS with the image stamps only, "model": with the fitted timing}
        over the instants used, after the poses were refitted.
    instants, points : instants and points used; variance_factor : the residuals' chi-square per dof.
    sigma_offset_model_s : (C,) the offsets' sigmas from the variance factor alone (residuals taken as
        independent); ``sigma_offset_s`` is the larger of these and the autocorrelation-robust sigmas.
    """

    reference: str
    cameras: tuple[str, ...]
    offset_s: np.ndarray
    sigma_offset_s: np.ndarray
    line_delay_s: np.ndarray
    sigma_line_delay_s: np.ndarray
    rms_px: dict[str, float]
    instants: int
    points: int
    variance_factor: float
    sigma_offset_model_s: np.ndarray
    drift_s_per_s: np.ndarray
    sigma_drift_s_per_s: np.ndarray
    mid_s: float
    span_s: tuple[float, float]


@dataclass(frozen=True)
class _Layout:
    """Where the timing parameters sit in ``theta``: ``n_cams`` offsets, then ``n_cams`` drifts if
    ``drift``, then ``n_cams`` line delays if ``line_delay``."""

    n_cams: int
    drift: bool
    line_delay: bool

    @property
    def n_par(self) -> int:
        return self.n_cams * (1 + int(self.drift) + int(self.line_delay))

    def block(self, which: str) -> slice | None:
        """The slice of ``theta`` of ``offset``, ``drift`` or ``line_delay`` (None when not estimated)."""
        order = ["offset"] + ["drift"] * self.drift + ["line_delay"] * self.line_delay
        if which not in order:
            return None
        k = order.index(which)
        return slice(k * self.n_cams, (k + 1) * self.n_cams)


@dataclass(frozen=True)
class LocalMotion:
    """The body's motion near one instant: the polynomial in time through its pose and its neighbours'.

    Attributes
    ----------
    scale_s : the time unit of the polynomial, seconds.
    coeffs : (n, 6) coefficients of ``(s / scale_s) ** m``, ``m = 0 .. n - 1``, of the world-frame
        displacement ``(dp, dphi)`` (m, rad: position change and rotation vector of ``R(t) R(t0)^T``) at
        ``s`` seconds after the instant's stamp ``t0``.
    """

    scale_s: float
    coeffs: np.ndarray

    def displacement(self, tau_s: np.ndarray) -> np.ndarray:
        """(N, 6) displacement ``(dp, dphi)`` at ``tau_s`` (N,) seconds after the instant."""
        x = np.asarray(tau_s, float) / self.scale_s
        return np.vander(x, len(self.coeffs), increasing=True) @ self.coeffs - self.coeffs[0]

    def twist(self, tau_s: np.ndarray) -> np.ndarray:
        """(N, 6) world-frame twist ``(v, omega)`` (m/s, rad/s) at ``tau_s`` (N,) seconds after the instant."""
        x = np.asarray(tau_s, float) / self.scale_s
        m = np.arange(1, len(self.coeffs))
        return (m * x[:, None] ** (m - 1)) @ self.coeffs[1:] / self.scale_s


def local_motion(poses: Sequence[BodyPose], i: int, max_gap_s: float, reach: int = 3) -> LocalMotion | None:
    """The polynomial (:class:`LocalMotion`) through the pose of instant ``i`` and up to ``reach`` tracked
    neighbours on each side (consecutive, each within ``max_gap_s`` of the next), or None without one on
    each side.

    A hand-moved board at a few frames per second turns within the span of a central difference, which then
    underestimates the speed (by 6 % for a 0.6 Hz sway at 6 frames/s) and overestimates every offset by as
    much. The polynomial through ``2 reach + 1`` equally spaced poses errs in the speed by about
    ``(omega h) ** (2 reach) / c`` (``h`` the frame interval; ``c`` = 30 for five poses, 140 for seven): for
    a 1 Hz sway at 6 frames/s, 4 % with five poses and 0.9 % with seven, whose curvature also carries the
    acceleration over offsets of tens of milliseconds. Noise-free simulated sways of up to 1 Hz
    (``bench/body_timing.py``'s motion, 4 seeds) left offset errors of 0.19 ms RMS with five poses and
    0.06 ms with seven, where the pixel noise gives sigmas of 0.15-0.25 ms; the speed's noise grows by 14 %
    from five poses to seven.
    """
    def ok(k: int) -> bool:
        return 0 <= k < len(poses) and poses[k].ok and poses[k].T_world_body is not None

    if not ok(i):
        return None
    ks = [i]
    for side in (-1, 1):
        k = i
        while abs(k - i) < reach and ok(k + side) and abs(poses[k + side].stamp_s - poses[k].stamp_s) <= max_gap_s:
            k += side
            ks.append(k)
    ks.sort()
    if ks[0] == i or ks[-1] == i or len({poses[k].stamp_s for k in ks}) < len(ks):
        return None
    T = {k: poses[k].T_world_body for k in ks}
    T_i = T[i]
    assert T_i is not None
    t_s = np.array([poses[k].stamp_s for k in ks]) - poses[i].stamp_s
    scale = float(np.max(np.abs(t_s)))
    d = np.array([np.r_[Tk[:3, 3] - T_i[:3, 3], Rotation.from_matrix(Tk[:3, :3] @ T_i[:3, :3].T).as_rotvec()]
                  for Tk in (T[k] for k in ks) if Tk is not None])
    return LocalMotion(scale, np.linalg.solve(np.vander(t_s / scale, len(ks), increasing=True), d))


@dataclass(frozen=True)
class _InstantRows:
    """One instant's points for the timing fit: predicted and observed pixels (N, 2), the pose Jacobian
    (N, 2, 6), each point's camera (N,) (index into the names), image stamp minus the instant's (N,) s,
    image stamp minus the timing's ``mid_s`` (N,) s, row from the image centre (N,), the projector
    (2N, 2N) that removes the pose, the whitened pose Jacobian's pseudo-inverse (6, 2N), and the local
    motion."""

    uv_pred: np.ndarray
    uv_obs: np.ndarray
    J: np.ndarray
    cam: np.ndarray
    dt_img_s: np.ndarray
    t_from_mid_s: np.ndarray
    row: np.ndarray
    Q: np.ndarray
    A_pinv: np.ndarray
    motion: LocalMotion


def _instant_rows(cameras: Mapping[str, CameraGeometry], body: PointBody, inst: BodyInstant, pose: BodyPose,
                  motion: LocalMotion, names: list[str], sigma_px: float, all_views: bool,
                  mid_s: float) -> _InstantRows:
    assert pose.T_world_body is not None
    views = [v for v in inst.views if (all_views or v.camera in pose.cameras) and v.camera in names]
    sc = stack_body(cameras, body, views, sigma_px)
    uv, _z, J = project_pose(sc, pose.T_world_body)
    assert J is not None
    A = J.reshape(-1, 6) / sigma_px
    A_pinv = np.linalg.pinv(A)
    dt_img = np.repeat([v.stamp_s - inst.stamp_s for v in views], [len(v.ids) for v in views])
    return _InstantRows(uv, sc.uv, J, np.array([names.index(sc.camera_names[k]) for k in sc.cam]), dt_img,
                        dt_img + (inst.stamp_s - mid_s),
                        sc.uv[:, 1] - np.array([cameras[sc.camera_names[k]].size[1] / 2 for k in sc.cam]),
                        np.eye(len(A)) - A @ A_pinv, A_pinv, motion)


def _exposure_s(rows: _InstantRows, theta: np.ndarray, lay: _Layout) -> np.ndarray:
    """Each point's exposure time (N,) after the instant's stamp, seconds, with the timing ``theta``."""
    tau = rows.dt_img_s + theta[rows.cam]
    drift, line = lay.block("drift"), lay.block("line_delay")
    if drift is not None:
        tau = tau + theta[drift][rows.cam] * rows.t_from_mid_s
    if line is not None:
        tau = tau + theta[line][rows.cam] * rows.row
    return tau


def _moved_residuals(rows: _InstantRows, theta: np.ndarray, lay: _Layout, sigma_px: float) -> np.ndarray:
    """Whitened residuals (2N,) with the body moved to each point's exposure time (pose not projected out)."""
    move = np.einsum("nij,nj->ni", rows.J, rows.motion.displacement(_exposure_s(rows, theta, lay)))
    return (rows.uv_pred - rows.uv_obs + move).reshape(-1) / sigma_px


def _instant_system(rows: _InstantRows, theta: np.ndarray, lay: _Layout, sigma_px: float
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Whitened ``(Q r, Q B, Q r_none)`` of one instant (pose projected out), linearised at the timing
    ``theta`` (:class:`_Layout`): the residuals with the body moved to each point's exposure time, the
    timing parameters' columns, the residuals without any timing."""
    tau = _exposure_s(rows, theta, lay)
    g = np.einsum("nij,nj->ni", rows.J, rows.motion.twist(tau))  # pixels per second
    B = np.zeros((len(tau), 2, len(theta)))
    per_point = {"offset": np.ones(len(tau)), "drift": rows.t_from_mid_s, "line_delay": rows.row}
    for which, factor in per_point.items():
        blk = lay.block(which)
        if blk is None:
            continue
        for k in range(lay.n_cams):
            m = rows.cam == k
            B[m, :, blk.start + k] = g[m] * factor[m, None]
    r = _moved_residuals(rows, theta, lay, sigma_px)
    return (rows.Q @ r, rows.Q @ (B.reshape(-1, len(theta)) / sigma_px),
            rows.Q @ ((rows.uv_pred - rows.uv_obs).reshape(-1) / sigma_px))


def _fit_timing(rows: Sequence[_InstantRows], free: list[int], theta0: np.ndarray, lay: _Layout, sigma_px: float,
                iterations: int) -> tuple[np.ndarray, list[tuple[np.ndarray, np.ndarray, np.ndarray]]]:
    """Gauss-Newton on the timing parameters ``free`` from ``theta0`` (the others held): the motion is a
    polynomial in each point's exposure time. Returns the parameters and each instant's system at them."""
    theta = theta0.copy()
    parts = [_instant_system(r, theta, lay, sigma_px) for r in rows]
    for _ in range(iterations):
        N = sum(qB.T @ qB for _, qB, _ in parts)
        b = sum(qB.T @ qr for qr, qB, _ in parts)
        theta[free] -= np.linalg.solve(N[np.ix_(free, free)], b[free])
        parts = [_instant_system(r, theta, lay, sigma_px) for r in rows]
    return theta, parts


@dataclass(frozen=True)
class _Selection:
    """Which instants enter the timing fit: the camera names, ``mid_s``, the span of stamps (inclusive;
    the local motions may reach beyond it), the largest gap between neighbours, and whether the views the
    pose fit rejected count."""

    names: list[str]
    mid_s: float
    span_s: tuple[float, float]
    max_gap_s: float
    all_views: bool
    reach: int


def _timing_rows(cameras: Mapping[str, CameraGeometry], body: PointBody, instants: Sequence[BodyInstant],
                 poses: Sequence[BodyPose], sel: _Selection, sigma_px: float) -> tuple[list[_InstantRows], list[int]]:
    """The rows of every instant in the span with a local motion and two cameras or more, and their indices."""
    rows, used = [], []
    for i, (inst, pose) in enumerate(zip(instants, poses, strict=True)):
        if not sel.span_s[0] <= inst.stamp_s <= sel.span_s[1]:
            continue
        motion = local_motion(poses, i, sel.max_gap_s, sel.reach)
        if motion is None or not pose.ok or len(pose.cameras) + (len(pose.rejected) if sel.all_views else 0) < 2:
            continue
        rows.append(_instant_rows(cameras, body, inst, pose, motion, sel.names, sigma_px, sel.all_views, sel.mid_s))
        used.append(i)
    return rows, used


def _poses_at_stamps(poses: Sequence[BodyPose], rows: Sequence[_InstantRows], used: Sequence[int],
                     theta: np.ndarray, lay: _Layout, sigma_px: float) -> list[BodyPose]:
    """The poses refitted at their instants' stamps with each point moved to its exposure time: the tracked
    poses blend cameras exposed tens of milliseconds apart, and the local motions run through them."""
    out = list(poses)
    for r, i in zip(rows, used, strict=True):
        T = poses[i].T_world_body
        assert T is not None
        xi = -r.A_pinv @ _moved_residuals(r, theta, lay, sigma_px)  # world-frame (dt, dphi)
        T_new = T.copy()
        T_new[:3, :3] = Rotation.from_rotvec(xi[3:]).as_matrix() @ T[:3, :3]
        T_new[:3, 3] = T[:3, 3] + xi[:3]
        out[i] = replace(poses[i], T_world_body=T_new)
    return out


def _determined(N: np.ndarray, candidates: list[int], tol: float = 1e-9) -> list[int]:
    """The parameters among ``candidates`` (in order) that the normal matrix ``N`` determines: each kept
    while the kept ones' correlation matrix stays well conditioned (smallest eigenvalue above ``tol``). A
    camera seen at one instant only of the span fitted has its drift's column proportional to its offset's;
    one never seen has none."""
    kept: list[int] = []
    for k in candidates:
        if N[k, k] <= 0:
            continue
        trial = [*kept, k]
        d = np.sqrt(np.diag(N)[trial])
        if np.linalg.eigvalsh(N[np.ix_(trial, trial)] / np.outer(d, d))[0] > tol:
            kept = trial
    return kept


def tracked_mid_s(poses: Sequence[BodyPose]) -> float:
    """The midpoint of the tracked poses' stamps (frame-time clock, seconds): where a timing refers its
    offsets by default."""
    t = [p.stamp_s for p in poses if p.ok]
    return 0.5 * (min(t) + max(t)) if t else math.nan


def _covariances(parts: list[tuple[np.ndarray, np.ndarray, np.ndarray]], used: list[int], free: list[int],
                 n_par: int, dof: int, lags: int) -> tuple[np.ndarray, np.ndarray, float]:
    """The variance factor's and the autocorrelation-robust covariances (n_par, n_par) of ``theta`` (nan
    outside ``free``), and the variance factor. The robust one is widened by Student's quantile at each
    parameter's degrees of freedom over the normal's (:mod:`gtrig.vision.body_timing_interval`), so that
    1.96 of its sigmas is a 95 % interval."""
    cov_model = np.full((n_par, n_par), np.nan)
    cov_hac = cov_model.copy()
    vf = sum(float(np.sum(qr**2)) for qr, _, _ in parts) / dof if dof > 0 else math.nan
    N_inv = np.linalg.inv(sum(qB.T @ qB for _, qB, _ in parts)[np.ix_(free, free)])
    cov_model[np.ix_(free, free)] = max(vf, 1.0) * N_inv
    cov, dof_t = sandwich_covariance([qB[:, free] for _, qB, _ in parts], [qr for qr, _, _ in parts],
                                     np.array(used), lags)
    widen = quantile_factor(dof_t)
    cov_hac[np.ix_(free, free)] = cov * np.outer(widen, widen)
    return cov_model, cov_hac, vf


def estimate_timing(cameras: Mapping[str, CameraGeometry], body: PointBody, instants: Sequence[BodyInstant],
                    poses: Sequence[BodyPose], reference: str | None = None, *, line_delay: bool = True,
                    drift: bool = False, mid_s: float | None = None, span_s: tuple[float, float] | None = None,
                    max_gap_s: float = 0.5, options: BodyOptions | None = None,
                    all_views: bool = True, reach: int = 3, lags: int | None = None, iterations: int = 3,
                    refits: int = 3) -> CameraTiming:
    """The cameras' offsets (and drifts, line delays) from the body's motion over ``instants`` (module
    docstring).

    ``drift``: each camera's offset changes linearly with time, about ``mid_s`` (default
    :func:`tracked_mid_s`). ``span_s``: only the instants stamped within it (inclusive) enter the fit;
    their local motions still run through the poses beyond it. ``all_views``: the views the pose fit
    dropped as outliers count too (a camera whose offset is large is dropped at every instant where the
    body moves; the pose is refitted here with its offset). ``reach``: the local motions run through up to
    this many neighbours on each side (:func:`local_motion`). ``lags``: instants this many apart or fewer may
    share a motion-model error (they share poses, and the hand's motion between them); the interval allows
    for it; default ``2 reach``, the farthest apart two instants whose local motions share a pose.
    ``iterations``: Gauss-Newton steps on the timing per refit of the poses at their stamps; ``refits``: how
    many times.

    Raises
    ------
    ValueError
        ``reference`` is not among the tracked cameras.
    """
    options = options or BodyOptions()
    sigma = options.sigma_px
    names = sorted({c for p in poses if p.ok for c in (*p.cameras, *(p.rejected if all_views else ()))})
    ref = reference or (names[0] if names else "")
    if ref not in names:
        raise ValueError(f"reference camera {ref!r} is in no tracked instant (cameras: {', '.join(names)})")
    C = len(names)
    lay = _Layout(C, drift, line_delay)
    mid = tracked_mid_s(poses) if mid_s is None else float(mid_s)
    sel = _Selection(names, mid, span_s or (-math.inf, math.inf), max_gap_s, all_views, reach)
    lags = 2 * reach if lags is None else lags
    rows, used = _timing_rows(cameras, body, instants, poses, sel, sigma)
    stamps_only = [_instant_system(r, np.zeros(lay.n_par), lay, sigma) for r in rows]
    N0 = sum((qB.T @ qB for _, qB, _ in stamps_only), np.zeros((lay.n_par, lay.n_par)))
    # only differences between cameras are observable: the reference's offset and drift are held at 0
    held = {blk.start + names.index(ref) for blk in (lay.block("offset"), lay.block("drift")) if blk is not None}
    free = _determined(N0, [k for k in range(lay.n_par) if k not in held])
    theta, parts = np.zeros(lay.n_par), stamps_only
    cov_model = cov_hac = np.full((lay.n_par, lay.n_par), np.nan)
    n_rows = sum(len(q) for q, _, _ in parts)
    dof = n_rows - 6 * len(parts) - len(free)
    vf = math.nan
    if parts and free:
        theta, parts = _fit_timing(rows, free, theta, lay, sigma, iterations)
        poses_now = list(poses)
        for _ in range(refits):
            poses_now = _poses_at_stamps(poses_now, rows, used, theta, lay, sigma)
            rows, used = _timing_rows(cameras, body, instants, poses_now, sel, sigma)
            theta, parts = _fit_timing(rows, free, theta, lay, sigma, iterations)
        cov_model, cov_hac, vf = _covariances(parts, used, free, lay.n_par, dof, lags)
    return _timing_result(ref, names, lay, theta, cov_model, cov_hac, stamps_only, parts, vf, mid,
                          [instants[i].stamp_s for i in used], sigma)


def _timing_result(ref: str, names: list[str], lay: _Layout, theta: np.ndarray, cov_model: np.ndarray,
                   cov_hac: np.ndarray, stamps_only: list[tuple[np.ndarray, np.ndarray, np.ndarray]],
                   parts: list[tuple[np.ndarray, np.ndarray, np.ndarray]], vf: float, mid_s: float,
                   stamps_used: list[float], sigma_px: float) -> CameraTiming:
    """The :class:`CameraTiming` of a fit: sigmas the larger of the variance factor's and the sandwich's,
    0 for the reference's held parameters."""
    sig_model = np.sqrt(np.clip(np.diag(cov_model), 0, None))
    sig = np.fmax(sig_model, np.sqrt(np.clip(np.diag(cov_hac), 0, None)))
    C = lay.n_cams
    nan = np.full(C, np.nan)

    def block(which: str, values: np.ndarray) -> np.ndarray:
        blk = lay.block(which)
        return values[blk] if blk is not None else nan

    for which in ("offset", "drift"):
        blk = lay.block(which)
        if blk is not None:
            sig[blk.start + names.index(ref)] = sig_model[blk.start + names.index(ref)] = 0.0
            theta[blk.start + names.index(ref)] = 0.0

    def rms(res: list[np.ndarray]) -> float:
        return float(np.sqrt(2 * np.mean(np.concatenate(res) ** 2)) * sigma_px) if res else math.nan

    rms_px = {"none": rms([q0 for _, _, q0 in stamps_only]), "stamps": rms([qs for qs, _, _ in stamps_only]),
              "model": rms([qr for qr, _, _ in parts])}
    n_points = sum(len(q) for q, _, _ in parts) // 2
    span = (min(stamps_used), max(stamps_used)) if stamps_used else (math.nan, math.nan)
    return CameraTiming(ref, tuple(names), block("offset", theta), block("offset", sig), block("line_delay", theta),
                        block("line_delay", sig), rms_px, len(parts), n_points, vf, block("offset", sig_model),
                        block("drift", theta), block("drift", sig), mid_s, span)
