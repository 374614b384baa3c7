"""`gtrig sim --rig RIG [--path TUM]`: a planned rig installed in the simulated GT room.

The GT room's own design written as a planned rig and read back installs the built-in scene; a planned
rig with other sensors and a path of its own gives a recording in the same layout, following the path;
what the simulator cannot simulate is refused with one line naming the rig's field."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from gtrig import geometry as geo
from gtrig.cli.main import app
from gtrig.errors import InputError
from gtrig.io.tum import Trajectory, read_tum, write_tum
from gtrig.rig.load import dump_rig, load_rig
from gtrig.rig.models import Pose, Rig
from gtrig.sim.config import CameraSimConfig, SimConfig
from gtrig.sim.gtroom import BAND_CENTRE, BAND_DIR_RAD, design_rig, make_scene
from gtrig.sim.install import install
from gtrig.sim.recording import PlannedPath, simulate


def _close(a: Rig, b: Rig) -> None:
    for ca, cb in zip(a.cameras, b.cameras, strict=True):
        assert np.allclose(ca.T_world_cam.matrix(), cb.T_world_cam.matrix(), atol=1e-12)
        assert ca.camera_matrix == cb.camera_matrix and ca.dist_coeffs == cb.dist_coeffs
        assert ca.model_copy(update={"T_world_cam": cb.T_world_cam}) == cb
    for sa, sb in zip(a.laser_scanners, b.laser_scanners, strict=True):
        assert np.allclose(sa.T_world_scanner.matrix(), sb.T_world_scanner.matrix(), atol=1e-12)
    for ma, mb in zip(a.robot.markers, b.robot.markers, strict=True):
        assert np.allclose(ma.T_robot_marker.matrix(), mb.T_robot_marker.matrix(), atol=1e-12)
    rest = {"cameras": (), "laser_scanners": ()}
    assert a.model_copy(update={**rest, "robot": a.robot.model_copy(update={"markers": ()})}) == \
        b.model_copy(update={**rest, "robot": b.robot.model_copy(update={"markers": ()})})


@pytest.mark.parametrize("seed", [0, 3])
def test_the_gt_rooms_design_installs_the_built_in_scene(tmp_path: Path, seed: int) -> None:
    dump_rig(design_rig(), tmp_path / "plan.yaml")
    scene = install(load_rig(tmp_path / "plan.yaml"), seed)
    built_in = make_scene(seed)
    _close(scene.rig_true, built_in.rig_true)
    _close(scene.rig_nominal, built_in.rig_nominal)
    assert scene.reference_true_xy == built_in.reference_true_xy
    assert np.array_equal(scene.T_board1_board2_true, built_in.T_board1_board2_true)
    for f in ("amp_m", "kx", "ky", "phase"):
        assert np.array_equal(getattr(scene.floor, f), getattr(built_in.floor, f))


def _band(u: float, v: float) -> np.ndarray:
    c, s = np.cos(BAND_DIR_RAD), np.sin(BAND_DIR_RAD)
    return BAND_CENTRE + u * np.array([c, s]) + v * np.array([-s, c])


def _three_cameras_three_scanners() -> Rig:
    """The design without its last camera and scanner, the first camera higher and aimed elsewhere."""
    d = design_rig()
    eye = np.r_[_band(-2.5, 2.3), 3.1]
    T = geo.look_at(eye, np.r_[_band(-2.2, 0.0), 0])
    cam0 = d.cameras[0].model_copy(update={"T_world_cam": Pose.from_matrix(T)})
    return d.model_copy(update={"cameras": (cam0, *d.cameras[1:3]), "laser_scanners": d.laser_scanners[:3]})


def test_a_planned_rig_and_path_give_a_recording(tmp_path: Path) -> None:
    plan = _three_cameras_three_scanners()
    t = np.arange(0.0, 1.2, 0.005)
    xy = np.array([_band(u, 0.1) for u in -1.0 + 0.3 * t])  # along the band at 0.3 m/s
    path = PlannedPath(t, np.column_stack([xy, np.full(t.size, BAND_DIR_RAD)]))
    cfg = SimConfig.quick_defaults(2).model_copy(update={
        "run_duration_s": 1.0, "static_pose_s": 0.05, "background_s": 0.3, "n_intrinsic_views": 3,
        "n_pair_views": 2, "n_handheld_views": 2, "workers": 1, "camera": CameraSimConfig(supersample=1)})
    out = tmp_path / "rec"
    simulate(cfg, out, plan=plan, path=path)
    rig, truth = load_rig(out / "rig.yaml"), load_rig(out / "truth" / "rig.yaml")
    assert [c.name for c in rig.cameras] == ["cam0", "cam1", "cam2"]
    assert [s.name for s in rig.laser_scanners] == ["laser0", "laser1", "laser2"]
    assert rig.cameras[0].camera_matrix == plan.cameras[0].camera_matrix  # the operator's: the planned lens
    # the true camera is the planned one, installed: the same eye, the aim moved by centimetres
    T_plan, T_true = plan.cameras[0].T_world_cam.matrix(), truth.cameras[0].T_world_cam.matrix()
    assert np.allclose(T_true[:3, 3], T_plan[:3, 3], atol=1e-9)
    assert 0.0 < np.degrees(geo.rotation_angle(T_plan[:3, :3].T @ T_true[:3, :3])) < 5.0
    for name in ("cam0", "cam1", "cam2"):
        assert any((out / "run" / "cameras" / name).glob("*.png"))
    assert sorted(p.name for p in (out / "run" / "lasers").glob("*.csv")) == ["laser0.csv", "laser1.csv", "laser2.csv"]
    run = read_tum(out / "truth" / "run.tum")
    rel = run.stamps_s - run.stamps_s[0]
    assert rel[-1] == pytest.approx(1.0, abs=0.01)
    expect = np.column_stack([np.interp(rel, t, xy[:, 0]), np.interp(rel, t, xy[:, 1])])
    assert np.abs(run.xyz[:, :2] - expect).max() < 0.002  # the floor's tilt moves the robot frame by less
    # the same plan and path resume; another plan is refused rather than mixed
    assert simulate(cfg, out, plan=plan, path=path) == {}
    with pytest.raises(InputError, match="other settings"):
        simulate(cfg, out, plan=design_rig(), path=path)


def _bad(field: str) -> Rig:
    d = design_rig()
    if field == "camera":
        up = Pose(xyz=d.cameras[1].T_world_cam.xyz, rpy_deg=(0.0, 0.0, 0.0))  # looking at the ceiling
        return d.model_copy(update={"cameras": (d.cameras[0], d.cameras[1].model_copy(update={"T_world_cam": up}))})
    if field == "scanner":
        s = d.laser_scanners[2]
        tilted = Pose(xyz=s.T_world_scanner.xyz, rpy_deg=(5.0, 0.0, 30.0))
        return d.model_copy(update={"laser_scanners": (s.model_copy(update={"T_world_scanner": tilted}),)})
    if field == "board":  # cam1 alone sees the world board
        return d.model_copy(update={"cameras": (d.cameras[0], d.cameras[2], d.cameras[3])})
    if field == "marker":
        m = d.robot.markers[1]
        high = Pose(xyz=(0.2, -0.14, 1.0), rpy_deg=(0.0, 0.0, 0.0))
        return d.model_copy(update={"robot": d.robot.model_copy(update={"markers": (
            d.robot.markers[0], m.model_copy(update={"T_robot_marker": high}))})})
    return d.model_copy(update={"robot": d.robot.model_copy(update={"hull": None})})


@pytest.mark.parametrize(("field", "named"), [
    ("camera", "cameras[1] (cam1).T_world_cam"), ("scanner", "laser_scanners[0] (laser2).T_world_scanner"),
    ("marker", "robot.markers[1] (id 6).T_robot_marker"), ("hull", "robot.hull"),
    ("board", "cameras: none sees the simulated world board whole"),
])
def test_what_cannot_be_simulated_is_refused_in_one_line(tmp_path: Path, field: str, named: str) -> None:
    dump_rig(_bad(field), tmp_path / "rig.yaml")
    r = CliRunner().invoke(app, ["sim", "--rig", str(tmp_path / "rig.yaml"), "--out", str(tmp_path / "rec"),
                                 "--quick"])
    assert r.exit_code != 0
    lines = [x for x in r.output.strip().splitlines() if x.strip()]
    assert len(lines) == 1 and named in lines[0] and "Traceback" not in r.output, r.output
    assert not (tmp_path / "rec").exists()  # nothing written


def test_a_path_outside_the_room_is_refused(tmp_path: Path) -> None:
    t = np.arange(3.0)
    xyz = np.array([[0.0, 0.0, 0.0], [0.5, 0.0, 0.0], [20.0, 0.0, 0.0]])
    write_tum(tmp_path / "p.tum", Trajectory(t, xyz, np.tile([0.0, 0.0, 0.0, 1.0], (3, 1))))
    r = CliRunner().invoke(app, ["sim", "--path", str(tmp_path / "p.tum"), "--out", str(tmp_path / "rec"), "--quick"])
    assert r.exit_code != 0 and "pose 3" in r.output and "outside" in r.output, r.output
    assert not (tmp_path / "rec").exists()


def _segment_distance(p: np.ndarray, walls: np.ndarray) -> np.ndarray:
    """Distance (M,) of points (M, 2) to the nearest of wall segments (S, 2, 2)."""
    a, e = walls[:, 0], walls[:, 1] - walls[:, 0]
    u = np.clip(np.einsum("msj,sj->ms", p[:, None] - a[None], e) / np.einsum("sj,sj->s", e, e), 0, 1)
    return np.min(np.linalg.norm(a[None] + u[..., None] * e[None] - p[:, None], axis=2), axis=1)


def test_a_rig_with_its_own_outline_gives_scans_of_that_outline(tmp_path: Path) -> None:
    from gtrig.laser.fuse import scan_points_world
    from gtrig.sim.config import LaserSimConfig
    from gtrig.sim.gtroom import room_walls
    from gtrig.sim.install import outline_walls
    from gtrig.sim.lasers import configure_scene, simulate_fixed_scans

    gt = room_walls()
    c = gt[:, 0].mean(axis=0)
    # a pentagon around the GT room: its corners 1.5 m farther out, a fifth corner off the first wall
    corners = gt[:, 0] + np.sign(gt[:, 0] - c) * 1.5
    bulge = 0.5 * (corners[0] + corners[1]) + 1.2 * (0.5 * (corners[0] + corners[1]) - c) / np.linalg.norm(
        0.5 * (corners[0] + corners[1]) - c)
    outline = np.vstack([corners[:1], bulge, corners[1:]])
    d = design_rig()
    plan = d.model_copy(update={"world": d.world.model_copy(update={
        "outline_xy": tuple((float(x), float(y)) for x, y in outline)})})
    dump_rig(plan, tmp_path / "plan.yaml")  # the outline round-trips through the rig file
    plan = load_rig(tmp_path / "plan.yaml")
    scene = install(plan, 0)
    assert np.allclose(scene.walls, outline_walls(outline))
    # a path is checked against the planned walls: beyond the GT room's but inside the outline drives
    from gtrig.sim.recording import check_path

    beyond = c + 1.15 * (gt[1].mean(axis=0) - c)  # past the middle of a GT room wall
    check_path(PlannedPath(np.arange(2.0), np.array([[*c, 0.0], [*beyond, 0.0]])), scene.walls[:, 0])
    with pytest.raises(InputError, match="outside"):
        check_path(PlannedPath(np.arange(2.0), np.array([[*c, 0.0], [*beyond, 0.0]])))
    # the world points mark the new walls' feet, 5 cm inside
    assert np.allclose(_segment_distance(scene.world_points_xy, scene.walls), 0.05, atol=1e-9)
    cfg = SimConfig(laser=LaserSimConfig(people=0, mixed_pixels=False, dropout_prob=0.0))
    scene = configure_scene(scene, cfg)
    scans, _ = simulate_fixed_scans(scene, None, np.array([[0.0, 0.1]]), cfg, 1, ideal=True)
    pts = np.concatenate([scan_points_world(scans[s.name].ranges_m[:1], s)[0]
                          for s in scene.rig_true.laser_scanners])
    pts = pts[np.isfinite(pts[:, 0])]
    on_new = _segment_distance(pts, scene.walls) < 0.01
    on_old = _segment_distance(pts, gt) < 0.05
    assert on_new.mean() > 0.5, on_new.mean()  # most beams end on the planned walls, the rest on clutter
    assert not np.any(on_old & ~on_new)  # none on the GT room's walls
    # the same design without an outline still scans the GT room's walls
    built = configure_scene(install(d, 0), cfg)
    scans0, _ = simulate_fixed_scans(built, None, np.array([[0.0, 0.1]]), cfg, 1, ideal=True)
    p0 = np.concatenate([scan_points_world(scans0[s.name].ranges_m[:1], s)[0] for s in built.rig_true.laser_scanners])
    p0 = p0[np.isfinite(p0[:, 0])]
    assert np.mean(_segment_distance(p0, gt) < 0.01) > 0.5
