"""Two calibrations of the same cameras compared parameter by parameter in combined standard deviations.

A lab recalibrates its cameras from a new board video and wants to know whether a lens changed (a webcam's
autofocus or zoom, a knocked lens) or only the calibration's noise moved it. For each camera in both sets
and each of ``fx fy cx cy`` (pixels), the difference is divided by ``hypot(sigma_a, sigma_b)``, each sigma
the calibration's ``std_honest`` (:func:`gtrig.calib.video_calib.fit_lens`) or else its ``std``. A camera
whose parameter differs by more than ``limit`` of them is named: its lens differs between the two, or its
sigmas are too small, and the check alone cannot tell which.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass

from gtrig.io.camfile import CameraIntrinsics

#: the compared parameters and their places in the camera matrix
LENS_PARAMETERS = {"fx": (0, 0), "fy": (1, 1), "cx": (0, 2), "cy": (1, 2)}
#: a difference beyond this many combined sigmas is named (about 1 in 400 by chance for Gaussian errors)
DIFFERENCE_LIMIT = 3.0


@dataclass(frozen=True)
class LensDifference:
    """One camera's parameter in two calibrations.

    Attributes
    ----------
    camera, parameter : the camera's name and ``fx``, ``fy``, ``cx`` or ``cy``.
    value_a_px, value_b_px : the parameter in each calibration, pixels.
    sigma_a_px, sigma_b_px : their standard deviations, pixels (NaN when a calibration states none).
    z : ``|a - b| / hypot(sigma_a, sigma_b)``; NaN without both sigmas.
    """

    camera: str
    parameter: str
    value_a_px: float
    value_b_px: float
    sigma_a_px: float
    sigma_b_px: float
    z: float


def lens_sigma(lens: CameraIntrinsics, parameter: str) -> float:
    """The standard deviation a calibration states for ``parameter`` (pixels): ``std_honest``, else ``std``,
    else NaN."""
    std = lens.extra.get("std_honest") or lens.extra.get("std") or {}
    v = std.get(parameter)
    return float(v) if v is not None and float(v) > 0 else math.nan


def compare_lenses(a: Mapping[str, CameraIntrinsics],
                   b: Mapping[str, CameraIntrinsics]) -> list[LensDifference]:
    """Each camera of both ``a`` and ``b`` (by name, sorted), each of ``fx fy cx cy`` (module docstring)."""
    out = []
    for cam in sorted(set(a) & set(b)):
        for p, (i, j) in LENS_PARAMETERS.items():
            va, vb = float(a[cam].camera_matrix[i, j]), float(b[cam].camera_matrix[i, j])
            sa, sb = lens_sigma(a[cam], p), lens_sigma(b[cam], p)
            out.append(LensDifference(cam, p, va, vb, sa, sb, abs(va - vb) / math.hypot(sa, sb)))
    return out


def differing(diffs: list[LensDifference], limit: float = DIFFERENCE_LIMIT) -> list[LensDifference]:
    """The differences beyond ``limit`` combined sigmas, largest first."""
    return sorted((d for d in diffs if d.z > limit), key=lambda d: -d.z)
