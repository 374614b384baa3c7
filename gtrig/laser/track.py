"""GTlaser tracking: background subtraction, fusion, hull ICP, (re)acquisition, smoothing.

The loop (journal paper, section 6, with the additions):

1. Foreground returns of every scan (:mod:`gtrig.laser.foreground`), all scanners fused into world
   points grouped by frame (:mod:`gtrig.laser.fuse`), in one vectorised pass.
2. While tracking, a constant-velocity Kalman filter predicts each frame; frames are fitted together
   (up to ``chunk_frames``) only as far ahead as the prediction's uncertainty stays within the ICP's
   reach, points are compensated for the motion within the frame (the scanners are not synchronised,
   each beam has its firing time), gated near the predicted outline, and the hull is fitted by
   point-to-line ICP (:func:`gtrig.laser.hull_icp.fit_hull_batch`, all frames of a chunk at once). A
   fit is accepted by its Mahalanobis distance from the prediction (a fixed 6 cm gate and a
   zero velocity after each acquisition lost robots faster than about 0.5 m/s).
3. A frame whose fit is degenerate is flagged (``DEGENERATE``); after ``lost_after`` failing frames in a
   row, or a gap in time, the track is lost and the global search (:mod:`gtrig.laser.acquire`) runs on
   each frame until the hull is found again.
4. The rectangle looks the same turned by pi: a new track takes the heading nearest the previous track's
   if that is recent, else the direction of motion decides once the robot has moved (``forward_motion``);
   a track that never moves and has no recent predecessor stays ``AMBIGUOUS``.
5. Each track is smoothed by a Rauch-Tung-Striebel smoother (constant acceleration by default), using
   each frame's ICP covariance as its measurement noise (degenerate frames only constrain the
   directions their points fix) and a process noise chosen near each frame by maximum likelihood
   (:mod:`gtrig.laser.process_noise`). The smoothed covariance is reported per pose, with what
   smoothing cannot average added: a floor, the fabric's range bias, the scanners' clock offsets and
   their calibration.
"""

from __future__ import annotations

import logging
import tempfile
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from gtrig.geometry import wrap_angle
from gtrig.laser.acquire import acquire
from gtrig.laser.fuse import FramedPoints, FrameSource
from gtrig.laser.hull_icp import (
    BeamPoints,
    HullFitBatch,
    HullModel,
    IcpSettings,
    assigned_sides,
    fit_hull_batch,
    scanner_sensitivity,
    side_bias_normal_equations,
    side_bias_scanner_pull,
    side_bias_sensitivity,
)
from gtrig.laser.process_noise import local_ml_process_noise
from gtrig.laser.side_bias import SideBias, estimate_side_bias, reduced_normal_equations, scanner_pull
from gtrig.memory import release_free_memory
from gtrig.smoothing import rts_smooth, rts_smooth_varying  # the core's smoother (re-exported for old callers)
from gtrig.trajectory import PoseStatus, PoseTrack

log = logging.getLogger(__name__)

OK = 0
DEGENERATE = 1
LOST = 2
AMBIGUOUS = 3
STATUS_NAMES = {OK: "ok", DEGENERATE: "degenerate", LOST: "lost", AMBIGUOUS: "ambiguous"}
# multiples of the settings' process noise searched by the maximum-likelihood choice (x 1 to x 100)
_Q_GRID = np.geomspace(1.0, 100.0, 5)


@dataclass(frozen=True)
class TrackSettings:
    """Settings of :func:`track_frames`.

    Attributes
    ----------
    icp : the hull ICP's settings.
    chunk_frames : frames fitted together from one prediction.
    max_gap_s : a longer gap between frames ends the track.
    lost_after : failing frames in a row after which the track is lost.
    max_rms_m : a fit with a larger residual RMS is a failure.
    max_jump_m, max_jump_rad : a fit farther than this from its prediction is a failure whatever the
        predicted uncertainty (a ceiling; the gate proper is ``gate_chi2``).
    predict_accel_std_mps2, predict_ang_accel_std_radps2 : white-acceleration process noise (square root
        of the spectral density) of the constant-velocity filter that predicts each frame while
        tracking: what real robots' accelerating, braking and turning leave unpredicted.
    max_speed_mps, max_turn_rate_radps : prior standard deviation of the velocity of a new track that
        has no recent predecessor: its first frames are fitted one by one until the filter knows it.
    capture_m, capture_rad : frames are fitted together from one prediction only as far ahead as its
        standard deviation stays within a third of these (the ICP's reach from its start pose).
    gate_chi2 : a fit whose Mahalanobis distance (squared) from its prediction, under the predicted
        covariance plus the fit's own, exceeds this is a failure (3 dof; 21.1 is p = 1e-4) ...
    min_jump_m, min_jump_rad : ... unless it is within these of the prediction in position and heading.
    prior_max_gap_s : a previous track at most this old sets the heading of a new one.
    reacquire_gap_s, reacquire_radius_m : a track lost for at most this long is searched for within this
        radius of its last pose, and near its heading.
    forward_motion : the robot drives forwards, so the direction of motion resolves the pi symmetry.
    min_motion_m : displacement needed to use the direction of motion.
    smooth : run the RTS smoother on each track.
    accel_std_mps2, ang_accel_std_radps2 : white-acceleration process noise of the smoother (with
        ``adapt_process_noise``, the least of those searched: up to 100 times these, chosen per track by
        maximum likelihood of its innovations over ``adapt_window_s`` around each frame,
        :mod:`gtrig.laser.process_noise`).
    floor_std_m, floor_std_rad : added in quadrature to the smoothed covariance: errors that smoothing
        cannot average out because they persist over many frames (the laser plane cutting a tilted gown,
        reflectivity bias). The scanners' calibration is propagated separately (``scanner_cov``).
    surface_bias_std_m, side_bias_std_m : range bias of the hull's fabric (its reflectivity: dark
        ranges long, light short), common to all sides and of each side: the prior of its estimate
        (``estimate_side_bias``), and what remains of it is propagated into each pose after smoothing
        (:func:`surface_bias_covariance`); 0 leaves it out.
    estimate_side_bias : estimate each side's range bias over the sequence (:mod:`gtrig.laser.side_bias`)
        and fit the OK frames again with their points corrected by it and de-skewed with the smoothed
        velocity, then smooth again.
    """

    icp: IcpSettings = field(default_factory=IcpSettings)
    chunk_frames: int = 16
    max_gap_s: float = 0.25
    lost_after: int = 8
    max_rms_m: float = 0.03
    max_jump_m: float = 0.30
    max_jump_rad: float = np.radians(20.0)
    predict_accel_std_mps2: float = 1.5
    predict_ang_accel_std_radps2: float = 3.0
    max_speed_mps: float = 2.5
    max_turn_rate_radps: float = 3.0
    capture_m: float = 0.04
    capture_rad: float = np.radians(3.0)
    gate_chi2: float = 21.1
    min_jump_m: float = 0.015
    min_jump_rad: float = np.radians(1.0)
    prior_max_gap_s: float = 2.0
    reacquire_gap_s: float = 0.5
    reacquire_radius_m: float = 1.0
    forward_motion: bool = True
    min_motion_m: float = 0.05
    smooth: bool = True
    adapt_process_noise: bool = True
    adapt_window_s: float = 1.0
    smoother_order: int = 3
    jerk_std_mps3: float = 0.1
    ang_jerk_std_radps3: float = 0.1
    accel_std_mps2: float = 0.07
    ang_accel_std_radps2: float = 0.07
    floor_std_m: float = 0.0005
    surface_bias_std_m: float = 0.0015
    side_bias_std_m: float = 0.001
    estimate_side_bias: bool = True
    floor_std_rad: float = np.radians(0.02)


