"""GTvision's detector reads each camera's frames in the tone the rig gives it, or, with the default
``tone: auto``, in the one its files declare (gtrig.io.imagetone): a phone-like camera's sRGB-stored
blurred marker is fitted in light and lands on the truth; read as linear it would shrink."""

from __future__ import annotations

import numpy as np

from gtrig.markers.synth import homography_from_pose, render
from gtrig.sim.gtroom import make_scene
from gtrig.vision.detect import make_detector
from gtrig.vision.observations import VisionModel


def _rms(views, truth) -> float:
    (v,) = views
    return float(np.sqrt(np.mean(np.sum((v.corners_px - truth.corners_px) ** 2, axis=1))))


def test_tone_from_the_file_unless_the_rig_says() -> None:
    rig = make_scene(0).rig_true
    mid, fam = rig.robot.markers[0].id, rig.robot.markers[0].family
    H = homography_from_pose(150, (500, 380), 20, 30, 10)
    img, (truth,) = render((768, 1024), [(fam, mid, H)], blur_px=2.0, noise=0.5, rng=np.random.default_rng(5),
                           srgb=True)
    # a camera without lens distortion, so that the rendered corners are its raw pixels
    cam0 = rig.cameras[0].model_copy(update={"dist_coeffs": (0.0,) * 5})
    auto = rig.model_copy(update={"cameras": (cam0, *rig.cameras[1:])})
    cam = VisionModel.from_rig(auto).cameras[cam0.name]
    det = make_detector(auto, "gtrig")
    in_light, in_levels = _rms(det(img, cam, "srgb"), truth), _rms(det(img, cam, "linear"), truth)
    assert in_light < 0.15 < in_levels, (in_light, in_levels)
    # the rig's word wins over the file's
    fixed = auto.model_copy(update={"cameras": (cam0.model_copy(update={"tone": "srgb"}), *rig.cameras[1:])})
    assert _rms(make_detector(fixed, "gtrig")(img, cam, "linear"), truth) == in_light
