"""Clock offsets between a GT source and the reference (odometry), from the robot's turns.

Sign convention: ``offset_s`` = the source's stamp minus the reference's stamp of the same instant, so
``source_stamp - offset_s`` is on the reference clock (:class:`~gtrig.fusion.fuse.FusionOptions` subtracts
it). A source whose clock runs 0.3 s late has ``offset_s = +0.3``.

Method (the seeds' check made quantitative, deliverable "Synchronization validation"):

1. coarse: normalised cross-correlation of the heading rates on a grid of half the faster stream's
   period (at most 100 Hz; the source's rate only where it has samples), over lags in
   ``[-search_s, search_s]``; its peak;
2. fine: a 1-D minimisation (a fine grid, then a parabola) of the least-squares misfit between the
   source's headings at their own stamps and the reference heading interpolated at ``stamp - offset``,
   with a gain and a level per window of at least 10 s (odometry's turn-scale error and heading drift);
3. interval: a jackknife over those windows (each left out in turn), Student's t with W - 1 dof;
4. optionally (:func:`refine_by_fusion`) the offset as a parameter of the fusion's own fit of the
   source with the odometry (positions and headings): the most precise where covariances exist.

Verdicts: ``unobservable`` when the robot turns too little (heading-rate spread under 0.02 rad/s, or
fewer than 3 windows with turns); ``ambiguous`` when a second correlation peak, away from the first by
more than its width, reaches 90 % of it, or when the jackknife interval is wider than ``max_ci_s``;
``ok`` otherwise. Only ``ok`` estimates carry a number to apply.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING, Literal

import numpy as np
from scipy.optimize import minimize_scalar
from scipy.stats import t as student_t

from gtrig.fusion.measurements import Fixes
from gtrig.io.odometry import OdometryLog
from gtrig.io.offsets import Z95

if TYPE_CHECKING:
    from gtrig.fusion.fuse import FusionOptions

Verdict = Literal["ok", "ambiguous", "unobservable"]


@dataclass(frozen=True)
class OffsetEstimate:
    """One source's clock offset to the reference.

    Attributes
    ----------
    source : its name. verdict : ``ok``, ``ambiguous`` or ``unobservable``.
    offset_s : the estimate (``nan`` unless ``ok``); ci95_s : (low, high) 95 % interval (``nan`` unless ok).
    coarse_s : the cross-correlation peak; peak : its normalised correlation; second_peak : the best
        other peak's. lags_s, corr : the correlation curve (for a figure). windows : used in the fit.
    reason : why the verdict, one line.
    """

    source: str
    verdict: Verdict
    offset_s: float
    ci95_s: tuple[float, float]
    coarse_s: float
    peak: float
    second_peak: float
    lags_s: np.ndarray
    corr: np.ndarray
    windows: int
    reason: str

    def to_dict(self) -> dict[str, object]:
        return {"verdict": self.verdict, "offset_s": None if np.isnan(self.offset_s) else float(self.offset_s),
                "ci95_s": None if np.isnan(self.offset_s) else [float(v) for v in self.ci95_s],
                "coarse_s": _num(self.coarse_s), "peak": _num(self.peak), "second_peak": _num(self.second_peak),
                "windows": int(self.windows), "reason": self.reason}


def _num(v: float) -> float | None:
    return None if not np.isfinite(v) else float(v)


def _rate_on_grid(stamps: np.ndarray, yaw: np.ndarray, grid: np.ndarray, max_dt: float,
                  ) -> tuple[np.ndarray, np.ndarray]:
    """Heading rate on ``grid`` (rad/s) and where it is valid (a sample within ``max_dt`` on both sides)."""
    th = np.unwrap(yaw)
    h = np.interp(grid, stamps, th)
    rate = np.gradient(h, grid)
    k = np.searchsorted(stamps, grid)
    prev = np.where(k > 0, stamps[np.maximum(k - 1, 0)], -np.inf)
    nxt = np.where(k < stamps.size, stamps[np.minimum(k, stamps.size - 1)], np.inf)
    valid = (grid - prev <= max_dt) & (nxt - grid <= max_dt) & (grid >= stamps[0]) & (grid <= stamps[-1])
    return rate, valid


def _window_misfits(offset: float, src_t: np.ndarray, src_th: np.ndarray, ref_t: np.ndarray, ref_th: np.ndarray,
                    win: np.ndarray, n_win: int) -> np.ndarray:
    """(W,) per window, the least-squares misfit of ``src_th ~ a_w + b_w ref_th(t - offset)`` (closed form
    from the windows' sums, one pass)."""
    x = np.interp(src_t - offset, ref_t, ref_th)
    y = src_th
    n = np.bincount(win, minlength=n_win).astype(float)
    sx, sy = np.bincount(win, x, n_win), np.bincount(win, y, n_win)
    nn = np.maximum(n, 1.0)
    xm, ym = sx / nn, sy / nn
    dx, dy = x - xm[win], y - ym[win]
    sxx, sxy, syy = np.bincount(win, dx * dx, n_win), np.bincount(win, dx * dy, n_win), np.bincount(win, dy * dy, n_win)
    return np.where(sxx > 0, syy - sxy**2 / np.where(sxx > 0, sxx, 1.0), syy)


def _parabolic_min(taus: np.ndarray, cost: np.ndarray) -> np.ndarray:
    """Minimum of each column of ``cost`` (G, K) over the grid ``taus`` (G,), refined by a parabola."""
    k = np.clip(np.argmin(cost, axis=0), 1, taus.size - 2)
    cols = np.arange(cost.shape[1])
    c0, c1, c2 = cost[k - 1, cols], cost[k, cols], cost[k + 1, cols]
    den = c0 - 2 * c1 + c2
    h = taus[1] - taus[0]
    shift = np.where(den > 0, 0.5 * (c0 - c2) / np.where(den > 0, den, 1.0), 0.0)
    return taus[k] + np.clip(shift, -1.0, 1.0) * h


def estimate_offset(ref_stamps_s: np.ndarray, ref_yaw: np.ndarray, src_stamps_s: np.ndarray, src_yaw: np.ndarray,
                    source: str = "source", search_s: float = 3.0, grid_hz: float = 100.0, window_s: float = 10.0,
                    min_rate_std: float = 0.02, ambiguity: float = 0.9, max_ci_s: float | None = None,
                    ) -> OffsetEstimate:
    """The clock offset of a source to the reference from their headings.

    Parameters
    ----------
    ref_stamps_s, ref_yaw : (N,) the reference's stamps and heading (rad; e.g. odometry theta).
    src_stamps_s, src_yaw : (M,) the source's stamps and heading (e.g. ``PoseTrack.yaw_rad()``).
    search_s : lags searched, both signs, seconds.
    grid_hz : the correlation's grid.
    window_s : the fit's windows (each has its own heading gain and level).
    min_rate_std : below this heading-rate spread (rad/s) in the overlap the offset is unobservable.
    ambiguity : a second peak at this fraction of the first makes the estimate ambiguous.
    max_ci_s : a wider 95 % interval is ambiguous (None: no limit; the fusion refinement checks its own).
    """
    rt, ry = np.asarray(ref_stamps_s, float), np.asarray(ref_yaw, float)
    st, sy = np.asarray(src_stamps_s, float), np.asarray(src_yaw, float)
    nan2 = (float("nan"), float("nan"))

    def verdict(v: Verdict, reason: str, coarse: float = float("nan"), peak: float = float("nan"),
                second: float = float("nan"), lags: np.ndarray | None = None, corr: np.ndarray | None = None,
                windows: int = 0) -> OffsetEstimate:
        return OffsetEstimate(source, v, float("nan"), nan2, coarse, peak, second,
                              np.zeros(0) if lags is None else lags, np.zeros(0) if corr is None else corr, windows,
                              reason)

    if rt.size < 3 or st.size < 3:
        return verdict("unobservable", "fewer than 3 samples")
    t0, t1 = max(rt[0], st[0]), min(rt[-1], st[-1])
    if t1 - t0 < 4 * search_s:
        return verdict("unobservable", f"the overlap ({max(t1 - t0, 0):.1f} s) is shorter than 4 x the search window")
    src_dt = float(np.median(np.diff(st)))
    ref_dt = float(np.median(np.diff(rt)))
    # the grid resolves the faster of the two streams, at most grid_hz
    step = max(1.0 / grid_hz, 0.5 * min(src_dt, ref_dt))
    grid = np.arange(t0, t1, step)
    s_rate, s_valid = _rate_on_grid(st, sy, grid, max(2.5 * src_dt, 2 * step))
    ref_grid = np.arange(rt[0], rt[-1], step)
    r_rate, _ = _rate_on_grid(rt, ry, ref_grid, np.inf)
    if np.std(s_rate[s_valid]) < min_rate_std or np.std(r_rate) < min_rate_std:
        return verdict("unobservable", "the robot hardly turns: no heading-rate signal to align")
    lags = np.arange(-round(search_s / step), round(search_s / step) + 1) * step
    corr = _lag_correlation(lags, grid, s_rate, s_valid, ref_grid, r_rate, (rt[0], rt[-1]))
    if not np.any(np.isfinite(corr)):
        return verdict("unobservable", "no overlap at any lag")
    kmax, peak, second = _main_peak(corr)
    coarse = float(lags[kmax])
    if peak < 0.3:
        return verdict("ambiguous", f"no correlation peak (best {peak:.2f})", coarse, peak, second, lags, corr)
    if np.isfinite(second) and second >= ambiguity * peak:
        return verdict("ambiguous", f"two peaks: {peak:.3f} at {coarse:+.3f} s and {second:.3f} elsewhere",
                       coarse, peak, second, lags, corr)
    if kmax in (0, corr.size - 1):
        return verdict("ambiguous", "the peak is at the edge of the search window; widen it", coarse, peak, second,
                       lags, corr)
    # --- fine: 1-D minimisation of the heading misfit at the source's own stamps
    keep = (st >= t0 + search_s) & (st <= t1 - search_s)
    sts, sys_ = st[keep], np.unwrap(sy)[keep]
    window_s = max(window_s, 10.0 * src_dt)  # at least ~10 samples of the source per window
    win, n_turning = _turning_windows(sts, sys_, window_s)
    if n_turning < 3:
        return verdict("unobservable", f"only {n_turning} windows of {window_s:.0f} s with turns",
                       coarse, peak, second, lags, corr, n_turning)
    use = win >= 0
    sts, sys_, win = sts[use], sys_[use], win[use]
    reach = max(4 * step, src_dt, ref_dt)
    best, half = _fine_offset(coarse, reach, sts, sys_, rt, np.unwrap(ry), win, n_turning)
    W = n_turning
    if abs(best - coarse) > 0.98 * reach:
        return verdict("ambiguous", f"the heading fit's minimum lies past {reach * 1e3:.0f} ms from the correlation "
                       "peak", coarse, peak, second, lags, corr, W)
    ci = (best - half, best + half)
    if max_ci_s is not None and 2 * half > max_ci_s:
        return OffsetEstimate(source, "ambiguous", float("nan"), nan2, coarse, peak, second, lags, corr, W,
                              f"the 95 % interval ({2 * half * 1e3:.1f} ms) is wider than {max_ci_s * 1e3:.1f} ms")
    return OffsetEstimate(source, "ok", best, ci, coarse, peak, second, lags, corr, W,
                          f"peak {peak:.3f} at {coarse:+.3f} s, refined over {W} windows")


def _lag_correlation(lags: np.ndarray, grid: np.ndarray, s_rate: np.ndarray, s_valid: np.ndarray,
                     ref_grid: np.ndarray, r_rate: np.ndarray, ref_span_s: tuple[float, float]) -> np.ndarray:
    """Normalised cross-correlation (L,) of the source's heading rate on ``grid`` with the reference's
    (on ``ref_grid``, its stamps spanning ``ref_span_s``) shifted by each lag (s); NaN where fewer than 10
    samples overlap."""
    corr = np.full(lags.size, np.nan)
    for k, lag in enumerate(lags):
        g = grid - lag
        m = s_valid & (g >= ref_span_s[0]) & (g <= ref_span_s[1])
        if m.sum() < 10:
            continue
        a = s_rate[m] - s_rate[m].mean()
        b = np.interp(g[m], ref_grid, r_rate)
        b = b - b.mean()
        den = np.sqrt((a @ a) * (b @ b))
        corr[k] = (a @ b) / den if den > 0 else np.nan
    return corr


def _main_peak(corr: np.ndarray) -> tuple[int, float, float]:
    """The correlation's highest peak (index, height) and the highest other local peak outside the main
    peak's half-height width (NaN if none)."""
    c = np.nan_to_num(corr, nan=-1.0)
    kmax = int(np.argmax(c))
    peak = float(c[kmax])
    lo = kmax
    while lo > 0 and c[lo - 1] > 0.5 * peak:
        lo -= 1
    hi = kmax
    while hi < c.size - 1 and c[hi + 1] > 0.5 * peak:
        hi += 1
    is_local = np.r_[False, (c[1:-1] >= c[:-2]) & (c[1:-1] >= c[2:]), False]
    others = is_local & ((np.arange(c.size) < lo) | (np.arange(c.size) > hi))
    second = float(c[others].max()) if np.any(others) else float("nan")
    return kmax, peak, second


def _turning_windows(stamps_s: np.ndarray, yaw_unwrapped: np.ndarray, window_s: float) -> tuple[np.ndarray, int]:
    """Each sample's window among those where the robot turns (heading spread over 2 deg, at least 4
    samples), numbered 0..W-1, or -1 in a window that does not turn; and W."""
    win = np.floor((stamps_s - stamps_s[0]) / window_s).astype(int)
    n_win = int(win.max()) + 1 if win.size else 0
    lo_w = np.full(n_win, np.inf)
    hi_w = np.full(n_win, -np.inf)
    np.minimum.at(lo_w, win, yaw_unwrapped)
    np.maximum.at(hi_w, win, yaw_unwrapped)
    turning = (hi_w - lo_w > np.deg2rad(2.0)) & (np.bincount(win, minlength=n_win) >= 4)
    ids = np.flatnonzero(turning)
    out = np.full(win.size, -1)
    use = turning[win] if win.size else np.zeros(0, bool)
    out[use] = np.searchsorted(ids, win[use])
    return out, int(ids.size)


def _fine_offset(coarse: float, reach: float, stamps_s: np.ndarray, yaw: np.ndarray, ref_stamps_s: np.ndarray,
                 ref_yaw_unwrapped: np.ndarray, win: np.ndarray, n_windows: int) -> tuple[float, float]:
    """The offset (s) minimising the windows' summed heading misfit on a grid of 161 lags within ``reach`` of
    ``coarse`` (parabolic vertex), and its 95 % half-interval from the leave-one-window-out jackknife."""
    W = n_windows
    taus = coarse + np.linspace(-reach, reach, 161)
    per_win = np.stack([_window_misfits(tau, stamps_s, yaw, ref_stamps_s, ref_yaw_unwrapped, win, W)
                        for tau in taus])  # (G, W)
    total = per_win.sum(axis=1)
    best = float(_parabolic_min(taus, total[:, None])[0])
    jack = _parabolic_min(taus, total[:, None] - per_win)
    se = float(np.sqrt((W - 1) / W * np.sum((jack - jack.mean()) ** 2)))
    return best, float(student_t.ppf(0.975, W - 1)) * max(se, 1e-6)


@dataclass(frozen=True)
class _RefineWindow:
    """One window of :func:`refine_by_fusion`: its fixes merged with the anchors' over the same span
    (``base``, :func:`gtrig.fusion.fuse.merge_fixes`), the odometry's node stamps (N,) covering them, the gate's
    verdict per fix (from the smoothing at the start offset) and the last solve's state (``warm``: X, K),
    which starts the next cost's solve."""

    base: dict[str, np.ndarray]
    names: tuple[str, ...]
    stamps: np.ndarray
    use: np.ndarray
    warm: dict[str, np.ndarray]

    @staticmethod
    def of(f: Fixes, anchors: tuple[Fixes, ...], c: float, margin: float, odometry: OdometryLog,
           opts: FusionOptions) -> _RefineWindow | None:
        """The window of the (decorrelated) fixes ``f`` (None when it has fewer than 10), with the
        anchors within ``margin`` (s) of its span (decorrelated there), smoothed at the start offset ``c``
        (s)."""
        from gtrig.fusion.ekf import smooth_ekf
        from gtrig.fusion.fuse import build_chain, decorrelated, merge_fixes

        if len(f) < 10:
            return None
        anc = [decorrelated(a.between(f.stamps_s[0] - c - margin, f.stamps_s[-1] - c + margin), opts.correlation_s)
               for a in anchors]
        base = merge_fixes([f, *anc])
        names = (f.source, *(a.source for a in anc))
        i0 = max(int(np.searchsorted(odometry.stamps_s, base["stamps"][0] - c - margin)) - 1, 0)
        i1 = min(int(np.searchsorted(odometry.stamps_s, base["stamps"][-1] - c + margin)), len(odometry) - 1)
        stamps = odometry.stamps_s[i0:i1 + 1]
        fx0, order0 = _shifted(base, c)
        chain0, _, _, P0 = build_chain(stamps, fx0, odometry, opts, names)
        ekf = smooth_ekf(chain0, P0, opts.odometry.prior()[1], gate_prob=opts.gate_prob)
        use = np.zeros(order0.size, bool)
        use[order0] = ekf.accept  # the gate's verdict per fix, in the unshifted order
        return _RefineWindow(base, names, stamps, use, {"X": ekf.X, "K": ekf.K})

    def cost(self, offset: float, odometry: OdometryLog, opts: FusionOptions) -> float:
        """The window's batch cost (-2 log-likelihood) with the source's fixes moved by ``offset`` (s)."""
        from gtrig.fusion.batch import smooth_batch
        from gtrig.fusion.fuse import build_chain

        fx, order = _shifted(self.base, offset)
        ch, _, _, _ = build_chain(self.stamps, fx, odometry, opts, self.names)
        res = smooth_batch(ch, self.warm["X"], self.warm["K"], fix_use=self.use[order], huber_k=opts.huber_k,
                           max_iter=8)
        self.warm["X"], self.warm["K"] = res.X, res.K
        return float(res.cost)


def _shifted(base: dict[str, np.ndarray], offset: float) -> tuple[dict[str, np.ndarray], np.ndarray]:
    """The merged fixes ``base`` with the first source's (index 0) moved by ``-offset`` (s), re-sorted by
    stamp, and the order that sorts them."""
    st_ = base["stamps"] - np.where(base["source"] == 0, offset, 0.0)
    order = np.argsort(st_, kind="stable")
    return {**{k: v[order] for k, v in base.items()}, "stamps": st_[order]}, order


def refine_by_fusion(estimate: OffsetEstimate, fixes: Fixes, odometry: OdometryLog,
                     options: FusionOptions | None = None, half_width_s: float = 0.015,
                     anchors: tuple[Fixes, ...] = (), window_s: float = 600.0) -> OffsetEstimate:
    """Refine an ``ok`` (or coarse) estimate with the offset as a parameter of the fusion's own fit.

    The source's fixes (positions and headings, each weighed by its covariance) are smoothed with the
    odometry alone at trial offsets; Brent's method minimises the batch cost (-2 log-likelihood) over the
    offset within ``half_width_s`` of the estimate (of the coarse peak when the estimate is not ``ok``),
    and the 95 % interval comes from the cost's curvature (Fisher information = cost'' / 2). The fixes'
    decorrelation (FusionOptions.correlation_s) keeps that curvature honest for time-correlated errors.

    ``anchors``: other sources fused unshifted (their clock then is the reference: a mm-accurate GT
    source pins the time far better than the odometry's slipping heading); ``estimate`` must then be
    relative to them too.

    ``window_s``: a source spanning more than this is smoothed a window of ``window_s`` of its fixes at
    a time (:class:`_RefineWindow`), the cost being the sum of the windows'; a shorter one is one batch.
    """
    from gtrig.fusion.fuse import FusionOptions, decorrelated

    if estimate.verdict == "unobservable" or not np.isfinite(estimate.coarse_s):
        return estimate
    opts = options or FusionOptions()
    # centred on the heading fit's estimate when there is one: the correlation's peak lies on a grid of
    # half the faster stream's period and, with noisy heading rates, a step or two off (a search around it
    # alone then missed the minimum and reported a good estimate as ambiguous)
    c = float(estimate.offset_s) if estimate.verdict == "ok" else float(estimate.coarse_s)
    o0, o1 = float(odometry.stamps_s[0]), float(odometry.stamps_s[-1])
    margin = 2 * half_width_s + 0.1
    keep = (fixes.stamps_s - c >= o0 + margin) & (fixes.stamps_s - c <= o1 - margin)
    if keep.sum() < 10:
        return estimate
    f = Fixes(fixes.source, fixes.stamps_s[keep], fixes.model, fixes.value[keep], fixes.cov[keep], fixes.lever_xy)
    f = decorrelated(f, opts.correlation_s)
    # a long run is smoothed a window at a time and the windows' costs summed (the cost is a sum over
    # the fixes; what a window's cut loses is one process factor): memory a window's, not the run's
    # (an hour of GTlaser's 75 Hz fixes took the client's peak up by 320 MB); one window up to window_s
    n_win = max(1, int(np.ceil((f.stamps_s[-1] - f.stamps_s[0]) / window_s)))
    edges = np.r_[-np.inf, f.stamps_s[0] + window_s * np.arange(1, n_win), np.inf]
    parts = [_RefineWindow.of(f.between(edges[w], np.nextafter(edges[w + 1], -np.inf)), anchors, c, margin,
                              odometry, opts) for w in range(n_win)]
    windows = [w for w in parts if w is not None]
    if not windows:
        return estimate

    def cost(offset: float) -> float:
        return float(sum(w.cost(offset, odometry, opts) for w in windows))

    res = minimize_scalar(cost, bounds=(c - half_width_s, c + half_width_s), method="bounded",
                          options={"xatol": 2e-5})
    best = float(res.x)
    h = 1e-3
    curv = (cost(best + h) - 2 * cost(best) + cost(best - h)) / h**2
    if not curv > 0:
        return OffsetEstimate(estimate.source, "ambiguous", float("nan"), (float("nan"),) * 2, estimate.coarse_s,
                              estimate.peak, estimate.second_peak, estimate.lags_s, estimate.corr, estimate.windows,
                              "the fusion cost has no minimum near the correlation peak")
    half = 1.96 * float(np.sqrt(2.0 / curv))
    verdict: Verdict = estimate.verdict if estimate.verdict != "ok" else "ok"
    if abs(best - c) > half_width_s * 0.95 or 2 * half > 2 * half_width_s:
        verdict = "ambiguous"
    if verdict != "ok":
        return OffsetEstimate(estimate.source, verdict, float("nan"), (float("nan"),) * 2, estimate.coarse_s,
                              estimate.peak, estimate.second_peak, estimate.lags_s, estimate.corr, estimate.windows,
                              estimate.reason)
    return OffsetEstimate(estimate.source, "ok", best, (best - half, best + half), estimate.coarse_s, estimate.peak,
                          estimate.second_peak, estimate.lags_s, estimate.corr, estimate.windows,
                          f"peak {estimate.peak:.3f} at {estimate.coarse_s:+.3f} s, heading fit {c * 1e3:+.2f} ms; "
                          f"refined by the fusion's fit ({sum(int(w.use.sum()) for w in windows)} fixes)")


def offset_sigmas(path: str | os.PathLike[str]) -> dict[str, float]:
    """Per source of a ``sync.yaml`` with an ``ok`` offset to the reference, the offset's standard error (s):
    its 95 % interval's half-width / 1.96 (for :attr:`~gtrig.fusion.fuse.FusionOptions.offsets_sigma_s`).
    Entries without an interval are left out; the file's other checks are :func:`gtrig.io.offsets.read_offsets`'."""
    from gtrig.io.offsets import read_offsets, sigma_from_ci95
    from gtrig.io.yamlfile import load_yaml

    ok = read_offsets(path)
    doc = load_yaml(path) or {}
    out: dict[str, float] = {}
    for name in ok:
        sigma = sigma_from_ci95((doc.get("sources") or {}).get(name, {}).get("ci95_s"))
        if sigma is not None:
            out[name] = sigma
    return out


def combine_with_laser_clock(vision: OffsetEstimate, laser: OffsetEstimate, laser_to_vision_s: float,
                             laser_to_vision_sigma_s: float) -> tuple[OffsetEstimate, OffsetEstimate]:
    """GTvision's and GTlaser's offsets to the reference made consistent with GTlaser's clock to GTvision's.

    Each source's offset to odometry scatters by about 1.3 ms on a 75 s run (the odometry's slip), and the
    two scatter apart: applied as they are, the sources disagree by their difference (3.9 ms on seed 0).
    GTlaser's clock to GTvision's is known far better (the scanners' offsets,
    :func:`gtrig.sync.sensors.laser_clock`: about 0.3 ms). So: one offset of GTvision's clock,
    the inverse-variance mean of GTvision's estimate and GTlaser's minus ``laser_to_vision_s``; GTlaser's is
    that plus ``laser_to_vision_s``. Its sigma assumes the two estimates' errors fully correlated (they
    share the odometry): the weighted mean of their sigmas, no narrower than the better one alone.
    Unchanged unless both estimates and ``laser_to_vision_s`` are ``ok`` / finite.
    """
    if vision.verdict != "ok" or laser.verdict != "ok" or not np.isfinite(laser_to_vision_s):
        return vision, laser
    z = Z95
    sv, sl = (vision.ci95_s[1] - vision.ci95_s[0]) / 2 / z, (laser.ci95_s[1] - laser.ci95_s[0]) / 2 / z
    sl = float(np.hypot(sl, laser_to_vision_sigma_s if np.isfinite(laser_to_vision_sigma_s) else 0.0))
    if not (sv > 0 and sl > 0):
        return vision, laser
    wv, wl = 1 / sv**2, 1 / sl**2
    theta = (wv * vision.offset_s + wl * (laser.offset_s - laser_to_vision_s)) / (wv + wl)
    sig = (wv * sv + wl * sl) / (wv + wl)
    why = (f"combined: GTvision alone {vision.offset_s * 1e3:+.3f} ms (sigma {sv * 1e3:.2f}), GTlaser alone "
           f"{laser.offset_s * 1e3:+.3f} ms less its clock to GTvision's {laser_to_vision_s * 1e3:+.3f} ms "
           f"(sigma {sl * 1e3:.2f})")
    sl_out = float(np.hypot(sig, laser_to_vision_sigma_s if np.isfinite(laser_to_vision_sigma_s) else 0.0))
    lo = theta + laser_to_vision_s
    return (replace(vision, offset_s=float(theta), ci95_s=(theta - z * sig, theta + z * sig), reason=why),
            replace(laser, offset_s=float(lo), ci95_s=(lo - z * sl_out, lo + z * sl_out), reason=why))
