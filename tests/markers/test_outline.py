"""The second path read from outlines off the marker (issue 16, session 37): a 20 px tag whose
candidate outline lies 1-2 px off (a notched quiet-zone hole, a blob bulging into a neighbour) was read
about one time in four, because the reader's basin is about a pixel; the outline moved onto the
marker's outer edge (:func:`gtrig.markers.detect.outline.snap_to_border`) is read from there."""

from __future__ import annotations

import cv2
import numpy as np

from gtrig.markers.detect import MarkerDetector
from gtrig.markers.detect.blurred import BlurredParams, image_noise, read_blurred
from gtrig.markers.detect.outline import snap_to_border
from gtrig.markers.families import decode_batch
from gtrig.markers.synth import homography_from_pose, render, textured_background

SHAPE = (160, 200)
FAMILY = "apriltag_36h11"


def _scene(seed: int) -> tuple[np.ndarray, int, np.ndarray]:
    """A 20 px AprilTag at 0-50 deg tilt on a textured background, blur 0.5-1.4 px, Bayer mosaic and
    JPEG 80, grey (H, W) uint8, with its ID and true corners (4, 2) px."""
    rng = np.random.default_rng(seed)
    bg = textured_background(SHAPE, rng, light=bool(rng.random() < 0.5))
    mid = int(rng.integers(0, 587))
    H = homography_from_pose(20.0, (100, 80), rng.uniform(0, 50), rng.uniform(0, 360), rng.uniform(0, 360))
    img, truths = render(SHAPE, [(FAMILY, mid, H)], blur_px=float(rng.uniform(0.5, 1.4)), noise=3.0, gain=200.0,
                         quiet_cells=1.5, background=bg, rng=rng, ink=0.2, paper=0.82, paper_texture=0.04,
                         bayer=True, jpeg_quality=80)
    if img.ndim == 3:
        img = cv2.cvtColor(img, cv2.COLOR_BGR2GRAY)
    return img, mid, truths[0].corners_px


def _off(truth: np.ndarray, rng: np.random.Generator, rms_px: float) -> np.ndarray:
    """The true corners (4, 2) each moved at random by ``rms_px`` RMS (both coordinates)."""
    return truth + rng.normal(0.0, rms_px / np.sqrt(2.0), truth.shape)


def _corner_error(q: np.ndarray, truth: np.ndarray) -> float:
    return min(float(np.abs(np.roll(q, k, axis=0) - truth).max()) for k in range(4))


def test_snapped_outline_lies_on_the_edge() -> None:
    """From starts 1.5 px RMS off the true corners, the snapped outlines of 16 renders lie within 1 px
    of them in the median (largest corner error) and closer than their start for at least 12."""
    rng = np.random.default_rng(7)
    before, after = [], []
    for seed in range(16):
        img, _, truth = _scene(seed)
        start = _off(truth, rng, 1.5)
        snapped = snap_to_border(img, start, 8, 3.0)
        assert snapped is not None
        before.append(_corner_error(start, truth))
        after.append(_corner_error(snapped, truth))
    assert float(np.median(after)) < 1.0
    assert sum(a < b for a, b in zip(after, before, strict=True)) >= 12


def test_reader_reads_outlines_off_the_marker() -> None:
    """The second path's reader, given one outline 1.5 px RMS off each of 16 rendered tags: with the
    snapped start it reads at least 13 to their ID, at least 4 more than without it
    (``snap_reach_px=0``, the reader of DETECTOR_VERSION 12), and never a wrong ID."""
    det = MarkerDetector(FAMILY)
    codes, n, border = det._all_codes(), det.spec.cells, det.spec.border_cells
    rng = np.random.default_rng(11)
    right = {True: 0, False: 0}
    for seed in range(16):
        img, mid, truth = _scene(seed)
        start = _off(truth, rng, 1.5)
        for snap in (True, False):
            params = BlurredParams(snap_reach_px=3.0 if snap else 0.0)
            reads = read_blurred(img, start[None], codes, n, border, params, image_noise(img), alternatives=True)
            for r in reads:
                ids, _, _ = decode_batch(FAMILY, codes[r.code][None], 0)
                assert ids[0] == mid
                assert _corner_error(r.corners, truth) < 1.0
            right[snap] += len(reads)
    assert right[True] >= 13
    assert right[True] >= right[False] + 4
