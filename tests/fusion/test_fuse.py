"""Fusion on a synthetic run: accuracy against the truth, honest covariances, both estimators, outliers, gaps,
position-only fixes with a lever arm, the constant-velocity model."""

from dataclasses import replace

import numpy as np
import pytest
from fusion_synth import nees, planar_errors

from gtrig.errors import InputError
from gtrig.fusion import FusionOptions, fixes_from_track, fuse, fuse_tracks
from gtrig.trajectory import PoseStatus, PoseTrack

INDEP = FusionOptions(correlation_s=0.0)  # the synthetic fixes' errors are independent


def test_fused_beats_each_source_and_is_consistent(run) -> None:
    track, rep = fuse_tracks({"vision": run.vision, "laser": run.laser}, run.odometry, INDEP)
    e = planar_errors(track, run.motion)
    pos = np.hypot(e[:, 0], e[:, 1])
    for src in (run.vision, run.laser):
        es = planar_errors(src, run.motion)
        ps = np.hypot(es[:, 0], es[:, 1])
        assert pos.mean() < ps.mean() and np.percentile(pos, 95) < np.percentile(ps, 95)
    assert 0.5 <= nees(track, run.motion).mean() / 3 <= 2.0
    # every odometry stamp inside the sources' span has a pose
    lo = min(run.vision.stamps_s[0], run.laser.stamps_s[0])
    hi = max(run.vision.stamps_s[-1], run.laser.stamps_s[-1])
    inside = run.odometry.stamps_s[(run.odometry.stamps_s >= lo) & (run.odometry.stamps_s <= hi)]
    np.testing.assert_array_equal(track.stamps_s, inside)
    k = rep.segments[0].odometry_params
    assert abs(k[0] - 1 / 1.007) < 2e-3  # the distance scale the odometry got wrong


def test_ekf_rts_and_batch_agree(run) -> None:
    a, _ = fuse_tracks({"vision": run.vision, "laser": run.laser}, run.odometry, INDEP)
    b, _ = fuse_tracks({"vision": run.vision, "laser": run.laser}, run.odometry, replace(INDEP, estimator="ekf"))
    assert np.abs(a.xyz - b.xyz).max() < 2e-4
    assert np.allclose(np.sqrt(a.cov[:, 0, 0]), np.sqrt(b.cov[:, 0, 0]), rtol=0.1)


def test_flipped_and_turned_fixes_are_rejected(run) -> None:
    vis_xyt = run.vision.xytheta().copy()
    las_xyt = run.laser.xytheta().copy()
    bad_v = np.arange(50, 60)
    vis_xyt[bad_v, 2] += np.deg2rad(8.0)  # a planar-ambiguity flip: heading and position off
    vis_xyt[bad_v, 0] += 0.03
    bad_l = np.arange(1000, 1040)
    las_xyt[bad_l, 2] += np.pi / 2  # a hull acquired turned by 90 deg
    vision = PoseTrack.from_xytheta(run.vision.stamps_s, vis_xyt, cov=run.vision.cov, source="vision")
    laser = PoseTrack.from_xytheta(run.laser.stamps_s, las_xyt, cov=run.laser.cov, source="laser")
    track, rep = fuse_tracks({"vision": vision, "laser": laser}, run.odometry, INDEP)
    gated = {(o.source, round(o.stamp_s, 6)) for o in rep.outliers if o.stage == "gate"}
    for i in bad_v:
        assert ("vision", round(float(vision.stamps_s[i]), 6)) in gated
    for i in bad_l:
        assert ("laser", round(float(laser.stamps_s[i]), 6)) in gated
    assert rep.sources["laser"]["rejected"] < len(bad_l) + 10
    e = planar_errors(track, run.motion)
    assert np.hypot(e[:, 0], e[:, 1]).max() < 0.005 and np.abs(e[:, 2]).max() < np.deg2rad(0.2)


def _with_gap(track: PoseTrack, t0: float, t1: float) -> PoseTrack:
    return track.select((track.stamps_s < t0) | (track.stamps_s > t1))


