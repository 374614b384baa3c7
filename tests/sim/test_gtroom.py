"""The simulated GT room is the room of the seeds: geometry, coverage, floor, determinism."""

from __future__ import annotations

import numpy as np
import pytest
from matplotlib.path import Path as PolyPath

from gtrig import geometry as geo
from gtrig.sim.gtroom import (
    VALIDATION_POSES,
    WORLD_POINTS_XY,
    continuous_path,
    make_scene,
)


@pytest.fixture(scope="module")
def scene():  # type: ignore[no-untyped-def]
    return make_scene(5)


def test_published_tables_are_the_truth(shared_dir) -> None:  # type: ignore[no-untyped-def]
    wp = np.genfromtxt(shared_dir / "reference/world_points.csv", delimiter=",", comments="#", skip_header=6)
    np.testing.assert_allclose(WORLD_POINTS_XY, wp[:, 5:7])
    vp = np.genfromtxt(shared_dir / "reference/validation_poses.csv", delimiter=",", comments="#", skip_header=3)
    np.testing.assert_allclose(VALIDATION_POSES, vp[:, 4:7])


def test_room_contains_everything(scene) -> None:  # type: ignore[no-untyped-def]
    room = PolyPath(scene.walls[:, 0])
    assert room.contains_points(WORLD_POINTS_XY).all()
    assert room.contains_points(VALIDATION_POSES[:, :2]).all()
    for c in scene.rig_true.cameras:
        assert room.contains_point(c.T_world_cam.xyz[:2])
        assert 2.5 <= c.T_world_cam.xyz[2] <= 3.0
        tilt = np.degrees(np.arcsin(-c.T_world_cam.matrix()[2, 2]))
        assert 38 < tilt < 50
    for s in scene.rig_true.laser_scanners:
        assert room.contains_point(s.T_world_scanner.xyz[:2])
        assert s.beams == 180 and s.rate_hz == 75 and s.T_world_scanner.xyz[2] == 0.25
    sides = np.linalg.norm(scene.walls[:, 1] - scene.walls[:, 0], axis=1)
    assert 7.5 < sides.max() < 9.0
    d = scene.walls[:, 1] - scene.walls[:, 0]
    d /= np.linalg.norm(d, axis=1)[:, None]
    short = np.argsort(sides)[:2]
    assert abs(abs(d[short[0]] @ d[short[1]]) - 1) > 1e-3  # short walls not parallel


def test_markers_as_published(scene) -> None:  # type: ignore[no-untyped-def]
    ids = sorted(m.id for m in scene.rig_true.robot.markers)
    assert ids == [3, 6, 14, 30, 89, 200]
    m14 = scene.rig_nominal.marker(14)
    assert m14.side_m == 0.160
    T = m14.T_robot_marker.matrix()
    np.testing.assert_allclose(T[:2, 3], [-0.143, 0.098])
    assert np.degrees(geo.T_to_se2(T)[2]) == pytest.approx(90)
    hull = scene.rig_true.robot.hull
    assert (hull.length_m, hull.width_m) == (0.78, 0.57)


def test_floor_tilt_bounded(scene) -> None:  # type: ignore[no-untyped-def]
    xs, ys = np.meshgrid(np.linspace(-3, 4, 60), np.linspace(-2, 6, 60))
    gx, gy = scene.floor.gradient(xs, ys)
    tilt = np.degrees(np.arctan(np.hypot(gx, gy)))
    assert tilt.max() <= 0.5 + 1e-9
    assert tilt.max() > 0.2  # not flat


def _markers_fully_visible(scene, xyth) -> list[int]:  # type: ignore[no-untyped-def]
    T = scene.T_world_robot(*xyth)
    counts = []
    for c in scene.rig_true.cameras:
        T_cam_world = geo.inv_T(c.T_world_cam.matrix())
        n = 0
        for m in scene.rig_true.robot.markers:
            h = m.side_m / 2
            corners = np.array([[-h, h, 0], [h, h, 0], [h, -h, 0], [-h, -h, 0]])
            p = geo.transform_points(T_cam_world @ T @ m.T_robot_marker.matrix(), corners)
            uv = geo.project_points(p, c.K, c.dist)
            n += bool((p[:, 2] > 0).all() and (uv >= 0).all() and (uv[:, 0] < 1023).all() and (uv[:, 1] < 767).all())
        counts.append(n)
    return counts


def test_every_validation_pose_is_seen(scene) -> None:  # type: ignore[no-untyped-def]
    for p in VALIDATION_POSES:
        assert sum(_markers_fully_visible(scene, p)) >= 2


def test_continuous_run() -> None:
    stamps, xyth = continuous_path()
    assert stamps[-1] >= 60
    v = np.linalg.norm(np.diff(xyth[:, :2], axis=0), axis=1) / np.diff(stamps)
    assert v.max() < 0.31
    assert np.abs(np.diff(xyth[:, 2])).max() < 0.05  # smooth heading at 200 Hz


def test_same_seed_same_scene() -> None:
    a, b, c = make_scene(11), make_scene(11), make_scene(12)
    assert a.rig_true == b.rig_true and a.rig_nominal == b.rig_nominal
    assert a.rig_true != c.rig_true
    assert a.rig_true != a.rig_nominal


def test_clutter_inside_and_apart(scene) -> None:  # type: ignore[no-untyped-def]
    room = PolyPath(scene.walls[:, 0])
    for b in scene.boxes:
        assert room.contains_points(b.corners_xy()).all(), b.name
        for s in scene.rig_true.laser_scanners:
            assert not PolyPath(b.corners_xy()).contains_point(s.T_world_scanner.xyz[:2]), b.name
    for i, a in enumerate(scene.boxes):
        for b in scene.boxes[i + 1:]:
            assert not PolyPath(a.corners_xy()).contains_points(b.corners_xy()).any(), (a.name, b.name)
            assert not PolyPath(b.corners_xy()).contains_points(a.corners_xy()).any(), (a.name, b.name)
