"""Occupancy-grid maps in the ROS map_server convention: a YAML file plus an image.

The YAML names ``image`` (relative to the YAML's folder), ``resolution`` (metres per pixel),
``origin`` ``[x, y, yaw]`` (the pose of the lower-left pixel's corner in the map frame), ``negate``,
``occupied_thresh`` and ``free_thresh``; ``mode`` trinary is assumed. A pixel's occupancy is
``(255 - v) / 255`` (``v / 255`` when negated): above ``occupied_thresh`` it is occupied, below
``free_thresh`` free, unknown in between. Image row 0 is the map's top (largest y).
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import yaml

from gtrig.errors import FormatError
from gtrig.io.atomic import atomic_group
from gtrig.io.text import read_text
from gtrig.io.yamlfile import safe_load


@dataclass(frozen=True)
class OccupancyMap:
    """An occupancy grid.

    Attributes
    ----------
    occupied : (H, W) bool, row 0 at the top (ROS image convention).
    free : (H, W) bool.
    resolution_m : metres per pixel.
    origin : (3,) x, y, yaw of the lower-left corner of pixel (H - 1, 0) in the map frame.
    """

    occupied: np.ndarray
    free: np.ndarray
    resolution_m: float
    origin: tuple[float, float, float]

    def pixel_centres(self, rows: np.ndarray, cols: np.ndarray) -> np.ndarray:
        """(N, 2) map-frame coordinates of pixel centres."""
        H = self.occupied.shape[0]
        u = (np.asarray(cols, dtype=float) + 0.5) * self.resolution_m
        v = (H - 1 - np.asarray(rows, dtype=float) + 0.5) * self.resolution_m
        x0, y0, yaw = self.origin
        c, s = np.cos(yaw), np.sin(yaw)
        return np.column_stack([x0 + c * u - s * v, y0 + s * u + c * v])


def read_map(path: str | os.PathLike[str]) -> OccupancyMap:
    """Read MAP.yaml and its image; one-line :class:`FormatError` for a missing field or an image
    that does not load."""
    import cv2

    p = Path(path)
    try:
        doc = safe_load(read_text(p, "YAML file"))
    except FileNotFoundError:
        raise FormatError(f"{p}: no such file") from None
    except (yaml.YAMLError, UnicodeDecodeError) as e:
        raise FormatError(f"{p}: not a YAML file ({type(e).__name__})") from None
    if not isinstance(doc, dict):
        raise FormatError(f"{p}: expected a mapping with image, resolution and origin")
    for key in ("image", "resolution", "origin"):
        if key not in doc:
            raise FormatError(f"{p}: field '{key}' is missing (ROS map_server map YAML)")
    try:
        res = float(doc["resolution"])
        origin = tuple(float(v) for v in doc["origin"])
    except (TypeError, ValueError):
        raise FormatError(f"{p}: 'resolution' must be a number and 'origin' [x, y, yaw]") from None
    if not res > 0 or len(origin) != 3:
        raise FormatError(f"{p}: 'resolution' must be > 0 and 'origin' have 3 numbers [x, y, yaw]")
    occ_t = float(doc.get("occupied_thresh", 0.65))
    free_t = float(doc.get("free_thresh", 0.196))
    if not 0 <= free_t < occ_t <= 1:
        raise FormatError(f"{p}: thresholds must satisfy 0 <= free_thresh < occupied_thresh <= 1")
    img_path = (p.parent / str(doc["image"])).resolve()
    img = cv2.imread(str(img_path), cv2.IMREAD_GRAYSCALE) if img_path.is_file() else None
    if img is None:
        raise FormatError(f"{p}: image '{doc['image']}' does not load ({img_path})")
    v = img.astype(float) / 255.0
    occ = v if int(doc.get("negate", 0)) else 1.0 - v
    return OccupancyMap(occ > occ_t, occ < free_t, res, (origin[0], origin[1], origin[2]))


def write_map(yaml_path: str | os.PathLike[str], occupied: np.ndarray, free: np.ndarray, resolution_m: float,
              origin: tuple[float, float, float]) -> None:
    """Write MAP.yaml and MAP.pgm (occupied 0, free 254, unknown 205; the map_saver's values), together."""
    import cv2

    yp = Path(yaml_path)
    ip = yp.with_suffix(".pgm")
    img = np.full(occupied.shape, 205, np.uint8)
    img[free] = 254
    img[occupied] = 0
    ok, buf = cv2.imencode(".pgm", img)
    if not ok:
        raise FormatError(f"{ip}: could not encode the map image")
    doc = {"image": ip.name, "resolution": float(resolution_m), "origin": [float(o) for o in origin],
           "negate": 0, "occupied_thresh": 0.65, "free_thresh": 0.196, "mode": "trinary"}
    with atomic_group(yp, ip) as (ty, ti):
        ty.write_text(yaml.safe_dump(doc, sort_keys=False), encoding="utf-8")
        ti.write_bytes(buf.tobytes())
