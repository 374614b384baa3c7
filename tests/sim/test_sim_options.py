"""Simulator options: a fast robot accelerating and braking as real ones do, a scanner
half blocked by clutter, scans stamped at the start, middle or end of the sweep (or all beams fired
at once), and a hull of two fabrics. The default settings leave the scene as it was."""

from __future__ import annotations

import numpy as np
import pytest

from gtrig.laser.fuse import scan_points_world
from gtrig.sim.config import LaserSimConfig, SimConfig
from gtrig.sim.gtroom import VALIDATION_POSES, continuous_path, make_scene
from gtrig.sim.lasers import configure_scene, simulate_fixed_scans
from gtrig.sim.motion import RobotMotion, agile_path, static_motion


def test_agile_path_respects_the_robots_limits():
    t, x = agile_path(VALIDATION_POSES, v_max_mps=1.5, accel_mps2=1.0, lat_accel_mps2=1.0, yaw_rate_max_radps=2.0)
    v = np.hypot(*np.gradient(x[:, :2], t, axis=0).T)
    w = np.gradient(x[:, 2], t)
    a = np.gradient(v, t)
    assert 1.45 < v.max() <= 1.501 and np.abs(w).max() <= 2.01
    assert np.percentile(np.abs(a), 99) <= 1.05
    assert v[0] < 0.05 and v[-1] < 0.05  # from rest to rest
    # the same path as the default run, driven faster
    t0, x0 = continuous_path()
    assert np.allclose(x[0, :2], x0[0, :2], atol=1e-6) and np.allclose(x[-1, :2], x0[-1, :2], atol=2e-3)
    assert t[-1] < 0.4 * t0[-1]


def test_default_settings_leave_the_scene_unchanged():
    sc = make_scene(1)
    assert configure_scene(sc, SimConfig()) is sc


def _quiet(**kw) -> SimConfig:
    return SimConfig(laser=LaserSimConfig(people=0, mixed_pixels=False, dropout_prob=0.0, **kw))


def test_blocked_scanner_loses_that_share_of_its_view():
    cfg = _quiet(blocked_scanner=2, blocked_fraction=0.5)
    sc = configure_scene(make_scene(1), cfg)
    scans, _ = simulate_fixed_scans(sc, None, np.array([[0.0, 0.1]]), cfg, 1, ideal=True)
    for i, s in enumerate(sc.rig_true.laser_scanners):
        near = np.mean(scans[s.name].ranges_m[0] < 0.6)
        if i == 2:
            assert 0.45 < near < 0.55
        else:
            assert near == 0.0


def _dist_to_outline(p: np.ndarray, poses: np.ndarray, hull) -> np.ndarray:  # noqa: ANN001
    """Distance (M,) of points (M, 2) to the hull outline at planar poses (M, 3)."""
    c, s = np.cos(poses[:, 2]), np.sin(poses[:, 2])
    q = p - poses[:, :2]
    q = np.column_stack([c * q[:, 0] + s * q[:, 1], -s * q[:, 0] + c * q[:, 1]])  # robot frame
    a = hull.corners_xy()
    e = np.roll(a, -1, axis=0) - a
    u = np.clip(np.einsum("mkj,kj->mk", q[:, None] - a[None], e) / np.einsum("kj,kj->k", e, e), 0, 1)
    return np.min(np.linalg.norm(a[None] + u[..., None] * e[None] - q[:, None], axis=2), axis=1)


@pytest.mark.parametrize(("timing", "stamp_at"), [("sweep", "start"), ("sweep", "end"), ("simultaneous", "start")])
def test_stamps_and_beam_timing_are_what_the_rig_says(timing, stamp_at):
    cfg = _quiet(beam_timing=timing, stamp_at=stamp_at)
    sc = configure_scene(make_scene(1), cfg)
    t, x = agile_path(VALIDATION_POSES, duration_s=8.0)
    mot = RobotMotion(t, x, sc.floor)
    scans, _ = simulate_fixed_scans(sc, mot, np.array([[5.0, 5.5]]), cfg, 2, ideal=True)
    hull = sc.rig_true.robot.hull
    right, wrong = [], []
    for s in sc.rig_true.laser_scanners:
        log = scans[s.name]
        pts = scan_points_world(log.ranges_m, s)  # (N, B, 2)
        # the wrong belief: a sweep taken for a flash, or a flash for a sweep
        swept = s.model_copy(update={"beam_timing": "sweep"}).beam_delays_s()
        other = np.zeros(s.beams) if timing == "sweep" else swept
        for told, out in ((s.beam_delays_s(), right), (other, wrong)):
            tb = log.stamps_s[:, None] + told[None, :]
            hit = np.isfinite(pts[..., 0])
            d = _dist_to_outline(pts[hit], mot.planar(tb[hit]), hull)
            out.append(d[d < 0.05])  # returns off the gown (walls, clutter) are far from it
    right, wrong = np.concatenate(right), np.concatenate(wrong)
    # the beams lie on the gown where the rig's timing puts it (the floor's tilt leaves a millimetre)
    assert right.size > 100
    assert np.median(right) < 0.002 and np.median(right) < 0.5 * np.median(wrong)


def test_two_fabrics_range_apart():
    # the same scans, noise and all, with one light fabric and with a dark and a light one: each beam
    # on the gown ranges differently by the bias of its side's fabric only
    pose = np.array([[1.2, 1.6, 0.7]])
    out = {}
    for refl in (None, (0.1, 0.9, 0.1, 0.9)):
        cfg = _quiet(gown_reflectivity=refl)
        sc = configure_scene(make_scene(1), cfg)
        val, iv = static_motion(pose, sc.floor, dwell_s=0.2)
        out[refl is None] = simulate_fixed_scans(sc, val, iv, cfg, 3)[0]
    bg = simulate_fixed_scans(sc, None, iv, cfg, 3)[0]
    k = cfg.laser.reflectivity_bias_m
    dark, light = k * (0.7 - 0.1), k * (0.7 - 0.9)  # against the default fabric (0.7)
    d = []
    for s in sc.rig_true.laser_scanners:
        on_gown = np.abs(out[True][s.name].ranges_m - bg[s.name].ranges_m) > 0.05
        d.append((out[False][s.name].ranges_m - out[True][s.name].ranges_m)[on_gown])
    d = np.concatenate(d)
    near_dark, near_light = np.abs(d - dark) <= 0.0011, np.abs(d - light) <= 0.0011  # 1 mm quantisation
    assert d.size > 200 and np.mean(near_dark | near_light) > 0.97
    assert near_dark.mean() > 0.2 and near_light.mean() > 0.2


def test_sim_settings_file_and_its_errors(tmp_path):
    from typer.testing import CliRunner

    from gtrig.cli.main import app
    from gtrig.cli.sim import _with_file

    p = tmp_path / "sim.yaml"
    p.write_text("motion: {profile: agile, speed_mps: 1.5}\nlaser: {blocked_scanner: 0}\n")
    cfg = _with_file(SimConfig(seed=4), p)
    assert cfg.seed == 4 and cfg.motion.profile == "agile" and cfg.laser.blocked_scanner == 0
    p.write_text("motion: {profile: rocket}\n")
    r = CliRunner().invoke(app, ["sim", "--out", str(tmp_path / "rec"), "--config", str(p)])
    lines = [x for x in r.output.splitlines() if x.strip()]
    assert r.exit_code == 2 and len(lines) == 1 and "motion.profile" in lines[0], r.output
