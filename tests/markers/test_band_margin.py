"""The edge band's white half ends with the paper: narrow quiet zones on dark and textured surrounds."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from gtrig.markers.detect import DetectorParams, MarkerDetector
from gtrig.markers.detect.edges import gather_band, white_extent
from gtrig.markers.synth import homography_from_pose, render
from gtrig.rig.models import MarkerFamily

FAM = MarkerFamily.ARTOOLKITPLUS_SIMPLE  # 12 cells: 100 px side, cells of 8.3 px (the band is not cell-bound)
SHAPE = (300, 400)
BLUR = 1.0
SIGMA = float(np.hypot(BLUR, np.sqrt(1 / 12)))  # the optics and the pixel's box


def _surround(kind: str, rng: np.random.Generator) -> np.ndarray:
    """Reflectance beyond the paper: near-black, or a mid-grey texture at 1, 4 and 16 px."""
    if kind == "dark":
        return np.full(SHAPE, 0.04)
    tex = np.zeros(SHAPE, np.float32)
    for s, a in ((1.0, 0.35), (4.0, 0.35), (16.0, 0.3)):
        g = cv2.GaussianBlur(rng.normal(0.0, 1.0, SHAPE).astype(np.float32), (0, 0), s)
        tex += a * g / float(g.std())
    return np.clip(0.45 + 0.08 * tex, 0.02, 0.98).astype(np.float64)


def _outward_bias(params: DetectorParams, margin_px: float, kind: str, n: int = 2) -> float:
    """Mean outward displacement (px) of the detected corners from the rendered ones, over ``n``
    images of a 100 px marker at sub-pixel positions, tilted and rolled."""
    out = []
    for k in range(n):
        rng = np.random.default_rng(100 * k + len(kind) + int(10 * margin_px))
        side = 100.0
        H = homography_from_pose(side, (200 + rng.uniform(-1, 1), 150 + rng.uniform(-1, 1)), rng.uniform(0, 30),
                                 rng.uniform(0, 180), rng.uniform(0, 90))
        img, truths = render(SHAPE, [(FAM, 5 + k, H)], blur_px=BLUR, noise=2.0, quiet_cells=margin_px / (side / 12),
                             background=_surround(kind, rng), rng=rng)
        dets = [d for d in MarkerDetector(FAM, params=params).detect(img) if d.id == 5 + k]
        assert len(dets) == 1
        t = truths[0].corners_px
        r = t - t.mean(axis=0)
        r /= np.linalg.norm(r, axis=1, keepdims=True)
        out.append(np.mean(np.sum((dets[0].corners_px - t) * r, axis=1)))
    return float(np.mean(out))


@pytest.mark.parametrize("kind", ["dark", "grey"])
@pytest.mark.parametrize("beyond", [1.5, 5.0])
def test_narrow_margin_corners_unbiased(kind: str, beyond: float) -> None:
    """A white margin 1.5 or 5 px beyond 3 sigma: the band of 5 px beyond 3 sigma would reach past it
    (+0.3 to +2.6 px outward without the measured end); with it the corners are within 0.02 px."""
    margin = 3.0 * SIGMA + beyond
    assert abs(_outward_bias(DetectorParams(), margin, kind)) < 0.02
    # the same images with the band ending only where the detector's widths put it: biased outward
    assert _outward_bias(DetectorParams(white_end=False), margin, kind) > 0.1


def test_white_extent_finds_the_paper_end() -> None:
    """On a straight edge rendered with a known margin the band's outer limit is 2.5 sigma inside the
    paper's end (within a pixel), and a wide margin keeps the whole band."""
    rng = np.random.default_rng(3)
    side = 100.0
    H = homography_from_pose(side, (200.3, 150.6), 0.0, 0.0, 7.0)
    lim = {}
    for margin in (6.0, 40.0):
        img, truths = render(SHAPE, [(FAM, 5, H)], blur_px=BLUR, noise=2.0, quiet_cells=margin / (side / 12),
                             background=np.full(SHAPE, 0.04), rng=rng)
        c = truths[0].corners_px
        p0, p1 = c, np.roll(c, -1, axis=0)
        w_in, w_out = np.full(4, 4.0), np.full(4, 12.0)
        s = gather_band(img, p0, p1, w_in, w_out, np.full(4, 10.0))
        lim[margin] = white_extent(s, p0, p1, np.full(4, SIGMA), w_in, w_out)
    assert np.all(np.abs(lim[6.0] - (6.0 - 2.5 * SIGMA)) < 1.0)
    assert np.all(lim[40.0] == 12.0)
