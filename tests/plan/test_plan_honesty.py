"""The plan's GTvision sigma against GTvision's errors on simulated corners of a rig whose cameras and
markers are off their nominal poses by the stated sigmas, the robot on a floor as uneven as GTvision's
floor prior says: per region of the floor (the camera that sees
the robot), the RMS error over the predicted sigma lies within 0.7-1.4."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from gtrig import geometry as geo
from gtrig.plan.vision import CALIBRATED_RIG, DETECTOR_SCATTER, VisionPlanSettings, after_calibration, predict_vision
from gtrig.rig.models import Pose, Rig
from gtrig.sim.gtroom import BAND_CENTRE, BAND_DIR_RAD, make_scene
from gtrig.vision.covariance import RigUncertainty, pose_error_xi
from gtrig.vision.estimate import VisionOptions, estimate_frame
from gtrig.vision.observations import VisionModel
from gtrig.vision.synthetic import CornerNoise, synthetic_observations

RU = RigUncertainty(0.0005, math.radians(0.01), 0.0003, math.radians(0.05))


def _moved(T: np.ndarray, dt: np.ndarray, dphi: np.ndarray) -> Pose:
    out = T.copy()
    out[:3, :3] = Rotation.from_rotvec(dphi).as_matrix() @ T[:3, :3]
    out[:3, 3] += dt
    return Pose.from_matrix(out)


def _drawn_rig(rig: Rig, rng: np.random.Generator, ru: RigUncertainty = RU) -> Rig:
    """The rig with every camera (world axes) and marker (robot axes, about its centre) moved by ``ru``."""
    cams = tuple(c.model_copy(update={"T_world_cam": _moved(
        c.T_world_cam.matrix(), rng.normal(0, ru.camera_xyz_m, 3), rng.normal(0, ru.camera_rot_rad, 3))})
        for c in rig.cameras)
    marks = tuple(m.model_copy(update={"T_robot_marker": _moved(
        m.T_robot_marker.matrix(), rng.normal(0, ru.marker_xyz_m, 3), rng.normal(0, ru.marker_rot_rad, 3))})
        for m in rig.robot.markers)
    return rig.model_copy(update={"cameras": cams, "robot": rig.robot.model_copy(update={"markers": marks})})


# the plan's default noise models; and a calibrated run's (the detector's scatter, the calibration's reach),
# whose prediction leaves GTvision's corner floor out: the floor evens the corners' weights, it does not
# add to their errors
CASES = {"stated": (RU, CornerNoise(), VisionPlanSettings(rig_uncertainty=RU)),
         "after calibration": (CALIBRATED_RIG, DETECTOR_SCATTER, after_calibration())}


@pytest.mark.parametrize("case", list(CASES))
def test_rms_error_over_predicted_sigma_per_region(case):
    ru, noise, settings = CASES[case]
    rig = make_scene(0).rig_true
    rng = np.random.default_rng(11)
    # poses along the band of the cameras, each camera's stretch a region
    u = rng.uniform(-3.4, 3.4, 120)
    v = rng.uniform(-0.8, 0.8, u.size)
    c, s = math.cos(BAND_DIR_RAD), math.sin(BAND_DIR_RAD)
    xy = BAND_CENTRE + np.column_stack([u * c - v * s, u * s + v * c])
    poses = np.column_stack([xy, rng.uniform(-np.pi, np.pi, u.size)])
    pred = predict_vision(rig, poses, settings)
    model = VisionModel.from_rig(rig)
    opts = VisionOptions(rig_uncertainty=ru)
    err, sig, region = [], [], []
    for k, p in enumerate(poses):
        if pred.views[k].sum() == 0:
            continue
        # the true robot stands on an uneven floor as the floor prior says (3 mm, 0.3 deg)
        T = geo.se2_to_T(*p) @ geo.T_from_xyz_rpy([0, 0, rng.normal(0, 0.003)],
                                                 [*rng.normal(0, math.radians(0.3), 2), 0.0])
        est = estimate_frame(model, synthetic_observations(_drawn_rig(rig, rng, ru), T, 0.0, rng, noise), opts)
        if not est.ok or est.T_world_robot is None:
            continue
        e = pose_error_xi(est.T_world_robot, T)
        err.append(e[[0, 1, 5]])
        sig.append(np.sqrt(np.diag(pred.cov_xytheta[k])))
        region.append(int(np.argmax(pred.views[k])))
    err_a, sig_a, reg = np.array(err), np.array(sig), np.array(region)
    assert err_a.shape[0] >= 80
    ratios = []
    for r in np.unique(reg):
        m = reg == r
        if m.sum() < 12:
            continue
        pos = np.sqrt(np.mean(err_a[m, :2] ** 2)) / np.sqrt(np.mean(sig_a[m, :2] ** 2))
        yaw = np.sqrt(np.mean(err_a[m, 2] ** 2)) / np.sqrt(np.mean(sig_a[m, 2] ** 2))
        ratios.append((r, int(m.sum()), pos, yaw))
        assert 0.7 <= pos <= 1.4 and 0.7 <= yaw <= 1.4, (r, m.sum(), pos, yaw)
    print("region (camera), poses, RMS error / predicted sigma: position, yaw:", ratios)
    assert len(ratios) >= 3


def test_extreme_poses_are_the_errors_the_covariance_does_not_explain():
    from gtrig.plan.honesty import extreme_poses, nees, region_ratios

    rng = np.random.default_rng(5)
    k = 900
    # per-pose covariances: mm in position, hundredths of a degree in yaw, correlated
    A = rng.normal(size=(k, 3, 3)) * np.array([1e-3, 1e-3, 3e-4])[:, None]
    cov = A @ A.transpose(0, 2, 1) + np.diag([1e-7, 1e-7, 1e-8])
    err = np.linalg.cholesky(cov) @ rng.normal(size=(k, 3, 1))
    err = err[:, :, 0]
    n = nees(err, cov)
    assert 2.7 < np.mean(n) < 3.3  # chi-square, 3 degrees of freedom
    region = np.arange(k) % 3
    bad = rng.choice(k, 18, replace=False)
    err[bad, :2] += rng.choice([-1, 1], (18, 2)) * 0.02  # 20 mm: wrong poses
    flagged = extreme_poses(err, cov)
    assert set(bad) <= set(np.flatnonzero(flagged))
    assert flagged.sum() <= bad.size + 5
    with_bad = region_ratios(err, cov, region)
    without = region_ratios(err, cov, region, keep=~flagged)
    assert all(r.position > 1.4 for r in with_bad)
    assert all(0.85 < r.position < 1.15 and 0.85 < r.yaw < 1.15 for r in without), without
    assert sum(r.poses for r in without) == k - int(flagged.sum())