@dataclass(frozen=True)
class TrackResult:
    """Per-frame GTlaser output.

    Attributes
    ----------
    stamps_s : (F,) frame times, seconds.
    xytheta : (F, 3) robot pose in the world (x, y m; theta rad, wrapped); ``nan`` where ``LOST``.
    cov_xytheta : (F, 3, 3) covariance of ``xytheta``; ``nan`` where ``LOST``.
    status : (F,) ``OK``, ``DEGENERATE``, ``LOST`` or ``AMBIGUOUS``.
    raw_xytheta : (F, 3) the per-frame ICP poses before smoothing.
    raw_cov_xytheta : (F, 3, 3) their covariances.
    n_points : (F,) inliers of the frame's fit.
    n_sides : (F,) hull sides holding enough inliers.
    rms_m : (F,) point-to-line residual RMS.
    track_id : (F,) which continuous track a frame belongs to (-1 where lost).
    reasons : (F,) why a frame is not ``OK`` (empty when it is).
    cov_calibration : (F, 3, 3) the part of ``cov_xytheta`` due to the scanners' calibration (zero when
        no calibration covariance was given).
    side_bias : the hull sides' range bias estimate.
    cov_calibration_shared : (3, 3) the covariance of the calibration error's mean over the ``OK`` poses
        (world x, y m, yaw rad): the share of it that every pose has in common, for fusion's run-constant
        error (:mod:`gtrig.fusion.bias`). The rest of ``cov_calibration`` changes with the pose (which
        scanners see the robot, at what lever), so it is no bias the whole run shares.
    """

    stamps_s: np.ndarray
    xytheta: np.ndarray
    cov_xytheta: np.ndarray
    status: np.ndarray
    raw_xytheta: np.ndarray
    raw_cov_xytheta: np.ndarray
    n_points: np.ndarray
    n_sides: np.ndarray
    rms_m: np.ndarray
    track_id: np.ndarray
    reasons: tuple[str, ...]
    cov_calibration: np.ndarray
    side_bias: SideBias | None = None
    cov_calibration_shared: np.ndarray = field(default_factory=lambda: np.zeros((3, 3)))

    def __len__(self) -> int:
        return int(self.stamps_s.size)

    @property
    def ok(self) -> np.ndarray:
        return self.status == OK

    def counts(self) -> dict[str, int]:
        return {name: int(np.sum(self.status == code)) for code, name in STATUS_NAMES.items()}


def _velocity(stamps: np.ndarray, poses: np.ndarray) -> np.ndarray:
    """Least-squares velocity (3,) of a few poses (n, 3) at ``stamps`` (n,)."""
    if len(stamps) < 2:
        return np.zeros(3)
    t = stamps - stamps.mean()
    den = float(t @ t)
    if den <= 0:
        return np.zeros(3)
    return (t @ (poses - poses.mean(axis=0))) / den


def _cv_transition(dt: float, qd: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Transition (6, 6) and process noise (6, 6) of the constant-velocity model over ``dt`` seconds,
    state (x, y, theta, vx, vy, omega), white acceleration of spectral density ``qd`` (3,)."""
    F = np.eye(6)
    F[[0, 1, 2], [3, 4, 5]] = dt
    Q = np.zeros((6, 6))
    Q[[0, 1, 2], [0, 1, 2]] = qd * dt**3 / 3
    Q[[0, 1, 2], [3, 4, 5]] = Q[[3, 4, 5], [0, 1, 2]] = qd * dt**2 / 2
    Q[[3, 4, 5], [3, 4, 5]] = qd * dt
    return F, Q


@dataclass(frozen=True)
class _Predictor:
    """The tracking filter's state at ``stamp_s``: mean (6,) and covariance (6, 6) of (x, y, theta,
    vx, vy, omega), world frame, theta continuous."""

    stamp_s: float
    x: np.ndarray
    P: np.ndarray

    def predict(self, stamps_s: np.ndarray, qd: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Predicted poses (n, 3) and their covariances (n, 3, 3) at ``stamps_s`` (n,)."""
        tau = np.asarray(stamps_s, dtype=float) - self.stamp_s
        pose = self.x[:3] + tau[:, None] * self.x[3:]
        P = self.P
        cov = (
            P[:3, :3]
            + tau[:, None, None] * (P[:3, 3:] + P[3:, :3])
            + tau[:, None, None] ** 2 * P[3:, 3:]
            + np.einsum("n,ij->nij", np.abs(tau) ** 3 / 3, np.diag(qd))
        )
        return pose, cov

    def update(self, stamp_s: float, z: np.ndarray, R: np.ndarray, qd: np.ndarray) -> _Predictor:
        """The state after predicting to ``stamp_s`` and measuring pose ``z`` (3,) with covariance R."""
        F, Q = _cv_transition(stamp_s - self.stamp_s, qd)
        x = F @ self.x
        P = F @ self.P @ F.T + Q
        K = P[:, :3] @ np.linalg.inv(P[:3, :3] + R)
        x = x + K @ (z - x[:3])
        P = P - K @ P[:3, :]
        return _Predictor(float(stamp_s), x, 0.5 * (P + P.T))


def _start_predictor(
    stamp_s: float, pose: np.ndarray, R: np.ndarray, v0: np.ndarray, Pv0: np.ndarray
) -> _Predictor:
    P = np.zeros((6, 6))
    P[:3, :3] = R
    P[3:, 3:] = Pv0
    return _Predictor(float(stamp_s), np.r_[pose, v0], P)


