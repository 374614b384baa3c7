"""A rig missing one camera gets one suggested where the hole is."""

from __future__ import annotations

import numpy as np

from gtrig.plan.grid import area_grid
from gtrig.plan.maps import cell_maps
from gtrig.plan.predict import PlanSettings, predict_plan
from gtrig.plan.suggest import suggest_cameras
from gtrig.plan.vision import VisionPlanSettings
from gtrig.sim.gtroom import make_scene, room_walls
from gtrig.vision.covariance import RigUncertainty

# gtrig plan's defaults: a calibrated camera network and calibrated markers
SETTINGS = PlanSettings(vision=VisionPlanSettings(
    rig_uncertainty=RigUncertainty(0.0005, np.radians(0.01), 0.0003, np.radians(0.05))))


def test_missing_camera_is_suggested_where_the_hole_is():
    full = make_scene(0).rig_nominal
    grid = area_grid(room_walls()[:, 0], 0.3, 4)
    plan_full = predict_plan(full, grid, SETTINGS)
    missing = 1
    rig = full.model_copy(update={"cameras": tuple(c for i, c in enumerate(full.cameras) if i != missing)})
    plan = predict_plan(rig, grid, SETTINGS)
    covered_full = np.isfinite(cell_maps(plan_full).sigma_xy_m["vision"][1])
    covered = np.isfinite(cell_maps(plan).sigma_xy_m["vision"][1])
    hole = covered_full & ~covered  # median heading seen by vision with the camera, not without
    assert hole.sum() >= 10
    target = (0.003, np.radians(0.1))  # met where GTvision sees the robot, not by GTlaser alone
    [s] = suggest_cameras(rig, plan, 1, *target, SETTINGS, n_positions=12)
    assert s.share_after > s.share_before
    seen = np.isfinite(cell_maps(s.plan).sigma_xy_m["vision"][1])
    assert seen[hole].mean() > 0.5, seen[hole].mean()
    cam = s.plan.views[:, -1].reshape(grid.n_cells, -1).max(axis=1) > 0
    assert cam[hole].mean() > 0.5  # it is the suggested camera that fills the hole
