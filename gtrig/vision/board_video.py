"""A ChArUco board tracked through the videos of calibrated fixed cameras (the file side of
:mod:`gtrig.vision.body_track`).

Cameras: the folder ``gtrig calib video`` writes (``<cam>.yaml`` lenses and ``network.yaml``: the world is
the reference camera's frame) or caliscope's ``camera_array.toml`` / ``config.toml`` (its world frame).
Videos: the folder layout of docs/formats.md, "Camera videos" (``<cam>.mp4`` with its frame times).
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from pathlib import Path

import numpy as np
import yaml

from gtrig import geometry as geo
from gtrig.calib.charuco import CharucoBoard
from gtrig.calib.video_detect import VideoDetections
from gtrig.errors import FormatError, InputError
from gtrig.vision.body import BodyView, PointBody, camera_geometry
from gtrig.vision.body_track import BodyInstant, group_instants
from gtrig.vision.observations import CameraGeometry


def board_body(board: CharucoBoard) -> PointBody:
    """The board's inner corners as a rigid body (board frame, :meth:`CharucoBoard.object_points`)."""
    return PointBody("board", board.object_points())


def _network_poses(path: Path) -> dict[str, np.ndarray]:
    try:
        doc = yaml.safe_load(path.read_text(encoding="utf-8"))
        return {str(c): np.asarray(d["T_ref_cam"], float).reshape(4, 4) for c, d in doc["cameras"].items()}
    except (OSError, yaml.YAMLError) as e:
        raise FormatError(f"{path}: cannot read ({e})") from None
    except (KeyError, TypeError, ValueError, AttributeError):
        raise FormatError(f"{path}: cameras.<cam>.T_ref_cam: missing or not a 4 x 4 matrix") from None


def read_cameras(path: str | os.PathLike[str]) -> dict[str, CameraGeometry]:
    """Calibrated cameras with their poses: a ``gtrig calib video`` output folder or a caliscope .toml."""
    p = Path(path)
    if p.is_dir():
        from gtrig.io.camfile import read_cam_yaml

        net = p / "network.yaml"
        if not net.is_file():
            raise InputError(f"{p}: no network.yaml (the output of gtrig calib video)")
        cams = {}
        for c, T in _network_poses(net).items():
            lens = read_cam_yaml(p / f"{c}.yaml")
            cams[c] = camera_geometry(c, lens.camera_matrix, lens.dist_coeffs, T, lens.image_size)
        return cams
    if p.suffix.lower() == ".toml":
        from gtrig.io.caliscope import read_caliscope_cameras

        out = {}
        for c, cc in read_caliscope_cameras(p).items():
            if cc.T_cam_world is None:
                raise FormatError(f"{p}: {c}: no rotation and translation (an intrinsic-only calibration)")
            i = cc.intrinsics
            out[c] = camera_geometry(c, i.camera_matrix, i.dist_coeffs, geo.inv_T(cc.T_cam_world), i.image_size)
        return out
    raise InputError(f"{p}: expected a gtrig calib video folder or caliscope's camera_array.toml")


def board_instants(dets: Mapping[str, VideoDetections], min_points: int = 1) -> list[BodyInstant]:
    """The board's views of every camera grouped by instant (the videos' shared frame index)."""
    pairs = []
    for c, d in dets.items():
        for k, t, v in zip(d.sync_index, d.stamps_s, d.views, strict=True):
            if len(v.ids) >= min_points:
                pairs.append((int(k), BodyView(c, np.asarray(v.ids, int), v.corners_px, float(t))))
    return group_instants(pairs)
