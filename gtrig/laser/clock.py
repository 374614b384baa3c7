"""GTlaser on one clock: each fixed scanner's stamps corrected by its measured clock offset.

A frame's fit holds at the share-weighted mean true time of its points, so a track made from the
scanners' own stamps is on no clock in particular: the mean of the scanners' offsets shifts it as a
whole (at 2 rad/s, 1.6 ms is 0.18 deg of yaw), their differences make the scanners disagree in the
turns. Neither the common part nor, at low turn rates, the differences can be seen in laser data; a
reference on another clock can (:mod:`gtrig.sync.sensors` fits each scanner's returns against
GTvision's smoothed track). Here each scanner's stamps are moved onto the reference clock by its
measured offset before the frames are formed, so the fit, the motion compensation and the smoother
all run on that clock, and the rig's ``stamp_sigma_s`` of each scanner becomes the standard
deviation of its offset's estimate: the timing term of the covariance (``sigma_t^2 v v^T``,
:func:`gtrig.laser.track.timing_covariance`) then carries what is left unknown of the clocks.

Convention (``sync.yaml``, :mod:`gtrig.io.offsets`): ``offset_s = scanner stamp - reference stamp of
the same instant``, so the reference stamp of a scan is its stamp minus the offset.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any, Literal

from gtrig.io.offsets import sigma_from_ci95
from gtrig.io.scans import ScanLog
from gtrig.rig.models import LaserScanner, Rig

#: the clocks a GTlaser track can be delivered on: the scanners' own stamps, GTvision's (the cameras'),
#: or odometry's (the robot's)
Clock = Literal["scanners", "vision", "odometry"]


@dataclass(frozen=True)
class ScannerClock:
    """One scanner's clock against the reference clock.

    Attributes
    ----------
    offset_s : scanner stamp minus reference stamp of the same instant, seconds.
    sigma_s : standard deviation of that offset's estimate, seconds.
    """

    offset_s: float
    sigma_s: float


def clocks_from_sync(sources: Mapping[str, Any], clock: Clock) -> dict[str, ScannerClock]:
    """The scanners' offsets to ``clock`` from ``sync.yaml``'s ``sources`` mapping (entries
    ``laser/<scanner>`` whose verdict is ``ok``; a scanner without one is left out).

    ``vision``: ``offset_to_vision_s`` and its interval (GTvision's clock, the cameras'); ``odometry``:
    ``offset_s`` and its interval (that plus GTvision's offset to odometry, whose interval is added in
    quadrature by the sync stage); ``scanners``: nothing (the scanners' own stamps).
    """
    if clock == "scanners":
        return {}
    key, ci_key = ("offset_to_vision_s", "ci95_to_vision_s") if clock == "vision" else ("offset_s", "ci95_s")
    out: dict[str, ScannerClock] = {}
    for name, v in sources.items():
        if not str(name).startswith("laser/") or not isinstance(v, Mapping) or v.get("verdict") != "ok":
            continue
        off, sigma = v.get(key), sigma_from_ci95(v.get(ci_key))
        if off is None or sigma is None:
            continue
        out[str(name).split("/", 1)[1]] = ScannerClock(float(off), sigma)
    return out


def on_clock(rig: Rig, logs: Mapping[str, ScanLog], clocks: Mapping[str, ScannerClock]
             ) -> tuple[Rig, dict[str, ScanLog]]:
    """The scans moved onto the reference clock and the rig saying how well they now are.

    Parameters
    ----------
    rig : the rig whose ``laser_scanners`` made ``logs``.
    logs : per scanner, its scans (stamps on its own clock).
    clocks : per scanner, its offset to the reference clock (:func:`clocks_from_sync`); a scanner left
        out keeps its stamps and its rig's ``stamp_sigma_s``.

    Returns
    -------
    rig : ``stamp_sigma_s`` of each corrected scanner replaced by its offset's standard deviation.
    logs : the scans, stamps minus the offsets (ranges shared, not copied).
    """
    scs, out = scanners_on_clock(rig.laser_scanners, logs, clocks)
    return rig.model_copy(update={"laser_scanners": scs}), out


def scanners_on_clock(scanners: Sequence[LaserScanner], logs: Mapping[str, ScanLog],
                      clocks: Mapping[str, ScannerClock]) -> tuple[tuple[LaserScanner, ...], dict[str, ScanLog]]:
    """:func:`on_clock` for a list of scanners (their ``stamp_sigma_s`` replaced) instead of a rig."""
    scs = tuple(s.model_copy(update={"stamp_sigma_s": clocks[s.name].sigma_s}) if s.name in clocks else s
                for s in scanners)
    out = {k: ScanLog(v.stamps_s - clocks[k].offset_s, v.ranges_m) if k in clocks else v for k, v in logs.items()}
    return scs, out


__all__ = ["Clock", "ScannerClock", "clocks_from_sync", "on_clock", "scanners_on_clock"]