def test_gap_is_bridged_with_honest_covariance(run) -> None:
    t0 = run.motion.stamps_s[0] + 12.0
    vision, laser = _with_gap(run.vision, t0, t0 + 3.0), _with_gap(run.laser, t0, t0 + 3.0)
    track, rep = fuse_tracks({"vision": vision, "laser": laser}, run.odometry, INDEP)
    br = track.status == PoseStatus.BRIDGED
    assert 140 <= br.sum() <= 152 and all(r.startswith("bridged: 3.0") for r in np.array(track.reasons)[br])
    q = nees(track, run.motion)[br]
    assert np.mean(q < 14.16) >= 0.99  # inside the 3-sigma ellipsoid (chi-square, 3 dof, 99.73 %)
    assert 0.3 < q.mean() / 3 < 2.0
    # --max-gap ends the segment instead: no pose inside the gap
    split, rep2 = fuse_tracks({"vision": vision, "laser": laser}, run.odometry, replace(INDEP, max_gap_s=1.0))
    assert len(rep2.segments) == 2
    assert not np.any((split.stamps_s > t0 + 0.1) & (split.stamps_s < t0 + 2.9))


def test_position_fixes_with_a_lever_arm(run) -> None:
    lever = np.array([0.2, -0.1])
    st = run.laser.stamps_s[::15]
    truth = run.motion.planar(st)
    c, s = np.cos(truth[:, 2]), np.sin(truth[:, 2])
    rng = np.random.default_rng(3)
    ant = truth[:, :2] + np.column_stack([c * lever[0] - s * lever[1], s * lever[0] + c * lever[1]])
    ant += rng.normal(0, 0.01, ant.shape)
    cov = np.tile(np.diag([1e-4, 1e-4, 4e-4]), (st.size, 1, 1))
    gps = PoseTrack(st, np.column_stack([ant, np.zeros(st.size)]), np.tile([0, 0, 0, 1.0], (st.size, 1)), cov, "xyz",
                    source="gps")
    track, _ = fuse([fixes_from_track(gps, lever_xy=tuple(lever))], run.odometry, INDEP)
    e = planar_errors(track, run.motion)
    assert np.hypot(e[:, 0], e[:, 1]).mean() < 0.006  # 5 Hz, 1 cm fixes smoothed by odometry
    assert np.degrees(np.abs(e[:, 2])).mean() < 1.0  # heading from the lever arm and the motion
    assert 0.3 <= nees(track, run.motion).mean() / 3 <= 2.0


def test_constant_velocity_without_odometry(run) -> None:
    track, rep = fuse_tracks({"vision": run.vision, "laser": run.laser}, None, replace(INDEP, rate_hz=50.0))
    assert rep.process == "constant velocity"
    e = planar_errors(track, run.motion)
    assert np.hypot(e[:, 0], e[:, 1]).mean() < 0.001
    assert 0.3 <= nees(track, run.motion).mean() / 3 <= 2.0


def test_bad_inputs_are_one_line_errors(run) -> None:
    late = run.laser.shifted(1000.0)
    with pytest.raises(InputError, match="does not overlap"):
        fuse_tracks({"laser": late}, run.odometry)
    cov = np.array(run.laser.cov)
    cov[7, 0, 0] = -1.0
    with pytest.raises(InputError, match="not positive definite"):
        fuse_tracks({"laser": run.laser.with_cov(cov)}, run.odometry)


def test_an_offsets_uncertainty_widens_the_poses_along_the_motion(run) -> None:
    """Both sources' clocks 4 ms off an applied offset of 0 (an offset wrong by its sigma): the poses are
    then about v * 4 ms off along the motion; with the offsets' sigma given, their covariance says so."""
    tracks = {"vision": run.vision.shifted(0.004), "laser": run.laser.shifted(0.004)}
    zero = {"vision": 0.0, "laser": 0.0}
    plain, _ = fuse_tracks(tracks, run.odometry, replace(INDEP, offsets_s=zero))
    timed, rep = fuse_tracks(tracks, run.odometry, replace(INDEP, offsets_s=zero,
                                                           offsets_sigma_s={"vision": 0.004, "laser": 0.005}))
    np.testing.assert_allclose(timed.xyz, plain.xyz)  # the estimate itself is unchanged
    assert nees(plain, run.motion).mean() / 3 > 2.0
    assert 0.5 <= nees(timed, run.motion).mean() / 3 <= 2.0
    v = np.gradient(plain.xytheta()[:, :2], plain.stamps_s, axis=0)
    extra = timed.cov[:, :2, :2] - plain.cov[:, :2, :2]
    want = 0.004**2 * v[:, :, None] * v[:, None, :]  # the best-timed source's sigma
    np.testing.assert_allclose(extra[1:-1], want[1:-1], rtol=1e-6, atol=1e-15)
    assert rep.sources["laser"]["offset_sigma_s"] == 0.005


