"""Step 5a: the starting pose of each image, and the views that disagree with it.

Given the markers' poses on the robot from the pose graph, every view offers two candidate poses of
the robot in the camera, ``T_cam_robot = T_cam_marker inv(T_robot_marker)`` (one per IPPE solution).
The candidate most other views of the image agree with is the image's pose; each view keeps its
solution nearest to it, and the views with none near it (a flip no other view supports, a misread
marker) are set aside before the bundle adjustment.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from gtrig import geometry as geo
from gtrig.geometry.se3avg import mean_pose
from gtrig.markers.robotcal.observe import Array
from gtrig.markers.robotcal.pairs import close_matrix
from gtrig.markers.robotcal.pnp import ViewPoses


@dataclass(frozen=True)
class ImagePose:
    """``T_cam_robot`` (4, 4) of one image, the IDs of the views that agree and of those that do not."""

    T_cam_robot: Array
    agree: tuple[int, ...]
    disagree: tuple[int, ...]


def image_pose(sols: Sequence[ViewPoses], T_robot_marker: Mapping[int, Array], tol_m: float = 0.03,
               tol_rad: float = math.radians(3.0)) -> ImagePose | None:
    """The robot's pose in one image from its views' IPPE solutions; None when no two views agree."""
    cands = []
    for s in sols:
        Ti = geo.inv_T(T_robot_marker[s.view.marker_id])
        for j in range(2):
            cands.append((s.view.marker_id, s.T_cam_marker[j] @ Ti, float(s.rms[j])))
    Ts = np.stack([T for _, T, _ in cands])
    mids = np.array([m for m, _, _ in cands])
    close = close_matrix(Ts, Ts, tol_m, tol_rad)
    best = None
    for i, (_, T, rms) in enumerate(cands):
        key = (len(set(mids[close[i]].tolist())), -rms)
        if best is None or key > best[0]:
            best = (key, T)
    assert best is not None
    if best[0][0] < 2:
        return None
    ref = best[1]
    for _ in range(2):
        chosen: dict[int, Array] = {}
        for mid, T, _ in cands:
            if _near(ref, T, tol_m, tol_rad):
                prev = chosen.get(mid)
                if prev is None or _score(ref, T, tol_m, tol_rad) < _score(ref, prev, tol_m, tol_rad):
                    chosen[mid] = T
        if len(chosen) < 2:
            return None
        ref = mean_pose(np.stack(list(chosen.values()))).T
    agree = tuple(sorted(chosen))
    disagree = tuple(sorted({s.view.marker_id for s in sols} - set(chosen)))
    return ImagePose(ref, agree, disagree)


def _near(Ta: Array, Tb: Array, tol_m: float, tol_rad: float) -> bool:
    dt, dr = geo.pose_error(Ta, Tb)
    return dt < tol_m and dr < tol_rad


def _score(Ta: Array, Tb: Array, tol_m: float, tol_rad: float) -> float:
    dt, dr = geo.pose_error(Ta, Tb)
    return dt / tol_m + dr / tol_rad
