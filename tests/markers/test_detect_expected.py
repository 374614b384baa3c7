"""Markers confirmed at expected corners (``MarkerDetector.detect_expected``): refined from a prediction a few
pixels off, and refused unless gtrig's cells read the expected ID in the expected orientation."""

from __future__ import annotations

import cv2
import numpy as np

from gtrig.markers.detect import MarkerDetector
from gtrig.markers.synth import clutter_background, homography_from_pose, render
from gtrig.rig.models import MarkerFamily
from gtrig.sim.cameras import motion_kernel

SHAPE = (360, 480)
FAM = MarkerFamily.ARTOOLKITPLUS_SIMPLE


def _scene(seed: int, smear_px: float = 0.0) -> tuple[np.ndarray, list]:  # type: ignore[type-arg]
    rng = np.random.default_rng(seed)
    bg = clutter_background(SHAPE, rng, n_shapes=20)
    markers = [(FAM, 7, homography_from_pose(90, (140, 170), 30, 20, 25)),
               (FAM, 200, homography_from_pose(70, (350, 220), 40, 100, -70))]
    img, truths = render(SHAPE, markers, blur_px=0.8, noise=0.0 if smear_px else 3.0, background=bg, rng=rng)
    if smear_px:
        k = motion_kernel(smear_px, 0.4)
        assert k is not None
        smeared = cv2.filter2D(img.astype(np.float32), -1, k, borderType=cv2.BORDER_REPLICATE)
        img = np.clip(np.rint(smeared + rng.normal(0, 3.0, img.shape)), 0, 255).astype(np.uint8)
    return img, truths


def test_a_prediction_off_by_pixels_is_refined_to_the_corners() -> None:
    img, truths = _scene(1)
    det = MarkerDetector(FAM)
    off = np.array([[1.6, -1.1], [1.2, -0.7], [1.9, -1.4], [1.4, -0.9]])
    quads = np.array([t.corners_px + off for t in truths])
    got = det.detect_expected(img, quads, np.array([t.marker_id for t in truths]))
    assert [d.id for d in got] == [t.marker_id for t in truths]
    for d, t in zip(got, truths, strict=True):
        err = d.corners_px - t.corners_px  # ordered as printed
        assert np.sqrt(np.mean(np.sum(err**2, axis=1))) < 0.08
        assert np.all(np.isfinite(d.blur_px)) and np.all(np.linalg.eigvalsh(d.corner_cov) > 0)
    # the whole-image detector agrees with the confirmed corners
    whole = {d.id: d for d in det.detect(img)}
    for d in got:
        assert np.abs(whole[d.id].corners_px - d.corners_px).max() < 0.05


def test_a_motion_blurred_marker_is_confirmed_at_its_prediction() -> None:
    img, truths = _scene(2, smear_px=8.0)
    det = MarkerDetector(FAM)
    assert det.detect(img) == []  # an 8 px smear: the peers give no candidate
    got = det.detect_expected(img, np.array([t.corners_px + 1.5 for t in truths]), np.array([7, 200]))
    assert [d.id for d in got] == [7, 200]
    for d, t in zip(got, truths, strict=True):
        # the smear is not the edge model's Gaussian: corners within 0.6 px (tests/markers/test_detect.py)
        assert np.abs(d.corners_px - t.corners_px).max() < 0.6


def test_wrong_ids_orientations_and_empty_places_are_refused() -> None:
    img, truths = _scene(3)
    det = MarkerDetector(FAM)
    t = truths[0]
    # another ID expected at a marker's place: its cells read 7, never 8 or 200
    assert det.detect_expected(img, np.array([t.corners_px, t.corners_px]), np.array([8, 200])) == []
    # the right ID with the corners rolled by one (the marker expected turned a quarter): refused
    assert det.detect_expected(img, np.roll(t.corners_px, 1, axis=0)[None], np.array([7])) == []
    # a place without a marker (the clutter around it)
    empty = t.corners_px + np.array([0.0, 150.0])
    assert det.detect_expected(img, empty[None], np.array([7])) == []
    # a prediction too far off for the edge fit's start
    assert det.detect_expected(img, (t.corners_px + 12.0)[None], np.array([7])) == []
