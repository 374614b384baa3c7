"""Per-scanner, per-beam background model from a static sequence (journal paper, section 6).

The background range of a beam is the median of the returns in its *farthest* cluster: a person
walking through only ever shortens a beam, so the returns of the empty room are the long ones. The
90th percentile finds that cluster (robust while the beam is blocked less than 90 % of the time) and
the median of the returns within a few noise sigmas of it is an unbiased estimate of the room's range,
precise enough (noise / sqrt(scans)) for the calibration to use as well.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from gtrig.errors import InputError
from gtrig.rig.models import LaserScanner

# A beam needs a return in at least this fraction of the static scans to have a background range.
MIN_RETURN_FRACTION = 0.2


@dataclass(frozen=True)
class BackgroundModel:
    """The empty room as one scanner sees it.

    Attributes
    ----------
    scanner : scanner name (rig file).
    ranges_m : (B,) background range per beam, metres; ``nan`` where the room gives no stable return
        (beyond ``range_max_m`` or absorbed): any return there is foreground.
    spread_m : (B,) robust standard deviation (1.4826 MAD) of the background returns per beam, metres.
    n_scans : number of static scans used.
    """

    scanner: str
    ranges_m: np.ndarray
    spread_m: np.ndarray
    n_scans: int

    def __post_init__(self) -> None:
        for a in (self.ranges_m, self.spread_m):
            a.setflags(write=False)

    @property
    def beams(self) -> int:
        return int(self.ranges_m.size)


def build_background(
    ranges_m: np.ndarray,
    scanner: LaserScanner,
    upper_percentile: float = 90.0,
    window_sigma: float = 4.0,
) -> BackgroundModel:
    """Background model of ``scanner`` from its static scans.

    Parameters
    ----------
    ranges_m
        (N, B) static scans, metres, ``nan`` = no return; B must equal ``scanner.beams``.
    scanner
        The scanner (its ``range_sigma_m`` sets the width of the background cluster).
    upper_percentile
        Percentile of each beam's returns taken to lie in the room's cluster.
    window_sigma
        Half-width of the cluster below that percentile, in range sigmas (plus 1 cm).

    Returns
    -------
    BackgroundModel
    """
    r = np.asarray(ranges_m, dtype=float)
    if r.ndim != 2 or r.shape[1] != scanner.beams:
        got = r.shape[1] if r.ndim == 2 else r.shape
        raise InputError(
            f"scanner {scanner.name}: static scans have {got} beams, the rig says {scanner.beams}"
        )
    if r.shape[0] == 0:
        raise InputError(f"scanner {scanner.name}: the static sequence holds no scans")
    valid = np.isfinite(r)
    n_valid = valid.sum(axis=0)
    enough = n_valid >= max(1, int(np.ceil(MIN_RETURN_FRACTION * r.shape[0])))
    with np.errstate(all="ignore"):
        import warnings

        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            upper = np.nanpercentile(r, upper_percentile, axis=0)
            half = window_sigma * scanner.range_sigma_m + 0.01
            inside = valid & (np.abs(r - upper) <= half)
            rin = np.where(inside, r, np.nan)
            med = np.nanmedian(rin, axis=0)
            mad = np.nanmedian(np.abs(rin - med), axis=0) * 1.4826
    med = np.where(enough, med, np.nan)
    mad = np.where(enough & np.isfinite(mad), mad, 0.0)
    return BackgroundModel(scanner.name, med, mad, int(r.shape[0]))
