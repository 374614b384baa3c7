"""Fusion across an odometry reset: the jump is a new odometry segment, not a motion to fit through."""

from dataclasses import replace

import numpy as np
from fusion_synth import nees, planar_errors

from gtrig.fusion import FusionOptions, fuse_tracks
from gtrig.fusion.process import OdometryJumps, odometry_jumps
from gtrig.io.odometry import OdometryLog
from gtrig.trajectory import PoseTrack

INDEP = FusionOptions(correlation_s=0.0)  # the synthetic fixes' errors are independent


def _reset_at(odo: OdometryLog, t_s: float) -> OdometryLog:
    """The odometry restarted at ``t_s``: from there on its poses are relative to the pose it had then
    (the driver reset to zero)."""
    k = int(np.searchsorted(odo.stamps_s, t_s))
    xyt = odo.xytheta.copy()
    x0, y0, th0 = xyt[k]
    c, s = np.cos(th0), np.sin(th0)
    d = xyt[k:, :2] - [x0, y0]
    xyt[k:, 0], xyt[k:, 1] = c * d[:, 0] + s * d[:, 1], -s * d[:, 0] + c * d[:, 1]
    xyt[k:, 2] = (xyt[k:, 2] - th0 + np.pi) % (2 * np.pi) - np.pi
    return replace(odo, xytheta=xyt)


def test_fusion_across_an_odometry_reset(run) -> None:
    t_reset = float(run.motion.stamps_s[0]) + 14.0
    odo = _reset_at(run.odometry, t_reset)
    sources = {"vision": run.vision, "laser": run.laser}
    plain, _ = fuse_tracks(sources, run.odometry, INDEP)
    track, rep = fuse_tracks(sources, odo, INDEP)
    # the reset is found, once, where it is
    assert len(rep.odometry_jumps_s) == 1 and abs(rep.odometry_jumps_s[0] - t_reset) < 0.03
    assert 0.5 <= nees(track, run.motion).mean() / 3 <= 2.0
    # no pose pulled toward the jump: within a second of it, as close to the truth as without the reset
    e, e0 = planar_errors(track, run.motion), planar_errors(plain, run.motion)
    near = np.abs(track.stamps_s - t_reset) < 1.0
    pos, pos0 = np.hypot(e[near, 0], e[near, 1]), np.hypot(e0[near, 0], e0[near, 1])
    assert pos.max() < 2.0 * pos0.max() + 0.0005 and pos.max() < 0.004
    assert np.abs(e[near, 2]).max() < np.deg2rad(0.2)
    # and without the jump cut (the reset taken for motion), the poses are dragged metres off
    dragged, _ = fuse_tracks(sources, odo, replace(INDEP, jumps=OdometryJumps(max_speed_mps=1e6,
                                                                               max_yaw_rate_radps=1e6)))
    assert np.hypot(*planar_errors(dragged, run.motion)[near, :2].T).max() > 10 * pos.max()


def test_motion_is_not_taken_for_a_jump(run) -> None:
    # the simulated robot's own increments, at 50 Hz, are never jumps
    xyt = run.odometry.xytheta.copy()
    d = np.diff(xyt, axis=0)
    c, s = np.cos(xyt[:-1, 2]), np.sin(xyt[:-1, 2])
    u = np.column_stack([c * d[:, 0] + s * d[:, 1], -s * d[:, 0] + c * d[:, 1], np.diff(np.unwrap(xyt[:, 2]))])
    assert not odometry_jumps(u, np.diff(run.odometry.stamps_s), OdometryJumps()).any()


