"""The camera's tone curve (gtrig.markers.detect.tone): a marker rendered in light and stored through
sRGB's curve, as a phone stores it, is fitted in light with ``tone="srgb"``."""

from __future__ import annotations

import numpy as np

from gtrig.markers.detect import DetectorParams, MarkerDetector
from gtrig.markers.detect.tone import linear_to_srgb, srgb_to_linear, to_levels, to_light
from gtrig.markers.synth import homography_from_pose, render

FAMILY = "apriltag_36h11"


def test_round_trip_and_clip_bounds() -> None:
    v = np.arange(256, dtype=np.float64)
    assert np.allclose(linear_to_srgb(srgb_to_linear(v)), v, atol=1e-9)
    light = to_light(v, "srgb")
    # levels 1-254 stay inside the edge fits' clip bounds; 0 and 255 are the clipped ones
    assert light[0] == 0.0 and light[255] == 255.0 and light[1:255].min() > 0.5 and light[1:255].max() < 254.5
    assert np.allclose(to_levels(light[7:], "srgb"), v[7:], atol=1e-9)
    assert to_light(v, "linear") is v


def test_srgb_stored_marker_fits_better_in_light() -> None:
    """A blurred marker (sigma 2 px) stored through sRGB: the midpoint of the stored levels lies inside
    the black, so the corners fitted in stored levels are pulled in (0.3-0.4 px); fitted in light they
    are back on the truth."""
    shape = (260, 260)
    H = homography_from_pose(150, (130, 130), 20, 30, 10)
    stored, truths = render(shape, [(FAMILY, 7, H)], blur_px=2.0, noise=0.5, rng=np.random.default_rng(3), srgb=True)
    err = {}
    for tone in ("linear", "srgb"):
        dets = MarkerDetector(FAMILY, params=DetectorParams(tone=tone)).detect(stored)
        assert [d.id for d in dets] == [7]
        err[tone] = float(np.sqrt(np.mean(np.sum((dets[0].corners_px - truths[0].corners_px) ** 2, axis=1))))
    assert err["srgb"] < 0.1 < err["linear"], err
