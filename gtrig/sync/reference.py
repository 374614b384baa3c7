"""The reference a sensor is timed against (GT fixes smoothed by the constant-velocity model, no
odometry) and the pieces every per-sensor offset fit shares: the cost curve's score, the ridge, the
block jackknife and the verdict."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.stats import t as student_t

from gtrig.errors import InputError
from gtrig.fusion.fuse import FusionOptions, fuse
from gtrig.fusion.measurements import Fixes
from gtrig.fusion.process import OdometryJumps
from gtrig.sync.offset import OffsetEstimate, Verdict

_NAN2 = (float("nan"), float("nan"))


# ------------------------------------------------------------------------------------------ reference
@dataclass(frozen=True)
class Reference:
    """A smoothed trajectory to time sensors against: stamps (N,) on its sources' clock, poses (N, 3)
    world (x, y m, yaw rad unwrapped), velocities (N, 3) per second, covariances (N, 3, 3)."""

    stamps_s: np.ndarray
    xytheta: np.ndarray
    velocity: np.ndarray
    cov: np.ndarray

    def at(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Poses and velocities (M, 3) at ``t`` (M,), linearly interpolated."""
        P = np.column_stack([np.interp(t, self.stamps_s, self.xytheta[:, k]) for k in range(3)])
        V = np.column_stack([np.interp(t, self.stamps_s, self.velocity[:, k]) for k in range(3)])
        return P, V

    def covers(self, t: np.ndarray, margin_s: float) -> np.ndarray:
        return (t >= self.stamps_s[0] + margin_s) & (t <= self.stamps_s[-1] - margin_s)


#: a reference longer than this is smoothed in windows of this length (seconds), each with
#: :data:`REFERENCE_OVERLAP_S` more fixes on either side (one batch over an hour held ~600 MB)
REFERENCE_WINDOW_S = 600.0
#: the fixes beyond each window's ends that its smoothing sees: a fix's pull on the constant-velocity
#: smoothing dies out within seconds, so with 30 s of them the kept part of a window is the whole batch's
#: to 1e-13 m on a synthetic 1000 s run (tests/sync/test_sensors.py)
REFERENCE_OVERLAP_S = 30.0


def jump_stamps(fixes: list[Fixes], jumps: OdometryJumps | None = None) -> np.ndarray:
    """Stamps (s) where a source's consecutive fixes move faster than the robot can (``jumps``; position
    fixes by their position alone): each the first fix after a jump, as a recording joined from laps or a
    relocalised robot shows (default :class:`~gtrig.fusion.process.OdometryJumps`). Sorted, unique."""
    jumps = OdometryJumps() if jumps is None else jumps
    out = []
    for f in fixes:
        if len(f) < 2:
            continue
        d = np.diff(f.value, axis=0)
        dist = np.hypot(d[:, 0], d[:, 1])
        turn = np.abs((d[:, 2] + np.pi) % (2 * np.pi) - np.pi) if f.dim == 3 else np.zeros(dist.size)
        dt = np.diff(f.stamps_s)
        hit = (dist > jumps.max_speed_mps * dt + jumps.tol_m) | (turn > jumps.max_yaw_rate_radps * dt + jumps.tol_rad)
        out.append(f.stamps_s[1:][hit])
    return np.unique(np.concatenate(out)) if out else np.zeros(0)


