"""Simulated laser scanners: exact geometry against a simple per-beam ray caster, the gown section of a
tilted robot, the sensor model's statistics, people and determinism."""

from __future__ import annotations

import math

import numpy as np
import pytest

from gtrig import geometry as geo
from gtrig.io.scans import read_scans
from gtrig.sim import lasers
from gtrig.sim.config import LaserSimConfig, SimConfig
from gtrig.sim.gtroom import continuous_path, make_scene
from gtrig.sim.motion import RobotMotion
from gtrig.sim.people import LEG_RADIUS_M
from gtrig.sim.raycast import cast, cast_circles, cast_segments


@pytest.fixture(scope="module")
def scene():  # type: ignore[no-untyped-def]
    return make_scene(3)


@pytest.fixture(scope="module")
def run(scene):  # type: ignore[no-untyped-def]
    st, xy = continuous_path()
    return RobotMotion(st + 500.0, xy, scene.floor)


# ------------------------------------------------------------------------- reference implementation
def ref_segment(o, d, a, b):  # type: ignore[no-untyped-def]
    """Distance along unit d from o to segment ab, or inf: solve o + t d = a + u (b - a)."""
    m00, m01, m10, m11 = d[0], a[0] - b[0], d[1], a[1] - b[1]
    det = m00 * m11 - m01 * m10
    if abs(det) < 1e-15:
        return math.inf
    r0, r1 = a[0] - o[0], a[1] - o[1]
    t = (r0 * m11 - m01 * r1) / det  # Cramer's rule
    u = (m00 * r1 - r0 * m10) / det
    return t if (t > 0 and 0 <= u <= 1) else math.inf


def ref_circle(o, d, c, r):  # type: ignore[no-untyped-def]
    w = np.asarray(o) - np.asarray(c)
    b = float(d @ w)
    disc = b * b - (w @ w - r * r)
    if disc < 0 or w @ w <= r * r:
        return math.inf
    t = -b - math.sqrt(disc)
    return t if t > 0 else math.inf


def ref_section(hull, T_plane_robot):  # type: ignore[no-untyped-def]
    """Direct 3D plane-box intersection: all 12 edges of the box against z = 0 of the plane frame."""
    xs = (hull.offset_xy_m[0] - hull.length_m / 2, hull.offset_xy_m[0] + hull.length_m / 2)
    ys = (hull.offset_xy_m[1] - hull.width_m / 2, hull.offset_xy_m[1] + hull.width_m / 2)
    zs = (hull.z_min_m, hull.z_max_m)
    corners = {(i, j, k): T_plane_robot[:3, :3] @ [xs[i], ys[j], zs[k]] + T_plane_robot[:3, 3]
               for i in (0, 1) for j in (0, 1) for k in (0, 1)}
    pts = []
    for key, p in corners.items():
        for axis in range(3):
            if key[axis] == 0:
                q = corners[tuple(1 if n == axis else key[n] for n in range(3))]
                if (p[2] < 0) != (q[2] < 0):
                    s = p[2] / (p[2] - q[2])
                    pts.append((p + s * (q - p))[:2])
    pts = np.array(pts)
    c = pts.mean(axis=0)
    return pts[np.argsort(np.arctan2(pts[:, 1] - c[1], pts[:, 0] - c[0]))]


def ref_scan_range(scene, T_ws, angle, T_world_robot, legs_xy):  # type: ignore[no-untyped-def]
    """One beam, one segment at a time, in the world; 3D range."""
    d3 = T_ws[:3, :3] @ [math.cos(angle), math.sin(angle), 0.0]
    h = math.hypot(d3[0], d3[1])
    d = d3[:2] / h
    o = T_ws[:2, 3]
    best = math.inf
    for a, b in scene.walls:
        best = min(best, ref_segment(o, d, a, b))
    for bx in scene.boxes:
        c = bx.corners_xy()
        for i in range(4):
            t = ref_segment(o, d, c[i], c[(i + 1) % 4])
            if math.isfinite(t) and T_ws[2, 3] + t * d3[2] / h <= bx.size[2]:
                best = min(best, t)
    if T_world_robot is not None:
        poly = ref_section(scene.rig_true.robot.hull, geo.inv_T(T_ws) @ T_world_robot)
        poly_w = geo.transform_points(T_ws, np.column_stack([poly, np.zeros(len(poly))]))[:, :2]
        for i in range(len(poly_w)):
            best = min(best, ref_segment(o, d, poly_w[i], poly_w[(i + 1) % len(poly_w)]))
    for c in legs_xy:
        best = min(best, ref_circle(o, d, c, LEG_RADIUS_M))
    return best / h


