"""Whether the cameras' timing holds over a recording: its first and second halves fitted apart and compared.

The halves are the tracked instants stamped before and after the recording's midpoint (``mid_s`` of
:func:`gtrig.vision.body_timing.tracked_mid_s`); each half's timing is fitted on its own instants (their
local motions may reach across the midpoint, their residuals do not), so the two fits' errors are nearly
independent and their difference's sigma is the root sum of squares of theirs. Both fits refer their
offsets to the same ``mid_s``: with a drift, each half's offset is its line carried to the midpoint, and a
steady drift makes the two lines one (offsets and drifts both agree); with constant offsets, a drifting
camera shows as halves that disagree.

Agreement is stated as ``|difference| / (1.96 sigma)``: below 1, the halves agree within their combined
95 % interval. :func:`timing_windows` fits any number of equal spans of the recording apart: the offsets
against time.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from gtrig.vision.body import BodyOptions, BodyPose, PointBody
from gtrig.vision.body_timing import CameraTiming, estimate_timing, tracked_mid_s
from gtrig.vision.body_track import BodyInstant
from gtrig.vision.observations import CameraGeometry


@dataclass(frozen=True)
class HalvesCheck:
    """The timing of a recording's two halves and their agreement.

    Attributes
    ----------
    first, second : the halves' timings (offsets at the whole recording's ``mid_s``).
    offset_ratio : (C,) ``|offset difference| / (1.96 sigma)`` per camera (0 for the reference).
    drift_ratio : (C,) the same of the drifts (nan when not estimated).
    """

    first: CameraTiming
    second: CameraTiming
    offset_ratio: np.ndarray
    drift_ratio: np.ndarray


def _ratio(a: np.ndarray, b: np.ndarray, sa: np.ndarray, sb: np.ndarray) -> np.ndarray:
    """``|a - b| / (1.96 hypot(sa, sb))``, 0 where both are held at 0 (the reference camera)."""
    s = 1.96 * np.hypot(sa, sb)
    d = np.abs(a - b)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where((s == 0) & (d == 0), 0.0, d / s)


def timing_windows(cameras: Mapping[str, CameraGeometry], body: PointBody, instants: Sequence[BodyInstant],
                   poses: Sequence[BodyPose], reference: str | None = None, *, parts: int = 2,
                   line_delay: bool = False, drift: bool = False,
                   options: BodyOptions | None = None) -> list[CameraTiming]:
    """The timing (:func:`gtrig.vision.body_timing.estimate_timing`, same model, offsets referred to the
    whole recording's midpoint) of ``parts`` equal spans of the tracked instants' stamps, each fitted apart.

    Raises
    ------
    ValueError
        ``parts`` is below 1.
    """
    if parts < 1:
        raise ValueError(f"parts must be 1 or more, not {parts}")
    t = [p.stamp_s for p in poses if p.ok]
    mid = tracked_mid_s(poses)
    if not t:
        edges = np.full(parts + 1, math.nan)
    else:
        edges = np.linspace(min(t), max(t), parts + 1)
        edges[0], edges[-1] = -math.inf, math.inf
    return [estimate_timing(cameras, body, instants, poses, reference, line_delay=line_delay, drift=drift,
                            mid_s=mid, span_s=(float(lo), math.nextafter(float(hi), -math.inf) if k < parts - 1
                                               else float(hi)), options=options)
            for k, (lo, hi) in enumerate(zip(edges[:-1], edges[1:], strict=True))]


def timing_halves(cameras: Mapping[str, CameraGeometry], body: PointBody, instants: Sequence[BodyInstant],
                  poses: Sequence[BodyPose], reference: str | None = None, *, line_delay: bool = False,
                  drift: bool = False, options: BodyOptions | None = None) -> HalvesCheck:
    """The timing (:func:`gtrig.vision.body_timing.estimate_timing`, same model) of the instants before and
    after the recording's midpoint, each fitted apart (:func:`timing_windows`), and their agreement (module
    docstring)."""
    a, b = timing_windows(cameras, body, instants, poses, reference, parts=2, line_delay=line_delay, drift=drift,
                          options=options)
    return HalvesCheck(a, b, _ratio(a.offset_s, b.offset_s, a.sigma_offset_s, b.sigma_offset_s),
                       _ratio(a.drift_s_per_s, b.drift_s_per_s, a.sigma_drift_s_per_s, b.sigma_drift_s_per_s))
