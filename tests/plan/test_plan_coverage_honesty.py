"""The plan's coverage per camera against the images in which the marker detector finds a marker: the
robot standing at random poses around one camera's view (half of them near its edges), rendered by the
simulator from the true rig and searched with the detector GTvision uses; the plan, made from the
operator's nominal rig (poses taped to 3 cm and 1 deg), predicts the share of images showing a marker
within 5 points, and agrees image by image on nearly all of them."""

from __future__ import annotations

import numpy as np

from gtrig import geometry as geo
from gtrig.markers.detect import detect_markers
from gtrig.plan.honesty import coverage_check
from gtrig.plan.vision import predict_vision
from gtrig.sim.cameras import make_view, render_robot_frame
from gtrig.sim.config import CameraSimConfig
from gtrig.sim.gtroom import make_scene
from gtrig.sim.motion import RobotMotion
from gtrig.sim.render import PinholeCamera

N_IMAGES = 60


def _poses_around_the_view(scene, cam_index: int, rng: np.random.Generator) -> np.ndarray:
    """Poses (N, 3) on the floor within 2.5 m of where the camera looks, random headings."""
    T = scene.rig_true.cameras[cam_index].T_world_cam.matrix()
    aim = T[:2, 3] + (-T[2, 3] / T[2, 2]) * T[:2, 2]
    r = 2.5 * np.sqrt(rng.uniform(0, 1, N_IMAGES))
    a = rng.uniform(-np.pi, np.pi, N_IMAGES)
    return np.column_stack([aim[0] + r * np.cos(a), aim[1] + r * np.sin(a), rng.uniform(-np.pi, np.pi, N_IMAGES)])


def test_predicted_coverage_matches_the_detected_share():
    scene = make_scene(0)
    ci = 1
    cam_true, cam_nominal = scene.rig_true.cameras[ci], scene.rig_nominal.cameras[ci]
    rng = np.random.default_rng(4)
    poses = _poses_around_the_view(scene, ci, rng)
    ccfg = CameraSimConfig(supersample=2)
    view = make_view(scene, PinholeCamera.from_rig(cam_true), cam_true.T_world_cam.matrix(), ccfg)
    K, dist = np.asarray(cam_true.camera_matrix), np.asarray(cam_true.dist_coeffs)
    family = scene.rig_true.robot.markers[0].family
    found = np.zeros(N_IMAGES, dtype=bool)
    for k, p in enumerate(poses):
        standing = RobotMotion(np.array([0.0, 1.0]), np.array([p, p]), scene.floor)
        img = render_robot_frame(scene, view, standing, 0.5, ccfg, np.random.default_rng(k))
        found[k] = len(detect_markers(img, family, K, dist)) > 0
    plan = scene.rig_nominal.model_copy(update={"cameras": (cam_nominal,)})
    seen = predict_vision(plan, np.array([geo.T_to_se2(scene.T_world_robot(*p)) for p in poses])).views[:, 0] > 0
    check = coverage_check(cam_nominal.name, seen, found)
    print(check)
    assert 0.2 < check.localized_pct / 100 < 0.8  # the test needs images with and without a marker
    assert abs(check.difference_points) <= 5.0
    assert check.agree_pct >= 90.0