def _vision_off_in_x(run, seconds: float, dx: float) -> tuple[PoseTrack, np.ndarray, float]:  # noqa: ANN001
    """GTvision with its poses ``dx`` off in x for ``seconds`` from 15 s into the run; which, and the start."""
    xyt = run.vision.xytheta().copy()
    t0 = float(run.vision.stamps_s[0]) + 15.0
    bad = (run.vision.stamps_s > t0) & (run.vision.stamps_s < t0 + seconds)
    xyt[bad, 0] += dx
    return PoseTrack.from_xytheta(run.vision.stamps_s, xyt, cov=run.vision.cov, source="vision"), bad, t0


def test_a_biased_stretch_is_gated_against_the_fixes_own_covariance(run) -> None:
    """Two seconds of GTvision poses 15 mm off, agreeing with each other (7.5 sigma of their own covariance):
    the decorrelation inflates each covariance by the count of fixes within 0.5 s, which must not let them
    through the gate."""
    vision, bad, t0 = _vision_off_in_x(run, 2.0, 0.015)
    opts = FusionOptions(correlation_s=0.5)
    track, rep = fuse_tracks({"vision": vision, "laser": run.laser}, run.odometry, opts)
    old, rep_old = fuse_tracks({"vision": vision, "laser": run.laser}, run.odometry, replace(opts, gate_own_cov=False))
    gated = {round(o.stamp_s, 6) for o in rep.outliers if o.stage == "gate" and o.source == "vision"}
    assert {round(float(s), 6) for s in run.vision.stamps_s[bad]} <= gated
    assert rep_old.sources["vision"]["rejected"] < bad.sum() / 2  # inflated, most of them passed
    e, e_old = planar_errors(track, run.motion), planar_errors(old, run.motion)
    assert np.abs(e[:, 0]).max() < np.abs(e_old[:, 0]).max()


def test_a_stretch_disagreeing_with_the_prediction_is_down_weighted(run) -> None:
    """Three seconds of GTvision poses 5 mm off (2.5 sigma each: the gate lets them in): their innovations
    against the laser-and-odometry prediction stay above their covariance over the stretch, so the batch
    weighs them by that disagreement and the fused track follows them less."""
    vision, bad, t0 = _vision_off_in_x(run, 3.0, 0.005)
    opts = FusionOptions(correlation_s=0.5)
    track, rep = fuse_tracks({"vision": vision, "laser": run.laser}, run.odometry, opts)
    plain, _ = fuse_tracks({"vision": vision, "laser": run.laser}, run.odometry, replace(opts, innovation_window_s=0))
    assert rep.sources["vision"]["rejected"] < bad.sum() / 2  # not a gate's matter
    near = (track.stamps_s > t0) & (track.stamps_s < t0 + 3.0)
    e, e_plain = planar_errors(track, run.motion)[near, 0], planar_errors(plain, run.motion)[near, 0]
    assert np.abs(e).mean() < 0.8 * np.abs(e_plain).mean()
    q, q_plain = nees(track, run.motion)[near], nees(plain, run.motion)[near]
    assert q.mean() < q_plain.mean()  # and its covariance is the more honest there


def test_odometry_ending_inside_the_sources_span_still_gives_its_last_stamps_poses(run) -> None:
    """The sources run on past the odometry (their last fixes lie after its last record, as on the simulated
    runs by a few ms): the fixes beyond it are dropped, but every odometry stamp inside the sources' span,
    up to its last, gets a pose."""
    from gtrig.io.odometry import OdometryLog

    o = run.odometry
    n = o.stamps_s.size - 40  # the odometry ends 0.8 s before the sources
    cut = OdometryLog(o.stamps_s[:n], o.xytheta[:n], o.v_mps[:n], o.omega_radps[:n])
    track, _ = fuse_tracks({"vision": run.vision, "laser": run.laser}, cut, INDEP)
    lo = min(run.vision.stamps_s[0], run.laser.stamps_s[0])
    inside = cut.stamps_s[cut.stamps_s >= lo]
    assert run.laser.stamps_s[-1] > cut.stamps_s[-1]
    np.testing.assert_array_equal(track.stamps_s, inside)
    assert np.hypot(*planar_errors(track, run.motion)[-1, :2]) < 0.005