# ----------------------------------------------------------------------------------------- raycast
def test_raycast_simple_cases() -> None:
    seg = np.array([[[2.0, -1.0], [2.0, 1.0]], [[5.0, -1.0], [5.0, 1.0]]])
    d, i = cast_segments([0.0, 0.0], [[1.0, 0.0], [-1.0, 0.0], [0.0, 1.0]], seg)
    np.testing.assert_array_equal(d, [2.0, np.inf, np.inf])
    np.testing.assert_array_equal(i, [0, -1, -1])
    d, i = cast_circles([0.0, 0.0], [[1.0, 0.0]], [[[3.0, 0.0]]], [0.5])
    assert d[0] == pytest.approx(2.5) and i[0] == 0
    d, i = cast([0.0, 0.0], [[1.0, 0.0]], seg, [[1.0, 0.0]], [0.25])
    assert d[0] == pytest.approx(0.75) and i[0] == 2  # circles are numbered after the segments
    # a face taller than the ray at the hit counts, a lower one is passed over
    d, _ = cast_segments([0.0, 0.0], [[1.0, 0.0]], seg, z0=[0.25], dz=[0.1], z_top=[0.4, 0.9])
    assert d[0] == pytest.approx(5.0)


def test_raycast_matches_reference_on_random_scenes() -> None:
    rng = np.random.default_rng(0)
    seg = rng.uniform(-5, 5, (20, 2, 2))
    cen = rng.uniform(-5, 5, (6, 2))
    a = rng.uniform(-np.pi, np.pi, 300)
    dirs = np.column_stack([np.cos(a), np.sin(a)])
    o = np.array([0.1, -0.2])
    d, _ = cast(o, dirs, seg, cen, np.full(6, 0.3))
    ref = [min([ref_segment(o, u, s[0], s[1]) for s in seg] + [ref_circle(o, u, c, 0.3) for c in cen])
           for u in dirs]
    np.testing.assert_allclose(d, ref, rtol=0, atol=1e-9)


# ------------------------------------------------------------------------------------------- gown
def test_gown_section_of_tilted_robot_matches_plane_box_intersection(scene) -> None:  # type: ignore[no-untyped-def]
    hull = scene.rig_true.robot.hull
    sc = scene.rig_true.laser_scanners[0]
    T_sw = geo.inv_T(sc.T_world_scanner.matrix())
    poses = [
        geo.T_from_xyz_rpy([0.5, 1.0, 0.002], np.radians([0.4, -0.3, 30.0])),  # floor-like tilt
        geo.T_from_xyz_rpy([0.5, 1.0, -0.01], np.radians([3.0, 2.0, -70.0])),  # steep: plane low on one side
        geo.T_from_xyz_rpy([0.5, 1.0, 0.0], np.radians([25.0, 0.0, 10.0])),  # cuts the top face: 5-6 sides
    ]
    T_sr = np.stack([T_sw @ T for T in poses])
    got = lasers.gown_sections(hull, T_sr)
    for k, T in enumerate(T_sr):
        ref = ref_section(hull, T)
        poly = got[k][np.r_[True, np.linalg.norm(np.diff(got[k], axis=0), axis=1) > 1e-12]]
        assert len(poly) == len(ref)
        # same vertices (as sets) to 1e-12 m
        dist = np.linalg.norm(poly[:, None] - ref[None], axis=2)
        assert dist.min(axis=1).max() < 1e-12
    # the outline moves with the tilt: a flat robot's section is the footprint, a tilted one's is not
    flat = lasers.gown_sections(hull, T_sw @ geo.T_from_xyz_rpy([0.5, 1.0, 0.0], [0, 0, 0.5]))[0]
    T_tilt = geo.T_from_xyz_rpy([0.5, 1.0, 0.0], np.radians([0.5, 0.5, 28.65]))
    tilt = lasers.gown_sections(hull, T_sw @ T_tilt)[0]
    assert 1e-4 < np.abs(flat - tilt).max() < 1e-2


