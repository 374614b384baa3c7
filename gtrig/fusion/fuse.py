"""One smoothed trajectory from any GT sources and odometry: ``fuse`` and ``fuse_tracks``.

Steps: put every source on the reference (odometry) clock with its offset (gtrig.sync.offset); split the
span where no source sees the robot for longer than ``max_gap_s``; per segment, nodes at the odometry
stamps (or a fixed rate), one factor per odometry increment (or constant velocity) and one per fix at
its own stamp; a robust start (gtrig.fusion.init); the gated EKF + RTS (gtrig.fusion.ekf); then, by
default, the batch MAP solve with a Huber loss from the EKF's estimate (gtrig.fusion.batch), with marginal
covariances. The output has one pose per node inside the sources' span, each ``OK`` (observed) or
``BRIDGED`` (carried by odometry through a gap, its length in the reason), with the (x, y, yaw) marginal
covariance; the report names every rejected fix by source and stamp.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import asdict, dataclass, field, replace
from functools import partial
from typing import Any, Literal

import numpy as np

from gtrig.errors import ConvergenceError, InputError
from gtrig.fusion.batch import considered_covariance, smooth_batch
from gtrig.fusion.chain import PROCESS_CV, PROCESS_ODOMETRY, FactorChain
from gtrig.fusion.ekf import smooth_ekf
from gtrig.fusion.init import odom_in_world
from gtrig.fusion.measurements import Fixes, FixModel, fixes_from_track
from gtrig.fusion.odonoise import NoiseFit, fit_odometry_noise
from gtrig.fusion.process import (
    ConstantVelocityNoise,
    OdometryJumps,
    OdometryNoise,
    constant_velocity_cov,
    cut_at_jumps,
    interpolate_odometry,
    odometry_increments,
    odometry_jumps,
    whitening,
)
from gtrig.io.odometry import OdometryLog
from gtrig.trajectory import PoseStatus, PoseTrack


@dataclass(frozen=True)
class FusionOptions:
    """How to fuse.

    Attributes
    ----------
    estimator : ``"batch"`` (EKF + RTS start, then the robust MAP solve) or ``"ekf"`` (the seeds' EKF +
        RTS alone).
    rate_hz : None: one pose per odometry stamp; a number: a regular grid at that rate (the constant
        velocity model uses 50 Hz when None).
    offsets_s : per source, its clock minus the reference clock (``gtrig sync``); subtracted from its stamps.
    offsets_sigma_s : per source, the standard error of that offset (``gtrig sync``'s 95 % half-width / 1.96).
        The fused poses are stamped on the reference clock, so an offset wrong by ``dt`` puts every pose
        ``v dt`` off along the motion (``v`` the node's velocity): each node's covariance gains
        ``sigma_t^2 v v^T`` with ``sigma_t`` the smallest sigma of the sources whose offsets were applied
        (their errors, mostly the odometry's, are shared). Missing: 0.
    max_gap_s : a longer span without any fix ends a segment (None: odometry bridges every gap).
    bridge_after_s : poses inside a gap between accepted fixes longer than this are BRIDGED.
    gate_prob : chi-square gate of each fix's innovation (probability of keeping a good fix).
    gate_own_cov : the gate tests each fix's innovation against the fix's own covariance plus the
        prediction's (True), or against the covariance inflated for correlation (False).
    huber_k : Huber threshold (sigmas) of the batch solve.
    innovation_window_s : the batch solve weighs each fix with its covariance times the mean normalised
        innovation squared per dof of its source's fixes within this window (the gate's, at least 1):
        a source that disagrees with the prediction over a stretch by more than its covariance allows is
        down-weighted there. 0: off.
    odometry : the odometry noise model (the start of its fit, with ``fit_odometry_noise``); cv : the
        constant-velocity model (no odometry).
    fit_odometry_noise : the odometry's random errors (the wheels' slip per metre, the side slip at its
        stated ratio to it, and a floor per second) fitted to how far it and the pose sources disagree over
        windows of a few seconds, the sources' own noise taken out (gtrig.fusion.odonoise); ``odometry``
        as given where the run is too short for the fit. False: ``odometry`` as given.
    prior_sigma : (x, y, yaw) sigmas of the start around the robust anchor (m, m, rad).
    bias_cov : per source, the covariance of the error its fixes share over the whole run (its calibration:
        the scanners' registration, the robot frame's fit), over world (x, y, yaw) (3 x 3; m^2, rad^2) for
        a pose source, world (x, y) (2 x 2) for a position source. Considered (Schmidt), not estimated:
        the poses do not move, each pose's covariance gains ``sum_s S_s B_s S_s^T`` (``S_s`` its
        sensitivity to that bias, gtrig.fusion.batch), since averaging over fixes cannot shrink it. A
        source left out adds nothing.
    correlation_s : a source's errors stay correlated over about this long (its calibration and
        model errors change with the pose, not from frame to frame); each fix's covariance is multiplied
        by the number of the same source's fixes within this window, so that a second of 75 Hz fixes
        counts as ``1 / correlation_s`` independent ones (effective sample size). 0 treats every fix as
        independent.
    window_s, window_overlap_s : with odometry, a segment longer than ``window_s`` is smoothed in windows
        of about ``window_s`` (equal cores) with ``window_overlap_s`` of fixes and nodes beyond each end,
        so that memory is a window's, not the run's; each core keeps its own poses. The odometry
        parameters stay a whole-run estimate: a first pass gives each window's information on them,
        the second smooths each window with the others' as its prior (:func:`_smooth_windows`). None:
        one batch per segment, whatever its length.
    jumps : what odometry increment is a jump (a reset, a restart, a joined recording: faster than the
        robot moves, :class:`~gtrig.fusion.process.OdometryJumps`); a jump starts a new odometry segment:
        its increment ties nothing, the poses either side are held by the fixes.
    slip_ratio, slip_window_s : a wheel slip (the odometry wrong by more than its noise model over a short
        stretch) shows as odometry residuals far above the segment's typical ones: where the mean
        whitened odometry residual over ``slip_window_s`` exceeds ``slip_ratio`` times the segment's
        median of that mean, the increments' covariance there is multiplied by that excess and the
        segment smoothed again (:func:`_slip_factors`), so the fixes, not the slipping odometry, set the
        poses there; a slip large enough for the gate to refuse every source's fixes after it (they agree
        with each other, not with the odometry) widens the increments within ``slip_window_s`` before
        that stretch by :data:`SLIP_WIDEN` (:func:`_gated_stretches`). 0: off.
    """

    estimator: Literal["batch", "ekf"] = "batch"
    rate_hz: float | None = None
    offsets_s: Mapping[str, float] = field(default_factory=dict)
    offsets_sigma_s: Mapping[str, float] = field(default_factory=dict)
    max_gap_s: float | None = None
    bridge_after_s: float = 0.25
    gate_prob: float = 0.9999
    gate_own_cov: bool = True
    innovation_window_s: float = 1.0
    huber_k: float = 3.0
    odometry: OdometryNoise = OdometryNoise()
    fit_odometry_noise: bool = True
    cv: ConstantVelocityNoise = ConstantVelocityNoise()
    prior_sigma: tuple[float, float, float] = (0.1, 0.1, 0.1)
    correlation_s: float = 0.5
    bias_cov: Mapping[str, np.ndarray] = field(default_factory=dict)
    window_s: float | None = 600.0
    window_overlap_s: float = 30.0
    jumps: OdometryJumps = OdometryJumps()
    slip_ratio: float = 20.0
    slip_window_s: float = 0.5


@dataclass(frozen=True)
class Outlier:
    """A fix refused by the gate (``gate``) or down-weighted by the robust loss (``huber``)."""

    source: str
    stamp_s: float
    chi2: float
    dof: int
    stage: str


@dataclass(frozen=True)
class Segment:
    t0_s: float
    t1_s: float
    poses: int
    bridged: int
    longest_bridge_s: float
    odometry_params: tuple[float, ...]
    odometry_params_sigma: tuple[float, ...]
    iterations: int


@dataclass(frozen=True)
class FusionReport:
    """What fusion did: per source, fixes offered, used and rejected; segments; the outliers; timing."""

    estimator: str
    process: str
    sources: dict[str, dict[str, float]]
    segments: tuple[Segment, ...]
    outliers: tuple[Outlier, ...]
    seconds: float
    #: stamps (s, reference clock) of the odometry's jumps, each the start of a new odometry segment
    odometry_jumps_s: tuple[float, ...] = ()
    #: the odometry noise model used, and with its fit (FusionOptions.fit_odometry_noise) the windows it was
    #: fitted on and their NEES/dof under the given model and the fitted one
    odometry_noise: dict[str, float] = field(default_factory=dict)

    def to_dict(self) -> dict[str, object]:
        return asdict(self)


def _check_fixes(f: Fixes) -> None:
    if len(f) and (not np.all(np.isfinite(f.stamps_s)) or np.any(np.diff(f.stamps_s) <= 0)):
        i = int(np.argmax(~(np.diff(f.stamps_s) > 0))) + 1 if len(f) > 1 else 0
        raise InputError(f"{f.source}: stamps must increase strictly (fix {i + 1}, {f.stamps_s[i]:.6f})")


def _decorrelation_counts(f: Fixes, window_s: float) -> np.ndarray | None:
    """Per fix of ``f`` (M,) the count of its source's fixes within ``window_s`` (s), as floats; None when
    nothing is decorrelated (``window_s <= 0`` or fewer than two fixes)."""
    if window_s <= 0 or len(f) < 2:
        return None
    lo = np.searchsorted(f.stamps_s, f.stamps_s - window_s / 2, "left")
    hi = np.searchsorted(f.stamps_s, f.stamps_s + window_s / 2, "right")
    return np.maximum(hi - lo, 1).astype(float)


def decorrelated(f: Fixes, window_s: float) -> Fixes:
    """``f`` with each covariance multiplied by the count of its source's fixes within ``window_s``."""
    n = _decorrelation_counts(f, window_s)
    if n is None:
        return f
    cov = f.cov * n[:, None, None]
    if f.model is FixModel.POSITION:
        cov[:, 2, 2] = 1.0
    return Fixes(f.source, f.stamps_s, f.model, f.value, cov, f.lever_xy)


