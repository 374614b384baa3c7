"""The local-contrast candidates (issue 16, the harder set): a 20 px tag under Bayer demosaicing and
JPEG whose dark blob is broken by blur, or merged with a dark surface beside it, failed the blob tests
of every closure-ratio mask (solidity 0.43-0.83) and was missed until the seed boxes were also traced
in a mask of pixels darker than their neighbourhood's mean (``CandidateParams.local_windows``)."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from gtrig.markers.detect import DetectorParams, MarkerDetector
from gtrig.markers.synth import homography_from_pose, render

SHAPE = (160, 200)


def _scene(kind: str, seed: int) -> tuple[np.ndarray, int, np.ndarray]:
    """A 20 px AprilTag at 20-50 deg tilt, Bayer mosaic and JPEG 75, grey (H, W) uint8; with its ID and
    true corners (4, 2) px. ``merged``: a dark surface (reflectance 0.12) reaches the one-cell quiet zone
    from the left and from below; ``broken``: a mottled light background, blur 1.45 px, ink 0.3."""
    rng = np.random.default_rng(seed)
    yy, xx = np.mgrid[0:SHAPE[0], 0:SHAPE[1]]
    bg = np.full(SHAPE, 0.75)
    merged = kind == "merged"
    if merged:
        bg[(xx < 92) | (yy > 92)] = 0.12
    else:
        bg += 0.03 * rng.standard_normal(SHAPE)
    mid = int(rng.integers(0, 587))
    H = homography_from_pose(20.0, (100, 80), rng.uniform(20, 50), rng.uniform(0, 360), rng.uniform(0, 360))
    img, truths = render(SHAPE, [("apriltag_36h11", mid, H)], blur_px=1.2 if merged else 1.45,
                         noise=3.0 if merged else 4.0, gain=200.0, quiet_cells=1.0, background=bg, rng=rng,
                         ink=0.2 if merged else 0.3, paper=0.85, bayer=True, jpeg_quality=75)
    if img.ndim == 3:
        img = cv2.cvtColor(img, cv2.COLOR_BGR2GRAY)
    return img, mid, truths[0].corners_px


@pytest.mark.parametrize(("kind", "seed"), [("broken", 8), ("merged", 4), ("merged", 10)])
def test_low_solidity_tag_is_found(kind: str, seed: int) -> None:
    """Missed before the local-contrast candidates (blob solidity 0.83, 0.62, 0.43); found to 2 px."""
    img, mid, truth = _scene(kind, seed)
    out = MarkerDetector("apriltag_36h11", params=DetectorParams(threads=1)).detect(img)
    assert any(d.id == mid and np.abs(d.corners_px - truth).max() < 2.0 for d in out)


@pytest.mark.parametrize("kind", ["broken", "merged"])
def test_no_wrong_id(kind: str) -> None:
    """Twelve renders of each kind: whatever is found carries the true ID."""
    det = MarkerDetector("apriltag_36h11", params=DetectorParams(threads=1))
    for seed in range(12):
        img, mid, _ = _scene(kind, seed)
        assert all(d.id == mid for d in det.detect(img))