def test_vectorised_robot_pose_is_the_floors(scene, run) -> None:  # type: ignore[no-untyped-def]
    t = np.linspace(run.stamps_s[0], run.stamps_s[-1], 7)
    np.testing.assert_allclose(lasers.robot_poses(run, t), run.T_world_robot_many(t), atol=1e-14)


# --------------------------------------------------------------------------- ideal scans are exact
def test_fixed_scans_equal_exact_ray_casting(scene, run) -> None:  # type: ignore[no-untyped-def]
    t0 = run.stamps_s[0] + 20.0
    iv = np.array([[t0, t0 + 0.02]])  # one scan each
    cfg = SimConfig(laser=LaserSimConfig(people=2))
    scans, info = lasers.simulate_fixed_scans(scene, run, iv, cfg, seed=1, ideal=True)
    people = lasers.sequence_people(scene, run, iv, cfg)
    n_gown = 0
    for sc in scene.rig_true.laser_scanners:
        log = scans[sc.name]
        assert len(log) >= 1 and info.clock_offsets_s[sc.name] == 0.0
        T_ws = sc.T_world_scanner.matrix()
        delays = np.abs(sc.angles_rad - sc.angles_rad[0]) / (2 * np.pi) / sc.rate_hz
        for k in range(len(log)):
            for b in range(k % 2, sc.beams, 2):
                ang = sc.angles_rad[b]
                t = log.stamps_s[k] + delays[b]
                r = ref_scan_range(scene, T_ws, ang, run.T_world_robot(t), people.legs_xy(t))
                r_static = ref_scan_range(scene, T_ws, ang, None, np.zeros((0, 2)))
                n_gown += r < r_static - 1e-6
                if r > sc.range_max_m:
                    assert np.isnan(log.ranges_m[k, b])
                else:
                    assert abs(log.ranges_m[k, b] - r) < 1e-9, (sc.name, k, b)
    assert n_gown > 10  # the robot was in view


def test_onboard_scans_equal_exact_ray_casting(scene, run) -> None:  # type: ignore[no-untyped-def]
    t0 = run.stamps_s[0] + 30.0
    iv = np.array([[t0, t0 + 0.05]])
    cfg = SimConfig(laser=LaserSimConfig(people=2))
    scans, _ = lasers.simulate_onboard_scans(scene, run, iv, cfg, seed=1, ideal=True)
    people = lasers.sequence_people(scene, run, iv, cfg)
    for sc in scene.rig_true.robot.onboard_scanners:
        log = scans[sc.name]
        delays = np.abs(sc.angles_rad - sc.angles_rad[0]) / (2 * np.pi) / sc.rate_hz
        for k in range(len(log)):
            for b in range(0, sc.beams, 3):
                t = log.stamps_s[k] + delays[b]
                T_ws = run.T_world_robot(t) @ sc.T_robot_scanner.matrix()
                r = ref_scan_range(scene, T_ws, sc.angles_rad[b], None, people.legs_xy(t))
                assert abs(log.ranges_m[k, b] - r) < 1e-9, (sc.name, k, b)