def _bias_covs(fixes: Sequence[Fixes], bias_cov: Mapping[str, np.ndarray], names: set[str],
               ) -> list[np.ndarray | None]:
    """Per source (in ``fixes``' order) its checked bias covariance, or None; ``names``: every source given
    (one without a usable fix may carry a bias covariance too)."""
    for name in bias_cov:
        if name not in names:
            raise InputError(f"fusion: a bias covariance for {name!r}, which is no source ({', '.join(sorted(names))})")
    out: list[np.ndarray | None] = []
    for f in fixes:
        if f.source not in bias_cov:
            out.append(None)
            continue
        B = np.asarray(bias_cov[f.source], float)
        if B.shape != (f.dim, f.dim):
            raise InputError(f"fusion: {f.source}'s bias covariance is {B.shape}, its {f.model.value} fixes need "
                             f"{f.dim} x {f.dim}")
        if not (np.all(np.isfinite(B)) and np.allclose(B, B.T, rtol=1e-9, atol=1e-18)
                and np.linalg.eigvalsh(B).min() >= -1e-12 * max(float(np.abs(B).max()), 1e-300)):
            raise InputError(f"fusion: {f.source}'s bias covariance is not symmetric positive semi-definite")
        out.append(0.5 * (B + B.T))
    return out


def _check_units(fixes: Sequence[Fixes], odometry: OdometryLog) -> None:
    """Odometry in another unit (mm, degrees) travels or turns a multiple of what the sources see."""
    f = max(fixes, key=len)
    if len(f) < 3:
        return
    # compare over spans of about a second: the fixes' noise stays below the motion, and no span turns by pi
    step = max(1, int(round(1.0 / max(float(np.median(np.diff(f.stamps_s))), 1e-6))))
    z = f.value[::step]
    path_fix = float(np.sum(np.hypot(*np.diff(z[:, :2], axis=0).T)))
    o = interpolate_odometry(odometry, f.stamps_s[::step])
    path_odo = float(np.sum(np.hypot(*np.diff(o[:, :2], axis=0).T)))
    if path_fix > 0.5 and not 0.5 < path_odo / path_fix < 2.0:
        raise InputError(f"fusion: the odometry travels {path_odo:.3g} where {f.source} travels {path_fix:.3g} m: "
                         "is the odometry in another unit (mm? feet?)")
    if f.model is FixModel.POSE:
        turn_fix = float(np.sum(np.abs(np.diff(np.unwrap(z[:, 2])))))
        turn_odo = float(np.sum(np.abs(np.diff(o[:, 2]))))
        if turn_fix > 1.0 and not 0.5 < turn_odo / turn_fix < 2.0:
            raise InputError(f"fusion: the odometry turns {turn_odo:.3g} where {f.source} turns {turn_fix:.3g} rad: "
                             "is its heading in another unit (degrees?)")


