"""Scan-level geometry without a recording: normals of densely sampled noisy walls, corners, and
loop closure of relative poses."""

from __future__ import annotations

import numpy as np

from gtrig.scanmatch import se2
from gtrig.scanmatch.carmen import beam_angles_rad, triplet_closures
from gtrig.scanmatch.scan import ranges_to_scan


def _room_ranges(angles: np.ndarray, wall_x: float, wall_y: float) -> np.ndarray:
    """Ranges from the origin to the walls x = wall_x (ahead) and y = wall_y (left): a corner."""
    c, s = np.cos(angles), np.sin(angles)
    with np.errstate(divide="ignore"):
        to_x = np.where(c > 1e-9, wall_x / c, np.inf)
        to_y = np.where(s > 1e-9, wall_y / s, np.inf)
    return np.minimum(to_x, to_y)


def test_dense_noisy_wall_keeps_its_normals():
    # a 0.5-degree scanner 1.2 m from a wall, 1 cm noise rounded to the centimetre (the freiburg logs):
    # five neighbours span 4 cm, comparable to the noise; the normals must still be found, along x
    rng = np.random.default_rng(0)
    ang = beam_angles_rad(360)
    keep = np.abs(ang) < np.radians(40)
    r = 1.2 / np.cos(ang[keep]) + rng.normal(0, 0.006, keep.sum())
    sc = ranges_to_scan(np.round(r, 2), ang[keep], np.zeros(3), 0.01)
    assert sc.normal_ok.mean() > 0.9
    assert np.median(np.abs(sc.normals[sc.normal_ok, 0])) > 0.99


def test_corner_is_not_a_line():
    # a noise-free corner seen at 1 degree: the points at the vertex fit no line; the walls do
    ang = beam_angles_rad(180)
    r = _room_ranges(ang, 3.0, 3.0)
    ok = r < 10.0  # not the grazing far end of the wall ahead
    sc = ranges_to_scan(r[ok], ang[ok], np.zeros(3), 0.01)
    vertex = np.argmin(np.hypot(sc.xy[:, 0] - 3.0, sc.xy[:, 1] - 3.0))
    assert not sc.normal_ok[vertex]
    far = np.hypot(sc.xy[:, 0] - 3.0, sc.xy[:, 1] - 3.0) > 0.5
    assert sc.normal_ok[far].mean() > 0.95


def test_triplet_closures():
    rng = np.random.default_rng(1)
    poses = np.column_stack([rng.uniform(-2, 2, (6, 2)), rng.uniform(-3, 3, 6)])
    pairs = np.array([(i, j) for i in range(6) for j in range(i + 1, 6)])
    rel = se2.relative(poses[pairs[:, 0]], poses[pairs[:, 1]])
    cl = triplet_closures(pairs, rel)
    assert len(cl) == 20  # every triplet of 6 poses
    assert np.abs(cl).max() < 1e-12  # relative poses of one set of absolute poses close exactly
    noisy = rel + rng.normal(0, [0.01, 0.01, 0.001], rel.shape)
    cl = triplet_closures(pairs, noisy)
    # three independent errors of 1 cm per axis: about sqrt(3) cm per axis
    assert 0.012 < np.sqrt(np.mean(cl[:, :2] ** 2)) < 0.025
    assert len(triplet_closures(pairs[:3], rel[:3])) == 0  # (0,1), (0,2), (0,3): no closed triplet