def _slipped(odo: OdometryLog, t_s: float, duration_s: float, factor: float) -> OdometryLog:
    """The odometry with its travel over ``duration_s`` from ``t_s`` multiplied by ``factor`` (the wheels
    spinning on the floor), dead-reckoned on from there."""
    xyt = odo.xytheta
    d = np.diff(xyt, axis=0)
    c, s = np.cos(xyt[:-1, 2]), np.sin(xyt[:-1, 2])
    u = np.column_stack([c * d[:, 0] + s * d[:, 1], -s * d[:, 0] + c * d[:, 1], d[:, 2]])
    st = odo.stamps_s[1:]
    u[(st >= t_s) & (st < t_s + duration_s), :2] *= factor
    out = np.zeros_like(xyt)
    out[0] = xyt[0]
    for i in range(len(u)):  # dead reckoning; sequential by nature
        ci, si = np.cos(out[i, 2]), np.sin(out[i, 2])
        out[i + 1] = out[i] + [ci * u[i, 0] - si * u[i, 1], si * u[i, 0] + ci * u[i, 1], u[i, 2]]
    return replace(odo, xytheta=out)


def test_a_wheel_slip_widens_the_process_noise_where_it_happens(run) -> None:
    # 30 % too much travel for half a second (some 4 cm): fixes after it disagree with the odometry
    t_slip = float(run.motion.stamps_s[0]) + 14.0
    odo = _slipped(run.odometry, t_slip, 0.5, 1.3)
    sources = {"vision": run.vision, "laser": run.laser}
    track, rep = fuse_tracks(sources, odo, INDEP)
    assert not rep.odometry_jumps_s  # a slip, not a jump
    assert 0.5 <= nees(track, run.motion).mean() / 3 <= 2.0
    near = np.abs(track.stamps_s - t_slip - 0.25) < 1.0
    assert np.hypot(*planar_errors(track, run.motion)[near, :2].T).max() < 0.006
    # without the slip handling the gate refuses the fixes after it and the track follows the odometry
    stiff, _ = fuse_tracks(sources, odo, replace(INDEP, slip_ratio=0.0))
    assert nees(stiff, run.motion).mean() / 3 > 10.0


def _two_laps(run, cut_s: float = 0.3, pause_s: float = 0.2):  # noqa: ANN001, ANN202
    """The run twice, the second lap's stamps moved on by the run's length and ``pause_s``, as a recording
    made of laps: the odometry restarts from its first record and the robot from the run's start. The
    odometry's last ``cut_s`` of each lap is missing, so the sources' last fixes of a lap fall between
    the records either side of the jump. Returns the odometry, the sources and the lap's period."""
    t0, t1 = float(run.motion.stamps_s[0]), float(run.motion.stamps_s[-1])
    period = t1 - t0 + pause_s
    o = run.odometry
    k = o.stamps_s <= t1 - cut_s
    odo = OdometryLog(np.r_[o.stamps_s[k], o.stamps_s[k] + period], np.r_[o.xytheta[k], o.xytheta[k]],
                      np.r_[o.v_mps[k], o.v_mps[k]], np.r_[o.omega_radps[k], o.omega_radps[k]])
    sources = {name: PoseTrack.from_xytheta(np.r_[tr.stamps_s, tr.stamps_s + period], np.r_[tr.xytheta(), tr.xytheta()],
                                            cov=np.r_[tr.cov, tr.cov], source=name)
               for name, tr in (("vision", run.vision), ("laser", run.laser))}
    return odo, sources, period


def test_fixes_between_the_records_either_side_of_a_jump_do_not_pull_the_next_lap(run) -> None:
    odo, sources, period = _two_laps(run)
    track, rep = fuse_tracks(sources, odo, INDEP)
    assert len(rep.odometry_jumps_s) == 1
    second = track.stamps_s > float(run.motion.stamps_s[-1]) + 0.1
    e = track.xytheta() - run.motion.planar(np.where(second, track.stamps_s - period, track.stamps_s))
    e[:, 2] = (e[:, 2] + np.pi) % (2 * np.pi) - np.pi
    # the second lap as well fixed as the first (interpolated across the jump, a late fix of the first
    # lap had set the second's start and the gate then refused the whole lap: metres off)
    pos = np.hypot(e[:, 0], e[:, 1])
    assert pos[second].max() < 0.004 and pos[~second].max() < 0.004
    assert np.mean(track.status[second] == 2) < 0.05
    q = np.einsum("ni,nij,nj->n", e, np.linalg.inv(track.cov), e)
    assert 0.5 <= q.mean() / 3 <= 2.0
