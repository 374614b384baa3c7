"""The fixed scanners' beam timing checked from the tracked hull's residuals.

A scanner's beams do not all fire at its stamp: a mirror sweeps them over ``T_sweep = span / (2 pi rate)``
(the first beam at the stamp, or the stamp at the middle or end of the sweep), or a flash device fires them
all at once (:class:`gtrig.rig.models.BeamTiming`). The tracker moves every point back by the robot's
motion over its beam's declared delay; when the declared delay is wrong by ``delta``, a point on a hull
side of outward normal ``n`` (world) is left off that side by ``r = delta * (n . v_point)``, with
``v_point`` the hull's velocity at the point.

Per scanner ``s``, the delay error is modelled as ``delta = a_s + b_s * u * T_sweep_s`` with ``u`` the
point's place in the sweep (0 at the first beam, 1 at the last). Each frame's residuals are regressed
on ``(n . v)`` and ``(n . v) u T_sweep`` after the frame's own pose correction is projected out (a pose
error is not a timing error), summed over the run's tracked frames. The estimated sweep slope
``1 + b_s`` (declared sweep) or ``b_s`` (declared simultaneous) is compared with the timings a device can
have: 0 (all beams at once), +1 (a sweep from the first beam), -1 (a sweep from the last beam). The common
part of the offsets ``a_s`` moves every point by the same time, which the track absorbs; only the offsets'
differences are measured, and those are also the scanners' clock offsets, so the stamp reference is
judged against ``stamp_sigma_s``. The standard errors are cluster-robust (one cluster per second of run):
the residuals of neighbouring frames share the gown's shape and the surfaces' biases.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np

from gtrig.geometry import wrap_angle
from gtrig.laser.fuse import FramedPoints, FrameSource
from gtrig.laser.hull_icp import HullModel
from gtrig.rig.models import BeamTiming, LaserScanner, StampAt

#: the sweep slopes a device can have: beams all at once, a sweep from the first beam, from the last
SLOPES = {"simultaneous": 0.0, "sweep": 1.0, "sweep from the last beam": -1.0}


@dataclass(frozen=True)
class TimingFit:
    """What the residuals say about one scanner's beam timing.

    Attributes
    ----------
    scanner : its name.
    declared : the rig's timing, as text (``sweep, stamped at start``, ``simultaneous``).
    slope : the sweep slope the residuals fit (0 all at once, +1 a sweep from the first beam, -1 from the
        last), in units of the scanner's sweep time; nan when not measured.
    slope_sd : its standard error.
    offset_ms : the scanner's delay offset against the others (its stamp reference and clock offset), ms.
    offset_sd_ms : its standard error, ms (measurement only; the clock offsets' spread is separate).
    n_points : residuals used.
    fits_better : the timing that fits better than the declared one (empty when the declared one fits or
        nothing is measurable).
    """

    scanner: str
    declared: str
    slope: float
    slope_sd: float
    offset_ms: float
    offset_sd_ms: float
    n_points: int
    fits_better: str = ""

    @property
    def measured(self) -> bool:
        return bool(np.isfinite(self.slope_sd) and self.slope_sd < 0.5)


def declared_timing(scanner: LaserScanner) -> str:
    if scanner.beam_timing == BeamTiming.SIMULTANEOUS:
        return "simultaneous"
    return f"sweep, stamped at {scanner.stamp_at.value}"


def sweep_s(scanner: LaserScanner) -> float:
    """Time (s) from the scanner's first beam to its last when it sweeps."""
    return abs(scanner.angle_increment_rad) * (scanner.beams - 1) / (2 * math.pi) / scanner.rate_hz


def sweep_fraction(scanner: LaserScanner, dir_world: np.ndarray) -> np.ndarray:
    """Place (P,) in the sweep of beams pointing along ``dir_world`` (P, 2): 0 first beam, 1 last."""
    T = scanner.T_world_scanner.matrix()
    d_s = dir_world @ T[:2, :2]  # world -> scanner frame (planar part)
    ang = np.arctan2(d_s[:, 1], d_s[:, 0])
    span = scanner.angle_increment_rad * (scanner.beams - 1)
    dev = wrap_angle(ang - scanner.angle_min_rad - 0.5 * span) + 0.5 * span
    return np.clip(dev / span, 0.0, 1.0)


def _velocities(stamps_s: np.ndarray, xytheta: np.ndarray, track_id: np.ndarray, use: np.ndarray) -> np.ndarray:
    """(F, 3) velocity of the used frames from the poses of their own track (zero elsewhere)."""
    vel = np.zeros((len(stamps_s), 3))
    for tid in np.unique(track_id[use]):
        idx = np.flatnonzero(use & (track_id == tid))
        if idx.size >= 3:
            z = xytheta[idx].copy()
            z[:, 2] = np.unwrap(z[:, 2])
            vel[idx] = np.gradient(z, stamps_s[idx], axis=0)
    return vel


@dataclass
class _Sums:
    """Running normal equations of the timing parameters (2 S) and the range biases (S), and per-cluster
    scores."""

    A: np.ndarray
    b: np.ndarray
    scores: dict[int, np.ndarray]
    cluster_normal: dict[int, np.ndarray]
    counts: np.ndarray


def _side_residuals(model: HullModel, pose: np.ndarray, q: np.ndarray, d: np.ndarray, gate_m: float
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Signed distances (P,) of the points ``q`` (world) to the nearest hull side facing their beam ``d``,
    that side's world normal (P, 2), and which points are within ``gate_m`` of such a side."""
    c, s = math.cos(pose[2]), math.sin(pose[2])
    R = np.array([[c, -s], [s, c]])
    p_r = (q - pose[:2]) @ R
    n_w = model.normals @ R.T  # (4, 2)
    dist = p_r @ model.normals.T - model.offsets  # (P, 4)
    along = np.einsum("pj,kj->pk", p_r, model.tangents) - np.einsum("kj,kj->k", model.corners_xy, model.tangents)
    inside = (along > -0.03) & (along < model.lengths + 0.03)
    facing = d @ n_w.T < 0
    cost = np.where(facing & inside, np.abs(dist), np.inf)
    k = np.argmin(cost, axis=1)
    best = cost[np.arange(len(q)), k]
    return dist[np.arange(len(q)), k], n_w[k], best < gate_m


def _accumulate(sums: _Sums, fp: FramedPoints, scanners: Sequence[LaserScanner], model: HullModel,
                poses: np.ndarray, vel: np.ndarray, use: np.ndarray, cluster: np.ndarray,
                gate_m: float, sigma_model_m: float) -> None:
    """Add the used frames of the window ``fp`` to ``sums`` (module docstring)."""
    S = len(scanners)
    t_sw = np.array([sweep_s(s) for s in scanners])
    for k in np.flatnonzero(use):
        sl = fp.frame(int(k))
        q, d, dt, sid = fp.xy_world[sl], fp.dir_world[sl], fp.dt_s[sl], fp.scanner_index[sl]
        if len(q) < 8:
            continue
        rel = q - poses[k, :2]
        v_pt = vel[k, :2] + vel[k, 2] * np.column_stack([-rel[:, 1], rel[:, 0]])
        q_c = q - dt[:, None] * v_pt
        r, n_w, keep = _side_residuals(model, poses[k], q_c, d, gate_m)
        if keep.sum() < 8:
            continue
        r, n_w, sid, v_pt, rel, d = r[keep], n_w[keep], sid[keep], v_pt[keep], rel[keep], d[keep]
        g = np.einsum("pj,pj->p", n_w, v_pt)
        u = np.empty(len(r))
        for s_i in np.unique(sid):
            m = sid == s_i
            u[m] = sweep_fraction(scanners[int(s_i)], d[m])
        X = np.zeros((len(r), 3 * S))
        X[np.arange(len(r)), 2 * sid] = g
        X[np.arange(len(r)), 2 * sid + 1] = g * u * t_sw[sid]
        # the hull's range bias (a fabric's reflectivity) moves a point along its beam: a nuisance
        X[np.arange(len(r)), 2 * S + sid] = np.einsum("pj,pj->p", d, n_w)
        J = np.column_stack([n_w, n_w[:, 1] * rel[:, 0] - n_w[:, 0] * rel[:, 1]])
        w = 1.0 / (fp.sigma_m[sid] ** 2 + sigma_model_m ** 2)
        N = J.T @ (w[:, None] * J) + 1e-6 * np.eye(3)
        # Frisch-Waugh: the frame's pose correction projected out of the regressors and the residuals
        proj = np.linalg.solve(N, J.T @ (w[:, None] * np.column_stack([X, r])))
        Xr = np.column_stack([X, r]) - J @ proj
        Xp, rp = Xr[:, :-1], Xr[:, -1]
        A_k = Xp.T @ (w[:, None] * Xp)
        score = Xp.T @ (w * rp)
        sums.A += A_k
        sums.b += score
        c = int(cluster[k])
        sums.scores[c] = sums.scores.get(c, 0.0) + score
        sums.cluster_normal[c] = sums.cluster_normal.get(c, 0.0) + A_k
        np.add.at(sums.counts, sid, 1)


def _solve(sums: _Sums, scanners: Sequence[LaserScanner]) -> tuple[np.ndarray, np.ndarray]:
    """Timing parameters (2 S, then S range biases) and their cluster-robust covariance, never narrower
    than the points' noise alone gives."""
    S = len(scanners)
    P = np.zeros((3 * S, 3 * S))
    # the offsets' common part is not seen (a common time shift moves the track, not the residuals):
    # it is held at zero; their differences (clock offsets, stamp references) are left free (50 ms)
    P[0:2 * S:2, 0:2 * S:2] = np.full((S, S), 1.0 / (S * 1e-3 ** 2)) + np.eye(S) / 0.05 ** 2
    # a scanner that saw nothing keeps its declared timing
    P[1:2 * S:2, 1:2 * S:2] = np.diag(np.where(sums.counts > 0, 0.0, 1.0))
    A_inv = np.linalg.pinv(sums.A + P)
    theta = A_inv @ sums.b
    meat = np.zeros((3 * S, 3 * S))
    for c, score in sums.scores.items():
        e = score - sums.cluster_normal[c] @ theta
        meat += np.outer(e, e)
    cov = A_inv @ meat @ A_inv
    d = np.diag(cov)
    s = np.sqrt(np.maximum(d, np.diag(A_inv)) / np.where(d > 0, d, 1.0))
    s = np.where(d > 0, s, 1.0)
    cov = cov * np.outer(s, s)
    cov[np.diag_indices(3 * S)] = np.maximum(np.diag(cov), np.diag(A_inv))
    return theta, cov


def check_beam_timing(frames: FrameSource, xytheta: np.ndarray, status_ok: np.ndarray, track_id: np.ndarray,
                      scanners: Sequence[LaserScanner], model: HullModel, *, window: int = 400,
                      max_frames: int = 6000, gate_m: float = 0.03, sigma_model_m: float = 0.006,
                      min_speed_mps: float = 0.05) -> tuple[TimingFit, ...]:
    """Check every scanner's declared beam timing against the tracked run (module docstring).

    Parameters
    ----------
    frames
        The run's frames (the same the track was made from).
    xytheta, status_ok, track_id
        (F, 3) the tracked poses (world; x, y m; theta rad), (F,) which are ``OK``, (F,) their tracks.
    scanners
        The scanners of ``frames``, as declared by the rig.
    model
        The hull.
    window, max_frames
        Frames read at a time; at most this many frames used, spread evenly over the run.
    gate_m, sigma_model_m
        Points farther than this from a facing side are left out; model error added to the range noise.
    min_speed_mps
        Frames where the hull moves slower than this carry no timing information and are skipped.
    """
    S = len(scanners)
    stamps = np.asarray(frames.frame_stamps_s)
    F = len(stamps)
    ok = np.asarray(status_ok, dtype=bool) & np.isfinite(xytheta[:, 0])
    vel = _velocities(stamps, xytheta, np.asarray(track_id), ok)
    moving = ok & (np.hypot(vel[:, 0], vel[:, 1]) + 0.3 * np.abs(vel[:, 2]) >= min_speed_mps)
    idx = np.flatnonzero(moving)
    if idx.size > max_frames:
        idx = idx[np.linspace(0, idx.size - 1, max_frames).astype(int)]
    use = np.zeros(F, dtype=bool)
    use[idx] = True
    cluster = np.floor(stamps - stamps[0]).astype(int) if F else np.zeros(0, dtype=int)
    sums = _Sums(np.zeros((3 * S, 3 * S)), np.zeros(3 * S), {}, {}, np.zeros(S, dtype=int))
    for a in range(0, F, window):
        b = min(F, a + window)
        if not use[a:b].any():
            continue
        fp = frames.window(a, b, scans=False)
        _accumulate(sums, fp, scanners, model, xytheta[a:b], vel[a:b], use[a:b], cluster[a:b], gate_m,
                    sigma_model_m)
    theta, cov = _solve(sums, scanners)
    fits = [_fit(s, i, theta, cov, int(sums.counts[i])) for i, s in enumerate(scanners)]
    return _judge(fits, scanners, cov)


def _fit(scanner: LaserScanner, i: int, theta: np.ndarray, cov: np.ndarray, n: int) -> TimingFit:
    """The scanner's :class:`TimingFit` before any verdict: the declared slope plus the estimated error."""
    declared = declared_timing(scanner)
    if n == 0:
        return TimingFit(scanner.name, declared, math.nan, math.nan, math.nan, math.nan, 0)
    slope = declared_slope(scanner) + float(theta[2 * i + 1])
    sd = float(math.sqrt(max(cov[2 * i + 1, 2 * i + 1], 0.0)))
    # the delay offset at the stamp, as the declared stamp reference would have it
    ref = {StampAt.START: 0.0, StampAt.MIDDLE: -0.5, StampAt.END: -1.0}[scanner.stamp_at]
    off = float(theta[2 * i]) + ref * sweep_s(scanner) * declared_slope(scanner)
    off_sd = float(math.sqrt(max(cov[2 * i, 2 * i], 0.0)))
    return TimingFit(scanner.name, declared, slope, sd, 1000 * off, 1000 * off_sd, n)


def declared_slope(scanner: LaserScanner) -> float:
    return 0.0 if scanner.beam_timing == BeamTiming.SIMULTANEOUS else 1.0


def _nearest(slope: float) -> str:
    return min(SLOPES, key=lambda k: abs(SLOPES[k] - slope))


def _judge(fits: list[TimingFit], scanners: Sequence[LaserScanner], cov: np.ndarray) -> tuple[TimingFit, ...]:
    """Name what fits better where the declared timing does not fit. A scanner's own slope decides when
    it is more than 3 standard errors from the declared one and nearest another timing; scanners of one
    kind (the same declared timing and sweep time, usually one model) are also judged together, their
    slopes pooled (inverse-covariance weights): a pooled slope 3 standard errors off, nearest another
    timing, flags every scanner of the kind whose own slope is nearer that timing than the declared."""
    out = list(fits)
    kinds: dict[tuple[str, float], list[int]] = {}
    for i, (f, s) in enumerate(zip(fits, scanners, strict=True)):
        if f.n_points and np.isfinite(f.slope_sd):
            kinds.setdefault((f.declared, round(sweep_s(s), 5)), []).append(i)
    for idx in kinds.values():
        decl = declared_slope(scanners[idx[0]])
        C = cov[np.ix_([2 * i + 1 for i in idx], [2 * i + 1 for i in idx])]
        W = np.linalg.pinv(C)
        one = np.ones(len(idx))
        var = 1.0 / float(one @ W @ one)
        pooled = var * float(one @ W @ np.array([fits[i].slope for i in idx]))
        kind_best = _nearest(pooled)
        kind_off = kind_best != _nearest(decl) and abs(pooled - decl) > 3 * math.sqrt(var) and var < 0.3 ** 2
        for i in idx:
            f = fits[i]
            own = _nearest(f.slope)
            if own != _nearest(decl) and abs(f.slope - decl) > 3 * f.slope_sd and f.measured:
                out[i] = replace(f, fits_better=own)
            elif kind_off and abs(f.slope - SLOPES[kind_best]) < abs(f.slope - decl):
                out[i] = replace(f, fits_better=kind_best)
    return tuple(out)


def timing_check(fits: Sequence[TimingFit]) -> tuple[str, float, bool | None]:
    """The scanners' beam timing as one line of the summary: what it says, the largest distance (in
    standard errors) of a measured sweep slope from the declared one, and whether the rig's timing fits
    every scanner (None: nothing measurable). A mismatch names the scanners and what fits better."""
    seen = [f for f in fits if f.measured]
    z = max((abs(f.slope - (0.0 if f.declared == "simultaneous" else 1.0)) / f.slope_sd for f in seen),
            default=math.nan)
    if not seen and any(f.fits_better for f in fits):
        z = max(abs(f.slope - (0.0 if f.declared == "simultaneous" else 1.0)) / f.slope_sd for f in fits
                if f.fits_better)
    wrong = [f for f in fits if f.fits_better]
    if wrong:
        groups: dict[tuple[str, str], list[str]] = {}
        for f in wrong:
            groups.setdefault((f.fits_better, f.declared), []).append(f.scanner)
        text = "; ".join(f"beam timing of scanner{'s' if len(v) > 1 else ''} {', '.join(v)}: '{b}' fits the "
                         f"residuals better than the rig's '{d}'" for (b, d), v in groups.items())
        return text, z, False
    if not seen:
        return "beam timing: not measurable (the robot too slow or unseen)", z, None
    return "beam timing: the rig's fits every scanner measured", z, True