def _twin(xytheta: np.ndarray, cov: np.ndarray, centre_r: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The pose whose hull outline coincides with that of ``xytheta`` turned by pi, and its covariance."""
    th = xytheta[2]
    R = np.array([[np.cos(th), -np.sin(th)], [np.sin(th), np.cos(th)]])
    out = np.r_[xytheta[:2] + 2 * R @ centre_r, th + np.pi]
    J = np.eye(3)
    J[:2, 2] = 2 * np.array([[0.0, -1.0], [1.0, 0.0]]) @ R @ centre_r
    return out, J @ cov @ J.T


def _resolve_heading(
    tid: int,
    track_id: np.ndarray,
    status: np.ndarray,
    raw: np.ndarray,
    raw_cov: np.ndarray,
    centre_r: np.ndarray,
    min_motion_m: float,
) -> bool:
    """Resolve the pi symmetry of track ``tid`` from its forward motion (the robot drives forwards):
    turn all its poses by pi if it moved backwards. Returns whether the motion sufficed."""
    idx = np.flatnonzero(track_id == tid)
    okk = idx[status[idx] == OK]
    if okk.size < 2:
        return False
    # motion along the current heading, summed over the track (robust to turns)
    dp = np.diff(raw[okk, :2], axis=0)
    forward = float(np.sum(dp[:, 0] * np.cos(raw[okk[:-1], 2]) + dp[:, 1] * np.sin(raw[okk[:-1], 2])))
    if abs(forward) < min_motion_m:
        return False
    if forward < 0:
        for j in idx:
            raw[j], raw_cov[j] = _twin(raw[j], raw_cov[j], centre_r)
    return True


def _refilter(
    tid: int,
    track_id: np.ndarray,
    status: np.ndarray,
    stamps: np.ndarray,
    raw: np.ndarray,
    raw_cov: np.ndarray,
    qd: np.ndarray,
    Pv0: np.ndarray,
) -> _Predictor:
    """The tracking filter run afresh over the OK frames of track ``tid`` (after its heading flipped)."""
    idx = np.flatnonzero((track_id == tid) & (status == OK))
    state = _start_predictor(stamps[idx[0]], raw[idx[0]], raw_cov[idx[0]], np.zeros(3), Pv0)
    for j in idx[1:]:
        state = state.update(stamps[j], raw[j], raw_cov[j], qd)
    return state


def calibration_sensitivity(
    fp: FramedPoints, model: HullModel, xytheta: np.ndarray, icp: IcpSettings, bias_pull: np.ndarray | None = None,
) -> np.ndarray:
    """(F, 3, 3 S) how each pose ``xytheta`` (F, 3; ``nan`` rows get ``nan``) moves with the scanners'
    calibrated planar poses (:func:`gtrig.laser.hull_icp.scanner_sensitivity`).

    ``bias_pull`` (4, 3 S): how the sides' range bias estimate moved with the calibration
    (:attr:`gtrig.laser.side_bias.SideBias.scanner_pull`). The points are corrected by that estimate, so
    the share of a calibration error it took up (a scanner off along its beams onto a side looks like
    that side ranging long) is taken out: ``A - A_b D`` with ``A_b`` the pose's sensitivity to the sides'
    biases (:func:`gtrig.laser.hull_icp.side_bias_sensitivity`). Without it the same error counts once in
    the calibration's share and again in the refitted poses' (on the simulated GT room, 75 s agile runs,
    the calibrated and true scanners' tracks differ by 0.17 / 0.31 mm rms in x / y; ``A dc`` predicts
    0.26 / 0.47, ``(A - A_b D) dc`` 0.17 / 0.32)."""
    F = fp.n_frames
    S = len(fp.scanner_xy_world)
    out = np.full((F, 3, 3 * S), np.nan)
    have = np.isfinite(xytheta[:, 0])
    if not have.any():
        return out
    pts = _beam_points_of(fp, have)
    A = scanner_sensitivity(model, pts, xytheta[have], icp)
    if bias_pull is not None:
        A = A - side_bias_sensitivity(model, pts, xytheta[have], icp) @ np.asarray(bias_pull, dtype=float)
    out[have] = A
    return out


def surface_bias_covariance(
    fp: FramedPoints, model: HullModel, xytheta: np.ndarray, cov_bias: np.ndarray, icp: IcpSettings
) -> np.ndarray:
    """Covariance (F, 3, 3) that an unknown range bias of the hull's sides (covariance ``cov_bias``
    (4, 4), m^2, sides in the hull's order) induces on each pose ``xytheta`` (F, 3; ``nan`` rows get
    ``nan``), through :func:`gtrig.laser.hull_icp.side_bias_sensitivity`."""
    out = np.full((fp.n_frames, 3, 3), np.nan)
    have = np.isfinite(xytheta[:, 0])
    if not have.any():
        return out
    A = side_bias_sensitivity(model, _beam_points_of(fp, have), xytheta[have], icp)
    out[have] = A @ np.asarray(cov_bias, dtype=float) @ np.swapaxes(A, 1, 2)
    return out


def _frame_points_of(fp: FramedPoints, frames: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The points (mask (P,)) of the frames selected by ``frames`` (F,) and, for each of them, the
    index of its frame among the selected ones."""
    counts = np.diff(fp.frame_start)
    pt = np.repeat(frames, counts)
    return pt, np.repeat(np.cumsum(frames) - 1, counts)[pt]


def _beam_points_of(fp: FramedPoints, frames: np.ndarray) -> BeamPoints:
    """The points of the frames selected by ``frames`` (F,), frames numbered among the selected ones."""
    pt, fid = _frame_points_of(fp, frames)
    return BeamPoints(fp.xy_world[pt], fid, fp.scanner_index[pt], fp.scanner_xy_world, fp.dir_world[pt], fp.sigma_m)


def _bias_prior(st: TrackSettings) -> np.ndarray:
    """(4, 4) prior covariance of the sides' range bias: one fabric common to all sides plus each side's."""
    return st.surface_bias_std_m**2 * np.ones((4, 4)) + st.side_bias_std_m**2 * np.eye(4)


def compensate_motion(xy: np.ndarray, dt_s: np.ndarray, velocity: np.ndarray, centre_xy: np.ndarray) -> np.ndarray:
    """Points (M, 2, world) brought back by ``dt_s`` (M,) seconds of the robot's motion: velocity
    (M, 3) ``(vx, vy, omega)`` about ``centre_xy`` (M, 2), to first order in ``dt``."""
    v = np.broadcast_to(velocity, (len(xy), 3))
    return xy - dt_s[:, None] * (
        v[:, :2] + v[:, 2:3] * np.column_stack([-(xy[:, 1] - centre_xy[:, 1]), xy[:, 0] - centre_xy[:, 0]])
    )


