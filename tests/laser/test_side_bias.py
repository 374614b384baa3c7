"""The hull sides' range bias (dark and light fabric) is estimated over the sequence: the
estimate matches the simulator's bias, and the poses lose the error it caused."""

from __future__ import annotations

import numpy as np
import pytest

from gtrig.geometry import wrap_angle
from gtrig.laser.fuse import frame_points
from gtrig.laser.hull_icp import HullModel
from gtrig.laser.side_bias import estimate_side_bias
from gtrig.laser.track import OK, TrackSettings, track_frames
from gtrig.sim.config import LaserSimConfig, MotionSimConfig, SimConfig

from .conftest import agile_fixed_scans

FABRICS = (0.1, 0.9, 0.1, 0.9)  # dark rear and front, light sides
BIAS_M = 0.03  # black to white: glossy or very dark cloth


@pytest.fixture(scope="module")
def tracked():
    cfg = SimConfig(seed=3, laser=LaserSimConfig(gown_reflectivity=FABRICS, reflectivity_bias_m=BIAS_M,
                                                 clock_offset_sigma_s=0.0),
                    motion=MotionSimConfig(profile="agile", speed_mps=1.0))
    sc, mot, runs, masks = agile_fixed_scans(cfg, 3, (31, 33))
    scs = sc.rig_true.laser_scanners
    fp = frame_points(scs, [runs[s.name].stamps_s for s in scs], [runs[s.name].ranges_m for s in scs], masks)
    model = HullModel.from_hull(sc.rig_true.robot.hull)
    out = {}
    for estimate in (False, True):
        res = track_frames(fp, model, TrackSettings(estimate_side_bias=estimate))
        tru = mot.planar(res.stamps_s)
        ok = res.status == OK
        z = res.xytheta[ok] - tru[ok]
        z[:, 2] = wrap_angle(z[:, 2])
        nees = np.einsum("ni,nij,nj->n", z, np.linalg.inv(res.cov_xytheta[ok]), z).mean() / 3
        out[estimate] = (res, 1000 * np.hypot(*z[:, :2].T).mean(), np.degrees(np.abs(z[:, 2])).mean(), nees)
    return out


def test_side_bias_estimated(tracked):
    res, pos_mm, yaw_deg, nees = tracked[True]
    truth = BIAS_M * (0.5 - np.asarray(FABRICS))  # the simulator's sensor model: dark ranges long
    est, sd = res.side_bias.bias_m, np.sqrt(np.diag(res.side_bias.cov))
    print(f"bias {np.round(1000 * est, 1)} mm (truth {np.round(1000 * truth, 1)}, std {np.round(1000 * sd, 2)}); "
          f"{pos_mm:.2f} mm, {yaw_deg:.3f} deg, NEES/dof {nees:.2f}; without: {tracked[False][1]:.2f} mm, "
          f"{tracked[False][2]:.3f} deg, NEES/dof {tracked[False][3]:.2f}")
    # within 2.5 mm of a 10-12 mm bias, and within 4 sigma of its own covariance
    assert np.all(np.abs(est - truth) < 0.0025)
    assert np.all(np.abs(est - truth) < 4 * sd + 0.0005)


def test_side_bias_removes_its_error(tracked):
    _, pos0, yaw0, nees0 = tracked[False]
    _, pos1, yaw1, nees1 = tracked[True]
    assert pos1 < 0.6 * pos0 and pos1 < 2.0
    assert yaw1 < yaw0
    assert nees0 > 2.0 and 0.5 <= nees1 <= 2.0


def test_no_data_keeps_the_prior():
    prior = np.diag([1e-6] * 4)
    sb = estimate_side_bias(np.zeros((0, 4, 4)), np.zeros((0, 4)), np.zeros(0), prior)
    assert np.all(sb.bias_m == 0) and np.allclose(sb.cov, prior)
