"""The odometry's random errors fitted from the data (gtrig.fusion.odonoise): honest bridges through gaps."""

from __future__ import annotations

import numpy as np
import pytest
from fusion_synth import draw_fixes, nees

from gtrig.fusion import FusionOptions, fixes_from_track, fuse
from gtrig.fusion.odonoise import fit_odometry_noise
from gtrig.fusion.process import OdometryNoise
from gtrig.io.odometry import OdometryLog
from gtrig.sim.floor import Floor
from gtrig.sim.motion import RobotMotion
from gtrig.sim.odometry import OdometryErrors, simulate_odometry
from gtrig.trajectory import PoseTrack

SLIP = 0.002  # the simulated wheels' slip, m per sqrt(m)


@pytest.fixture(scope="module")
def motion() -> RobotMotion:
    """Three minutes of a robot wandering at 0.2-0.4 m/s and turning both ways (a fit needs 250 windows)."""
    st = 100.0 + np.arange(0.0, 180.0, 0.005)
    v = 0.3 + 0.1 * np.sin(st / 17.0)
    w = 0.6 * np.sin(st / 5.3) + 0.3 * np.sin(st / 2.1)
    th = np.cumsum(w) * 0.005
    xyth = np.column_stack([np.cumsum(v * np.cos(th)) * 0.005, np.cumsum(v * np.sin(th)) * 0.005, th])
    return RobotMotion(st, xyth, Floor.flat())


def _run(motion: RobotMotion, seed: int) -> tuple[list[PoseTrack], OdometryLog]:
    """Odometry made wheel by wheel (slip per metre rolled, whole encoder ticks, no side slip, nothing while
    standing) and two pose sources with white noise as stated."""
    rng = np.random.default_rng(seed)
    t0, t1 = motion.stamps_s[0], motion.stamps_s[-1]
    errors = OdometryErrors(scale=0.007, differential=-0.002, wheelbase=0.007, slip_sigma_m=SLIP, ticks_per_rev=4096)
    odo = simulate_odometry(motion, t0, t1, 50.0, errors, rng)
    tracks = [draw_fixes(motion, np.arange(t0 + 0.01, t1 - 0.01, 1 / rate), sig, rng, name)
              for name, rate, sig in (("vision", 40.0, (0.002, 0.002, 0.0007)),
                                      ("laser", 75.0, (0.0012, 0.0012, 0.0025)))]
    return tracks, odo


def _bridged_nees(motion: RobotMotion, opts: FusionOptions, seeds: range) -> float:
    """Mean NEES/dof of the poses bridged over 3 s gaps cut every 20 s from both sources, over ``seeds``."""
    q = []
    for seed in seeds:
        tracks, odo = _run(motion, seed)
        t0 = motion.stamps_s[0] + 5.0 + 10.0 * (seed % 2)
        cut = [t.select(((t.stamps_s - t0) % 20.0 < 10.0) | ((t.stamps_s - t0) % 20.0 > 13.0)) for t in tracks]
        track, report = fuse([fixes_from_track(t) for t in cut], odo, opts)
        assert ("windows" in report.odometry_noise) == opts.fit_odometry_noise
        b = track.status == 2
        assert b.sum() > 1200  # eight gaps of 150 nodes at least: the check is not empty
        q.append(nees(track.select(b), motion) / 3)
    return float(np.mean(np.concatenate(q)))


def test_the_fit_finds_the_wheels_slip(motion: RobotMotion) -> None:
    # the stated model starts at 2.5 times the slip; the fit takes the fixes' own noise (2 mm and 1.2 mm,
    # as much as the odometry's drift over the shorter windows) out of the disagreement
    start = OdometryNoise(slip_m_per_sqrt_m=2.5 * SLIP)
    slips = []
    for seed in range(4):
        tracks, odo = _run(motion, seed)
        fit = fit_odometry_noise([fixes_from_track(t) for t in tracks], odo, start)
        assert fit is not None
        slips.append(fit.noise.slip_m_per_sqrt_m)
        assert 0.8 < fit.nees_fitted < 1.25, fit.summary()
        np.testing.assert_allclose(fit.k, [1 / 1.007, 1.0, 0.0], atol=0.01)
    assert 0.8 * SLIP < np.mean(slips) < 1.25 * SLIP, slips


def test_bridged_poses_are_consistent_under_the_stated_model_and_the_fit(motion: RobotMotion) -> None:
    # the stated floors are the fit's least (wheels count nothing while standing); floors of 0.5 mm and
    # 0.5 mrad per sqrt(s) are errors these wheels do not make: taken as stated, a 3 s bridge's
    # covariance is too wide
    opts = FusionOptions(correlation_s=0.0)
    fitted = _bridged_nees(motion, opts, range(6))
    assert 0.75 < fitted < 1.5, fitted
    stated = _bridged_nees(motion, FusionOptions(correlation_s=0.0, fit_odometry_noise=False), range(6))
    assert 0.75 < stated < 1.5, (stated, fitted)
    floored = OdometryNoise(floor_m_per_sqrt_s=5e-4, floor_rad_per_sqrt_s=5e-4)
    wide = _bridged_nees(motion, FusionOptions(correlation_s=0.0, fit_odometry_noise=False, odometry=floored), range(6))
    assert wide < 0.8 * stated, (wide, stated)


def test_a_run_too_short_to_fit_keeps_the_stated_model(motion: RobotMotion) -> None:
    tracks, odo = _run(motion, 0)
    short = [fixes_from_track(t.select(t.stamps_s < motion.stamps_s[0] + 90.0)) for t in tracks]
    _, report = fuse(short, odo, FusionOptions())
    assert "windows" not in report.odometry_noise
    assert report.odometry_noise["slip_m_per_sqrt_m"] == OdometryNoise().slip_m_per_sqrt_m