def _merge_order(fixes: Sequence[Fixes]) -> np.ndarray:
    """The order (M,) that sorts the sources' fixes, concatenated, by stamp (stable: ties by source)."""
    return np.argsort(np.concatenate([f.stamps_s for f in fixes]), kind="stable")


def merge_fixes(fixes: Sequence[Fixes], order: np.ndarray | None = None) -> dict[str, np.ndarray]:
    """The sources' fixes as one set of arrays in ``order`` (:func:`_merge_order`, by default): stamps (M,),
    z (M, 3), cov (M, 3, 3), kind (M,), lever (M, 2), source (M,) (index into ``fixes``)."""
    if order is None:
        order = _merge_order(fixes)
    fields = {
        "stamps": lambda k, f: f.stamps_s,
        "z": lambda k, f: f.value,
        "cov": lambda k, f: f.cov,
        "kind": lambda k, f: np.full(len(f), f.kind_code(), np.int64),
        "lever": lambda k, f: np.tile(f.lever_xy, (len(f), 1)),
        "source": lambda k, f: np.full(len(f), k, np.int64),
    }
    # field by field: one field's concatenation is the only temporary at a time
    return {name: np.concatenate([get(k, f) for k, f in enumerate(fixes)])[order] for name, get in fields.items()}


def _decorrelated_cov(fixes: Sequence[Fixes], counts: Sequence[np.ndarray | None], cov: np.ndarray,
                      order: np.ndarray) -> np.ndarray:
    """:func:`decorrelated`'s covariances of the merged fixes, from their own merged ``cov`` (M, 3, 3) in
    ``order`` and each source's :func:`_decorrelation_counts` (``counts``): the same products, without a
    decorrelated copy of every source before the merge."""
    if all(c is None for c in counts):
        return cov
    n = np.concatenate([np.ones(len(f)) if c is None else c for f, c in zip(fixes, counts, strict=True)])[order]
    unused = np.concatenate([np.full(len(f), c is not None and f.model is FixModel.POSITION)
                             for f, c in zip(fixes, counts, strict=True)])[order]
    out = cov * n[:, None, None]
    out[unused, 2, 2] = 1.0  # a position fix's third axis stays 1, as decorrelated leaves it
    return out


def _merge_span(fixes: Sequence[Fixes], counts: Sequence[np.ndarray | None], t0: float, t1: float,
                gate_own_cov: bool = True) -> dict[str, np.ndarray]:
    """Every source's fixes stamped in ``[t0, t1]`` (s), merged (:func:`merge_fixes`; ``source`` indexes
    ``fixes``), with ``cov`` decorrelated by each source's whole-run ``counts`` and ``gate_cov`` the gate's
    (the fixes' own covariances, or ``cov`` when not ``gate_own_cov``)."""
    part, cnt = [], []
    for f, c in zip(fixes, counts, strict=True):
        i0, i1 = int(np.searchsorted(f.stamps_s, t0, "left")), int(np.searchsorted(f.stamps_s, t1, "right"))
        part.append(Fixes(f.source, f.stamps_s[i0:i1], f.model, f.value[i0:i1], f.cov[i0:i1], f.lever_xy))
        cnt.append(None if c is None else c[i0:i1])
    order = _merge_order(part)
    fx = merge_fixes(part, order)
    # the gate tests each fix against its own covariance: the decorrelation's inflation is for weighing a
    # second of correlated fixes, not for deciding whether one fix is an outlier
    fx["gate_cov"] = fx["cov"]
    fx["cov"] = _decorrelated_cov(part, cnt, fx["gate_cov"], order)
    if not gate_own_cov:
        fx["gate_cov"] = fx["cov"]
    return fx


def _segments(stamps: np.ndarray, max_gap_s: float | None) -> list[tuple[int, int]]:
    if max_gap_s is None or stamps.size < 2:
        return [(0, stamps.size)]
    cut = np.flatnonzero(np.diff(stamps) > max_gap_s) + 1
    edges = np.r_[0, cut, stamps.size]
    return [(int(a), int(b)) for a, b in zip(edges[:-1], edges[1:], strict=True) if b - a >= 3]


def _fix_whitening(cov: np.ndarray, kind: np.ndarray) -> np.ndarray:
    W = whitening(cov)
    W[kind == 1, 2, :] = 0.0  # a position fix says nothing on its third axis
    return W


def _node_stamps(t0: float, t1: float, odometry: OdometryLog | None, rate_hz: float | None) -> np.ndarray:
    if odometry is not None and rate_hz is None:
        s = odometry.stamps_s
        i0 = max(int(np.searchsorted(s, t0, "right")) - 1, 0)
        i1 = min(int(np.searchsorted(s, t1, "left")), s.size - 1)
        return s[i0:i1 + 1]
    step = 1.0 / (rate_hz or 50.0)
    n = int(np.ceil((t1 - t0) / step)) + 1
    return t0 + np.arange(n) * step


