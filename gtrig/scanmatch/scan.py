"""Planar scans as matchable point sets: ranges to points in a chosen frame, scan-order normals, two
scanners merged into one 360-degree scan through their mountings, and the low-noise scan of a stop.

A :class:`PlanarScan` is what the matchers take: points, their normals (for the point-to-line
metric), and each point's range noise. Points are in the frame the caller names (the robot frame
for merged scans, the scanner frame for one scanner).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.stats import chi2

from gtrig.errors import InputError
from gtrig.scanmatch import se2
from gtrig.scanmatch._kernels import ordered_normals

# Neighbours within this many beams either side fit a point's normal.
NORMAL_HALF_WINDOW = 2
# Two neighbours belong to one surface when closer than this plus 3.5 beam spacings at their range:
# the spacing of a surface seen at grazing incidence grows with range.
NORMAL_GAP_M = 0.06
# A fit is a line when its smaller spread is under this fraction of the larger one (a corner or a leg
# arc is not), or when its scatter across the line is within the points' range noise (chi-square 95 %).
NORMAL_MAX_FLATNESS = 0.05
_CHI2_95 = np.array([np.inf] + [float(chi2.ppf(0.95, k)) for k in range(1, 2 * NORMAL_HALF_WINDOW + 2)])


@dataclass(frozen=True)
class PlanarScan:
    """A scan as a point set.

    Attributes
    ----------
    xy : (N, 2) points, metres, in the scan's frame (robot or scanner; the caller says).
    normals : (N, 2) unit normals (line fit over scan-order neighbours); meaningful where ``normal_ok``.
    normal_ok : (N,) bool.
    sigma_m : (N,) standard deviation of each point along its beam (range noise), metres.
    stamp_s : the scan's time (its reference instant), seconds; nan when not known.
    """

    xy: np.ndarray
    normals: np.ndarray
    normal_ok: np.ndarray
    sigma_m: np.ndarray
    stamp_s: float = float("nan")

    def __post_init__(self) -> None:
        for name in ("xy", "normals", "normal_ok", "sigma_m"):
            a = np.ascontiguousarray(getattr(self, name))
            a.setflags(write=False)
            object.__setattr__(self, name, a)

    def __len__(self) -> int:
        return int(self.xy.shape[0])

    def moved(self, pose: np.ndarray) -> PlanarScan:
        """The same scan with its points and normals mapped by ``pose`` (x, y, theta)."""
        c, s = np.cos(pose[2]), np.sin(pose[2])
        R = np.array([[c, -s], [s, c]])
        return PlanarScan(se2.apply(pose, self.xy), self.normals @ R.T, self.normal_ok, self.sigma_m, self.stamp_s)


def ranges_to_scan(ranges_m: np.ndarray, angles_rad: np.ndarray, beam_pose: np.ndarray,
                   sigma_m: float | np.ndarray, range_max_m: float = np.inf, stamp_s: float = float("nan"),
                   min_range_m: float = 0.05) -> PlanarScan:
    """One scanner's scan as a :class:`PlanarScan` in the frame of ``beam_pose``.

    Parameters
    ----------
    ranges_m : (B,) ranges, ``nan`` for no return.
    angles_rad : (B,) beam angles in the scanner frame.
    beam_pose : (3,) or (B, 3) the scanner's pose (x, y, theta) in the target frame, per beam when the
        platform moves during the sweep (de-skewing).
    sigma_m : range noise, scalar or (B,).
    range_max_m : returns at or beyond it are dropped (no echo).
    min_range_m : returns closer than this are dropped (the scanner's own housing).

    Beams without a valid return are dropped; normals come from the remaining scan order.
    """
    r = np.asarray(ranges_m, dtype=float)
    a = np.asarray(angles_rad, dtype=float)
    sig = np.broadcast_to(np.asarray(sigma_m, dtype=float), r.shape)
    ok = np.isfinite(r) & (r >= min_range_m) & (r < range_max_m)
    local = np.column_stack([r * np.cos(a), r * np.sin(a)])[ok]
    bp = np.asarray(beam_pose, dtype=float)
    bp = np.broadcast_to(bp, (r.size, 3))[ok]
    xy = se2.apply(bp, local[:, None, :])[:, 0, :] if len(local) else np.zeros((0, 2))
    inc = float(np.median(np.abs(np.diff(a)))) if a.size > 1 else 0.0
    gap = NORMAL_GAP_M + 3.5 * r[ok] * inc
    nrm, nok = ordered_normals(np.ascontiguousarray(xy), np.ones(len(xy), np.bool_), gap, NORMAL_HALF_WINDOW,
                               NORMAL_MAX_FLATNESS, np.ascontiguousarray(sig[ok] ** 2), _CHI2_95)
    return PlanarScan(xy, nrm, nok, np.ascontiguousarray(sig[ok]), stamp_s)


def merge(scans: list[PlanarScan] | tuple[PlanarScan, ...], stamp_s: float | None = None) -> PlanarScan:
    """Concatenate scans already in one frame (e.g. front and rear scanners in the robot frame) into
    one 360-degree scan; normals were fitted per scanner, so no false normals across the seam."""
    if not scans:
        raise InputError("no scans to merge")
    st = scans[0].stamp_s if stamp_s is None else stamp_s
    return PlanarScan(np.concatenate([s.xy for s in scans]), np.concatenate([s.normals for s in scans]),
                      np.concatenate([s.normal_ok for s in scans]), np.concatenate([s.sigma_m for s in scans]), st)


def stop_ranges(ranges_m: np.ndarray, sigma_m: float, min_valid: float = 0.5,
                max_spread_sigma: float = 4.0) -> tuple[np.ndarray, np.ndarray]:
    """The low-noise scan of a robot standing still: per beam, the median over the stop's scans.

    Parameters
    ----------
    ranges_m : (K, B) the scans taken while the robot stood still.
    sigma_m : one scan's range noise.
    min_valid : a beam needs returns in at least this fraction of the scans.
    max_spread_sigma : a beam whose scans spread (1.4826 MAD) by more than this many ``sigma_m`` saw
        something move (a person walking through) and is dropped.

    Returns
    -------
    ranges : (B,) medians, nan where dropped.
    sigma : (B,) the medians' standard deviation, ``1.2533 * spread / sqrt(n)`` (the median's
        efficiency for Gaussian noise), not below ``sigma_m / sqrt(n)``.
    """
    R = np.asarray(ranges_m, dtype=float)
    if R.ndim != 2 or R.shape[0] == 0:
        raise InputError("a stop needs at least one scan")
    n = np.sum(np.isfinite(R), axis=0)
    with np.errstate(all="ignore"):
        import warnings

        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            med = np.nanmedian(R, axis=0)
            mad = 1.4826 * np.nanmedian(np.abs(R - med), axis=0)
    spread = np.maximum(np.nan_to_num(mad, nan=np.inf), sigma_m) if R.shape[0] > 2 else np.full(R.shape[1], sigma_m)
    keep = (n >= max(1, min_valid * R.shape[0])) & (spread <= max_spread_sigma * sigma_m)
    out = np.where(keep, med, np.nan)
    sig = 1.2533 * spread / np.sqrt(np.maximum(n, 1))
    return out, np.where(keep, sig, np.nan)
