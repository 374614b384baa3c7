"""The tracked body's shape as the recording reconstructs it, against its design: one summary per recording.

Size: every edge of the design's length ``edge_m`` (a board's square side) between two reconstructed points,
its reconstructed length minus ``edge_m``: the mean (the scale's error) and the RMS (scale and shape).
Flatness: the RMS distance of the reconstructed points from their least-squares plane (for a triangulated
board: per instant, then the RMS over instants).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from gtrig.vision.body_check import edge_errors, plane_rms, rigidity_nees, shape_from_poses, triangulate_points
from gtrig.vision.body_track import BodyTrack
from gtrig.vision.observations import CameraGeometry


@dataclass(frozen=True)
class ShapeCheck:
    """Size and flatness of one recording's reconstructions (metres), and the NEES figures.

    Attributes
    ----------
    edge_m : the design's edge length.
    pose_edge_mean_m, pose_edge_rms_m, pose_plane_rms_m, pose_points : the shape from the tracked poses
        (:func:`gtrig.vision.body_check.shape_from_poses`), over its ``pose_points`` points
    tri_edge_mean_m, tri_edge_rms_m, tri_plane_rms_m, tri_edges, tri_instants : the points triangulated at
        each instant (planes of instants with 6 points or more)
    rigidity_nees : mean NEES over 3 dof of the triangulated points against the tracked rigid body
    split_nees : mean NEES over 6 dof of the camera-split poses (before the covariances were scaled)
    """

    edge_m: float
    pose_edge_mean_m: float
    pose_edge_rms_m: float
    pose_plane_rms_m: float
    pose_points: int
    tri_edge_mean_m: float
    tri_edge_rms_m: float
    tri_plane_rms_m: float
    tri_edges: int
    tri_instants: int
    rigidity_nees: float
    split_nees: float


def _mean_rms(e: np.ndarray) -> tuple[float, float]:
    return (float(np.mean(e)), float(np.sqrt(np.mean(e**2)))) if e.size else (math.nan, math.nan)


def check_shape(cameras: Mapping[str, CameraGeometry], track: BodyTrack, edge_m: float,
                sigma_px: float) -> ShapeCheck:
    """The size and flatness of ``track.body`` reconstructed from ``track``'s poses and by triangulation."""
    body = track.body
    shape = shape_from_poses(cameras, track.poses, [i.views for i in track.instants])
    pe = edge_errors(shape, body, edge_m)
    pose_plane = plane_rms(np.array(list(shape.values()))) if len(shape) >= 4 else math.nan
    edges: list[np.ndarray] = []
    planes: list[float] = []
    nees: list[np.ndarray] = []
    for p, inst in zip(track.poses, track.instants, strict=True):
        if not p.ok or len(p.cameras) < 2:
            continue
        tri = triangulate_points(cameras, [v for v in inst.views if v.camera in p.cameras], sigma_px)
        if len(tri.ids) < 2:
            continue
        edges.append(edge_errors(dict(zip(tri.ids.tolist(), tri.X_world, strict=True)), body, edge_m))
        if len(tri.ids) >= 6:
            planes.append(plane_rms(tri.X_world))
        nees.append(rigidity_nees(tri, p, body))
    te = np.concatenate(edges) if edges else np.zeros(0)
    rn = np.concatenate(nees) if nees else np.zeros(0)
    return ShapeCheck(
        edge_m, *_mean_rms(pe), pose_plane, len(shape), *_mean_rms(te),
        float(np.sqrt(np.mean(np.square(planes)))) if planes else math.nan, int(te.size), len(planes),
        float(np.mean(rn)) / 3 if rn.size else math.nan,
        float(np.mean(track.split_nees)) / 6 if track.split_nees else math.nan)