def _odometry_between(stamps: np.ndarray, odometry: OdometryLog, opts: FusionOptions,
                      ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The odometry at the nodes (N, 3), its increments (N-1, 3) and their covariances (N-1, 3, 3), the
    jumps cut (:func:`~gtrig.fusion.process.cut_at_jumps`), and which increments (N-1,) are jumps."""
    odo = interpolate_odometry(odometry, stamps)
    u, qcov = odometry_increments(odo, stamps, opts.odometry)
    jump = odometry_jumps(u, np.diff(stamps), opts.jumps)
    u, qcov = cut_at_jumps(u, qcov, jump)
    return odo, u, qcov, jump


#: the covariance (m^2, rad^2) that makes a fix say nothing (a fix inside a jump's step)
_NO_INFORMATION = 1.0e12


def _fixes_across_jumps(cov: np.ndarray, node: np.ndarray, alpha: np.ndarray, jump: np.ndarray) -> np.ndarray:
    """The fixes' covariances (M, 3, 3), those taken between the two records either side of an odometry
    jump (``jump`` (N-1,) per step) made uninformative: which side of the jump such a fix was taken on is
    unknown, and interpolated between the poses either side it would pull the new segment's first pose
    to the old one's (a lapped recording's every other lap then lost all its fixes to the gate)."""
    lost = jump[node] & (alpha > 0.0)
    if not lost.any():
        return cov
    cov = cov.copy()
    cov[lost] = _NO_INFORMATION * np.eye(3)
    return cov


def build_chain(stamps: np.ndarray, fx: dict[str, np.ndarray], odometry: OdometryLog | None, opts: FusionOptions,
           sources: tuple[str, ...], k_prior: tuple[np.ndarray, np.ndarray] | None = None,
           slip: np.ndarray | None = None) -> tuple[FactorChain, np.ndarray, np.ndarray, np.ndarray]:
    """The factor chain, the start (N, d), the parameters' start and the start's covariance (d, d).
    ``k_prior``: the odometry parameters' prior (mean (3,), covariance (3, 3)); default the options'.
    ``slip``: (N-1,) factors on the odometry increments' covariances (wheel slips, :func:`_slip_factors`)."""
    N = stamps.size
    node = np.clip(np.searchsorted(stamps, fx["stamps"], "right") - 1, 0, N - 2)
    alpha = np.clip((fx["stamps"] - stamps[node]) / (stamps[node + 1] - stamps[node]), 0.0, 1.0)
    fix_cov = fx["cov"]
    if odometry is not None:
        odo, u, qcov, jump = _odometry_between(stamps, odometry, opts)
        fix_cov = _fixes_across_jumps(fix_cov, node, alpha, jump)
        if slip is not None:
            qcov = qcov * slip[:, None, None]
        proc, d = PROCESS_ODOMETRY, 3
        k0, Pk = opts.odometry.prior() if k_prior is None else k_prior
        proc_W = whitening(qcov)
        odo_fix = interpolate_odometry(odometry, fx["stamps"])
        tol = (0.05, np.deg2rad(3.0))
    else:
        odo = np.zeros((N, 3))
        u = np.zeros((N - 1, 3))
        proc, d = PROCESS_CV, 6
        k0, Pk = np.zeros(0), np.zeros((0, 0))
        proc_W = whitening(constant_velocity_cov(np.diff(stamps), opts.cv))
        odo_fix = np.zeros((fx["stamps"].size, 3))
        tol = (0.2, np.deg2rad(10.0))
    W = _fix_whitening(fix_cov, fx["kind"])
    # robust anchor from the first fixes (first 10 s or 200 fixes)
    first = np.flatnonzero(fx["stamps"] <= fx["stamps"][0] + 10.0)[:200]
    if odometry is None:
        first = first[:10]
    is_pose = fx["kind"][first] == 0
    T_wo = odom_in_world(fx["z"][first][is_pose], odo_fix[first][is_pose], fx["z"][first][~is_pose][:, :2],
                         odo_fix[first][~is_pose], fx["lever"][first][~is_pose], *tol)
    c, s = np.cos(T_wo[2]), np.sin(T_wo[2])
    X = np.zeros((N, d))
    X[:, 0] = T_wo[0] + c * odo[:, 0] - s * odo[:, 1]
    X[:, 1] = T_wo[1] + s * odo[:, 0] + c * odo[:, 1]
    X[:, 2] = T_wo[2] + odo[:, 2]
    P0 = np.diag(np.r_[np.square(opts.prior_sigma), np.full(d - 3, 1.0)])
    if proc == PROCESS_CV and not np.any(fx["kind"] == 0):
        P0[2, 2] = np.pi**2  # heading unknown: only positions seen
    chain = FactorChain(
        stamps_s=stamps, process=proc, proc_u=np.ascontiguousarray(u), proc_W=np.ascontiguousarray(proc_W),
        fix_node=node.astype(np.int64), fix_alpha=alpha, fix_kind=fx["kind"], fix_z=fx["z"], fix_cov=fix_cov,
        fix_W=np.ascontiguousarray(W), fix_lever=fx["lever"], fix_source=fx["source"], fix_stamps_s=fx["stamps"],
        sources=sources, x0=X[0].copy(), W0=whitening(P0[None])[0], k0=k0,
        Wk=whitening(Pk[None])[0] if Pk.size else np.zeros((0, 0)))
    return chain, X, k0, P0


def _without_fix_covariances(seg: dict[str, np.ndarray], chain: FactorChain) -> FactorChain:
    """``chain`` without its fixes' covariances, which are dropped from ``seg`` (the merged fixes) too:
    after the filter, the batch solve weighs each fix by its whitening ``fix_W`` alone, and the two
    (M, 3, 3) covariances (the decorrelated ones and the gate's) would otherwise be held through its peak."""
    seg.pop("cov")
    seg.pop("gate_cov")
    return replace(chain, fix_cov=np.zeros((0, 3, 3)))


def _bridged(out_stamps: np.ndarray, accepted_stamps: np.ndarray, after_s: float) -> tuple[np.ndarray, np.ndarray]:
    """Per pose: inside a gap longer than ``after_s`` between accepted fixes? and that gap's length."""
    if accepted_stamps.size == 0:
        span = float(out_stamps[-1] - out_stamps[0]) if out_stamps.size else 0.0
        return np.ones(out_stamps.size, bool), np.full(out_stamps.size, span)
    k = np.searchsorted(accepted_stamps, out_stamps)
    prev = np.where(k > 0, accepted_stamps[np.maximum(k - 1, 0)], out_stamps[0])
    nxt = np.where(k < accepted_stamps.size, accepted_stamps[np.minimum(k, accepted_stamps.size - 1)], out_stamps[-1])
    exact = (k < accepted_stamps.size) & (accepted_stamps[np.minimum(k, accepted_stamps.size - 1)] == out_stamps)
    gap = nxt - prev
    return (gap > after_s) & ~exact, gap


def _innovation_factor(seg: dict[str, np.ndarray], nis: np.ndarray, use: np.ndarray, window_s: float,
                       ) -> np.ndarray:
    """Per fix, how much its covariance understates its source's innovations nearby: the mean normalised
    innovation squared per degree of freedom of the same source's accepted fixes within ``window_s``
    (the gate's, against each fix's own covariance plus the prediction's), at least 1. A stretch of a
    source that keeps disagreeing with the prediction (the other sources and the odometry) by more than
    its covariance says is weighed as the disagreement says (covariance matching)."""
    dof = np.where(seg["kind"] == 0, 3.0, 2.0)
    q = np.where(use & np.isfinite(nis), nis / dof, 0.0)
    out = np.ones(q.size)
    for k in np.unique(seg["source"]):
        m = np.flatnonzero((seg["source"] == k) & use & np.isfinite(nis))
        if m.size == 0:
            continue
        st = seg["stamps"][m]
        c = np.r_[0.0, np.cumsum(q[m])]
        lo = np.searchsorted(st, st - window_s / 2, "left")
        hi = np.searchsorted(st, st + window_s / 2, "right")
        out[m] = np.maximum(1.0, (c[hi] - c[lo]) / np.maximum(hi - lo, 1))
    return out


