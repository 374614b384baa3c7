"""The high-accuracy detector on synthetic images with known corners."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from gtrig.markers.detect import MarkerDetector, detect_markers
from gtrig.markers.detect.camera import Undistorter
from gtrig.markers.synth import clutter_background, homography_from_pose, render
from gtrig.rig.models import MarkerFamily

SHAPE = (360, 480)


def _match(dets, truths):
    out = []
    for t in truths:
        m = [d for d in dets if d.id == t.marker_id]
        assert len(m) == 1, f"marker {t.marker_id}: {len(m)} detections"
        out.append((m[0], t))
    return out


@pytest.mark.parametrize(("family", "blur"), [(MarkerFamily.ARTOOLKITPLUS_SIMPLE, 1.0),
                                              (MarkerFamily.APRILTAG_36H11, 0.4)])
def test_corners_accurate_and_ordered_as_printed(family: MarkerFamily, blur: float) -> None:
    rng = np.random.default_rng(int(blur * 10) + len(family.value))
    bg = clutter_background(SHAPE, rng, n_shapes=20)
    markers = [
        (family, 7, homography_from_pose(110, (130, 130), 35, 20, 130)),
        (family, 200, homography_from_pose(70, (360, 250), 50, 100, -60)),
    ]
    img, truths = render(SHAPE, markers, blur_px=blur, noise=3.0, gradient=0.4, background=bg, rng=rng)
    dets = detect_markers(img, family)
    assert len(dets) == 2
    z2 = []
    for d, t in _match(dets, truths):
        err = d.corners_px - t.corners_px  # same order: as printed, despite the 130 deg roll
        assert np.sqrt(np.mean(np.sum(err**2, axis=1))) < 0.08
        assert abs(d.blur_px - np.hypot(blur, 0.3)) < 0.25
        for e, C in zip(err, d.corner_cov, strict=True):
            assert np.all(np.linalg.eigvalsh(C) > 0)
            z2.append(e @ np.linalg.solve(C, e))
    # the covariances are of the right size (chi-square with 2 dof has mean 2)
    assert 0.2 < np.mean(z2) < 12


def test_lens_distortion_is_modelled() -> None:
    K = np.array([[400.0, 0, 240], [0, 400, 180], [0, 0, 1]])
    dist = np.array([-0.3, 0.1, 0.0, 0.0, 0.0])
    fam = MarkerFamily.ARTOOLKITPLUS_SIMPLE
    rng = np.random.default_rng(3)
    # an undistorted scene, then warped into the raw (distorted) image
    und_img, truths = render(SHAPE, [(fam, 42, homography_from_pose(130, (360, 250), 20, 45, 10))],
                             blur_px=0.8, noise=0.0, rng=rng)
    u = Undistorter(K, dist, SHAPE)
    raw = cv2.remap(und_img, u.map_x, u.map_y, cv2.INTER_CUBIC, borderMode=cv2.BORDER_REPLICATE)
    raw = np.clip(raw + rng.normal(0, 2.0, raw.shape), 0, 255).astype(np.uint8)
    truth_raw = u.to_raw(truths[0].corners_px)
    with_cam = MarkerDetector(fam, K, dist).detect(raw)
    without = MarkerDetector(fam).detect(raw)
    assert [d.id for d in with_cam] == [42]
    e_cam = np.abs(with_cam[0].corners_px - truth_raw).max()
    assert e_cam < 0.12
    if without:  # a pinhole fit of curved edges is off by much more
        assert np.abs(without[0].corners_px - truth_raw).max() > 2 * e_cam


def test_small_markers_and_lighting() -> None:
    fam = MarkerFamily.APRILTAG_36H11
    rng = np.random.default_rng(5)
    centres = [(90 + 150 * (i % 3), 90 + 180 * (i // 3)) for i in range(6)]
    markers = [(fam, i, homography_from_pose(s, centres[i], 30, 60 * i, 17 * i))
               for i, s in enumerate([22, 32, 45, 55, 70, 80])]
    for gain in (60.0, 240.0):
        img, truths = render(SHAPE, markers, blur_px=0.7, noise=3.0, gain=gain, gradient=0.6, rng=rng,
                              ss=4)
        dets = MarkerDetector(fam).detect(img)
        assert sorted(d.id for d in dets) == list(range(6))


def test_no_detection_in_clutter() -> None:
    rng = np.random.default_rng(11)
    # (a 4x4 ArUco code can be matched exactly by a dark square holding one white rectangle)
    for fam in (MarkerFamily.ARTOOLKITPLUS_SIMPLE, MarkerFamily.APRILTAG_36H11):
        det = MarkerDetector(fam)
        for _ in range(2):
            bg = clutter_background(SHAPE, rng, n_shapes=80)
            img, _ = render(SHAPE, [], background=bg, blur_px=0.5, rng=rng, ss=2)
            assert det.detect(img) == []


def test_bad_image_rejected() -> None:
    from gtrig.errors import InputError

    with pytest.raises(InputError):
        detect_markers(np.zeros((10, 10), np.float32), MarkerFamily.APRILTAG_36H11)
