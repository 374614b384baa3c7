"""A rig missing one camera or one fixed scanner gets one suggested where the hole is, and the search's
additive scores are those of a full plan of the rig with the suggested sensor."""

from __future__ import annotations

import numpy as np

from gtrig.plan.grid import area_grid
from gtrig.plan.maps import cell_maps, summarize_target
from gtrig.plan.predict import PlanSettings, predict_plan
from gtrig.plan.suggest import suggest_cameras, suggest_sensors
from gtrig.sim.gtroom import make_scene, room_walls

# gtrig plan's defaults: a calibrated run
SETTINGS = PlanSettings()


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
    _assert_is_a_full_plan(s, grid, target)


def _assert_is_a_full_plan(s, grid, target):
    """The suggestion's plan and score equal those of the rig with the sensor, planned from scratch."""
    ref = predict_plan(s.rig, grid, SETTINGS)
    for src in ("vision", "laser", "fused"):
        a, b = s.plan.cov[src], ref.cov[src]
        assert np.array_equal(np.isfinite(a), np.isfinite(b)), src
        ok = np.isfinite(b)
        assert np.allclose(a[ok], b[ok], rtol=1e-6, atol=1e-15), src
    assert s.share_after == summarize_target(ref, *target).share_worst


def test_missing_scanner_is_suggested_where_the_hole_is():
    full = make_scene(0).rig_nominal
    grid = area_grid(room_walls()[:, 0], 0.3, 4)
    target = (0.0007, np.radians(1.0))  # fused GTlaser alone: met by 4 scanners on half the room, by 3 on less
    lasers_only = full.model_copy(update={"cameras": ()})
    share_full = summarize_target(predict_plan(lasers_only, grid, SETTINGS), *target).share_worst
    rig = lasers_only.model_copy(update={"laser_scanners": full.laser_scanners[1:]})
    plan = predict_plan(rig, grid, SETTINGS)
    [s] = suggest_sensors(rig, plan, 0, 1, *target, SETTINGS, n_positions=12)
    assert s.kind == "scanner" and s.share_before < share_full - 0.2
    assert s.share_after > share_full - 0.05, (s.share_before, s.share_after, share_full)
    removed = np.array(full.laser_scanners[0].T_world_scanner.xyz[:2])
    assert np.linalg.norm(np.array(s.position_m[:2]) - removed) < 1.5  # near the corner it was missing from
    assert s.plan.beams[:, -1].sum() > 0 and s.plan.scanner_names[-1] == s.sensor.name
    _assert_is_a_full_plan(s, grid, target)


def test_workers_score_the_candidates_as_one_process():
    full = make_scene(0).rig_nominal
    rig = full.model_copy(update={"cameras": full.cameras[1:], "laser_scanners": full.laser_scanners[1:]})
    settings = PlanSettings(vision=SETTINGS.vision, chunk_poses=16)  # small chunks: the cells go to the workers
    grid = area_grid(room_walls()[:, 0], 0.5, 2)
    plan = predict_plan(rig, grid, settings)
    target = (0.0005, np.radians(1.0))
    one = suggest_sensors(rig, plan, 1, 1, *target, settings, n_positions=4)
    two = suggest_sensors(rig, plan, 1, 1, *target, settings, n_positions=4, workers=2)
    assert [(s.kind, s.position_m, s.share_after) for s in one] == [(s.kind, s.position_m, s.share_after) for s in two]
    assert one[-1].share_after > one[0].share_before
