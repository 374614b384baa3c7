"""Pair an estimate with a ground truth by time stamp, never by row.

Two ways, both vectorized (``np.searchsorted``, O((N + M) log M)):

- :func:`associate_nearest`: evo's rule (``evo.core.sync.associate_trajectories``, nearest time): the
  track with fewer poses is matched against the other one; each of its stamps takes the nearest stamp of
  the longer track within ``max_dt`` (ties to the earlier one), so no pose of the shorter track is lost and
  a pose of the longer one may serve twice. Same pairs as evo, pose for pose.
- :func:`associate_interpolate`: the estimate interpolated at the GT stamps (SE(3): positions linearly,
  rotations by slerp), so that every GT pose keeps its own covariance. A GT stamp is used only when the
  estimate samples around it are at most ``max_gap_s`` apart; the others fall in a *gap* (skipped and
  counted) instead of being bridged by a long straight line.

The estimate's stamps are moved onto the GT clock by ``t_offset_s`` (``t_gt = t_est + t_offset_s``,
evo's ``offset_2``); :func:`gtrig.evaluate.time_offset.estimate_time_offset` estimates it.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Literal

import numpy as np
from scipy.spatial.transform import Rotation, Slerp

from gtrig.errors import InputError
from gtrig.trajectory import PoseTrack

AssociationMethod = Literal["nearest", "interpolate"]


@dataclass(frozen=True)
class Association:
    """Two tracks made pose-for-pose comparable, and how.

    Attributes
    ----------
    gt, est : the paired poses, same length M, row i of one paired with row i of the other. ``gt`` keeps
        its covariance and status. Both carry the pair's stamp on the GT clock: the GT's for interpolated
        pairs, the shorter track's for nearest-stamp pairs (a pose of the longer one may serve twice).
    dt_s : (M,) ``t_est - t_gt`` of each pair after the offset (0 for interpolated pairs).
    method : ``"nearest"`` or ``"interpolate"``.
    max_dt_s : the nearest-stamp tolerance, or the longest estimate gap bridged by interpolation.
    t_offset_s : added to the estimate's stamps.
    n_gt, n_est : poses in the inputs.
    n_gt_outside : GT poses outside the estimate's span (interpolate) or without a partner (nearest).
    n_gt_in_gaps : GT poses inside the span but in a gap of the estimate longer than ``max_dt_s``.
    gaps_s : (K, 2) ``[t0, t1]`` of the estimate's gaps inside the common span (GT clock): intervals longer
        than ``max_dt_s`` (interpolate) or than three typical intervals and ``2 max_dt_s`` (nearest).
    n_est_unpaired : estimate poses without a partner (nearest; 0 for interpolate).
    """

    gt: PoseTrack
    est: PoseTrack
    dt_s: np.ndarray
    method: AssociationMethod
    max_dt_s: float
    t_offset_s: float
    n_gt: int
    n_est: int
    n_gt_outside: int
    n_gt_in_gaps: int
    gaps_s: np.ndarray
    n_est_unpaired: int = 0

    def __len__(self) -> int:
        return len(self.gt)

    def summary(self) -> dict[str, float | int | str]:
        """What was paired and what was skipped (for tables and the JSON output)."""
        return {
            "method": self.method,
            "matched": len(self),
            "gt_poses": self.n_gt,
            "est_poses": self.n_est,
            "gt_skipped_outside": self.n_gt_outside,
            "gt_skipped_in_gaps": self.n_gt_in_gaps,
            "est_unpaired": self.n_est_unpaired,
            "gaps": int(len(self.gaps_s)),
            "gap_time_s": float(np.sum(self.gaps_s[:, 1] - self.gaps_s[:, 0])) if len(self.gaps_s) else 0.0,
            "max_dt_s": self.max_dt_s,
            "t_offset_s": self.t_offset_s,
        }


def nearest_indices(stamps_1: np.ndarray, stamps_2: np.ndarray, max_dt_s: float) -> tuple[np.ndarray, np.ndarray]:
    """Indices ``(i1, i2)`` pairing each stamp of ``stamps_1`` with the nearest of ``stamps_2`` (sorted)
    within ``max_dt_s``; ties go to the earlier stamp of ``stamps_2`` (evo's binary-search rule).

    Parameters
    ----------
    stamps_1 : (N,) seconds, any order.
    stamps_2 : (M,) seconds, non-decreasing.
    """
    s1 = np.asarray(stamps_1, float)
    s2 = np.asarray(stamps_2, float)
    if s1.size == 0 or s2.size == 0:
        return np.zeros(0, int), np.zeros(0, int)
    inside = (s1 >= s2[0] - max_dt_s) & (s1 <= s2[-1] + max_dt_s)
    i1 = np.nonzero(inside)[0]
    q = s1[i1]
    up = np.minimum(np.searchsorted(s2, q, side="right"), s2.size - 1)
    diff_ub = s2[up] - q
    diff_lb = np.where(up > 0, q - s2[np.maximum(up - 1, 0)], np.inf)
    take_ub = (diff_ub <= max_dt_s) & (diff_ub < diff_lb)
    take_lb = ~take_ub & (diff_lb <= max_dt_s) & (diff_lb <= diff_ub)
    keep = take_ub | take_lb
    i2 = np.where(take_ub, up, up - 1)
    return i1[keep], i2[keep]


def _n_distinct(idx: np.ndarray, n: int) -> int:
    m = np.zeros(n, bool)
    m[idx] = True
    return int(np.count_nonzero(m))


def _take(track: PoseTrack, idx: np.ndarray, stamps_s: np.ndarray) -> PoseTrack:
    """The poses ``idx`` of ``track`` (repeats allowed) stamped ``stamps_s``."""
    n = len(track)
    if idx.size == n and (n == 0 or (idx[0] == 0 and idx[-1] == n - 1 and bool(np.all(np.diff(idx) == 1)))):
        return replace(track, stamps_s=stamps_s)  # every pose once, in order: no copy of 10^6 poses
    reasons = tuple(track.reasons[i] for i in idx) if any(track.reasons) else ("",) * len(idx)
    return replace(track, stamps_s=stamps_s, xyz=track.xyz[idx], quat_xyzw=track.quat_xyzw[idx],
                   cov=None if track.cov is None else track.cov[idx], status=track.status[idx], reasons=reasons)


def _gaps(stamps: np.ndarray, max_gap_s: float, t0: float, t1: float) -> np.ndarray:
    d = np.diff(stamps)
    k = np.nonzero(d > max_gap_s)[0]
    g = np.column_stack([stamps[k], stamps[k + 1]]) if k.size else np.zeros((0, 2))
    return g[(g[:, 1] > t0) & (g[:, 0] < t1)] if len(g) else g


def _check_units(gt: PoseTrack, est: PoseTrack, t_offset_s: float) -> None:
    """A clear error for the usual clock mistakes: nanoseconds against seconds, no common span."""
    if not len(gt) or not len(est):
        raise InputError(f"an empty trajectory ({len(gt)} GT poses, {len(est)} estimated poses)")
    g0, g1 = gt.span_s()
    e0, e1 = est.span_s()
    e0, e1 = e0 + t_offset_s, e1 + t_offset_s
    big = max(abs(g0), abs(g1)), max(abs(e0), abs(e1))
    lo, hi = min(big), max(big)
    if lo > 0 and hi / lo > 1e5 and hi > 1e12:
        which = "the GT" if big[0] > big[1] else "the estimate"
        raise InputError(
            f"time unit mismatch: {which}'s stamps are ~{hi:.3g}, the other's ~{lo:.3g} (nanoseconds against "
            "seconds?); convert one of them"
        )
    sg, se = g1 - g0, e1 - e0
    if sg > 0 and se > 0 and max(sg / se, se / sg) > 1e5:
        which = "the GT" if sg > se else "the estimate"
        raise InputError(
            f"time unit mismatch: {which} spans {max(sg, se):.3g} time units, the other {min(sg, se):.3g} "
            "(nanoseconds against seconds?); convert one of them"
        )
    if e1 < g0 or e0 > g1:
        raise InputError(
            f"no common time span: GT {g0:.3f}..{g1:.3f} s, estimate {e0:.3f}..{e1:.3f} s "
            f"(t_offset {t_offset_s:g} s)"
        )


def associate_nearest(gt: PoseTrack, est: PoseTrack, max_dt_s: float = 0.01,
                      t_offset_s: float = 0.0) -> Association:
    """Nearest-stamp pairs, evo's rule (module docstring); raises InputError when nothing pairs."""
    _check_units(gt, est, t_offset_s)
    est_on_gt = est.shifted(t_offset_s)
    if len(est) > len(gt):
        i_gt, i_est = nearest_indices(gt.stamps_s, est_on_gt.stamps_s, max_dt_s)
    else:
        i_est, i_gt = nearest_indices(est_on_gt.stamps_s, gt.stamps_s, max_dt_s)
    if i_gt.size == 0:
        raise InputError(f"no pose pairs within --max-dt {max_dt_s:g} s (t_offset {t_offset_s:g} s); "
                         "raise --max-dt, set --t-offset, or use --associate interpolate")
    # one pose of the longer track may serve two pairs, so both paired tracks carry the shorter one's stamps
    # (strictly increasing); dt_s keeps the true stamp differences
    short_stamps = gt.stamps_s[i_gt] if len(est) > len(gt) else est_on_gt.stamps_s[i_est]
    dt = est_on_gt.stamps_s[i_est] - gt.stamps_s[i_gt]
    g = _take(gt, i_gt, short_stamps)
    e = _take(est_on_gt, i_est, short_stamps)
    lo, hi = max(gt.stamps_s[0], est_on_gt.stamps_s[0]), min(gt.stamps_s[-1], est_on_gt.stamps_s[-1])
    # a dropout of the estimate: an interval over three of its typical ones (and over the tolerance)
    med = float(np.median(np.diff(est_on_gt.stamps_s))) if len(est) > 1 else 0.0
    gaps = _gaps(est_on_gt.stamps_s, max(2 * max_dt_s, 3 * med), lo, hi)
    es = est_on_gt.stamps_s
    in_span = (gt.stamps_s >= es[0] - max_dt_s) & (gt.stamps_s <= es[-1] + max_dt_s)
    n_outside = int(np.sum(~in_span))
    # a denser GT has poses no estimate pose asks for, by design; a sparser one has poses without partner
    n_in_gaps = int(np.sum(in_span)) - _n_distinct(i_gt, len(gt)) if len(est) > len(gt) else 0
    return Association(g, e, dt, "nearest", float(max_dt_s), float(t_offset_s),
                       len(gt), len(est), n_outside, n_in_gaps, gaps, len(est) - _n_distinct(i_est, len(est)))


def interpolate_track(track: PoseTrack, stamps_s: np.ndarray) -> PoseTrack:
    """``track`` at ``stamps_s`` (inside its span): positions linearly, rotations by slerp (SE(3) interpolation
    on SO(3) x R^3, as evo's ``PoseTrajectory3D.interpolate``). Covariances, when present, are interpolated
    element-wise (a convex combination of covariances is one)."""
    t = np.asarray(stamps_s, float)
    s = track.stamps_s
    k = np.clip(np.searchsorted(s, t, side="right") - 1, 0, len(s) - 2)
    w = ((t - s[k]) / (s[k + 1] - s[k]))[:, None]
    xyz = (1 - w) * track.xyz[k] + w * track.xyz[k + 1]
    rot = Slerp(s, Rotation.from_quat(track.quat_xyzw))(np.clip(t, s[0], s[-1]))
    q = rot.as_quat()
    q[q[:, 3] < 0] *= -1
    cov = None
    if track.cov is not None:
        cov = (1 - w[:, :, None]) * track.cov[k] + w[:, :, None] * track.cov[k + 1]
    return PoseTrack(t, xyz, q, cov, track.cov_kind, np.maximum(track.status[k], track.status[k + 1]),
                     tuple("" for _ in range(t.size)), track.source, track.frame_id, track.child_frame_id)


def associate_interpolate(gt: PoseTrack, est: PoseTrack, max_gap_s: float = 0.2,
                          t_offset_s: float = 0.0) -> Association:
    """The estimate interpolated at every GT stamp inside its span and not in a gap (module docstring)."""
    _check_units(gt, est, t_offset_s)
    if len(est) < 2:
        raise InputError("the estimate has fewer than two poses: nothing to interpolate")
    e = est.shifted(t_offset_s)
    s = e.stamps_s
    t = gt.stamps_s
    inside = (t >= s[0]) & (t <= s[-1])
    k = np.clip(np.searchsorted(s, t, side="right") - 1, 0, len(s) - 2)
    bridged = (s[k + 1] - s[k]) <= max_gap_s
    # a GT stamp equal to an estimate stamp is never in a gap, whatever the neighbours
    exact = np.isin(t, s)
    ok = inside & (bridged | exact)
    if not np.any(ok):
        raise InputError(f"no GT stamp inside the estimate's span outside gaps longer than {max_gap_s:g} s "
                         f"(t_offset {t_offset_s:g} s)")
    g = gt.select(ok)
    ei = interpolate_track(e, g.stamps_s)
    lo, hi = max(t[0], s[0]), min(t[-1], s[-1])
    return Association(g, ei, np.zeros(len(g)), "interpolate", float(max_gap_s), float(t_offset_s), len(gt),
                       len(est), int(np.sum(~inside)), int(np.sum(inside & ~ok)), _gaps(s, max_gap_s, lo, hi))


def associate(gt: PoseTrack, est: PoseTrack, method: AssociationMethod = "nearest",
              max_dt_s: float | None = None, t_offset_s: float = 0.0) -> Association:
    """Dispatch on ``method``; ``max_dt_s`` defaults to evo's 0.01 s (nearest) and 0.2 s (interpolate)."""
    if method == "nearest":
        return associate_nearest(gt, est, 0.01 if max_dt_s is None else max_dt_s, t_offset_s)
    if method == "interpolate":
        return associate_interpolate(gt, est, 0.2 if max_dt_s is None else max_dt_s, t_offset_s)
    raise InputError(f"--associate must be nearest or interpolate, got {method!r}")