def _track_velocities(stamps_s: np.ndarray, xytheta: np.ndarray, track_id: np.ndarray) -> np.ndarray:
    """(F, 3) velocity of each frame from the poses of its own track (zero where it has none)."""
    vel = np.zeros((len(stamps_s), 3))
    for tid in np.unique(track_id[track_id >= 0]):
        idx = np.flatnonzero(track_id == tid)
        if idx.size >= 2:
            z = xytheta[idx].copy()
            z[:, 2] = np.unwrap(z[:, 2])
            vel[idx] = np.gradient(z, stamps_s[idx], axis=0)
    return vel


def _refine_with_side_bias(
    fp: FrameSource, model: HullModel, st: TrackSettings, stamps: np.ndarray, smoothed: np.ndarray,
    track_id: np.ndarray, status: np.ndarray, raw: np.ndarray, raw_cov: np.ndarray, iterations: int = 2,
) -> SideBias:
    """Estimate the sides' range bias over the OK frames (:mod:`gtrig.laser.side_bias`) and fit those
    frames again with their points corrected by it and de-skewed with the smoothed velocity; ``raw``
    and ``raw_cov`` are updated in place. Ambiguous frames (their sides may be swapped by the pi
    symmetry) are left out.

    The points are made, corrected and fitted a time window of :data:`COVARIANCE_WINDOW_FRAMES` frames
    at a time (the whole run's at once peaked at ~35 kB per frame); between windows only
    per-frame arrays are kept (poses, covariances, each frame's reduced normal equations). Each pass's
    correction is made again from the poses and biases of the passes before it, and the windows' fits
    iterate as one fit of every frame would (:func:`_fit_windows`): the same bits as one pass over the
    whole run."""
    ok = (status == OK) & np.isfinite(raw[:, 0])
    prior = _bias_prior(st)
    if ok.sum() < 10 or not np.any(prior):  # (a zero prior: the bias is known to be nil)
        return SideBias.prior(prior)
    W = COVARIANCE_WINDOW_FRAMES
    windows = [(a, min(fp.n_frames, a + W)) for a in range(0, fp.n_frames, W)]
    windows = [(a, b) for a, b in windows if ok[a:b].any()]
    # each window's rows in the arrays over the OK frames
    rows = np.cumsum([0] + [int(ok[a:b].sum()) for a, b in windows])
    vel = _track_velocities(stamps, smoothed, track_id)
    S, sig = fp.scanner_xy_world, fp.sigma_m
    poses = [raw[ok]]  # the OK frames' poses each pass starts from
    betas = [np.zeros(4)]  # the total correction of the points after each pass

    # a source read from the logs makes each window's points once; the pass's three other readings of
    # them come from a temporary file (parsing the logs' text again cost ~1/3 of GTlaser's CPU)
    spill = None if isinstance(fp, FramedPoints) else tempfile.TemporaryFile()
    placed: dict[int, int] = {}

    def made(w: int) -> tuple[np.ndarray, ...]:
        """Window ``w``'s OK points as the source makes them: (M, 2) world points, (M,) firing times
        after the frame's stamp, their frame among the window's OK frames, scanner index, (M, 2) beam
        directions."""
        if spill is not None and w in placed:
            spill.seek(placed[w])
            return tuple(np.load(spill) for _ in range(5))
        a, b = windows[w]
        win = fp.window(a, b, scans=False)
        pt, fid = _frame_points_of(win, ok[a:b])
        out = (win.xy_world[pt], win.dt_s[pt], fid, win.scanner_index[pt], win.dir_world[pt])
        if spill is not None:
            placed[w] = spill.seek(0, 2)
            for x in out:
                np.save(spill, x)
        return out

    def points(w: int, passes: int) -> BeamPoints:
        """Window ``w``'s OK points de-skewed and corrected by the first ``passes`` passes, their frames
        numbered among the window's OK frames."""
        a, b = windows[w]
        sel = ok[a:b]
        p, dt, fid, sid, d = made(w)
        xy = compensate_motion(p, dt, vel[a:b][sel][fid], smoothed[a:b][sel][fid, :2])
        pts = BeamPoints(xy, fid, sid, S, d, sig)
        for m in range(passes):
            side = assigned_sides(model, pts, poses[m][rows[w]:rows[w + 1]], st.icp)
            pts = replace(pts, xy_world=pts.xy_world - ((betas[m + 1] - betas[m])[side])[:, None] * pts.dir_world)
        return pts

    try:
        bias = SideBias.prior(prior)
        cov = raw_cov[ok]
        for it in range(iterations):
            pose = poses[it]
            Nu = []
            pulls: list[tuple[np.ndarray, np.ndarray]] = []
            for w in range(len(windows)):
                pts = points(w, it)
                eqs = side_bias_normal_equations(model, pts, pose[rows[w]:rows[w + 1]], st.icp)
                Nu.append(reduced_normal_equations(*eqs))
                if it == iterations - 1:
                    a, b = windows[w]
                    pulls.append(block_sums(side_bias_scanner_pull(model, pts, pose[rows[w]:rows[w + 1]], st.icp),
                                            a + np.flatnonzero(ok[a:b])))
            N = np.concatenate([n for n, _ in Nu])
            # the prior holds the total bias: solve for it with the points' current correction undone
            u = np.concatenate([u for _, u in Nu]) - np.einsum("kab,b->ka", N, betas[it])
            bias = estimate_side_bias(N, u, stamps[ok], prior)
            if it == iterations - 1:
                du_dc = ordered_total(pulls, (4, 3 * len(S)))
                bias = replace(bias, scanner_pull=scanner_pull(N, prior, du_dc))
            betas.append(bias.bias_m)

            def fit(w: int, min_iterations: int, it: int = it) -> HullFitBatch:
                return fit_hull_batch(model, points(w, it + 1), poses[it][rows[w]:rows[w + 1]], st.icp,
                                      min_iterations=min_iterations)

            fits = _fit_windows(fit, len(windows))
            good = np.concatenate([~f.degenerate & (f.n_points >= st.icp.min_points) for f in fits])
            poses.append(np.where(good[:, None], np.concatenate([f.xytheta for f in fits]), pose))
            cov = np.where(good[:, None, None], np.concatenate([f.cov_xytheta for f in fits]), cov)
    finally:
        if spill is not None:
            spill.close()
    raw[ok], raw_cov[ok] = poses[-1], cov
    log.info("hull sides' range bias %s mm (std %s mm, variance factor %.2f over %d blocks)",
             np.array2string(1000 * bias.bias_m, precision=1),
             np.array2string(1000 * np.sqrt(np.diag(bias.cov)), precision=2), bias.variance_factor, bias.n_blocks)
    return bias