def _timing_sigma(opts: FusionOptions, sources: Sequence[str]) -> float:
    """The fused track's clock uncertainty (s): the best-timed of the sources whose offsets were applied."""
    sig = [float(opts.offsets_sigma_s[s]) for s in sources if s in opts.offsets_s and s in opts.offsets_sigma_s]
    sig = [v for v in sig if np.isfinite(v) and v > 0]
    return min(sig) if sig else 0.0


def _with_timing(stamps: np.ndarray, X: np.ndarray, cov: np.ndarray, sigma_t: float) -> np.ndarray:
    """``cov`` (N, d, d) plus ``sigma_t^2 v v^T`` on (x, y, yaw), ``v`` (N, 3) the nodes' velocities."""
    if sigma_t <= 0 or stamps.size < 2:
        return cov
    v = np.gradient(X[:, :3], stamps, axis=0)
    out = cov.copy()
    out[:, :3, :3] += sigma_t**2 * v[:, :, None] * v[:, None, :]
    return out


@dataclass(frozen=True)
class _Smoothed:
    """One chain's estimate: X (N, d), K (p,); cov (N, d, d) with the considered biases' and the timing's
    shares; cov_k (p, p) with the biases' share, cov_k_data (p, p) without it (the data's and the prior's
    alone); per fix (M,): use (the gate's verdict), nis, huber_w; the batch solve's iterations."""

    X: np.ndarray
    K: np.ndarray
    cov: np.ndarray
    cov_k: np.ndarray
    cov_k_data: np.ndarray
    use: np.ndarray
    nis: np.ndarray
    huber_w: np.ndarray
    iterations: int


def _slip_factors(stamps: np.ndarray, u: np.ndarray, proc_W: np.ndarray, X: np.ndarray, K: np.ndarray,
                  ratio: float, window_s: float) -> np.ndarray | None:
    """Per odometry increment (N-1,), the factor its covariance needs where the wheels slipped: the mean
    squared whitened residual of the increments within ``window_s`` over the chain's median of that
    mean, where it exceeds ``ratio`` (1 elsewhere); None when nowhere. The median, not the expected
    value 3, is the reference: with fixes denser than the odometry's noise the residuals of a right
    odometry sit well below their dof, and a slip stands out against the chain's own typical level."""
    if len(u) < 10:
        return None
    xa, xb = X[:-1], X[1:]
    c, s = np.cos(xa[:, 2]), np.sin(xa[:, 2])
    dx, dy = xb[:, 0] - xa[:, 0], xb[:, 1] - xa[:, 1]
    r = np.column_stack([c * dx + s * dy - K[0] * u[:, 0], -s * dx + c * dy - K[0] * u[:, 1],
                         (xb[:, 2] - xa[:, 2]) - K[1] * u[:, 2] - K[2] * u[:, 0]])
    q = np.einsum("nij,nj->ni", proc_W, r)
    q2 = np.sum(q**2, axis=1)
    t = stamps[:-1]
    cs = np.r_[0.0, np.cumsum(q2)]
    lo = np.searchsorted(t, t - window_s / 2, "left")
    hi = np.searchsorted(t, t + window_s / 2, "right")
    mean = (cs[hi] - cs[lo]) / np.maximum(hi - lo, 1)
    base = float(np.median(mean))
    if not base > 0:
        return None
    excess = mean / base
    if not np.any(excess > ratio):
        return None
    return np.where(excess > ratio, excess, 1.0)


#: an odometry increment judged a slip has its covariance multiplied by this: it then ties the poses
#: about as loosely as 100 times its noise, so the fixes set them
SLIP_WIDEN = 1.0e4
#: smoothing passes at most while slips are still found
SLIP_PASSES = 4


def _gated_stretches(seg: dict[str, np.ndarray], use: np.ndarray, window_s: float = 0.3,
                     share: float = 0.8) -> np.ndarray:
    """Stamps (s) where a stretch begins in which every source's fixes are refused by the gate (each
    source with two fixes or more within ``window_s`` has at least ``share`` of them refused, three
    fixes at least in all): the fixes agree with each other and not with the odometry's prediction, so
    the odometry slipped just before."""
    t = seg["stamps"]
    if t.size < 3:
        return np.zeros(0)
    lo = np.searchsorted(t, t - window_s / 2, "left")
    hi = np.searchsorted(t, t + window_s / 2, "right")
    flag = (hi - lo) >= 3
    for k in np.unique(seg["source"]):
        mine = (seg["source"] == k).astype(float)
        bad = mine * ~use
        cm, cb = np.r_[0.0, np.cumsum(mine)], np.r_[0.0, np.cumsum(bad)]
        n, nb = cm[hi] - cm[lo], cb[hi] - cb[lo]
        flag &= (n < 2) | (nb >= share * n)
    flag &= ~use
    start = flag & ~np.r_[False, flag[:-1]]
    return t[start]


def _slip_widening(stamps: np.ndarray, starts_s: np.ndarray, before_s: float) -> np.ndarray | None:
    """(N-1,) factors: :data:`SLIP_WIDEN` on the increments within ``before_s`` before each of
    ``starts_s`` (where the gate began refusing every source), 1 elsewhere; None when there is none."""
    if starts_s.size == 0:
        return None
    t0, t1 = stamps[:-1], stamps[1:]
    hit = np.zeros(t0.size, bool)
    for ts in starts_s:
        hit |= (t1 >= ts - before_s) & (t0 <= ts)
    return np.where(hit, SLIP_WIDEN, 1.0) if hit.any() else None