# ---------------------------------------------------------------------------------- sensor model
def test_sensor_model_statistics(scene) -> None:  # type: ignore[no-untyped-def]
    iv = np.array([[10.0, 12.0]])
    cfg = SimConfig(laser=LaserSimConfig(people=0, dropout_prob=0.02, mixed_pixels=False))
    ideal, _ = lasers.simulate_fixed_scans(scene, None, iv, cfg, seed=2, ideal=True)
    real, info = lasers.simulate_fixed_scans(scene, None, iv, cfg, seed=2)
    sc = scene.rig_true.laser_scanners[0]
    a, b = ideal[sc.name].ranges_m, real[sc.name].ranges_m
    assert a.shape == b.shape
    drop = np.isnan(b) & np.isfinite(a)
    assert 0.01 < drop.mean() < 0.03
    res = (b - a)[np.isfinite(a) & np.isfinite(b)]
    # walls (reflectivity 0.8) read 0.3 * bias short; noise plus 1 mm quantisation
    assert np.median(res) == pytest.approx(-0.3 * cfg.laser.reflectivity_bias_m, abs=1e-3)
    assert np.std(res) == pytest.approx(math.hypot(sc.range_sigma_m, 0.001 / math.sqrt(12)), rel=0.05)
    np.testing.assert_allclose(np.round(b[np.isfinite(b)] * 1000), b[np.isfinite(b)] * 1000, atol=1e-6)
    # stamps: the scanner's rate, its clock offset, sub-millisecond jitter
    dt = np.diff(real[sc.name].stamps_s)
    assert np.all(np.abs(dt - 1 / sc.rate_hz) < 0.003)
    np.testing.assert_allclose(real[sc.name].stamps_s - ideal[sc.name].stamps_s,
                               info.clock_offsets_s[sc.name], atol=0.002)


def test_mixed_pixels_fall_between_surfaces(scene, run) -> None:  # type: ignore[no-untyped-def]
    iv = np.array([[run.stamps_s[0] + 5.0, run.stamps_s[0] + 7.0]])
    base = dict(people=0, dropout_prob=0.0, reflectivity_bias_m=0.0)
    cfg = SimConfig(laser=LaserSimConfig(**base))
    ideal, _ = lasers.simulate_fixed_scans(scene, run, iv, cfg, 4, ideal=True)
    mixed, _ = lasers.simulate_fixed_scans(scene, run, iv, cfg, 4)
    sc = scene.rig_true.laser_scanners[2]
    a, m = ideal[sc.name].ranges_m, mixed[sc.name].ranges_m
    # beams whose ideal neighbours differ by > 0.5 m straddle an edge: some read neither surface
    fg = np.minimum(a[:, :-2], a[:, 2:])
    bg = np.maximum(a[:, :-2], a[:, 2:])
    edge = (bg - fg > 0.5) & (bg - fg < lasers.MIXED_MAX_SEPARATION_M)
    between = edge & (m[:, 1:-1] > fg + 0.1) & (m[:, 1:-1] < bg - 0.1)
    assert between.sum() >= 3


def test_people_walk_around_the_robot(scene, run) -> None:  # type: ignore[no-untyped-def]
    iv = np.array([[run.stamps_s[0], run.stamps_s[0] + 30.0]])
    people = lasers.sequence_people(scene, run, iv, SimConfig(laser=LaserSimConfig(people=3)))
    t = people.stamps_s
    legs = people.legs_xy(t)
    robot = run.planar(t)[:, :2]
    d = np.linalg.norm(legs - robot[:, None], axis=2)
    assert d.min() > 0.5  # never inside the robot (half diagonal 0.48 m)
    speed = np.linalg.norm(np.diff(people.centres_xy, axis=0), axis=2) / np.diff(t)[:, None]
    assert 0.3 < np.median(speed) < 1.3


# ------------------------------------------------------------------------------------ determinism
def test_same_seed_same_files(tmp_path, scene, run) -> None:  # type: ignore[no-untyped-def]
    t0 = run.stamps_s[0]
    iv = np.array([[t0 + 1.0, t0 + 1.2], [t0 + 3.0, t0 + 3.1]])
    cfg = SimConfig.quick_defaults()
    for name, seed in (("a", 7), ("b", 7), ("c", 8)):
        lasers.write_fixed_scans(scene, run, iv, tmp_path / name, cfg, seed)
        lasers.write_onboard_scans(scene, run, iv, tmp_path / name / "onboard", cfg, seed)
    for f in ("laser0.csv", "laser3.csv", "onboard/sick_front.csv"):
        assert (tmp_path / "a" / f).read_bytes() == (tmp_path / "b" / f).read_bytes()
        assert (tmp_path / "a" / f).read_bytes() != (tmp_path / "c" / f).read_bytes()
    log = read_scans(tmp_path / "a" / "laser0.csv", scene.rig_true.laser_scanners[0])
    assert 20 <= len(log) <= 24  # 0.3 s at 75 Hz, whole scans only