def _fit_windows(fit: Callable[[int, int], HullFitBatch], n_windows: int) -> list[HullFitBatch]:
    """The hull fits of ``n_windows`` windows of frames, ``fit(w, min_iterations)`` fitting window ``w``
    (:func:`gtrig.laser.hull_icp.fit_hull_batch`), iterated as one fit of all their frames would be.

    One fit stops at the first iteration where every frame has converged, and a frame's pose changes
    with every iteration done; a window's own stop is never after the whole fit's, so the latest stop
    is a lower bound of it: the windows that stopped earlier are fitted again to at least that many
    iterations, until all stop at the same one (on the simulated 75 s runs no window needed it)."""
    fits = [fit(w, 0) for w in range(n_windows)]
    while fits:
        g = max(f.iterations for f in fits)
        redo = [w for w, f in enumerate(fits) if f.iterations < g]
        if not redo:
            break
        for w in redo:
            fits[w] = fit(w, g)
    return fits


def _smooth_tracks(
    stamps: np.ndarray, raw: np.ndarray, raw_cov: np.ndarray, status: np.ndarray, track_id: np.ndarray,
    n_tracks: int, st: TrackSettings,
) -> tuple[np.ndarray, np.ndarray]:
    """Each track smoothed (``st.smooth``), with the floor added; (F, 3) poses and (F, 3, 3) covariances
    (the raw fits where a track is not smoothed)."""
    xytheta = raw.copy()
    cov = raw_cov.copy()
    if not st.smooth:
        return xytheta, cov
    for tid in range(n_tracks):
        idx = np.flatnonzero(track_id == tid)
        if idx.size < 2:
            continue
        z = raw[idx].copy()
        z[:, 2] = np.unwrap(z[:, 2])
        qa, qw = st.accel_std_mps2, st.ang_accel_std_radps2
        if st.adapt_process_noise and idx.size >= 10:
            # the robot's own accelerations, from the track's innovations, near each frame
            # (process_noise): braking into a bend needs a looser model than cruising
            good = np.isin(status[idx], (OK, AMBIGUOUS))
            zz = np.where(good[:, None], z, np.nan)
            if st.smoother_order == 3:
                qa, qw = st.jerk_std_mps3, st.ang_jerk_std_radps3
            qda, qdw = local_ml_process_noise(
                stamps[idx], zz, raw_cov[idx], qa * _Q_GRID, qw * _Q_GRID, st.adapt_window_s, st.smoother_order,
            )
            qd = np.column_stack([qda**2, qda**2, qdw**2])
            xs, Ps = rts_smooth_varying(stamps[idx], z, raw_cov[idx], qd, st.smoother_order)
        else:
            xs, Ps = rts_smooth(stamps[idx], z, raw_cov[idx], qa, qw)
        xytheta[idx], cov[idx] = xs, Ps + np.diag([st.floor_std_m**2, st.floor_std_m**2, st.floor_std_rad**2])
    return xytheta, cov


#: frames per chunk of the per-frame covariance terms (a time window of the run)
COVARIANCE_WINDOW_FRAMES = 256
#: frames per block of the run-wide sums over frames (the calibration sensitivity, the side-bias pull):
#: blocks start at the multiples of it and are added in frame order, so windows of any multiple of it
#: frames give one pass's bits
SUM_BLOCK_FRAMES = 16

#: a window's share of a run-wide sum: the blocks' indices (B,) and their sums (B, ...)
BlockSums = tuple[np.ndarray, np.ndarray]


def block_sums(rows: np.ndarray, frames: np.ndarray) -> BlockSums:
    """Sums of ``rows`` (K, ...) over the blocks of :data:`SUM_BLOCK_FRAMES` frames their ``frames`` (K,;
    absolute frame indices, increasing) fall in, each block's rows added in order."""
    blk = np.asarray(frames, dtype=np.intp) // SUM_BLOCK_FRAMES
    if blk.size == 0:
        return blk, np.zeros((0,) + rows.shape[1:])
    starts = np.flatnonzero(np.r_[True, blk[1:] != blk[:-1]])
    return blk[starts], np.add.reduceat(np.asarray(rows, dtype=float), starts, axis=0)


def ordered_total(parts: Sequence[BlockSums], shape: tuple[int, ...]) -> np.ndarray:
    """The windows' block sums (:func:`block_sums`; windows in frame order, none splitting a block) added
    block after block: the same bits however the frames were cut into windows."""
    sums = [s for _, s in parts if len(s)]
    if not sums:
        return np.zeros(shape)
    return np.cumsum(np.concatenate(sums), axis=0)[-1]


def _window_covariances(part: FrameSource, model: HullModel, raw: np.ndarray, cov_bias: np.ndarray | None,
                        scanner_cov: np.ndarray | None, st: TrackSettings, bias_pull: np.ndarray | None = None,
                        use: np.ndarray | None = None, first: int = 0,
                        ) -> tuple[np.ndarray | None, np.ndarray | None, BlockSums | None]:
    # (on a worker: a source read from the logs on disk makes its points here)
    fp = part.window(0, part.n_frames, scans=False)
    bias = None if cov_bias is None else surface_bias_covariance(fp, model, raw, cov_bias, st.icp)
    if scanner_cov is None:
        return bias, None, None
    A = calibration_sensitivity(fp, model, raw, st.icp, bias_pull)
    keep = np.isfinite(A[:, 0, 0]) & (np.ones(len(A), bool) if use is None else use)
    cal = A @ np.asarray(scanner_cov, dtype=float) @ np.swapaxes(A, 1, 2)
    return bias, cal, block_sums(A[keep], first + np.flatnonzero(keep))


def frame_covariances(fp: FrameSource, model: HullModel, raw: np.ndarray, cov_bias: np.ndarray | None,
                      scanner_cov: np.ndarray | None, st: TrackSettings, executor: Any = None, workers: int = 1,
                      progress: Callable[[int, int], None] | None = None, bias_pull: np.ndarray | None = None,
                      use: np.ndarray | None = None,
                      ) -> tuple[np.ndarray | None, np.ndarray | None, np.ndarray | None]:
    """The hull-surface bias and the scanners' calibration terms of every frame's covariance, (F, 3, 3)
    each (None when not asked for), computed in windows of :data:`COVARIANCE_WINDOW_FRAMES` frames over
    ``executor`` (:mod:`gtrig.executor`), and the calibration sensitivity (3, 3 S) summed over the frames
    ``use`` (F,) selects (:func:`calibration_sensitivity`; None without ``scanner_cov``). Each frame's
    term depends on its own points and pose only, so the windows give the same bits as one pass."""
    from gtrig.executor import Chunk, map_chunks

    F = fp.n_frames
    edges = list(range(0, F, COVARIANCE_WINDOW_FRAMES)) + [F]
    chunks = [Chunk((fp.part(a, b), model, raw[a:b], cov_bias, scanner_cov, st, bias_pull,
                     None if use is None else use[a:b], a),
                    f"frames {a}-{b - 1} ({fp.frame_stamps_s[a]:.3f}-{fp.frame_stamps_s[b - 1]:.3f} s)")
              for a, b in zip(edges[:-1], edges[1:], strict=True) if b > a]
    parts: dict[int, tuple[np.ndarray | None, np.ndarray | None, BlockSums | None]] = {}
    map_chunks(_window_covariances, chunks, parts.__setitem__, executor=executor, workers=workers, progress=progress)
    if not parts:
        bias, cal, one = _window_covariances(fp.part(0, F), model, raw, cov_bias, scanner_cov, st, bias_pull, use)
        return bias, cal, None if one is None else ordered_total([one], (3, 3 * len(fp.scanner_xy_world)))
    out: list[np.ndarray | None] = []
    for k in (0, 1):
        pieces = [parts[i][k] for i in range(len(chunks))]
        out.append(None if pieces[0] is None else np.concatenate(pieces))  # type: ignore[arg-type]
    sums = [a for a in (parts[i][2] for i in range(len(chunks))) if a is not None]
    return out[0], out[1], ordered_total(sums, (3, 3 * len(fp.scanner_xy_world))) if sums else None