def _smooth(stamps: np.ndarray, seg: dict[str, np.ndarray], odometry: OdometryLog | None, opts: FusionOptions,
            sources: tuple[str, ...], bias: list[np.ndarray | None], sigma_t: float,
            k_prior: tuple[np.ndarray, np.ndarray] | None = None, slip: np.ndarray | None = None) -> _Smoothed:
    """The gated EKF + RTS, then (``opts.estimator == "batch"``) the robust batch solve, of the fixes ``seg``
    on the nodes ``stamps``; ``k_prior`` the odometry parameters' prior (default the options'). The
    fixes' covariances are dropped from ``seg`` once the batch solve no longer needs them. Where the
    odometry slipped (:func:`_slip_factors`), the segment is smoothed once more with its increments'
    covariances widened there (``slip``)."""
    if odometry is not None and slip is None and opts.slip_ratio > 0:
        keep: dict[str, np.ndarray] = {k: seg[k] for k in ("cov", "gate_cov") if k in seg}
        _, u, qcov, _ = _odometry_between(stamps, odometry, opts)
        W = whitening(qcov)
        f = np.ones(stamps.size - 1)
        for _ in range(SLIP_PASSES):
            sm = _smooth(stamps, seg, odometry, opts, sources, bias, sigma_t, k_prior, f)
            seg.update(keep)
            more = _slip_factors(stamps, u, W / np.sqrt(f)[:, None, None], sm.X, sm.K, opts.slip_ratio,
                                 opts.slip_window_s)
            g = _slip_widening(stamps, _gated_stretches(seg, sm.use), opts.slip_window_s)
            if g is not None:
                more = g if more is None else np.maximum(more, g)
            if more is None:
                break
            f = np.minimum(f * more, SLIP_WIDEN)
        for k in keep:  # dropped as the batch solve drops them
            seg.pop(k, None)
        return sm
    chain, _, _, P0 = build_chain(stamps, seg, odometry, opts, sources, k_prior, slip)
    Pk = np.zeros((0, 0)) if odometry is None else (opts.odometry.prior() if k_prior is None else k_prior)[1]
    ekf = smooth_ekf(chain, P0, Pk, gate_prob=opts.gate_prob, gate_cov=seg["gate_cov"],
                     covariances=opts.estimator != "batch")
    use, nis = ekf.accept, ekf.nis
    huber_w = np.ones(use.size)
    if opts.estimator == "batch":
        chain = _without_fix_covariances(seg, chain)
        if opts.innovation_window_s > 0:
            chain = replace(chain, fix_W=chain.fix_W / np.sqrt(_innovation_factor(
                seg, nis, use, opts.innovation_window_s))[:, None, None])
        X0, K0 = ekf.X, ekf.K
        del ekf  # its covariances (N, d, d) and filtered states are not the batch solve's: freed first
        res = smooth_batch(chain, X0, K0, fix_use=use, huber_k=opts.huber_k, bias_cov=bias)
        del X0
        X, K, cov, cov_k, iters = res.X, res.K, res.cov_x, res.cov_k, res.iterations
        huber_w = res.robust_w
        cov_k_data = cov_k - res.cov_bias_k if res.cov_bias_k is not None else cov_k
        del res  # its bias share of the covariances (N, d, d), held in cov already
    else:
        X, K, cov, cov_k, iters = ekf.X, ekf.K, ekf.cov_x, ekf.cov_k, 0
        cov_k_data = cov_k
        if any(B is not None for B in bias):
            cb_x, cb_k = considered_covariance(chain, X, K, use, bias)
            cov, cov_k = cov + cb_x, cov_k + cb_k
    cov = _with_timing(stamps, X, cov, sigma_t)
    return _Smoothed(X, K, cov, cov_k, cov_k_data, use, nis, huber_w, int(iters))


class _Parts:
    """What :func:`fuse` gathers from its chains (segments, or windows' cores), in time order: the poses
    and their covariances, statuses and reasons, the outliers, one :class:`Segment` per chain, and the
    per-source counts (``per_source``, updated in place)."""

    def __init__(self, per_source: dict[str, dict[str, float]]) -> None:
        self.per_source = per_source
        self.st: list[np.ndarray] = []
        self.xyt: list[np.ndarray] = []
        self.cov: list[np.ndarray] = []
        self.status: list[np.ndarray] = []
        self.reason: list[str] = []
        self.outliers: list[Outlier] = []
        self.segments: list[Segment] = []

    def add(self, sources: tuple[str, ...], seg: dict[str, np.ndarray], fix_keep: np.ndarray, sm: _Smoothed,
            stamps: np.ndarray, node_keep: np.ndarray, bridge_after_s: float, t01: tuple[float, float]) -> None:
        """The nodes ``node_keep`` (N,) of ``sm`` on ``stamps`` and the fixes ``fix_keep`` (M,) of ``seg``
        (a chain's own, or a window's core), as the segment ``t01`` (s)."""
        use, nis, huber_w = sm.use[fix_keep], sm.nis[fix_keep], sm.huber_w[fix_keep]
        src, st = seg["source"][fix_keep], seg["stamps"][fix_keep]
        dims = np.where(seg["kind"][fix_keep] == 0, 3, 2)
        for j in np.flatnonzero(~use):
            self.outliers.append(Outlier(sources[src[j]], float(st[j]), float(nis[j]), int(dims[j]), "gate"))
        for j in np.flatnonzero(use & (huber_w < 1.0)):
            self.outliers.append(Outlier(sources[src[j]], float(st[j]), float(nis[j]), int(dims[j]), "huber"))
        for k, s in enumerate(sources):
            m = src == k
            self.per_source[s]["used"] += float(np.sum(use[m]))
            self.per_source[s]["rejected"] += float(np.sum(~use[m]))
            self.per_source[s]["downweighted"] += float(np.sum(use[m] & (huber_w[m] < 1.0)))
        # bridges against every accepted fix of the chain (a window's overlaps included: a gap at a core's
        # end is measured across it)
        br, gap = _bridged(stamps, np.unique(seg["stamps"][sm.use]), bridge_after_s)
        br, gap = br[node_keep], gap[node_keep]
        self.st.append(stamps[node_keep])
        self.xyt.append(sm.X[node_keep, :3])
        self.cov.append(sm.cov[node_keep, :3, :3])
        self.status.append(np.where(br, PoseStatus.BRIDGED, PoseStatus.OK).astype(np.uint8))
        self.reason += [f"bridged: {g:.2f} s without a fix" if f else "" for f, g in zip(br, gap, strict=True)]
        sig = np.sqrt(np.diag(sm.cov_k)) if sm.cov_k.size else np.zeros(0)
        self.segments.append(Segment(t01[0], t01[1], int(node_keep.sum()), int(br.sum()),
                                     float(gap[br].max()) if br.any() else 0.0, tuple(float(v) for v in sm.K),
                                     tuple(float(v) for v in sig), sm.iterations))


    def mark(self) -> tuple[tuple[int, ...], dict[str, dict[str, float]]]:
        """The state to :meth:`rollback` to: the lists' lengths and the per-source counts."""
        lists = (self.st, self.xyt, self.cov, self.status, self.reason, self.outliers, self.segments)
        return tuple(len(x) for x in lists), {k: dict(v) for k, v in self.per_source.items()}

    def rollback(self, mark: tuple[tuple[int, ...], dict[str, dict[str, float]]]) -> None:
        """Forget what was added since ``mark`` (:meth:`mark`); the per-source counts restored in place."""
        lens, counts = mark
        kept: tuple[list[Any], ...] = (self.st, self.xyt, self.cov, self.status, self.reason, self.outliers,
                                       self.segments)
        for x, n in zip(kept, lens, strict=True):
            del x[n:]
        for k, v in counts.items():
            self.per_source[k].update(v)

    def track(self) -> PoseTrack:
        """The poses gathered, as one track (``source="fusion"``); each list is emptied as it is joined."""

        def joined(parts: list[np.ndarray]) -> np.ndarray:
            out = np.concatenate(parts)
            parts.clear()
            return out

        st, xyt, cov, status = joined(self.st), joined(self.xyt), joined(self.cov), joined(self.status)
        return PoseTrack.from_xytheta(st, xyt, cov=cov, status=status, reasons=tuple(self.reason), source="fusion")


