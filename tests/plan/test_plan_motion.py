"""On a path with time stamps the plan adds the cameras' time-stamp jitter times the robot's velocity to
GTvision's covariance: GTvision's errors on images taken off their stamps match it (RMS error over
predicted sigma within 0.7-1.4 in position and yaw), and the plan without the term is optimistic."""

from __future__ import annotations

import math

import numpy as np

from gtrig import geometry as geo
from gtrig.plan.grid import path_grid
from gtrig.plan.predict import PlanSettings, predict_plan
from gtrig.plan.vision import VisionPlanSettings
from gtrig.sim.gtroom import BAND_CENTRE, BAND_DIR_RAD, make_scene
from gtrig.vision.covariance import RigUncertainty, pose_error_xi
from gtrig.vision.estimate import VisionOptions, estimate_frame
from gtrig.vision.observations import VisionModel
from gtrig.vision.synthetic import synthetic_observations

RU = RigUncertainty(1e-6, 1e-8, 1e-6, 1e-8)  # a perfectly known rig: the jitter dominates
STAMP_SIGMA_S = 0.01


def test_stamp_jitter_on_a_moving_path():
    rig = make_scene(0).rig_true
    rig = rig.model_copy(update={"cameras": tuple(c.model_copy(update={"stamp_sigma_s": STAMP_SIGMA_S})
                                                  for c in rig.cameras)})
    # an arc along the band at 0.4 m/s turning at 0.5 rad/s, one image every 0.2 s
    t = np.arange(0.0, 12.0, 0.2)
    th = BAND_DIR_RAD + 0.5 * t
    c, s = math.cos(BAND_DIR_RAD), math.sin(BAND_DIR_RAD)
    u = -2.4 + 0.4 * t
    xy = BAND_CENTRE + np.column_stack([u * c, u * s]) + 0.3 * np.column_stack([np.cos(th), np.sin(th)])
    grid = path_grid(xy, th, t)
    settings = PlanSettings(vision=VisionPlanSettings(rig_uncertainty=RU))
    moving = predict_plan(rig, grid, settings)
    standing = predict_plan(rig, path_grid(xy, th), settings)
    model = VisionModel.from_rig(rig)
    opts = VisionOptions(rig_uncertainty=RU)
    rng = np.random.default_rng(2)
    err, keep = [], []
    for k in range(t.size):
        if moving.views[k].sum() == 0:
            continue
        dt = rng.normal(0.0, STAMP_SIGMA_S)  # the image is taken dt after its stamp
        v = grid.path_velocity[k]
        T_taken = geo.se2_to_T(*(np.r_[xy[k], th[k]] + v * dt))
        est = estimate_frame(model, synthetic_observations(rig, T_taken, 0.0, rng), opts)
        if not est.ok or est.T_world_robot is None:
            continue
        err.append(pose_error_xi(est.T_world_robot, geo.se2_to_T(xy[k, 0], xy[k, 1], th[k]))[[0, 1, 5]])
        keep.append(k)
    e, idx = np.array(err), np.array(keep)
    assert idx.size >= 30

    def ratio(cov: np.ndarray) -> tuple[float, float]:
        C = cov[idx]
        return (float(np.sqrt(np.mean(e[:, :2] ** 2) / np.mean((C[:, 0, 0] + C[:, 1, 1]) / 2))),
                float(np.sqrt(np.mean(e[:, 2] ** 2) / np.mean(C[:, 2, 2]))))

    pos, yaw = ratio(moving.cov["vision"])
    print("RMS error / predicted sigma with the jitter term (position, yaw):", pos, yaw,
          "without:", ratio(standing.cov["vision"]))
    assert 0.7 <= pos <= 1.4 and 0.7 <= yaw <= 1.4
    assert min(ratio(standing.cov["vision"])) > 2.0
    # the term is the jitter times the velocity, nothing else
    extra = moving.cov["vision"] - standing.cov["vision"]
    seen = moving.views.sum(axis=1) > 0
    v = grid.path_velocity
    assert np.allclose(extra[seen], STAMP_SIGMA_S**2 * v[seen, :, None] * v[seen, None, :], atol=1e-15)