def timing_covariance(points: np.ndarray, stamp_sigma_s: np.ndarray | None, stamps_s: np.ndarray,
                      xytheta: np.ndarray, track_id: np.ndarray) -> np.ndarray:
    """Covariance (F, 3, 3) of the poses due to the scanners' clock offsets (standard deviations
    ``stamp_sigma_s`` (S,), seconds): a frame's fit holds at the mean of its points' true times, off
    from its stamp by the points' share-weighted mean offset (standard deviation
    ``sqrt(sum_s w_s^2 sigma_s^2)``, offsets independent between scanners; ``points`` (F, S) is each
    frame's count of points from each scanner), so the pose is off by that times its velocity (from the
    smoothed poses of its own track)."""
    F = len(stamps_s)
    out = np.zeros((F, 3, 3))
    sig = stamp_sigma_s
    if sig is None or not np.any(sig > 0):
        return out
    n = np.asarray(points, dtype=float)
    w = n / np.maximum(n.sum(axis=1, keepdims=True), 1.0)
    var_t = (w**2) @ (sig**2)
    vel = _track_velocities(stamps_s, xytheta, track_id)
    return var_t[:, None, None] * np.einsum("fi,fj->fij", vel, vel)


def points_per_scanner(fp: FramedPoints) -> np.ndarray:
    """(F, S) each frame's count of points from each scanner (for :func:`timing_covariance`)."""
    F, S = fp.n_frames, len(fp.sigma_m)
    fid = np.repeat(np.arange(F), np.diff(fp.frame_start))
    return np.bincount(fid * S + fp.scanner_index, minlength=F * S).reshape(F, S)


def track_frames(
    fp: FrameSource,
    model: HullModel,
    settings: TrackSettings = TrackSettings(),
    scanner_cov: np.ndarray | None = None,
    *,
    executor: Any = None,
    workers: int = 1,
    progress: Callable[[int, int], None] | None = None,
) -> TrackResult:
    """Track the hull through the frames of ``fp``.

    Parameters
    ----------
    fp
        Foreground points of the sequence, in the world, by frame: all of them
        (:func:`gtrig.laser.fuse.frame_points`) or a source that reads them a time window of
        :data:`COVARIANCE_WINDOW_FRAMES` frames at a time (:class:`gtrig.laser.recording.LoggedFrames`:
        then no pass holds more than a window's points).
    model
        The hull outline (:meth:`HullModel.from_hull`).
    settings
        Tracking settings.
    scanner_cov
        (3 S, 3 S) covariance of the scanners' calibrated planar poses (``CalibrationReport.cov_xytheta``),
        scanners in ``fp``'s order. Its effect on each pose is added to the reported covariance *after*
        smoothing: a calibration error is common to every frame, so smoothing cannot average it out.
    executor, workers, progress
        Where the per-frame covariance terms run, in time windows (:func:`frame_covariances`); the
        tracking filter itself is sequential (each fit starts from the previous frames' prediction) and
        runs here. The output does not depend on them.

    Returns
    -------
    TrackResult
    """
    st = settings
    F = fp.n_frames
    stamps = fp.frame_stamps_s
    tr = _FrameTracker(fp, model, st)
    k = 0
    while k < F:
        k = tr.track_chunk(k) if tr.tracking else tr.acquire_at(k)
    tracks, track_id, status, reasons = tr.tracks, tr.track_id, tr.status, tr.reasons
    raw, raw_cov = tr.raw, tr.raw_cov
    for tid, (_first, ambiguous) in enumerate(tracks):
        idx = np.flatnonzero(track_id == tid)
        if ambiguous:
            status[idx[status[idx] == OK]] = AMBIGUOUS
            for j in idx.tolist():
                reasons[j] = reasons[j] or "heading ambiguous (pi symmetry, no motion, no recent pose)"

    xytheta, cov = _smooth_tracks(stamps, raw, raw_cov, status, track_id, len(tracks), st)
    bias = SideBias.prior(_bias_prior(st))
    if st.estimate_side_bias and st.smooth:
        # the fabric's range bias over the whole sequence, then every OK frame fitted again with its
        # points corrected and de-skewed with the smoothed velocity, and smoothed again
        bias = _refine_with_side_bias(fp, model, st, stamps, xytheta, track_id, status, raw, raw_cov)
        # its windows' points and fits, freed, would otherwise stay in the heap under what the later
        # passes allocate (an hour's log: ~200 MB more at the stage's peak)
        release_free_memory()
        xytheta, cov = _smooth_tracks(stamps, raw, raw_cov, status, track_id, len(tracks), st)
    cov_bias, cov_cal, A_sum = frame_covariances(fp, model, raw, bias.cov if np.any(bias.cov != 0) else None,
                                                 scanner_cov, st, executor, workers, progress, bias.scanner_pull,
                                                 status == OK)
    if cov_bias is not None:
        # what is left unknown of the fabric's range bias moves with the side, not from frame to
        # frame: after smoothing
        cov = cov + np.nan_to_num(cov_bias)
    # the scanners' clocks: the motion a stamp offset hides (the rig's stamp_sigma_s)
    cov = cov + timing_covariance(tr.counts, fp.stamp_sigma_s, stamps, xytheta, track_id)
    shared = np.zeros((3, 3))
    if cov_cal is not None:
        cov = cov + cov_cal
        if A_sum is not None and np.any(status == OK):
            # the run-constant share: the calibration error's mean over the OK poses (mean sensitivity)
            A_mean = A_sum / np.sum(status == OK)
            shared = A_mean @ np.asarray(scanner_cov, dtype=float) @ A_mean.T
    else:
        cov_cal = np.zeros((F, 3, 3))
    xytheta[:, 2] = wrap_angle(xytheta[:, 2])
    raw_w = raw.copy()
    raw_w[:, 2] = wrap_angle(raw_w[:, 2])
    return TrackResult(
        stamps.copy(), xytheta, cov, status, raw_w, raw_cov, tr.n_points, tr.n_sides, tr.rms, track_id,
        tuple(reasons), cov_cal, bias, 0.5 * (shared + shared.T),
    )


