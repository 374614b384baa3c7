"""The fixed scanners' beam timing checked from the residuals: scans simulated with one timing, tracked
with the rig declaring it or another (gtrig.laser.beam_timing)."""

from __future__ import annotations

import numpy as np
import pytest

from gtrig.geometry import wrap_angle
from gtrig.laser.background import build_background
from gtrig.laser.beam_timing import check_beam_timing, timing_check
from gtrig.laser.foreground import foreground_mask, foreground_threshold
from gtrig.laser.fuse import frame_points
from gtrig.laser.hull_icp import HullModel
from gtrig.laser.track import OK, track_frames
from gtrig.rig.models import BeamTiming
from gtrig.sim.config import LaserSimConfig, MotionSimConfig, SimConfig
from gtrig.sim.gtroom import VALIDATION_POSES, make_scene
from gtrig.sim.lasers import configure_scene, simulate_fixed_scans, with_scanner_stamp_sigma
from gtrig.sim.motion import RobotMotion, agile_path

SEED = 1
DURATION_S = 12.0


@pytest.fixture(scope="module", params=["sweep", "simultaneous"])
def simulated(request):
    """The simulated GT room's scans of an agile run (up to 1.5 m/s), the scanners firing as ``param``."""
    cfg = SimConfig(seed=SEED, laser=LaserSimConfig(beam_timing=request.param),
                    motion=MotionSimConfig(profile="agile", speed_mps=1.5))
    sc = configure_scene(make_scene(SEED), cfg)
    m = cfg.motion
    ts, xyth = agile_path(VALIDATION_POSES, m.speed_mps, m.accel_mps2, m.lat_accel_mps2, m.yaw_rate_max_radps,
                          duration_s=DURATION_S)
    mot = RobotMotion(ts, xyth, sc.floor)
    bgs, _ = simulate_fixed_scans(sc, None, np.array([[-10.0, -10.0 + cfg.background_s]]), cfg, SEED * 10 + 1)
    runs, _ = simulate_fixed_scans(sc, mot, np.array([[0.0, ts[-1]]]), cfg, SEED * 10 + 3)
    return request.param, with_scanner_stamp_sigma(sc.rig_true), mot, bgs, runs


def _track_and_check(simulated, declared: str):
    _, rig, mot, bgs, runs = simulated
    scs = tuple(s.model_copy(update={"beam_timing": BeamTiming(declared)}) for s in rig.laser_scanners)
    masks = [foreground_mask(runs[s.name].ranges_m, foreground_threshold(build_background(bgs[s.name].ranges_m, s)))
             for s in scs]
    fp = frame_points(scs, [runs[s.name].stamps_s for s in scs], [runs[s.name].ranges_m for s in scs], masks)
    model = HullModel.from_hull(rig.robot.hull)
    res = track_frames(fp, model)
    ok = res.status == OK
    z = res.xytheta[ok] - mot.planar(res.stamps_s[ok])
    z[:, 2] = wrap_angle(z[:, 2])
    nees_dof = float(np.mean(np.einsum("ni,nij,nj->n", z, np.linalg.inv(res.cov_xytheta[ok]), z))) / 3
    fits = check_beam_timing(fp, res.xytheta, ok, res.track_id, scs, model)
    return nees_dof, fits


def test_the_right_timing_fits_and_its_covariance_is_consistent(simulated):
    fired = simulated[0]
    nees_dof, fits = _track_and_check(simulated, fired)
    text, z, ok = timing_check(fits)
    assert ok is True, text
    assert z < 3
    # every scanner seen measures its slope to well under the distance between two timings
    assert all(f.measured and f.slope_sd < 0.5 for f in fits)
    assert 0.5 <= nees_dof <= 2.0


def test_a_wrong_timing_is_one_warning_naming_the_scanners(simulated):
    fired = simulated[0]
    declared = "simultaneous" if fired == "sweep" else "sweep"
    _, fits = _track_and_check(simulated, declared)
    text, z, ok = timing_check(fits)
    assert ok is False and z > 3
    wrong = [f for f in fits if f.fits_better]
    # most scanners are caught, each with the timing the scans were made with, and the line names them
    assert len(wrong) >= len(fits) - 1
    assert all(f.fits_better == fired for f in wrong)
    assert all(f.scanner in text for f in wrong) and f"'{fired}' fits" in text
