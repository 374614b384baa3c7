"""Foreground extraction: returns clearly shorter than the background (journal paper, section 6).

A return is foreground when it is shorter than the background of its beam *and of both neighbouring
beams* by a margin. The neighbours matter at the edges of furniture, where the room's own mixed pixels
(returns between the near edge and the far wall) would otherwise pass for foreground in every scan.
"""

from __future__ import annotations

import numpy as np

from gtrig.laser.background import BackgroundModel


def foreground_threshold(bg: BackgroundModel, margin_m: float = 0.05, spread_k: float = 5.0) -> np.ndarray:
    """Per-beam range (B,) below which a return is foreground, metres (``inf`` where no background).

    The threshold is ``min(bg[i-1], bg[i], bg[i+1]) - max(margin_m, spread_k * spread[i])``.
    """
    r = np.where(np.isfinite(bg.ranges_m), bg.ranges_m, np.inf)
    near = r.copy()
    near[1:] = np.minimum(near[1:], r[:-1])
    near[:-1] = np.minimum(near[:-1], r[1:])
    return near - np.maximum(margin_m, spread_k * bg.spread_m)


def foreground_mask(ranges_m: np.ndarray, threshold_m: np.ndarray, min_range_m: float = 0.05) -> np.ndarray:
    """Boolean mask (N, B) of foreground returns in scans ``ranges_m`` (N, B) given the per-beam
    ``threshold_m`` (B,) of :func:`foreground_threshold`; ``nan`` (no return) is never foreground."""
    r = np.asarray(ranges_m, dtype=float)
    with np.errstate(invalid="ignore"):
        return (r < threshold_m) & (r > min_range_m)
