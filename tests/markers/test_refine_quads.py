"""The compiled edge refinement (:func:`gtrig.markers.detect.edges.refine_quads`) against the same chain of
the public step functions called in turn (band, white end, trim, context, fits, corners:
:func:`~gtrig.markers.detect.edges.refine_quads_stepwise`), on renders."""

from __future__ import annotations

import numpy as np
import pytest

from gtrig.markers.detect import _edge_kernels
from gtrig.markers.detect.camera import Undistorter
from gtrig.markers.detect.edges import RefineParams, refine_quads, refine_quads_stepwise
from gtrig.markers.detect.tone import to_light
from gtrig.markers.families import family_spec, marker_cells
from gtrig.markers.synth import clutter_background, homography_from_pose, render
from gtrig.rig.models import MarkerFamily

FAMILY = MarkerFamily.APRILTAG_36H11


def _scene(seed: int, side: float, blur: float, gain: float = 230.0, undist: Undistorter | None = None
           ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """A render of three markers: image, start quads (true corners moved by up to 1 px, fit
    coordinates), white cells (Q, n, n) and the true corners (Q, 4, 2, fit coordinates)."""
    rng = np.random.default_rng(seed)
    markers = []
    for k, c in enumerate([(220, 250), (520, 480), (800, 260)]):
        H = homography_from_pose(side, c, 30.0 * k, rng.uniform(0, 360), rng.uniform(0, 360))
        markers.append((FAMILY, int(rng.integers(0, 587)), H))
    bg = clutter_background((768, 1024), rng, n_shapes=30)
    img, truths = render((768, 1024), markers, blur_px=blur, noise=3.0, gain=gain, background=bg, rng=rng)
    true = np.array([t.corners_px for t in truths], np.float64)
    if undist is not None:
        true = undist.to_undistorted(true.reshape(-1, 2)).reshape(-1, 4, 2)
    quads = true + rng.uniform(-1.0, 1.0, true.shape)
    white = np.array([marker_cells(FAMILY, t.marker_id) for t in truths], np.float64)
    return img, quads, white, true


@pytest.mark.parametrize(("seed", "side", "blur", "gain"), [(0, 24.0, 0.5, 230.0), (1, 60.0, 1.0, 230.0),
                                                            (2, 110.0, 0.0, 230.0), (3, 45.0, 2.0, 70.0),
                                                            (4, 40.0, 0.8, 400.0)])
def test_compiled_refinement_is_the_step_functions_chain(seed: int, side: float, blur: float, gain: float) -> None:
    """Corners within 1e-6 px and the fits' blur, levels, covariances and flags those of the step
    functions called in turn, sharp, blurred, dim and over-exposed (clipped) markers alike; and the
    corners near the truth where the render is not clipped."""
    img, quads, white, true = _scene(seed, side, blur, gain)
    bc = family_spec(FAMILY).border_cells
    prm = RefineParams()
    ref, c_ref, cov_ref = refine_quads_stepwise(img, quads, white, bc, prm)
    fit, corners, cov = refine_quads(img, quads, white, bc, prm)
    assert np.abs(corners - c_ref).max() < 1e-6
    assert np.allclose(cov, cov_ref, rtol=1e-6, atol=1e-12)
    for name in ("sigma", "a", "b", "rms"):
        assert np.allclose(getattr(fit, name), getattr(ref, name), rtol=1e-6, atol=1e-6), name
    assert np.array_equal(fit.ok, ref.ok) and np.array_equal(fit.n_px, ref.n_px)
    if gain < 255:  # (clipped renders: the agreement only)
        assert np.sqrt(np.mean(np.sum((corners - true) ** 2, axis=2))) < (0.15 if blur <= 1.0 else 0.3)


def test_compiled_refinement_with_a_lens_model_tone_and_two_threads() -> None:
    """The same with undistorted coordinates (a lens of the simulated room's strength), sRGB-stored
    levels, no white-end search and two threads."""
    K = np.array([[700.0, 0, 511.5], [0, 700.0, 383.5], [0, 0, 1]])
    und = Undistorter(K, np.array([-0.12, 0.1, 1e-4, -1e-4, 0.0]), (768, 1024))
    img, quads, white, _true = _scene(5, 50.0, 0.7, undist=und)
    bc = family_spec(FAMILY).border_cells
    for prm, tone in ((RefineParams(), "srgb"), (RefineParams(white_end=False, margin_cells=1.0), "linear")):
        light = to_light(np.arange(256, dtype=np.float64), tone)  # type: ignore[arg-type]
        _ref, c_ref, _ = refine_quads_stepwise(img, quads, white, bc, prm, und, light if tone != "linear" else None)
        _fit, corners, _ = refine_quads(img, quads, white, bc, prm, und, light, threads=2)
        assert np.abs(corners - c_ref).max() < 1e-6


@pytest.mark.parametrize(("seed", "side", "blur"), [(6, 22.0, 1.0), (7, 60.0, 0.5), (8, 35.0, 2.0)])
def test_settled_quads_and_a_sparse_first_pass_keep_the_corners(seed: int, side: float, blur: float) -> None:
    """A quad stopped once a pass moved its corners less than ``settle_px`` keeps them within that of
    where the remaining pass puts them, with covariances of the same size; a first pass on fewer columns
    (it only gives the start) leaves the corners as near the truth as one on every column."""
    img, quads, white, true = _scene(seed, side, blur)
    bc = family_spec(FAMILY).border_cells
    _fit, fast, cov = refine_quads(img, quads, white, bc, RefineParams())
    _fit, every_pass, cov_every = refine_quads(img, quads, white, bc, RefineParams(settle_px=0.0))
    _fit, dense_first, _cov = refine_quads(img, quads, white, bc, RefineParams(first_columns=0))
    assert np.abs(fast - every_pass).max() < 0.1
    np.testing.assert_allclose(np.sqrt(np.trace(cov, axis1=2, axis2=3)),
                               np.sqrt(np.trace(cov_every, axis1=2, axis2=3)), rtol=0.5)
    rms_fast, rms_dense = (float(np.sqrt(np.mean(np.sum((c - true) ** 2, axis=2)))) for c in (fast, dense_first))
    assert rms_fast < 1.25 * rms_dense + 0.01


def test_one_compiled_call_per_share_without_the_white_end_and_with_stored_tone() -> None:
    """Without a lens model every pass of a share of the quads runs in one compiled call: one thread (one
    share) and two (the quads shared between them) give the same results to the last bit, and those of the
    step functions to rounding, with a known margin, no white-end search and sRGB-stored levels; a quad
    refined alone gets the results it gets among the others (the white end's bins are its own)."""
    img, quads, white, true = _scene(9, 30.0, 1.0)
    bc = family_spec(FAMILY).border_cells
    light = to_light(np.arange(256, dtype=np.float64), "srgb")
    for prm in (RefineParams(white_end=False, margin_cells=1.0), RefineParams(passes=2, max_columns=0)):
        _ref, c_ref, cov_ref = refine_quads_stepwise(img, quads, white, bc, prm, None, light)
        _fit, one, cov_one = refine_quads(img, quads, white, bc, prm, None, light, threads=1)
        _fit, split, cov_split = refine_quads(img, quads, white, bc, prm, None, light, threads=2)
        assert np.abs(one - c_ref).max() < 1e-6
        assert np.array_equal(one, split) and np.array_equal(cov_one, cov_split)
        for q in range(len(quads)):
            _fit, alone, cov_alone = refine_quads(img, quads[q:q + 1], white[q:q + 1], bc, prm, None, light)
            assert np.array_equal(alone[0], one[q]) and np.array_equal(cov_alone[0], cov_one[q])
        assert np.abs(one - true).max() < 1.0  # (the stored tone taken back: the corners found, not lost)


def test_band_limits_follow_their_formulas() -> None:
    """The compiled band limits are the documented formulas, first pass and next, with and without a known
    margin and the white-end search, NaN blurs kept NaN."""
    from gtrig.markers.detect.edges import band_limits

    rng = np.random.default_rng(3)
    sigma = np.append(rng.uniform(0.2, 4.0, 40), np.nan)
    side = rng.uniform(10.0, 200.0, 41)
    cell = side / 8.0
    border = cell * rng.integers(1, 3, 41)
    for first in (True, False):
        for prm in (RefineParams(), RefineParams(margin_cells=0.5, white_end=False, band_px=2.0)):
            w_in, w_out, w_look, excl = band_limits(sigma, side, cell, border, first, prm)
            w = 3.0 * sigma + prm.band_px
            out = np.maximum(1.5, np.minimum(w, cell + 1.0))
            if prm.margin_cells is not None:
                out = np.maximum(1.0, np.minimum(out, prm.margin_cells * cell - 2.0 * sigma))
            inner = border - 1.5 * sigma if first else border + 0.5 * cell
            ends = (np.minimum(np.maximum(3.0 * sigma + 1.0, 0.08 * side), 0.3 * side) if first
                    else np.minimum(sigma, 0.3 * side))
            np.testing.assert_array_equal(w_in, np.maximum(1.0, np.minimum(w, inner)))
            np.testing.assert_array_equal(w_out, out)
            np.testing.assert_array_equal(w_look, out + prm.look_sigmas * sigma if prm.white_end else out)
            np.testing.assert_array_equal(excl, ends)


def test_band_boxes_hold_every_raw_pixel_of_the_band() -> None:
    """With a lens model the compiled passes scan each band's box in the raw image: every raw pixel whose
    undistorted position lies in the band (up to ``max(w_in, w_out)`` across the edge and beyond its ends)
    is inside it, and the box is not much larger than those pixels' own."""
    K = np.array([[700.0, 0, 511.5], [0, 700.0, 383.5], [0, 0, 1]])
    dist = np.array([-0.25, 0.12, 2e-4, -3e-4, -0.02, 0.0, 0.0, 0.0])
    und = Undistorter(K, dist[:5], (768, 1024))
    rng = np.random.default_rng(3)
    p0 = rng.uniform([60.0, 60.0], [960.0, 700.0], (12, 2))
    p1 = p0 + rng.uniform(-50.0, 50.0, (12, 2))
    w_in, w_out = rng.uniform(1.0, 8.0, 12), rng.uniform(1.0, 8.0, 12)
    boxes = _edge_kernels.raw_boxes(768, 1024, p0, p1, w_in, w_out, K, dist)
    for e in range(12):
        t = (p1[e] - p0[e]) / np.linalg.norm(p1[e] - p0[e])
        rel = np.stack([und.map_x - p0[e, 0], und.map_y - p0[e, 1]], axis=-1)
        s, d = rel @ t, rel @ np.array([t[1], -t[0]])
        ext = max(w_in[e], w_out[e])
        iy, ix = np.nonzero((np.abs(d) <= ext) & (s >= -ext) & (s <= np.linalg.norm(p1[e] - p0[e]) + ext))
        x0, y0, x1, y1 = boxes[e]
        assert ix.min() >= x0 and ix.max() < x1 and iy.min() >= y0 and iy.max() < y1
        assert ix.min() - x0 <= 3 and x1 - ix.max() <= 4 and iy.min() - y0 <= 3 and y1 - iy.max() <= 4