def _windows(fix_stamps: np.ndarray, t0: float, t1: float, opts: FusionOptions,
             ) -> list[tuple[float, float, float, float]]:
    """The windows of a segment of fixes ``fix_stamps`` spanning ``[t0, t1]`` (s): (core start, core end,
    window start, window end) each, equal cores of at most ``opts.window_s``, windows ``window_overlap_s``
    beyond; none (one batch) when the segment is no longer than a window or a core would hold fewer
    than 10 fixes to start from."""
    if opts.window_s is None or not np.isfinite(opts.window_s) or t1 - t0 <= opts.window_s:
        return []
    n = int(np.ceil((t1 - t0) / opts.window_s))
    edges = np.linspace(t0, t1, n + 1)
    ov = opts.window_overlap_s
    wins = [(float(edges[i]), float(edges[i + 1]), float(max(t0, edges[i] - ov)), float(min(t1, edges[i + 1] + ov)))
            for i in range(n)]
    counts = [np.searchsorted(fix_stamps, c1, "right") - np.searchsorted(fix_stamps, c0, "left")
              for c0, c1, _, _ in wins]  # the first pass smooths the cores alone
    return wins if min(counts) >= 10 else []


def _smooth_windows(parts: _Parts, between: Callable[[float, float], dict[str, np.ndarray]],
                    wins: list[tuple[float, float, float, float]],
                    odometry: OdometryLog, opts: FusionOptions, sources: tuple[str, ...],
                    bias: list[np.ndarray | None], sigma_t: float, span: tuple[float, float]) -> None:
    """A long segment smoothed window by window (:func:`_windows`), the odometry parameters a whole-run
    estimate, into ``parts``: each core's nodes (the first core from ``span[0]``, the last to ``span[1]``)
    and fixes; ``between(t0, t1)`` merges the fixes stamped in ``[t0, t1]`` (:func:`_merge_span`), one
    window's at a time.

    The parameters: the first pass smooths each core alone (no overlap, the options' prior) and keeps
    its information on them, the posterior's minus the prior's; the second smooths each window with the
    prior plus every other core's information: its posterior on the parameters is then the whole run's
    (to the cores' coupling through the odometry factor across each seam, the overlaps' fixes counted
    twice, and the linearisation), and its poses are the whole run's smoothing wherever a core lies
    further than a few seconds from the ends of its window. The first pass needs no covariances of the
    poses nor the considered biases (the estimate does not depend on them)."""
    k0, P0 = opts.odometry.prior()
    I0 = np.linalg.inv(P0)
    info, eta = [], []
    for c0, c1, _, _ in wins:
        sm = _smooth(_node_stamps(c0, c1, odometry, opts.rate_hz), between(c0, c1), odometry, opts, sources,
                     [None] * len(bias), 0.0)
        Iw = np.linalg.inv(sm.cov_k_data)
        info.append(Iw - I0)
        eta.append(Iw @ sm.K - I0 @ k0)
        del sm  # one window's working set at a time
    info_all, eta_all = I0 + np.sum(info, axis=0), I0 @ k0 + np.sum(eta, axis=0)
    for w, (c0, c1, w0, w1) in enumerate(wins):
        sw, st = between(w0, w1), _node_stamps(w0, w1, odometry, opts.rate_hz)
        Pw = np.linalg.inv(info_all - info[w])
        Pw = 0.5 * (Pw + Pw.T)
        sm = _smooth(st, sw, odometry, opts, sources, bias, sigma_t, k_prior=(Pw @ (eta_all - eta[w]), Pw))
        lo = span[0] if w == 0 else c0
        hi = span[1] if w == len(wins) - 1 else c1
        last = w == len(wins) - 1
        node_keep = (st >= lo) & ((st <= hi) if last else (st < hi))
        fix_keep = (sw["stamps"] >= lo) & ((sw["stamps"] <= hi) if last else (sw["stamps"] < hi))
        parts.add(sources, sw, fix_keep, sm, st, node_keep, opts.bridge_after_s, (c0, c1))
        del sm, sw


def _jump_stamps(odometry: OdometryLog | None, jumps: OdometryJumps) -> tuple[float, ...]:
    """Stamps (s) of the records where the odometry jumps (each the first record of its new segment)."""
    if odometry is None or len(odometry) < 2:
        return ()
    xyt = odometry.xytheta.copy()
    xyt[:, 2] = np.unwrap(xyt[:, 2])
    u, _ = odometry_increments(xyt, odometry.stamps_s, OdometryNoise())
    hit = odometry_jumps(u, np.diff(odometry.stamps_s), jumps)
    return tuple(float(t) for t in odometry.stamps_s[1:][hit])


def _noise_summary(noise: OdometryNoise, fit: NoiseFit | None) -> dict[str, float]:
    """The odometry noise model used (its random errors), with the fit's windows and NEES when fitted."""
    if fit is not None:
        return fit.summary()
    return {"slip_m_per_sqrt_m": noise.slip_m_per_sqrt_m, "lateral_ratio": noise.lateral_ratio,
            "floor_m_per_sqrt_s": noise.floor_m_per_sqrt_s, "floor_rad_per_sqrt_s": noise.floor_rad_per_sqrt_s}


