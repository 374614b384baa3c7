"""GTvision's predicted covariance against the estimator's on synthetic corners, and its pieces."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from gtrig import geometry as geo
from gtrig.plan.visibility import camera_sight
from gtrig.plan.vision import VisionPlanSettings, camera_jacobian, marker_jacobian, predict_vision
from gtrig.sim.gtroom import VALIDATION_POSES, make_scene
from gtrig.vision.covariance import UNCALIBRATED_MARKERS, RigUncertainty
from gtrig.vision.estimate import VisionOptions, estimate_frame
from gtrig.vision.observations import MarkerView, VisionModel, stack_corners
from gtrig.vision.projection import camera_pose_jacobian, marker_pose_jacobian, project_pose
from gtrig.vision.synthetic import synthetic_observations, visible_views

CALIBRATED = RigUncertainty(0.0005, math.radians(0.01), 0.0003, math.radians(0.05))


@pytest.fixture(scope="module")
def rig():
    return make_scene(0).rig_true


@pytest.mark.parametrize("rig_u", [UNCALIBRATED_MARKERS, CALIBRATED], ids=["hand-measured", "calibrated"])
def test_predicted_sigma_agrees_with_the_estimator(rig, rig_u):
    poses = VALIDATION_POSES[::4]
    pred = predict_vision(rig, poses, VisionPlanSettings(rig_uncertainty=rig_u))
    model = VisionModel.from_rig(rig)
    rng = np.random.default_rng(3)
    ratios = []
    for k, (x, y, th) in enumerate(poses):
        obs = synthetic_observations(rig, geo.se2_to_T(x, y, th), 0.0, rng)
        est = estimate_frame(model, obs, VisionOptions(rig_uncertainty=rig_u))
        assert est.ok and est.cov_6x6 is not None
        i = [0, 1, 5]
        s_est = np.sqrt(np.diag(est.cov_6x6[np.ix_(i, i)]))
        s_pred = np.sqrt(np.diag(pred.cov_xytheta[k]))
        ratios.append(s_pred / s_est)
    r = np.array(ratios)
    assert np.all(np.abs(r - 1) < 0.2), r


def test_visibility_matches_the_synthetic_views(rig):
    rng = np.random.default_rng(0)
    poses = np.column_stack([rng.uniform(-3, 3, 60), rng.uniform(-2, 6, 60), rng.uniform(-np.pi, np.pi, 60)])
    poses = np.vstack([poses, VALIDATION_POSES])
    model = VisionModel.from_rig(rig)
    mids = [m.id for m in rig.robot.markers]
    corners = np.stack([model.corners_robot[m] for m in mids])
    sights = {c.name: camera_sight(model.cameras[c.name], corners, poses, rig.robot.hull) for c in rig.cameras}
    n_seen = 0
    for k, (x, y, th) in enumerate(poses):
        ref = {(c, m) for c, m, _ in visible_views(rig, geo.se2_to_T(x, y, th))}
        got = {(c, mids[j]) for c, s in sights.items() for j in np.flatnonzero(s.visible[k])}
        assert got == ref
        n_seen += len(ref)
    assert n_seen > 50


def test_marker_jacobian_is_the_estimators(rig):
    model = VisionModel.from_rig(rig)
    T = geo.se2_to_T(0.5, 2.0, 0.7)
    views = [MarkerView(c, m, uv, np.tile(np.eye(2) * 0.01, (4, 1, 1))) for c, m, uv in visible_views(rig, T)]
    sc = stack_corners(model, views)
    ref = marker_pose_jacobian(sc, T)
    _, _, J = project_pose(sc, T)
    ctr = np.concatenate([np.repeat(sc.p_robot[sc.view == v].mean(axis=0)[None], 4, axis=0)
                          for v in range(len(views))])
    got = marker_jacobian(J, np.broadcast_to(T[:3, :3], (sc.p_robot.shape[0], 3, 3)), sc.p_robot, ctr)
    assert np.allclose(got, ref, rtol=1e-9, atol=1e-6)


def test_camera_jacobian_is_the_estimators(rig):
    model = VisionModel.from_rig(rig)
    T = geo.se2_to_T(0.5, 2.0, 0.7)
    views = [MarkerView(c, m, uv, np.tile(np.eye(2) * 0.01, (4, 1, 1))) for c, m, uv in visible_views(rig, T)]
    assert len({v.camera for v in views}) >= 2
    sc = stack_corners(model, views)
    ref = camera_pose_jacobian(sc, T)
    _, _, J = project_pose(sc, T)
    p_world = sc.p_robot @ T[:3, :3].T + T[:3, 3]
    got = camera_jacobian(J, p_world, sc.cam_centre_w)
    assert np.allclose(got, ref, rtol=1e-9, atol=1e-6)


def test_free_running_cameras_make_each_pose_of_one_camera(rig):
    """With ``instants="per_camera"`` the predicted covariance of a pose is the mean over the cameras
    seeing it of GTvision's covariance from that camera's image alone; where two cameras see the
    robot it is wider than the one of both cameras together."""
    from dataclasses import replace

    poses = VALIDATION_POSES
    settings = VisionPlanSettings(rig_uncertainty=CALIBRATED, instants="per_camera")
    pred = predict_vision(rig, poses, settings)
    model = VisionModel.from_rig(rig)
    rng = np.random.default_rng(7)
    i = [0, 1, 5]
    ratios, wider = [], []
    for k, (x, y, th) in enumerate(poses):
        obs = synthetic_observations(rig, geo.se2_to_T(x, y, th), 0.0, rng)
        cams = obs.cameras_with_views()
        covs = []
        for c in cams:
            est = estimate_frame(model, replace(obs, views=tuple(v for v in obs.views if v.camera == c)),
                                 VisionOptions(rig_uncertainty=CALIBRATED))
            if est.ok and est.cov_6x6 is not None:
                covs.append(est.cov_6x6[np.ix_(i, i)])
        if len(covs) != len(cams) or not covs or pred.views[k].astype(bool).sum() != len(cams):
            continue  # an ambiguous single-marker view, or a view the plan's margins leave out
        mean = np.mean(covs, axis=0)
        ratios.append(np.sqrt(np.diag(pred.cov_of_a_pose[k]) / np.diag(mean)))
        if len(cams) >= 2:
            wider.append(np.sqrt(np.diag(pred.cov_of_a_pose[k])[:2] / np.diag(pred.cov_xytheta[k])[:2]))
    r = np.array(ratios)
    assert r.shape[0] >= 8 and np.all(np.abs(r - 1) < 0.2), r
    assert len(wider) >= 3 and np.all(np.array(wider) > 1.1), wider


def test_instants_per_camera_leave_fusion_as_it_is():
    """The plan with instants per camera: GTvision's covariance of a pose is the per-camera one, at
    least as wide as all cameras' together, and fusion's (which takes all cameras' information per
    second) is the same to the bit."""
    from dataclasses import replace

    from gtrig.plan.grid import area_grid
    from gtrig.plan.predict import PlanSettings, predict_plan
    from gtrig.sim.gtroom import room_walls

    rig = make_scene(0).rig_nominal
    grid = area_grid(room_walls()[:, 0], 0.4, 4)
    together = PlanSettings(vision=VisionPlanSettings(rig_uncertainty=CALIBRATED))
    free = replace(together, vision=replace(together.vision, instants="per_camera"))
    a, b = predict_plan(rig, grid, together), predict_plan(rig, grid, free)
    np.testing.assert_array_equal(a.cov["fused"], b.cov["fused"])
    np.testing.assert_array_equal(a.cov["vision"], b.vision_for_fusion)
    seen = np.isfinite(a.cov["vision"][:, 0, 0])
    assert seen.sum() > 50 and np.array_equal(seen, np.isfinite(b.cov["vision"][:, 0, 0]))
    va, vb = np.trace(a.cov["vision"][seen], axis1=1, axis2=2), np.trace(b.cov["vision"][seen], axis1=1, axis2=2)
    assert np.all(vb >= va * (1 - 1e-9))
    several = (a.views[seen] > 0).sum(axis=1) >= 2
    assert several.sum() > 10 and np.median(vb[several] / va[several]) > 1.3
    single = ~several
    np.testing.assert_allclose(vb[single], va[single], rtol=1e-9)


def test_sunlit_markers_predicted_as_the_estimator_states_them(rig):
    """Markers over the sunlit floor: the plan's sigma (corners of ``SUNLIT_OWN_PX`` each and an offset common
    to a marker's edges, in the information) is within 35 % of GTvision's stated covariance of such corners
    (its fit, which takes them as independent, plus the considered common error, which
    tests/vision/test_common_corners.py checks against the errors; the plan's information form is the fit
    that knows the common error, a little better across the line of sight); and its position sigma is well
    above the plan's for the same markers in the shade."""
    from gtrig.plan.vision import DETECTOR_SCATTER, SUNLIT_COMMON_PX, SUNLIT_OWN_PX
    from gtrig.vision.covariance import edge_pull_jacobian
    from gtrig.vision.observations import FrameObservations

    poses = VALIDATION_POSES[::4]
    sun = ((-20.0, -20.0), (20.0, -20.0), (20.0, 20.0), (-20.0, 20.0))
    base = VisionPlanSettings(corner_noise=DETECTOR_SCATTER, corner_floor_px=0.0, rig_uncertainty=CALIBRATED)
    lit = predict_vision(rig, poses, replace(base, sunlit_xy=sun))
    shade = predict_vision(rig, poses, base)
    model = VisionModel.from_rig(rig)
    opts = VisionOptions(rig_uncertainty=CALIBRATED, corner_floor_px=0.0, blur_pull=False)
    ratios, gain = [], []
    for k, (x, y, th) in enumerate(poses):
        views = []
        for cam, mid, uv in visible_views(rig, geo.se2_to_T(x, y, th)):
            c = -(edge_pull_jacobian(uv) @ np.full(4, SUNLIT_COMMON_PX)).reshape(4, 2)
            cov = SUNLIT_OWN_PX**2 * np.eye(2) + np.einsum("ci,cj->cij", c, c)
            views.append(MarkerView(cam, mid, uv, cov, corner_common=c))
        est = estimate_frame(model, FrameObservations(0.0, tuple(views)), opts)
        assert est.ok and est.cov_6x6 is not None
        i = [0, 1, 5]
        ratios.append(np.sqrt(np.diag(lit.cov_xytheta[k]) / np.diag(est.cov_6x6[np.ix_(i, i)])))
        gain.append(np.sqrt(np.trace(lit.cov_xytheta[k][:2, :2]) / np.trace(shade.cov_xytheta[k][:2, :2])))
    r = np.array(ratios)
    assert np.all((r > 0.65) & (r < 1.35)), r.round(2)
    assert np.median(gain) > 1.3, np.round(gain, 2)
