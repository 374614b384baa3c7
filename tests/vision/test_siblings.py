"""Markers cut by the image's edge predicted from the robot's other markers in the same image
(gtrig.vision.siblings), on the simulated room's rig."""

from __future__ import annotations

import numpy as np

from gtrig import geometry as geo
from gtrig.sim.gtroom import VALIDATION_POSES, make_scene
from gtrig.vision.observations import MarkerView, VisionModel
from gtrig.vision.siblings import cut_siblings, robot_in_camera
from gtrig.vision.track import inside_image


def _views(model: VisionModel, camera: str, T_world_robot: np.ndarray, rng: np.random.Generator | None = None,
           sigma_px: float = 0.0) -> tuple[list[MarkerView], dict[int, np.ndarray]]:
    """The markers whole in ``camera``'s image as views (corners with noise of ``sigma_px``), and the true
    corners of those cut by its edge (three corners inside)."""
    g = model.cameras[camera]
    whole, cut = [], {}
    for m, corners in sorted(model.corners_robot.items()):
        T_cam_marker = g.T_cam_world @ T_world_robot @ model.T_robot_marker[m]
        if T_cam_marker[:3, 2] @ T_cam_marker[:3, 3] >= 0:
            continue
        uv = geo.project_points(geo.transform_points(g.T_cam_world @ T_world_robot, corners), g.K, g.dist)
        if inside_image(uv, g.size):
            noisy = uv if rng is None else uv + rng.normal(0, sigma_px, uv.shape)
            whole.append(MarkerView(camera, m, noisy, np.tile(np.eye(2) * 0.01, (4, 1, 1))))
        elif inside_image(uv, g.size, at_least=3):
            cut[m] = uv
    return whole, cut


def test_a_cut_marker_is_placed_by_the_others() -> None:
    scene = make_scene(0)
    model = VisionModel.from_rig(scene.rig_true)
    x, y, th = VALIDATION_POSES[3]
    T = scene.T_world_robot(x + 0.25, y, th)
    views, cut = _views(model, "cam1", T)
    assert len(views) >= 3 and list(cut) == [6]
    got = cut_siblings(views, model.cameras["cam1"], model)
    assert [m for m, _ in got] == [6]
    np.testing.assert_allclose(got[0][1], cut[6], atol=1e-3)  # the fit is exact but for its tolerance
    # with corners measured to a tenth of a pixel, well within the edge fit's reach (a few pixels)
    noisy, _ = _views(model, "cam1", T, np.random.default_rng(0), 0.1)
    got = cut_siblings(noisy, model.cameras["cam1"], model)
    assert [m for m, _ in got] == [6] and np.abs(got[0][1] - cut[6]).max() < 0.5
    # one marker alone places it too
    x, y, th = VALIDATION_POSES[5]
    T = scene.T_world_robot(x - 1.0, y, th)
    views, cut = _views(model, "cam1", T, np.random.default_rng(1), 0.1)
    assert [v.marker_id for v in views] == [3] and list(cut) == [6]
    got = cut_siblings(views, model.cameras["cam1"], model)
    assert [m for m, _ in got] == [6] and np.abs(got[0][1] - cut[6]).max() < 1.5


def test_nothing_is_placed_from_views_that_disagree_with_the_rig() -> None:
    scene = make_scene(0)
    model = VisionModel.from_rig(scene.rig_true)
    x, y, th = VALIDATION_POSES[3]
    views, _ = _views(model, "cam1", scene.T_world_robot(x + 0.25, y, th))
    # two markers' IDs swapped: no pose of the rigid robot fits their corners
    a, b = views[0], views[1]
    swapped = [MarkerView(a.camera, b.marker_id, a.corners_px, a.corner_cov),
               MarkerView(b.camera, a.marker_id, b.corners_px, b.corner_cov)] + views[2:]
    assert robot_in_camera(swapped, model.cameras["cam1"], model) is None
    assert cut_siblings(swapped, model.cameras["cam1"], model) == []
    assert cut_siblings([], model.cameras["cam1"], model) == []
