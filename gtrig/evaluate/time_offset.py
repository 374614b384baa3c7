"""Estimate the clock offset between an estimate and the ground truth (``t_gt = t_est + offset``).

Two steps:

1. coarse: the speed profiles ``|v(t)|`` of both tracks (frame- and alignment-free) resampled on one grid
   and cross-correlated (FFT) over ``+- max_offset_s``;
2. fine: the offset minimizing the RMS position residual after interpolated association and alignment
   (bounded Brent search over two grid steps around the coarse peak).

The interval is Gauss-Newton's: the residual's derivative with respect to the offset is the estimate's
velocity, so ``var = s^2 / sum |v_i|^2`` with ``s^2`` the residual variance per axis, inflated by the
residuals' lag-1 autocorrelation (AR(1) effective sample size).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from gtrig.errors import InputError
from gtrig.evaluate.align import AlignKind, apply_alignment, fit_alignment
from gtrig.evaluate.associate import associate_interpolate
from gtrig.evaluate.gt_aware import Z95
from gtrig.trajectory import PoseTrack


@dataclass(frozen=True)
class TimeOffset:
    """``t_gt = t_est + offset_s``; ``low_s``, ``high_s`` the 95 % interval; ``coarse_s`` step 1's answer."""

    offset_s: float
    sigma_s: float
    low_s: float
    high_s: float
    coarse_s: float
    rms_m: float


def _speed(track: PoseTrack, grid: np.ndarray) -> np.ndarray:
    p = np.column_stack([np.interp(grid, track.stamps_s, track.xyz[:, i]) for i in range(3)])
    v = np.linalg.norm(np.diff(p, axis=0), axis=1) / np.diff(grid)
    return np.append(v, v[-1])


def _residual(gt: PoseTrack, est: PoseTrack, tau: float, align: AlignKind, max_gap_s: float
              ) -> tuple[float, PoseTrack, PoseTrack]:
    a = associate_interpolate(gt, est, max_gap_s, tau)
    al = fit_alignment(a.gt.xyz, a.est.xyz, align)
    e = apply_alignment(a.est, al)
    r = e.xyz - a.gt.xyz
    return float(np.sqrt(np.mean(np.sum(r * r, axis=1)))), a.gt, e


def estimate_time_offset(gt: PoseTrack, est: PoseTrack, align: AlignKind = "se3", max_offset_s: float = 5.0,
                         max_gap_s: float = 0.2) -> TimeOffset:
    """The offset to add to the estimate's stamps (module docstring)."""
    from scipy import optimize, signal  # here: a CLI call without --t-offset auto need not import them

    lo = max(gt.stamps_s[0], est.stamps_s[0] - max_offset_s)
    hi = min(gt.stamps_s[-1], est.stamps_s[-1] + max_offset_s)
    if hi - lo < 4 * max_offset_s:
        raise InputError(f"common span {max(hi - lo, 0):.2f} s is too short to estimate a time offset within "
                         f"+-{max_offset_s:g} s")
    dt = max(float(np.median(np.diff(gt.stamps_s))), float(np.median(np.diff(est.stamps_s))), 1e-3)
    grid = np.arange(max(gt.stamps_s[0], est.stamps_s[0]), min(gt.stamps_s[-1], est.stamps_s[-1]), dt)
    if grid.size < 16:
        raise InputError("too few samples in the common span to estimate a time offset")
    vg, ve = _speed(gt, grid), _speed(est, grid)
    vg, ve = vg - vg.mean(), ve - ve.mean()
    cc = signal.correlate(vg, ve, mode="full", method="fft")
    lags = signal.correlation_lags(vg.size, ve.size, mode="full") * dt
    keep = np.abs(lags) <= max_offset_s
    coarse = float(lags[keep][np.argmax(cc[keep])])
    res = optimize.minimize_scalar(lambda tau: _residual(gt, est, tau, align, max_gap_s)[0],
                                   bounds=(coarse - 2 * dt, coarse + 2 * dt), method="bounded",
                                   options={"xatol": 1e-6})
    tau = float(res.x)
    rms, g, e = _residual(gt, est, tau, align, max_gap_s)
    r = e.xyz - g.xyz
    v = np.gradient(e.xyz, e.stamps_s, axis=0)
    rx = r[:, 0] - r[:, 0].mean()
    rho = float(np.corrcoef(rx[:-1], rx[1:])[0, 1]) if len(rx) > 3 and np.std(rx) > 0 else 0.0
    rho = min(max(rho, 0.0), 0.999)
    s2 = float(np.mean(np.sum((r - r.mean(axis=0)) ** 2, axis=1))) / 3
    sigma = float(np.sqrt(s2 * (1 + rho) / (1 - rho) / max(float(np.sum(v * v)), 1e-300)))
    return TimeOffset(tau, sigma, tau - Z95 * sigma, tau + Z95 * sigma, coarse, rms)
