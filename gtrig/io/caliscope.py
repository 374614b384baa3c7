"""caliscope's camera calibration (``config.toml`` with ``[cam_N]`` tables, or ``camera_array.toml`` with
``[cameras.N]``): each camera's intrinsics, its stated reprojection ``error`` and its pose.

caliscope's ``rotation`` (3 x 3) and ``translation`` (metres) map world points into the camera,
``x_cam = R x_world + t``: they are ``T_cam_world``.
"""

from __future__ import annotations

import os
import tomllib
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from gtrig.errors import FormatError
from gtrig.io.camfile import CameraIntrinsics


@dataclass(frozen=True)
class CaliscopeCamera:
    """One camera of a caliscope calibration: ``intrinsics`` (its ``rms_px`` is caliscope's ``error``),
    ``T_cam_world`` (4, 4) or None when the file holds no pose."""

    name: str
    intrinsics: CameraIntrinsics
    error_px: float
    T_cam_world: np.ndarray | None


def _camera(name: str, d: dict[str, Any], where: str) -> CaliscopeCamera:
    try:
        K = np.asarray(d["matrix"], dtype=float).reshape(3, 3)
        dist = np.asarray(d["distortions"], dtype=float).ravel()
        w, h = (int(v) for v in d["size"])
        err = float(d.get("error", float("nan")))
        T = None
        if "rotation" in d and "translation" in d:
            T = np.eye(4)
            T[:3, :3] = np.asarray(d["rotation"], dtype=float).reshape(3, 3)
            T[:3, 3] = np.asarray(d["translation"], dtype=float).ravel()
    except KeyError as e:
        raise FormatError(f"{where}: {name}: {e.args[0]}: missing field") from None
    except (TypeError, ValueError):
        raise FormatError(
            f"{where}: {name}: matrix, distortions, size, rotation, translation must be numbers"
        ) from None
    return CaliscopeCamera(name, CameraIntrinsics((w, h), K, dist, err, {}), err, T)


def read_caliscope_cameras(path: str | os.PathLike[str]) -> dict[str, CaliscopeCamera]:
    """The cameras of a caliscope ``config.toml`` or ``camera_array.toml``, named ``cam_N``."""
    p = Path(path)
    try:
        data = tomllib.loads(p.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError) as e:
        raise FormatError(f"{p}: cannot read as TOML ({e})") from None
    tables = {f"cam_{k}": v for k, v in data.get("cameras", {}).items()}
    tables.update({k: v for k, v in data.items() if k.startswith("cam_") and isinstance(v, dict)})
    if not tables:
        raise FormatError(f"{p}: no cameras ([cam_N] or [cameras.N] tables)")
    return {name: _camera(name, d, str(p)) for name, d in sorted(tables.items())}
