"""Read and write the camera calibration file ``cam.yaml`` (docs/formats.md, "Camera calibration file").

Required: ``image_size: [w, h]``, ``camera_matrix`` (3 x 3), ``dist_coeffs`` (OpenCV order). Optional,
written by ``gtrig calib intrinsics``: ``rms_px``, ``std`` (standard deviation of each parameter, pixels
for fx fy cx cy), ``per_image_rms_px`` {file: px}, ``rejected`` {file: reason}, ``board``,
``coverage``, ``tilt_deg`` and ``warnings``.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from gtrig.errors import FormatError
from gtrig.io.atomic import atomic_write_text
from gtrig.io.yamlfile import load_yaml


@dataclass(frozen=True)
class CameraIntrinsics:
    """A pinhole camera with OpenCV distortion.

    Attributes
    ----------
    image_size : (w, h) pixels.
    camera_matrix : (3, 3) ``[[fx, s, cx], [0, fy, cy], [0, 0, 1]]``, pixels; pixel centres at integers.
    dist_coeffs : (n,) OpenCV order (k1, k2, p1, p2, k3, ...).
    rms_px : reprojection RMS of the calibration (pixels), NaN if unknown.
    extra : every other field of the file, as read (std, per_image_rms_px, rejected, ...).
    """

    image_size: tuple[int, int]
    camera_matrix: np.ndarray
    dist_coeffs: np.ndarray
    rms_px: float = math.nan
    extra: dict[str, Any] = field(default_factory=dict)


def _floats(x: Any) -> Any:
    if isinstance(x, dict):
        return {str(k): _floats(v) for k, v in x.items()}
    if isinstance(x, list | tuple):
        return [_floats(v) for v in x]
    if isinstance(x, np.ndarray):
        return _floats(x.tolist())
    if isinstance(x, np.integer):
        return int(x)
    if isinstance(x, float | np.floating):
        return float(x)
    return x


def cam_to_dict(cam: CameraIntrinsics) -> dict[str, Any]:
    """The document written to ``cam.yaml``."""
    d: dict[str, Any] = {
        "image_size": [int(cam.image_size[0]), int(cam.image_size[1])],
        "camera_matrix": _floats(np.asarray(cam.camera_matrix, dtype=float)),
        "dist_coeffs": _floats(np.asarray(cam.dist_coeffs, dtype=float).ravel()),
    }
    if not math.isnan(cam.rms_px):
        d["rms_px"] = float(cam.rms_px)
    for k, v in cam.extra.items():
        if k not in d:
            d[k] = _floats(v)
    return d


def write_cam_yaml(path: str | os.PathLike[str], cam: CameraIntrinsics) -> None:
    """Write ``cam.yaml`` atomically."""
    text = yaml.safe_dump(cam_to_dict(cam), sort_keys=False, default_flow_style=None, width=120)
    atomic_write_text(path, text)


def cam_from_dict(d: Any, source: str = "<cam>") -> CameraIntrinsics:
    """Validate a parsed ``cam.yaml`` document; one-line :class:`FormatError` on failure."""
    if not isinstance(d, dict):
        raise FormatError(f"{source}: expected a mapping with image_size, camera_matrix, dist_coeffs")
    for k in ("image_size", "camera_matrix", "dist_coeffs"):
        if k not in d:
            raise FormatError(f"{source}: {k}: missing field")
    try:
        w, h = (int(v) for v in d["image_size"])
    except (TypeError, ValueError):
        raise FormatError(f"{source}: image_size: expected [w, h] in pixels") from None
    try:
        K = np.asarray(d["camera_matrix"], dtype=float)
        dist = np.asarray(d["dist_coeffs"], dtype=float).ravel()
    except (TypeError, ValueError):
        raise FormatError(f"{source}: camera_matrix and dist_coeffs must be numbers") from None
    if K.shape != (3, 3) or K[0, 0] <= 0 or K[1, 1] <= 0 or not np.allclose(K[2], [0, 0, 1]):
        raise FormatError(
            f"{source}: camera_matrix: expected [[fx, s, cx], [0, fy, cy], [0, 0, 1]], fx, fy > 0"
        )
    if dist.size not in (4, 5, 8, 12, 14):
        raise FormatError(f"{source}: dist_coeffs: expected 4, 5, 8, 12 or 14 coefficients, got {dist.size}")
    if w <= 0 or h <= 0:
        raise FormatError(f"{source}: image_size: must be positive")
    if not (np.all(np.isfinite(K)) and np.all(np.isfinite(dist))):
        raise FormatError(f"{source}: camera_matrix and dist_coeffs must be finite numbers")
    try:
        rms = float(d.get("rms_px", math.nan))
    except (TypeError, ValueError):
        raise FormatError(f"{source}: rms_px: expected a number of pixels") from None
    extra = {k: v for k, v in d.items() if k not in ("image_size", "camera_matrix", "dist_coeffs", "rms_px")}
    return CameraIntrinsics((w, h), K, dist, rms, extra)


def read_cam_yaml(path: str | os.PathLike[str]) -> CameraIntrinsics:
    """Read ``cam.yaml`` (also the hand-held camera's ``handheld/camera.yaml``)."""
    p = Path(path)
    return cam_from_dict(load_yaml(p), str(p))
