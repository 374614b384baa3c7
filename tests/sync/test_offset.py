"""Clock offsets: injected odometry offsets recovered with intervals covering them; no turning -> unobservable."""

from dataclasses import replace

import numpy as np
import pytest

from gtrig.fusion import FusionOptions, fixes_from_track
from gtrig.io.odometry import OdometryLog
from gtrig.sync.offset import estimate_offset, refine_by_fusion


@pytest.mark.parametrize("lag", [0.05, 0.3, 2.0])
def test_injected_odometry_offset_recovered(run, lag: float) -> None:
    o = run.odometry
    odo = OdometryLog(o.stamps_s + lag, o.xytheta, o.v_mps, o.omega_radps)
    est = estimate_offset(odo.stamps_s, odo.xytheta[:, 2], run.laser.stamps_s, run.laser.yaw_rad(), "laser")
    assert est.verdict == "ok" and abs(est.coarse_s + lag) <= 0.011
    fine = refine_by_fusion(est, fixes_from_track(run.laser), odo, FusionOptions(correlation_s=0.0))
    assert fine.verdict == "ok"
    assert abs(fine.offset_s + lag) < 0.002  # the source runs `lag` early relative to the odometry
    assert fine.ci95_s[0] <= -lag <= fine.ci95_s[1]
    assert fine.ci95_s[1] - fine.ci95_s[0] < 0.01


def test_no_turning_is_unobservable() -> None:
    t = np.arange(0, 60, 0.02)
    yaw = np.full(t.size, 0.3) + np.random.default_rng(1).normal(0, 1e-4, t.size)
    est = estimate_offset(t, yaw, t[::5] + 0.1, yaw[::5], "straight")
    assert est.verdict == "unobservable" and np.isnan(est.offset_s)


def test_offset_between_two_gt_sources(run) -> None:
    """A GT source as the reference (its fixes anchor the fit): a 3 ms camera offset to the laser's clock."""
    vision = run.vision.shifted(0.003)  # the camera clock reads 3 ms late
    coarse = estimate_offset(run.laser.stamps_s, run.laser.yaw_rad(), vision.stamps_s, vision.yaw_rad(), "vision")
    fine = refine_by_fusion(coarse, fixes_from_track(vision), run.odometry, anchors=(fixes_from_track(run.laser),))
    assert fine.verdict == "ok" and abs(fine.offset_s - 0.003) < 0.001
    assert fine.ci95_s[0] <= 0.003 <= fine.ci95_s[1]


def test_refinement_starts_from_the_heading_fit_not_the_grid_peak(run) -> None:
    """The correlation's peak lies on a grid and may be a step or two off; the fusion's refinement
    searches around the heading fit's estimate, so a peak 20 ms off still gives the right answer."""
    from dataclasses import replace

    o = run.odometry
    est = estimate_offset(o.stamps_s, o.xytheta[:, 2], run.laser.stamps_s, run.laser.yaw_rad(), "laser")
    assert est.verdict == "ok"
    off_grid = replace(est, coarse_s=est.offset_s - 0.02)
    fine = refine_by_fusion(off_grid, fixes_from_track(run.laser), o, FusionOptions(correlation_s=0.0))
    assert fine.verdict == "ok" and abs(fine.offset_s) < 0.002 and fine.ci95_s[0] <= 0.0 <= fine.ci95_s[1]


def test_both_sources_offsets_made_consistent_with_gtlasers_clock(run) -> None:
    """GTlaser's clock 3 ms behind GTvision's: each source's offset to odometry alone scatters by the
    odometry's slip, apart; combined with GTlaser's clock to GTvision's, their difference is that clock
    and both intervals still cover the truth."""
    from gtrig.sync.offset import combine_with_laser_clock

    odo = run.odometry
    laser = run.laser.shifted(0.003)
    opts = FusionOptions(correlation_s=0.0)
    est = {}
    for name, tr in (("vision", run.vision), ("laser", laser)):
        e = estimate_offset(odo.stamps_s, odo.xytheta[:, 2], tr.stamps_s, tr.yaw_rad(), name)
        est[name] = refine_by_fusion(e, fixes_from_track(tr, name), odo, opts)
        assert est[name].verdict == "ok"
    v, la = combine_with_laser_clock(est["vision"], est["laser"], 0.003, 0.0003)
    assert la.offset_s - v.offset_s == pytest.approx(0.003, abs=1e-12)
    for e, truth, alone in ((v, 0.0, est["vision"]), (la, 0.003, est["laser"])):
        assert e.verdict == "ok" and e.ci95_s[0] <= truth <= e.ci95_s[1]
        assert e.ci95_s[1] - e.ci95_s[0] >= 0.9 * min(alone.ci95_s[1] - alone.ci95_s[0] for alone in est.values())
    lo, hi = sorted((est["vision"].offset_s, est["laser"].offset_s - 0.003))
    assert lo <= v.offset_s <= hi  # between the two estimates of GTvision's clock
    # an estimate that is not ok leaves both as they are
    amb = replace(est["laser"], verdict="ambiguous")
    assert combine_with_laser_clock(est["vision"], amb, 0.003, 0.0003) == (est["vision"], amb)


@pytest.mark.parametrize("anchored", [False, True])
def test_refinement_in_windows_is_the_whole_batch_estimate(run, anchored: bool) -> None:
    """A long source refined a window at a time (the windows' costs summed, so memory is a window's)
    gives the one-batch offset to a small part of its interval, the same interval within 10 %, and the
    injected offset inside it; with anchors too (each window takes the anchors within its span)."""
    lag = 0.3
    o = run.odometry
    odo = OdometryLog(o.stamps_s + lag, o.xytheta, o.v_mps, o.omega_radps)
    src = run.vision.shifted(0.003) if anchored else run.laser
    anchors = (fixes_from_track(run.laser),) if anchored else ()
    ref_s, ref = (run.laser.stamps_s, run.laser.yaw_rad()) if anchored else (odo.stamps_s, odo.xytheta[:, 2])
    est = estimate_offset(ref_s, ref, src.stamps_s, src.yaw_rad(), "src")
    span = src.stamps_s[-1] - src.stamps_s[0]
    opts = FusionOptions(correlation_s=0.0)
    base = run.odometry if anchored else odo
    whole = refine_by_fusion(est, fixes_from_track(src), base, opts, anchors=anchors, window_s=np.inf)
    parts = refine_by_fusion(est, fixes_from_track(src), base, opts, anchors=anchors, window_s=span / 3)
    assert whole.verdict == parts.verdict == "ok"
    half = 0.5 * (whole.ci95_s[1] - whole.ci95_s[0])
    assert abs(parts.offset_s - whole.offset_s) < 0.15 * half, (parts.offset_s, whole.offset_s, half)
    np.testing.assert_allclose(np.diff(parts.ci95_s), np.diff(whole.ci95_s), rtol=0.1)
    truth = 0.003 if anchored else -lag
    assert parts.ci95_s[0] <= truth <= parts.ci95_s[1]
    default = refine_by_fusion(est, fixes_from_track(src), base, opts, anchors=anchors)  # shorter than 600 s
    assert (default.offset_s, default.ci95_s) == (whole.offset_s, whole.ci95_s)