def reference_track(fixes: list[Fixes], rate_hz: float = 50.0, max_gap_s: float = 0.5,
                    window_s: float = REFERENCE_WINDOW_S, overlap_s: float = REFERENCE_OVERLAP_S) -> Reference:
    """The fixes smoothed by the constant-velocity model (robust batch MAP, no odometry) on a ``rate_hz``
    grid, one segment per stretch without a gap over ``max_gap_s``; the fits use only times with poses of
    the reference within 50 ms on both sides, so no gap is interpolated across.

    Where the fixes jump (:func:`jump_stamps`) the reference is cut: smoothed across, the constant-velocity
    model made the robot cross the room in a few frames there, and those speeds, a thousand times the
    robot's, outweighed every other time of the offset fits (a lapped recording's scanner offsets 2-14 ms
    off, its cameras' intervals 25-80 ms wide). Each piece between jumps is smoothed on its own.

    Fixes spanning more than ``window_s`` are smoothed a window of ``window_s`` at a time (each seeing
    ``overlap_s`` of fixes beyond its ends, its own part kept), so that the memory does not grow with the
    recording's length; a shorter span is one batch, as before."""
    cuts = jump_stamps(fixes)
    if cuts.size == 0:
        return _reference_between_jumps(fixes, rate_hz, max_gap_s, window_s, overlap_s)
    edges = np.r_[-np.inf, cuts, np.inf]
    parts = []
    for a, b in zip(edges[:-1], edges[1:], strict=True):
        # the piece's fixes: from the first fix after a jump up to, not including, the next jump's
        sel = [f.between(a, np.nextafter(b, -np.inf)) for f in fixes]
        if sum(len(f) for f in sel) < 3:
            continue
        try:
            parts.append(_reference_between_jumps([f for f in sel if len(f)], rate_hz, max_gap_s, window_s, overlap_s))
        except InputError:  # a few scattered fixes between two jumps: nothing to smooth
            continue
    return _joined(parts)


def _joined(parts: list[Reference]) -> Reference:
    """References of successive spans as one (yaw unwrapped over the whole)."""
    if not parts:
        raise InputError("fusion: no segment with at least three fixes")
    xyt = np.concatenate([p.xytheta for p in parts])
    xyt[:, 2] = np.unwrap(xyt[:, 2])  # each part's yaw was unwrapped from its own start
    return Reference(np.concatenate([p.stamps_s for p in parts]), xyt, np.concatenate([p.velocity for p in parts]),
                     np.concatenate([p.cov for p in parts]))


def _reference_between_jumps(fixes: list[Fixes], rate_hz: float, max_gap_s: float, window_s: float,
                             overlap_s: float) -> Reference:
    """:func:`reference_track` of fixes without a jump: one batch, or windows of ``window_s``."""
    t0 = min(float(f.stamps_s[0]) for f in fixes if len(f))
    t1 = max(float(f.stamps_s[-1]) for f in fixes if len(f))
    if t1 - t0 <= window_s:
        return _reference_part(fixes, rate_hz, max_gap_s)
    parts = []
    n_win = int(np.ceil((t1 - t0) / window_s))
    for w in range(n_win):
        a, b = t0 + w * window_s, (t0 + (w + 1) * window_s if w + 1 < n_win else np.inf)
        sel = [f.between(a - overlap_s, b + overlap_s) for f in fixes]
        if sum(len(f) for f in sel) < 3:
            continue
        try:
            ref = _reference_part([f for f in sel if len(f)], rate_hz, max_gap_s)
        except InputError:  # a window of a few scattered fixes (a long gap) has no segment to smooth
            continue
        keep = (ref.stamps_s >= a) & (ref.stamps_s < b)
        parts.append(Reference(ref.stamps_s[keep], ref.xytheta[keep], ref.velocity[keep], ref.cov[keep]))
    return _joined(parts)


def _reference_part(fixes: list[Fixes], rate_hz: float, max_gap_s: float) -> Reference:
    """:func:`reference_track` of fixes smoothed in one batch."""
    # no innovation weighting: one source against a constant-velocity prediction has no other to
    # disagree with (its turns would read as disagreement)
    track, _ = fuse(fixes, None, FusionOptions(rate_hz=rate_hz, max_gap_s=max_gap_s, innovation_window_s=0.0))
    xyt = track.xytheta()
    xyt[:, 2] = np.unwrap(xyt[:, 2])
    vel = np.gradient(xyt, track.stamps_s, axis=0)
    cov = track.cov_xytheta()
    assert cov is not None  # fusion always gives one
    return Reference(track.stamps_s, xyt, vel, cov)


