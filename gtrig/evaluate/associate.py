"""Pair an estimate with a ground truth by time stamp, never by row.

Three ways, all vectorized (``np.searchsorted``, O((N + M) log M)):

- :func:`associate_nearest` (``nearest``): evo's rule (``evo.core.sync.associate_trajectories``, nearest
  time): the track with fewer poses is matched against the other one; each of its stamps takes the nearest
  stamp of the longer track within ``max_dt`` (ties to the earlier one), so no pose of the shorter track is
  lost and a pose of the longer one may serve twice. Same pairs as evo, pose for pose. The motion between
  the two stamps of a pair counts as error.
- :func:`associate_interpolate` (``interpolate``): the estimate interpolated at the GT stamps (SE(3):
  positions linearly, rotations by slerp), so that every GT pose keeps its own covariance.
- :func:`associate_interpolate_gt` (``interpolate-gt``): the GT interpolated at the estimate's stamps (its
  covariance interpolated element-wise), as evo's ``SyncMethod.interpolation`` does when the GT is the
  longer track.

An interpolated track is used only where it is dense enough: a stamp is paired only when the two samples
around it are at most ``max_gap_s`` apart; the others fall in a *gap* (skipped and counted) instead of
being bridged by a long straight line. :func:`associate` with ``method="auto"`` (the CLI's default)
interpolates the denser track at the sparser one's stamps, so that no motion between two stamps is counted
as error, and :func:`default_max_dt` sizes the tolerance from the sample periods when none is given.

Counting: the pairs take the stamps of one track, the *anchor* (the GT for ``interpolate``, the estimate
for ``interpolate-gt``, the shorter track for ``nearest``). Each anchor pose is exactly one of: paired,
outside the other track's span, or in a gap of the other track (for ``nearest``: inside the span but
without a partner within ``max_dt``); :meth:`Association.summary` gives the three counts, which add up to
the anchor's poses.

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

AssociationMethod = Literal["nearest", "interpolate", "interpolate-gt"]
#: what ``--associate`` takes: a method, or ``auto`` (the denser track interpolated)
AssociationChoice = Literal["auto", "nearest", "interpolate", "interpolate-gt"]
METHODS: tuple[str, ...] = ("auto", "nearest", "interpolate", "interpolate-gt")
Anchor = Literal["gt", "est"]

#: nearest: the tolerance is at least evo's 0.01 s, else this share of the longer track's median period
NEAREST_PERIOD_SHARE = 0.75
#: interpolation: the longest interval bridged, in median sample periods of the interpolated track
GAP_PERIODS = 3.0


@dataclass(frozen=True)
class Association:
    """Two tracks made pose-for-pose comparable, and how.

    Attributes
    ----------
    gt, est : the paired poses, same length M, row i of one paired with row i of the other. ``gt`` keeps
        its covariance and status (interpolated element-wise for ``interpolate-gt``). Both carry the pair's
        stamp on the GT clock: the anchor's (module docstring).
    dt_s : (M,) ``t_est - t_gt`` of each pair after the offset (0 for interpolated pairs).
    method : ``"nearest"``, ``"interpolate"`` or ``"interpolate-gt"``.
    max_dt_s : the nearest-stamp tolerance, or the longest interval of the interpolated track bridged.
    t_offset_s : added to the estimate's stamps.
    n_gt, n_est : poses in the inputs.
    anchor : whose stamps the pairs take, ``"gt"`` or ``"est"``.
    n_anchor_outside : anchor poses outside the other track's span (nearest: the span +- ``max_dt_s``).
    n_anchor_in_gaps : anchor poses inside that span but in a gap of the other track (nearest: without a
        partner within ``max_dt_s``). ``len(self) + n_anchor_outside + n_anchor_in_gaps`` is the anchor's
        pose count.
    gaps_s : (K, 2) ``[t0, t1]`` of the other track's gaps inside the common span (GT clock): intervals
        longer than ``max_dt_s`` (interpolation) or than three typical intervals and ``2 max_dt_s`` (nearest).
    n_other_used : distinct poses of the other track in a pair (nearest) or around an interpolated stamp.
    auto : True when :func:`associate` chose the method (``method="auto"``).
    max_dt_auto : True when ``max_dt_s`` was sized from the sample periods (:func:`default_max_dt`).
    """

    gt: PoseTrack
    est: PoseTrack
    dt_s: np.ndarray
    method: AssociationMethod
    max_dt_s: float
    t_offset_s: float
    n_gt: int
    n_est: int
    anchor: Anchor
    n_anchor_outside: int
    n_anchor_in_gaps: int
    gaps_s: np.ndarray
    n_other_used: int = 0
    auto: bool = False
    max_dt_auto: bool = False

    def __len__(self) -> int:
        return len(self.gt)

    @property
    def n_anchor(self) -> int:
        return self.n_gt if self.anchor == "gt" else self.n_est

    def summary(self) -> dict[str, float | int | str]:
        """What was paired and what was skipped (for tables and the JSON output); ``matched +
        anchor_outside + anchor_in_gaps == anchor_poses``."""
        return {
            "method": self.method,
            "chosen": "auto" if self.auto else "given",
            "matched": len(self),
            "gt_poses": self.n_gt,
            "est_poses": self.n_est,
            "paired_at": "gt" if self.anchor == "gt" else "estimate",
            "anchor_poses": self.n_anchor,
            "anchor_outside": self.n_anchor_outside,
            "anchor_in_gaps": self.n_anchor_in_gaps,
            "other_used": self.n_other_used,
            "gaps": int(len(self.gaps_s)),
            "gap_time_s": float(np.sum(self.gaps_s[:, 1] - self.gaps_s[:, 0])) if len(self.gaps_s) else 0.0,
            "max_dt_s": self.max_dt_s,
            "max_dt_from": "sample periods" if self.max_dt_auto else "given",
            "t_offset_s": self.t_offset_s,
        }

    def describe(self) -> str:
        """One line: which association, how chosen, and the counts that add up."""
        anchor, other = ("GT", "estimate") if self.anchor == "gt" else ("estimate", "GT")
        how = {"nearest": f"each {anchor} stamp with the nearest {other} stamp within {self.max_dt_s:g} s; "
                          "the motion between the two stamps counts as error",
               "interpolate": f"the estimate interpolated at the GT stamps, over intervals up to "
                              f"{self.max_dt_s:g} s",
               "interpolate-gt": f"the GT interpolated at the estimate's stamps, over intervals up to "
                                 f"{self.max_dt_s:g} s"}[self.method]
        chosen = []
        if self.auto:
            chosen.append(f"chosen as the {other} is the denser track" if self.method != "nearest" else "auto")
        if self.max_dt_auto:
            chosen.append("tolerance from the sample periods")
        gap_word = "without a partner" if self.method == "nearest" else f"in the {other}'s gaps"
        return (f"association {self.method} ({how}{'; ' if chosen else ''}{', '.join(chosen)}): "
                f"{len(self)} pairs at the {anchor}'s stamps; of the {anchor}'s {self.n_anchor} poses "
                f"{len(self)} paired + {self.n_anchor_outside} outside the {other}'s span + "
                f"{self.n_anchor_in_gaps} {gap_word}; {self.n_other_used} of the {other}'s "
                f"{self.n_est if self.anchor == 'gt' else self.n_gt} poses used; t_offset {self.t_offset_s:.6g} s")


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


def mutual_nearest_indices(stamps_1: np.ndarray, stamps_2: np.ndarray, max_dt_s: float
                           ) -> tuple[np.ndarray, np.ndarray]:
    """Indices ``(i1, i2)`` of the stamps that are each other's nearest within ``max_dt_s``: every pose
    serves at most one pair, so a sparser track's pose is never paired with two poses of a denser one
    (the pose at its own stamp, not its neighbour's).

    Parameters
    ----------
    stamps_1, stamps_2 : (N,), (M,) seconds, increasing.
    """
    i1, i2 = nearest_indices(stamps_1, stamps_2, max_dt_s)
    back2, back1 = nearest_indices(np.asarray(stamps_2, float)[i2], stamps_1, max_dt_s)
    mutual = np.zeros(i1.size, bool)
    mutual[back2] = back1 == i1[back2]
    return i1[mutual], i2[mutual]


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
    gt_anchor = len(est) > len(gt)
    if gt_anchor:
        i_gt, i_est = nearest_indices(gt.stamps_s, est_on_gt.stamps_s, max_dt_s)
    else:
        i_est, i_gt = nearest_indices(est_on_gt.stamps_s, gt.stamps_s, max_dt_s)
    if i_gt.size == 0:
        raise InputError(f"no pose pairs within --max-dt {max_dt_s:g} s (t_offset {t_offset_s:g} s); "
                         "raise --max-dt, set --t-offset, or use --associate interpolate")
    # one pose of the longer track may serve two pairs, so both paired tracks carry the shorter one's stamps
    # (strictly increasing); dt_s keeps the true stamp differences
    short_stamps = gt.stamps_s[i_gt] if gt_anchor else est_on_gt.stamps_s[i_est]
    dt = est_on_gt.stamps_s[i_est] - gt.stamps_s[i_gt]
    g = _take(gt, i_gt, short_stamps)
    e = _take(est_on_gt, i_est, short_stamps)
    lo, hi = max(gt.stamps_s[0], est_on_gt.stamps_s[0]), min(gt.stamps_s[-1], est_on_gt.stamps_s[-1])
    anchor_s, other_s = (gt.stamps_s, est_on_gt.stamps_s) if gt_anchor else (est_on_gt.stamps_s, gt.stamps_s)
    # a dropout of the other track: an interval over three of its typical ones (and over the tolerance)
    med = float(np.median(np.diff(other_s))) if len(other_s) > 1 else 0.0
    gaps = _gaps(other_s, max(2 * max_dt_s, 3 * med), lo, hi)
    in_span = (anchor_s >= other_s[0] - max_dt_s) & (anchor_s <= other_s[-1] + max_dt_s)
    n_outside = int(np.sum(~in_span))
    n_paired = len(short_stamps)
    n_used = _n_distinct(i_est, len(est)) if gt_anchor else _n_distinct(i_gt, len(gt))
    return Association(g, e, dt, "nearest", float(max_dt_s), float(t_offset_s), len(gt), len(est),
                       "gt" if gt_anchor else "est", n_outside, int(np.sum(in_span)) - n_paired, gaps, n_used)


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


@dataclass(frozen=True)
class _Bracketed:
    """Which stamps of a sparse track a dense track can be interpolated at."""

    inside: np.ndarray  # (n,) bool: within the dense track's span
    ok: np.ndarray  # (n,) bool: inside and between two dense samples at most max_gap_s apart (or on one)
    n_used: int  # distinct dense samples around an ok stamp


def _bracket(dense_s: np.ndarray, t: np.ndarray, max_gap_s: float) -> _Bracketed:
    inside = (t >= dense_s[0]) & (t <= dense_s[-1])
    k = np.clip(np.searchsorted(dense_s, t, side="right") - 1, 0, len(dense_s) - 2)
    bridged = (dense_s[k + 1] - dense_s[k]) <= max_gap_s
    # a stamp equal to a dense stamp is never in a gap, whatever the neighbours
    ok = inside & (bridged | np.isin(t, dense_s))
    used = np.zeros(len(dense_s), bool)
    used[k[ok]] = True
    used[k[ok] + 1] = True
    return _Bracketed(inside, ok, int(np.count_nonzero(used)))


def associate_interpolate(gt: PoseTrack, est: PoseTrack, max_gap_s: float = 0.2,
                          t_offset_s: float = 0.0) -> Association:
    """The estimate interpolated at every GT stamp inside its span and not in a gap (module docstring)."""
    _check_units(gt, est, t_offset_s)
    if len(est) < 2:
        raise InputError("the estimate has fewer than two poses: nothing to interpolate")
    e = est.shifted(t_offset_s)
    s, t = e.stamps_s, gt.stamps_s
    b = _bracket(s, t, max_gap_s)
    if not np.any(b.ok):
        raise InputError(f"no GT stamp inside the estimate's span outside gaps longer than {max_gap_s:g} s "
                         f"(t_offset {t_offset_s:g} s)")
    g = gt.select(b.ok)
    ei = interpolate_track(e, g.stamps_s)
    lo, hi = max(t[0], s[0]), min(t[-1], s[-1])
    return Association(g, ei, np.zeros(len(g)), "interpolate", float(max_gap_s), float(t_offset_s), len(gt),
                       len(est), "gt", int(np.sum(~b.inside)), int(np.sum(b.inside & ~b.ok)),
                       _gaps(s, max_gap_s, lo, hi), b.n_used)


def associate_interpolate_gt(gt: PoseTrack, est: PoseTrack, max_gap_s: float = 0.2,
                             t_offset_s: float = 0.0) -> Association:
    """The GT interpolated at every estimate stamp inside its span and not in a gap (module docstring)."""
    _check_units(gt, est, t_offset_s)
    if len(gt) < 2:
        raise InputError("the GT has fewer than two poses: nothing to interpolate")
    e = est.shifted(t_offset_s)
    s, t = gt.stamps_s, e.stamps_s
    b = _bracket(s, t, max_gap_s)
    if not np.any(b.ok):
        raise InputError(f"no estimate stamp inside the GT's span outside gaps longer than {max_gap_s:g} s "
                         f"(t_offset {t_offset_s:g} s)")
    ep = e.select(b.ok)
    gi = interpolate_track(gt, ep.stamps_s)
    lo, hi = max(t[0], s[0]), min(t[-1], s[-1])
    return Association(gi, ep, np.zeros(len(ep)), "interpolate-gt", float(max_gap_s), float(t_offset_s),
                       len(gt), len(est), "est", int(np.sum(~b.inside)), int(np.sum(b.inside & ~b.ok)),
                       _gaps(s, max_gap_s, lo, hi), b.n_used)


def median_period_s(track: PoseTrack) -> float:
    """The median interval between consecutive stamps (s); ``inf`` for fewer than two poses."""
    return float(np.median(np.diff(track.stamps_s))) if len(track) > 1 else float("inf")


def choose_method(gt: PoseTrack, est: PoseTrack) -> AssociationMethod:
    """``auto``'s choice: the denser track (the shorter median period) interpolated at the other one's
    stamps; the GT when both are alike."""
    return "interpolate-gt" if median_period_s(gt) <= median_period_s(est) else "interpolate"


def default_max_dt(method: AssociationMethod, gt: PoseTrack, est: PoseTrack) -> float:
    """The tolerance when none is given, from the sample periods.

    ``nearest``: evo's 0.01 s, or :data:`NEAREST_PERIOD_SHARE` of the longer track's median period when
    that is more (the nearest stamp of a regular track is at most half a period away). Interpolation:
    :data:`GAP_PERIODS` median periods of the interpolated track (a dropped sample or two are bridged, a
    dropout is not).
    """
    if method == "nearest":
        longer = est if len(est) > len(gt) else gt
        return max(0.01, NEAREST_PERIOD_SHARE * median_period_s(longer)) if len(longer) > 1 else 0.01
    dense = gt if method == "interpolate-gt" else est
    return GAP_PERIODS * median_period_s(dense) if len(dense) > 1 else 0.2


def associate(gt: PoseTrack, est: PoseTrack, method: AssociationChoice = "auto",
              max_dt_s: float | None = None, t_offset_s: float = 0.0) -> Association:
    """Dispatch on ``method`` (``auto``: :func:`choose_method`); ``max_dt_s`` defaults to
    :func:`default_max_dt`. The result says whether the method and the tolerance were chosen."""
    if method not in METHODS:
        raise InputError(f"--associate must be one of {', '.join(METHODS)}, got {method!r}")
    chosen: AssociationMethod = choose_method(gt, est) if method == "auto" else method
    tol = default_max_dt(chosen, gt, est) if max_dt_s is None else float(max_dt_s)
    run = {"nearest": associate_nearest, "interpolate": associate_interpolate,
           "interpolate-gt": associate_interpolate_gt}[chosen]
    a = run(gt, est, tol, t_offset_s)
    return replace(a, auto=method == "auto", max_dt_auto=max_dt_s is None)