class _FrameTracker:
    """The tracking filter walking a sequence's frames in order: acquisition of the hull where no track
    runs (:meth:`acquire_at`), then chunks of frames fitted together from the track's prediction
    (:meth:`track_chunk`); the per-frame results in its arrays. The frames are read a window at a time
    (the filter's state between windows is its predictor); each frame's count of points per scanner is
    kept for the timing term."""

    def __init__(self, fp: FrameSource, model: HullModel, st: TrackSettings) -> None:
        F = fp.n_frames
        self.fp, self.model, self.st, self.F = fp, model, st, F
        self.stamps = fp.frame_stamps_s
        self.raw = np.full((F, 3), np.nan)
        self.raw_cov = np.full((F, 3, 3), np.nan)
        self.status = np.full(F, LOST, dtype=np.int8)
        self.n_points = np.zeros(F, dtype=int)
        self.n_sides = np.zeros(F, dtype=int)
        self.rms = np.full(F, np.nan)
        self.track_id = np.full(F, -1, dtype=int)
        self.reasons = [""] * F
        self.centre_r = model.corners_xy.mean(axis=0)
        self.tracks: list[list[int | bool]] = []  # [first frame, heading ambiguous]
        self.qd = np.array([st.predict_accel_std_mps2**2] * 2 + [st.predict_ang_accel_std_radps2**2])
        self.Pv_unknown = np.diag([st.max_speed_mps**2, st.max_speed_mps**2, st.max_turn_rate_radps**2])
        self.counts = np.zeros((F, len(fp.sigma_m)), dtype=np.int64)
        self.win: FramedPoints | None = None
        self.w0 = 0  # the window's first frame
        self.pred_state: _Predictor | None = None  # the tracking filter of the current track
        self.tracking = False
        self.fails = 0
        self.last_pose_frame = -1  # last OK frame of any track

    def window_at(self, k: int) -> FramedPoints:
        """The window holding frames ``[k, k + chunk_frames)`` (or up to the last); ``k`` never decreases."""
        st, F = self.st, self.F
        if self.win is None or (k + st.chunk_frames > self.w0 + self.win.n_frames and self.w0 + self.win.n_frames < F):
            self.w0, self.win = k, self.fp.window(k, min(F, k + max(COVARIANCE_WINDOW_FRAMES, st.chunk_frames)))
            self.counts[self.w0:self.w0 + self.win.n_frames] = points_per_scanner(self.win)
        return self.win

    def acquire_at(self, k: int) -> int:
        """Look for the hull in frame ``k`` with no track running (near the last pose when it is recent);
        a hull found starts a track. Returns the next frame."""
        st, stamps, model = self.st, self.stamps, self.model
        wf = self.window_at(k)
        w0 = self.w0
        sl = wf.frame(k - w0)
        prior, radius, inherited = None, None, False
        gap = np.inf if self.last_pose_frame < 0 else stamps[k] - stamps[self.last_pose_frame]
        if gap <= st.prior_max_gap_s:
            prior = self.raw[self.last_pose_frame]
            inherited = bool(self.tracks[self.track_id[self.last_pose_frame]][1])  # the prior's heading unresolved
            if gap <= st.reacquire_gap_s:
                radius = st.reacquire_radius_m
        acq = None
        if sl.stop - sl.start >= st.icp.min_points:
            pts = BeamPoints.one_frame(wf.xy_world[sl], wf.scanner_index[sl], wf.scanner_xy_world, wf.dir_world[sl],
                                       wf.sigma_m)
            acq = acquire(
                model,
                pts,
                st.icp,
                prior_xytheta=prior,
                search_radius_m=radius,
                free_rays=wf.free_rays(k - w0),
            )
        if acq is None or acq.fit.rms_m > st.max_rms_m:
            self.reasons[k] = "hull not found"
            return k + 1
        f = acq.fit
        pose = f.xytheta.copy()
        if prior is not None:
            pose[2] = prior[2] + wrap_angle(pose[2] - prior[2])  # continuous heading
        self.tracks.append([k, acq.ambiguous or inherited])
        self.raw[k], self.raw_cov[k] = pose, f.cov_xytheta
        self.status[k], self.n_points[k], self.n_sides[k], self.rms[k] = OK, f.n_points, f.n_sides, f.rms_m
        self.track_id[k] = len(self.tracks) - 1
        # the velocity of a new track: that of the track just lost, made uncertain by the robot's
        # accelerations over the gap, else unknown up to the robot's top speed; its first frames
        # are then fitted one at a time until the filter has measured it
        if self.pred_state is not None and radius is not None and not acq.ambiguous:
            v0 = self.pred_state.x[3:].copy()
            Pv0 = (self.pred_state.P[3:, 3:] + np.diag(self.qd) * gap
                   + self.Pv_unknown * min(1.0, gap / st.reacquire_gap_s) ** 2)
        else:
            v0, Pv0 = np.zeros(3), self.Pv_unknown
        self.pred_state = _start_predictor(stamps[k], pose, f.cov_xytheta, v0, Pv0)
        self.fails, self.tracking, self.last_pose_frame = 0, True, k
        log.debug("hull acquired at frame %d (%.3f s)%s", k, stamps[k], " (heading ambiguous)" * acq.ambiguous)
        return k + 1

    def track_chunk(self, k: int) -> int:
        """Fit the frames from ``k`` that the track's prediction reaches together, then judge each one
        against the prediction (a frame refused after the first is fitted again from a fresh prediction);
        the pi symmetry resolved as soon as the robot has moved. Returns the next frame."""
        st, stamps, model, F = self.st, self.stamps, self.model, self.F
        wf = self.window_at(k)
        w0 = self.w0
        assert self.pred_state is not None
        end = min(F, k + st.chunk_frames)
        gaps = np.flatnonzero(np.diff(stamps[k - 1 : end]) > st.max_gap_s)
        if gaps.size:
            end = k + int(gaps[0])
        if end <= k:
            self.tracking = False
            return k
        pred, pred_cov = self.pred_state.predict(stamps[k:end], self.qd)
        # fit together only the frames the prediction reaches: its standard deviation within a third
        # of the ICP's capture (at least one frame)
        sd_xy = np.sqrt(np.maximum(pred_cov[:, 0, 0], pred_cov[:, 1, 1]))
        sd_th = np.sqrt(pred_cov[:, 2, 2])
        reach = (3 * sd_xy <= st.capture_m) & (3 * sd_th <= st.capture_rad)
        n_fit = max(1, int(np.argmin(reach)) if not reach.all() else len(reach))
        end = k + n_fit
        pred, pred_cov = pred[:n_fit], pred_cov[:n_fit]
        vel = self.pred_state.x[3:]
        sl = slice(int(wf.frame_start[k - w0]), int(wf.frame_start[end - w0]))
        fid = np.repeat(np.arange(end - k), np.diff(wf.frame_start[k - w0 : end - w0 + 1]))
        xy = wf.xy_world[sl]
        dt = wf.dt_s[sl]
        # motion within the frame: bring each point back to the frame time
        pc = pred[fid]
        xy = compensate_motion(xy, dt, vel, pc)
        # gate: only points near the predicted outline
        near = (
            np.hypot(xy[:, 0] - pc[:, 0], xy[:, 1] - pc[:, 1])
            < model.half_diagonal_m + np.hypot(*model.corners_xy.mean(axis=0)) + 2 * st.icp.gate_m
        )
        pts = BeamPoints(xy[near], fid[near], wf.scanner_index[sl][near], wf.scanner_xy_world, wf.dir_world[sl][near],
                         wf.sigma_m)
        fits = fit_hull_batch(model, pts, pred, st.icp)
        end = self._judge(k, end, fits, pred, pred_cov)
        # resolve the pi symmetry as soon as the robot has moved, before a later track inherits it
        tid = len(self.tracks) - 1
        if st.forward_motion and self.tracks[tid][1]:
            if _resolve_heading(tid, self.track_id, self.status, self.raw, self.raw_cov, self.centre_r,
                                st.min_motion_m):
                self.tracks[tid][1] = False
                self.pred_state = _refilter(tid, self.track_id, self.status, stamps, self.raw, self.raw_cov, self.qd,
                                            self.Pv_unknown)
        return end

    def _judge(self, k: int, end: int, fits: Any, pred: np.ndarray, pred_cov: np.ndarray) -> int:
        """Frames ``k .. end - 1``'s fits against the prediction: kept (OK, or DEGENERATE), refused (the
        reason kept), or, after the first frame, fitted again from a fresh prediction; the track lost after
        ``lost_after`` failures. Returns the next frame."""
        st = self.st
        assert self.pred_state is not None
        next_k = end
        for i in range(end - k):
            j = k + i
            pose = fits.xytheta[i]
            d = pose - pred[i]
            jump = float(np.hypot(d[0], d[1]))
            self.n_points[j], self.n_sides[j], self.rms[j] = fits.n_points[i], fits.n_sides[i], fits.rms_m[i]
            bad = ""
            if fits.n_points[i] < st.icp.min_points:
                bad = f"few points ({fits.n_points[i]})"
            elif not fits.rms_m[i] <= st.max_rms_m:
                bad = f"residual {1000 * fits.rms_m[i]:.0f} mm"
            elif not fits.degenerate[i]:
                # the gate scales with what the prediction and the fit can each be off by
                S = pred_cov[i] + fits.cov_xytheta[i]
                m2 = float(d @ np.linalg.solve(S, d))
                small = jump <= st.min_jump_m and abs(d[2]) <= st.min_jump_rad
                if jump > st.max_jump_m or abs(d[2]) > st.max_jump_rad or (m2 > st.gate_chi2 and not small):
                    bad = f"jump of {1000 * jump:.0f} mm, {np.degrees(d[2]):.1f} deg from the prediction"
            if bad and i > 0:
                # predicted from farther back than the frame before it: try again from a fresh prediction
                return j
            if bad:
                self.reasons[j] = bad
                self.fails += 1
            elif fits.degenerate[i]:
                self.raw[j], self.raw_cov[j] = pose, fits.cov_xytheta[i]
                self.status[j], self.reasons[j] = DEGENERATE, fits.reasons[i]
                self.track_id[j] = len(self.tracks) - 1
                self.fails += 1
            else:
                self.raw[j], self.raw_cov[j] = pose, fits.cov_xytheta[i]
                self.status[j], self.reasons[j] = OK, ""
                self.track_id[j] = len(self.tracks) - 1
                self.pred_state = self.pred_state.update(self.stamps[j], pose, fits.cov_xytheta[i], self.qd)
                self.last_pose_frame = j
                self.fails = 0
            if self.fails >= st.lost_after:
                self.tracking = False
                log.debug("track lost at frame %d (%.3f s): %s", j, self.stamps[j], self.reasons[j])
                return j + 1
        return next_k