def fuse(fixes: Sequence[Fixes], odometry: OdometryLog | None = None, options: FusionOptions | None = None,
         ) -> tuple[PoseTrack, FusionReport]:
    """Smooth absolute fixes with odometry (or constant velocity) into one trajectory.

    Parameters
    ----------
    fixes : the sources' fixes (:func:`~gtrig.fusion.measurements.fixes_from_track`), each on its own clock.
    odometry : wheel odometry on the reference clock, or None for the constant-velocity model.
    options : :class:`FusionOptions`.

    Returns
    -------
    track : ``source="fusion"``, ``cov_kind="xyyaw"``, one pose per node inside the sources' span, OK or
        BRIDGED; stamps on the reference clock.
    report : :class:`FusionReport`.

    Raises
    ------
    InputError : no fixes, stamps not increasing, sources outside the odometry's span, a covariance that is
        not positive definite.
    """
    t_start = time.perf_counter()
    opts = options or FusionOptions()
    given = {f.source for f in fixes}
    fixes = [f.shifted(-float(opts.offsets_s.get(f.source, 0.0))) for f in fixes if len(f)]
    if not fixes:
        raise InputError("fusion: no usable fix in any source")
    for f in fixes:
        _check_fixes(f)
    sources = tuple(f.source for f in fixes)
    if len(set(sources)) != len(sources):
        raise InputError(f"fusion: two sources share a name ({', '.join(sources)})")
    # the sources' span, before fixes outside the odometry are dropped: a node of the odometry inside it
    # gets a pose even where the nearest fixes beyond it lie past the odometry's ends
    span0 = min(float(f.stamps_s[0]) for f in fixes)
    span1 = max(float(f.stamps_s[-1]) for f in fixes)
    noise_fit: NoiseFit | None = None
    if odometry is not None:
        if len(odometry) < 2:
            raise InputError("fusion: the odometry has fewer than two records")
        o0, o1 = float(odometry.stamps_s[0]), float(odometry.stamps_s[-1])
        kept: list[Fixes] = []
        for f in fixes:
            inside = f.between(o0, o1)
            if not len(inside):
                raise InputError(f"fusion: {f.source} ({f.stamps_s[0]:.3f}-{f.stamps_s[-1]:.3f} s) does not overlap "
                                 f"the odometry ({o0:.3f}-{o1:.3f} s); wrong clock or offset?")
            kept.append(inside)
        fixes = kept
        _check_units(fixes, odometry)
        noise_fit = fit_odometry_noise(fixes, odometry, opts.odometry, opts.jumps) if opts.fit_odometry_noise else None
        if noise_fit is not None:
            opts = replace(opts, odometry=noise_fit.noise)
    counts = [_decorrelation_counts(f, opts.correlation_s) for f in fixes]
    per_source = {s: {"offered": float(len(f)), "used": 0.0, "rejected": 0.0, "downweighted": 0.0,
                      "offset_s": float(opts.offsets_s.get(s, 0.0)),
                      "offset_sigma_s": float(opts.offsets_sigma_s.get(s, 0.0)) if s in opts.offsets_s else 0.0}
                  for s, f in zip(sources, fixes, strict=True)}
    sigma_t = _timing_sigma(opts, sources)
    bias = _bias_covs(fixes, opts.bias_cov, given)
    parts = _Parts(per_source)
    # the fixes are merged segment by segment (or window by window) from the sources, not all at once: the
    # merged arrays are some 200 B a fix
    all_stamps = np.sort(np.concatenate([f.stamps_s for f in fixes]))
    cuts = _segments(all_stamps, opts.max_gap_s)
    for a, b in cuts:
        t0, t1 = float(all_stamps[a]), float(all_stamps[b - 1])
        # the first and last segments reach to the sources' span (their nodes past the kept fixes exist)
        lo = span0 if a == cuts[0][0] else t0
        hi = span1 if b == cuts[-1][1] else t1
        stamps = _node_stamps(t0, t1, odometry, opts.rate_hz)
        if stamps.size < 2:
            continue
        span = (min(t0, lo), max(t1, hi))
        wins = _windows(all_stamps[a:b], t0, t1, opts) if odometry is not None else []
        between = partial(_merge_span, fixes, counts, gate_own_cov=opts.gate_own_cov)
        if wins:
            assert odometry is not None  # (windows are made only with odometry)
            mark = parts.mark()
            try:
                _smooth_windows(parts, between, wins, odometry, opts, sources, bias, sigma_t, span)
                continue
            except (InputError, ConvergenceError):
                # a window the one batch does not have failed (a start without motion for position-only
                # fixes, a window the fixes do not pin): this segment in one batch after all
                parts.rollback(mark)
        seg = between(t0, t1)
        sm = _smooth(stamps, seg, odometry, opts, sources, bias, sigma_t)
        in_span = (stamps >= span[0]) & (stamps <= span[1])
        parts.add(sources, seg, np.ones(b - a, bool), sm, stamps, in_span, opts.bridge_after_s, (t0, t1))
    seg = None  # type: ignore[assignment]  # the last segment's merged fixes are not the track's: freed before it is made
    if not parts.st:
        raise InputError("fusion: no segment with at least three fixes")
    track = parts.track()
    report = FusionReport(opts.estimator, "odometry" if odometry is not None else "constant velocity", per_source,
                          tuple(parts.segments), tuple(sorted(parts.outliers, key=lambda o: o.stamp_s)),
                          time.perf_counter() - t_start, _jump_stamps(odometry, opts.jumps),
                          _noise_summary(opts.odometry, noise_fit) if odometry is not None else {})
    return track, report


def fuse_tracks(tracks: Mapping[str, PoseTrack], odometry: OdometryLog | None = None,
                options: FusionOptions | None = None,
                lever_xy: Mapping[str, tuple[float, float]] | None = None) -> tuple[PoseTrack, FusionReport]:
    """:func:`fuse` on pose tracks (``{"vision": track, "laser": track}``); ``xyz`` tracks become position
    fixes of the point at ``lever_xy[name]`` in the robot frame."""
    fixes = [fixes_from_track(t, name, (lever_xy or {}).get(name),
                              FixModel.POSITION if t.cov_kind == "xyz" else FixModel.POSE)
             for name, t in tracks.items()]
    return fuse(fixes, odometry, options)