def near_reference(ref: Reference, t: np.ndarray, tol_s: float) -> np.ndarray:
    """True where ``t`` has reference poses within ``tol_s`` on both sides (no interpolation over gaps)."""
    k = np.clip(np.searchsorted(ref.stamps_s, t), 1, ref.stamps_s.size - 1)
    return (t - ref.stamps_s[k - 1] <= tol_s) & (ref.stamps_s[k] - t <= tol_s) & ref.covers(t, 0.0)


# ------------------------------------------------------------------------------------------ the fit
def cost_score(cost: np.ndarray) -> np.ndarray:
    """``min cost / cost`` of a cost curve: 1 at its minimum; 0 where the cost is 0 (no observation)."""
    return np.divide(cost.min(), cost, out=np.zeros_like(cost), where=cost > 0)


def ridge(H: np.ndarray) -> np.ndarray:
    """A ridge far below any informed direction of ``H``: what nobody informs (a hull side never seen, the
    difference of two cameras always seen together) stays at zero, and its variance comes out huge."""
    return 1e-12 * max(float(np.trace(H)) / H.shape[0], 1e-300) * np.eye(H.shape[0])


def jackknife(H_b: np.ndarray, g_b: np.ndarray, cols: np.ndarray, L: np.ndarray | None = None,
               ) -> tuple[np.ndarray, np.ndarray, int]:
    """Solve ``sum_b H_b x = -sum_b g_b`` (blocks (B, n, n), (B, n)) and the jackknife standard error of
    ``x[cols]`` (or, with ``L`` (k, len(cols)), of ``L x[cols]``); returns (x, se, number of blocks with
    data)."""
    H, g = H_b.sum(axis=0) + ridge(H_b.sum(axis=0)), g_b.sum(axis=0)
    x = -np.linalg.solve(H, g)
    used = np.flatnonzero(np.abs(g_b).sum(axis=1) > 0)
    B = used.size
    Lm = np.eye(cols.size) if L is None else L
    if B < 3:
        return x, np.full(Lm.shape[0], np.inf), B
    loo = np.array([Lm @ -np.linalg.solve(H - H_b[b], g - g_b[b])[cols] for b in used])
    se = np.sqrt((B - 1) / B * np.sum((loo - loo.mean(axis=0)) ** 2, axis=0))
    return x, se, B


def offset_verdict(name: str, tau: float, se: float, white_se: float, B: int, taus: np.ndarray, curve: np.ndarray,
             max_ci_s: float, n_obs: int, min_obs: int) -> OffsetEstimate:
    half = float(student_t.ppf(0.975, max(B - 1, 1))) * se if np.isfinite(se) else float("inf")
    v: Verdict = "ok"
    if n_obs < min_obs or B < 3:
        v, reason = "unobservable", f"{n_obs} observations in {B} blocks of time"
    elif 2 * 1.96 * white_se > max_ci_s:
        v, reason = "unobservable", "the robot hardly moves in this sensor's view"
    elif 2 * half > max_ci_s:
        v, reason = "ambiguous", f"the 95 % interval ({2 * half * 1e3:.1f} ms) is wider than {max_ci_s * 1e3:.1f} ms"
    elif curve.size and abs(taus[int(np.argmax(curve))] - tau) > 2 * (taus[1] - taus[0]) + half:
        v, reason = "ambiguous", "the fit's cost has its minimum away from the estimate"
    else:
        reason = f"{n_obs} observations, {B} blocks of time"
    if v != "ok":
        return OffsetEstimate(name, v, float("nan"), _NAN2, float("nan"), float("nan"), float("nan"), taus, curve,
                              B, reason)
    return OffsetEstimate(name, "ok", tau, (tau - half, tau + half), float("nan"), 1.0, float("nan"), taus, curve,
                          B, reason)