def _planar_transforms(xytheta: np.ndarray) -> np.ndarray:
    """(N, 4, 4) transforms of (N, 3) planar poses, the matrices :func:`gtrig.geometry.se2_to_T` builds
    one at a time (the same numbers: a whole array of cosines is the scalar's, bit for bit), without a
    Python object per frame (an hour of GTlaser is 270,000 frames)."""
    c, s = np.cos(xytheta[:, 2]), np.sin(xytheta[:, 2])
    T = np.zeros((len(xytheta), 4, 4))
    T[:, 0, 0], T[:, 0, 1], T[:, 1, 0], T[:, 1, 1] = c, -s, s, c
    T[:, 2, 2] = T[:, 3, 3] = 1.0
    T[:, :2, 3] = xytheta[:, :2]
    return T


def to_pose_track(result: TrackResult, source: str = "GTlaser") -> PoseTrack:
    """The frames with a pose as the one pose-track type (planar, ``xyyaw`` covariance).

    ``OK`` frames are OK; ``DEGENERATE`` and ``AMBIGUOUS`` ones are kept as REJECTED with their reason
    (never ground truth: a degenerate fit leaves a direction unmeasured, an ambiguous one may be turned
    by pi); ``LOST`` frames have no pose and are left out. The poses are the same transforms the TUM
    file always held (:func:`gtrig.geometry.se2_to_T`).
    """
    idx = np.flatnonzero(np.isfinite(result.xytheta[:, 0]))
    if idx.size == 0:
        return PoseTrack.empty(source, "xyyaw")
    T = _planar_transforms(result.xytheta[idx])
    ok = result.status[idx] == OK
    status = np.where(ok, PoseStatus.OK, PoseStatus.REJECTED).astype(np.uint8)
    reasons = tuple("" if o else f"{STATUS_NAMES[int(result.status[k])]}: {result.reasons[k]}".rstrip(": ")
                    for k, o in zip(idx, ok, strict=True))
    return PoseTrack.from_matrices(result.stamps_s[idx], T, cov=result.cov_xytheta[idx], cov_kind="xyyaw",
                                   status=status, reasons=reasons, source=source)
