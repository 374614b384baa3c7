"""Candidate stage: a closure-normalised image, connected components, morphological tests and a
robust quadrilateral per candidate.

The normalisation follows the idea of the RAWSEEDS vision GT system (the image divided by its
morphological closing, which estimates the local brightness of the paper around dark objects), so a
single global threshold on the ratio works under uneven lighting. The closing is computed on an
image downsampled ``scale`` times for speed and upsampled bilinearly; the threshold on the ratio is
applied in 8 bits (:func:`dark_mask`).
"""

from __future__ import annotations

import functools
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import cv2
import numpy as np
from numpy.typing import NDArray

from gtrig.markers.detect import _kernels, _threads


@dataclass(frozen=True)
class CandidateParams:
    """Tunables of the candidate stage (pixel units refer to the input image).

    ratio_threshold : a pixel is dark when image / closing < this.
    min_side_px, max_side_frac : accepted marker side range (max as a fraction of the image's
        smaller dimension).
    min_solidity : contour area / convex hull area.
    max_hole_fraction : total hole area / filled area (the white data area cannot exceed the grid).
    max_holes : bound on the number of holes (Euler number >= 1 - max_holes).
    more_thresholds : further ratio thresholds, each giving its own mask and candidates (kept where no
        candidate of an earlier threshold covers the same square). One ratio cannot suit every marker
        of a real photo: on the ChArUco photos of ``markers_real`` (19-28 px markers, 2.5 px borders)
        a thin blurred border reaches only 0.6-0.8 of the paper and the white cells break it at 0.6
        (blob solidity 0.56-0.74, 3 of 17 markers of ``img_02.jpg`` lost), while at 0.9 a marker
        whose quiet zone is dimmed by the next chessboard square merges with it; on a marker in
        shadow beside a sunlit surface (``tagtest.jpg``, ID 9 on the dark face of a cube) the closing
        takes the sunlit paper for the background, the shaded white cells and quiet zone sit at
        0.55-0.65 of it, like the floor behind, and only 0.45 separates the marker from the floor.
        The ratio stays a ratio, so the set still works under uneven light (OpenCV's detector likewise
        thresholds at several window sizes).
    scale : downsampling factor of the closing.
    smooth : smooth the dark mask (3 x 3 median) after thresholding. Where flat background sits near
        the threshold (dim light, noise sigma 3) the raw mask breaks into tens of thousands of
        specks, and tracing them cost most of the time of the candidate stage (94 ms on one
        1024 x 768 image); smoothed, a few hundred remain. A 2-px-wide border (20 px AprilTag)
        survives the median.
    local_windows : window sides (pixels) of the local-contrast masks (:func:`_local_contours`), traced
        after the ratio masks in the same seed boxes. A 20 px tag under Bayer demosaicing, JPEG and 1-1.5 px
        blur is broken at the stricter ratios and merged with a dark surface or texture at the looser ones
        (the closing does not separate them): no ratio gives a solid square (the hard bench's misses had
        solidity 0.36-0.81). A pixel darker than its neighbourhood's mean follows the border's edges
        instead of its level; 11 px is about half the smallest tag the detector is meant to read well.
        Empty: off. On the hard bench (seeds 0-3) 49 misses -> 34; the masks themselves cost 3.3 % of the
        detector's CPU on the --quick set, the detector's wall 9-16 % idle with the later stages of the
        extra candidates (BENCHMARKS.md, issue 16, session 29).
    local_offset : how much darker than the local mean (grey levels) a pixel of those masks is; about the
        noise the 3 x 3 median leaves.
    faint_seeds : seed the further thresholds also with the blobs of a local-contrast mask of the
        closing's small image (:func:`_faint_seeds`; ``faint_window`` small pixels, ``faint_offset`` grey
        levels), of sides from ``faint_min_side_px`` up: markers veiled by glare, which leave no blob at
        the first threshold.
    """

    ratio_threshold: float = 0.6
    min_side_px: float = 12.0
    max_side_frac: float = 0.9
    min_solidity: float = 0.85
    max_hole_fraction: float = 0.6
    max_holes: int = 40
    more_thresholds: tuple[float, ...] = (0.45, 0.75, 0.9)
    scale: int = 4
    smooth: bool = True
    local_windows: tuple[int, ...] = (11,)
    local_offset: float = 3.0
    faint_seeds: bool = True
    faint_min_side_px: float = 24.0
    faint_window: int = 15
    faint_offset: float = 6.0

    def max_side_px(self, shape: tuple[int, ...]) -> float:
        """Largest accepted marker side in an image of ``shape`` (H, W), pixels."""
        return self.max_side_frac * min(shape[0], shape[1])


def closure_normalised(gray: NDArray[np.uint8], max_side_px: float, scale: int = 4) -> NDArray[np.float32]:
    """``gray / closing(gray)`` in [0, ~1]: dark objects narrower than ``max_side_px`` get low values.

    Parameters
    ----------
    gray : (H, W) uint8
    max_side_px : largest dark object (marker side) to normalise, pixels.
    scale : the closing runs on an image ``scale`` times smaller.
    """
    bg = _closing_background(gray, max_side_px, scale).astype(np.float32)
    return gray.astype(np.float32) / np.maximum(bg, 1.0)


def _closing_background(gray: NDArray[np.uint8], max_side_px: float, scale: int) -> NDArray[np.uint8]:
    """The closing of ``gray`` (on an image ``scale`` times smaller), upsampled bilinearly, uint8."""
    _small, closed = _small_closing(gray, max_side_px, scale)
    return cv2.resize(closed, (gray.shape[1], gray.shape[0]), interpolation=cv2.INTER_LINEAR)


def _small_closing(gray: NDArray[np.uint8], max_side_px: float, scale: int
                   ) -> tuple[NDArray[np.uint8], NDArray[np.uint8]]:
    """``gray`` area-averaged ``scale`` times smaller, and its closing by a square a marker wide."""
    h, w = gray.shape
    sw, sh = max(1, w // scale), max(1, h // scale)
    small = cv2.resize(gray, (sw, sh), interpolation=cv2.INTER_AREA)
    k = int(max_side_px / scale) | 1
    k = max(3, k + 2)
    closed = cv2.morphologyEx(small, cv2.MORPH_CLOSE, cv2.getStructuringElement(cv2.MORPH_RECT, (k, k)))
    return np.asarray(small, np.uint8), np.asarray(closed, np.uint8)


def _faint_seeds(small: NDArray[np.uint8], closed: NDArray[np.uint8], first: float, scale: int, window: int,
                 offset: float, min_side_px: float, max_side_px: float) -> list[tuple[int, int, int, int]]:
    """Boxes ``(x, y, w, h)`` (image pixels) of the blobs of the ``scale`` times smaller image ``small``
    darker by ``offset`` grey levels than the mean of their ``window`` x ``window`` neighbourhood, of a
    marker's size and about as filled as one, and with less than a fifth of it darker than ``first`` of
    the closing ``closed`` (a blob the first threshold sees, it has seeded or explained already; a
    veiled marker shows there only where the highlight thins out).

    The further thresholds look only where the first left a blob (:func:`_seed_regions`); a marker
    under a veil of glare, its black lifted to 0.75-0.85 of its paper, leaves none at the first one,
    and nothing else would look there. On a textured background that ratio is the texture's too, so
    no ratio of the closing separates the marker, while its black is still darker than the paper
    around it: a local-contrast mask of the small image shows it, where the texture averages out and
    tracing costs a sixteenth of the pixels (renders made apart from the project, issue 16, session
    42: 68-90 px markers that OpenCV's adaptive thresholds find).
    """
    mask = cv2.adaptiveThreshold(small, 255, cv2.ADAPTIVE_THRESH_MEAN_C, cv2.THRESH_BINARY_INV, window | 1, offset)
    n, lab, stats, _c = cv2.connectedComponentsWithStats(mask, connectivity=8)
    x, y, w, h, area = stats[1:].T.astype(np.int64)
    lo, hi = min_side_px / scale, max_side_px / scale
    big, short = np.maximum(w, h), np.minimum(w, h)
    # a marker's blob: its box a marker wide, not a sliver, and a good part of it dark (holes: white cells)
    keep = (short >= lo) & (big <= hi) & (big <= 3 * short) & (area >= 0.3 * w * h)
    if keep.any():
        dark = cv2.compare(small, cv2.LUT(closed, _ratio_lut(first)), cv2.CMP_LT)
        keep &= np.bincount(lab.ravel(), weights=(dark.ravel() > 0), minlength=n)[1:] < 0.2 * area
    return [(int(a) * scale, int(b) * scale, int(c) * scale, int(d) * scale)
            for a, b, c, d in zip(x[keep], y[keep], w[keep], h[keep], strict=True)]


@functools.lru_cache(maxsize=8)
def _ratio_lut(threshold: float) -> NDArray[np.uint8]:
    """``lut[b]`` = the smallest grey level ``g`` with ``g / max(b, 1) >= threshold`` in float32, so
    that ``g < lut[b]`` is exactly ``closure_normalised(...) < threshold`` for 8-bit ``g`` and ``b``."""
    g = np.arange(256, dtype=np.float32)
    b = np.maximum(np.arange(256, dtype=np.float32), 1.0)
    dark = (g[None, :] / b[:, None]) < np.float32(threshold)  # (b, g), monotone in g
    return np.minimum(dark.sum(axis=1), 255).astype(np.uint8)


def dark_mask(gray: NDArray[np.uint8], max_side_px: float, scale: int = 4, threshold: float = 0.6
              ) -> NDArray[np.uint8]:
    """``closure_normalised(gray, max_side_px, scale) < threshold`` as a 0 / 255 uint8 mask.

    Computed in 8 bits (a per-pixel threshold from a lookup table on the background, then one
    comparison) instead of a float image: the float division cost 12 ms on a 1024 x 768 image, this
    about 1 ms, with the same result.
    """
    bg = _closing_background(gray, max_side_px, scale)
    return cv2.compare(gray, cv2.LUT(bg, _ratio_lut(threshold)), cv2.CMP_LT)


# corner / side index helpers: side i runs from corner i to corner i + 1
_NEXT = np.array([1, 2, 3, 0])


def _ordered_cw(quad: NDArray[np.float64]) -> NDArray[np.float64]:
    """Order 4 points clockwise on screen (image y down): positive shoelace sum."""
    x, y = quad[:, 0], quad[:, 1]
    area2 = float(x @ y[_NEXT] - x[_NEXT] @ y)
    return quad if area2 > 0 else quad[::-1].copy()


def robust_quad(contour: NDArray[np.int32], approx: NDArray[np.float64]) -> NDArray[np.float64] | None:
    """Refine 4 approximate vertices by Huber line fits to the contour points of each side.

    Points within 15 % of a side's length from its ends are left out (rounded corners).
    Returns (4, 2) corners ordered clockwise on screen, or None when a side has too few points.
    """
    pts = contour.reshape(-1, 2)
    approx = np.ascontiguousarray(approx, np.float64)
    # the tests and the intersections are compiled: called for every blob that passes the shape
    # tests, their NumPy forms cost more than the four line fits
    sel, ok = _kernels.side_select(np.ascontiguousarray(pts, np.float64), approx)
    if not ok:
        return None
    pts32 = pts.astype(np.float32)
    lines = np.empty((4, 3))
    for i in range(4):
        vx, vy, x0, y0 = cv2.fitLine(pts32[sel[i]], cv2.DIST_HUBER, 0, 0.01, 0.01).ravel()
        lines[i] = (vy, -vx, float(vy) * float(x0) - float(vx) * float(y0))
    q, ok = _kernels.quad_from_lines(lines, approx)
    return q if ok else None


def solid_quad(c: NDArray[np.int32], min_side_px: float, max_side_px: float, min_solidity: float
               ) -> NDArray[np.float64] | None:
    """The quad (4, 2), clockwise on screen, of the contour ``c`` ((N, 1, 2) pixels) of a small blob or hole
    when it is a solid convex quadrilateral of sides ``min_side_px`` - ``max_side_px``, else None (the
    second path's test: no hole tests, a blurred marker's blob has none).

    Tests: area, solidity (area / hull area >= ``min_solidity``), a four-vertex convex approximation of
    the hull, its shortest side; the quad is the robust one (:func:`robust_quad`), or the hull's vertices
    when that fails (a blurred blob's corners are rounded: they are then a fair start).
    """
    area = cv2.contourArea(c)
    if area < 0.5 * min_side_px**2 or area > 1.3 * max_side_px**2:
        return None
    hull = cv2.convexHull(c)
    hull_area = cv2.contourArea(hull)
    if hull_area <= 0 or area / hull_area < min_solidity:
        return None
    approx = cv2.approxPolyDP(hull, 0.05 * cv2.arcLength(hull, True), True)
    if len(approx) != 4 or not cv2.isContourConvex(approx):
        return None
    a = _ordered_cw(approx.reshape(4, 2).astype(np.float64))
    sides = np.hypot(*(a[_NEXT] - a).T)
    if sides.min() < 0.7 * min_side_px or sides.min() < 0.4 * sides.max():
        return None
    q = robust_quad(c, a)
    return _ordered_cw(a if q is None else q)


def find_candidates(
    gray: NDArray[np.uint8], params: CandidateParams, max_hole_fraction: float | None = None,
    trace: list | None = None, threads: int = 1,
) -> list[NDArray[np.float64]]:
    """Candidate quadrilaterals (each (4, 2), clockwise on screen, pixel coordinates) of dark squares.

    Tests, in order of cost: contour length, area, solidity, holes (Euler number and hole fraction),
    four-vertex convex polygon, robust quadrilateral. ``trace`` (a list) receives a
    :class:`gtrig.markers.detect.Rejection` for each blob of a plausible size that fails a later test.

    The first threshold runs on the whole image; a further one (``params.more_thresholds``) only
    around the blobs the first one left unexplained (:func:`_seed_regions`): a marker the first
    threshold misses leaves there a blob that failed a test (a thin border broken by the white cells,
    a marker merged with a shadowed floor). Tracing three more masks over the whole image cost a
    quarter of the detector's time on the bench. A marker veiled by glare leaves no such blob: the
    loosest threshold and the local masks also look around the faint seeds (:func:`_faint_seeds`).
    """
    max_side = params.max_side_px(gray.shape)
    small, closed = _small_closing(gray, max_side, params.scale)
    bg = cv2.resize(closed, (gray.shape[1], gray.shape[0]), interpolation=cv2.INTER_LINEAR)
    rejected: list = []
    seeds: list[tuple[int, int, int, int]] = []
    weak: list[NDArray[np.float64]] = []
    out = _mask_candidates(_contours_at(gray, bg, params.ratio_threshold, params.smooth), params, max_side,
                           max_hole_fraction, None if trace is None else rejected, seeds=seeds, weak=weak)
    covered = np.zeros(gray.shape, np.uint8)
    more = params.more_thresholds
    faint = (_faint_seeds(small, closed, params.ratio_threshold, params.scale, params.faint_window,
                          params.faint_offset, params.faint_min_side_px, max_side)
             if more and params.faint_seeds else [])
    if more and (seeds or faint):
        regions = {looser: _seed_regions(gray.shape, seeds, looser) for looser in (False, True)}
        # squares already found, filled: a blob of a later threshold centred in one is the same marker
        if out:
            _fill(covered, out)
        # a box's contours do not depend on what the earlier boxes found: with two threads a helper
        # traces the next boxes (OpenCV releases the GIL) while this thread tests the blobs of one; the
        # further ratio thresholds first, the local-contrast masks (:func:`_local_contours`) last
        jobs = [(_contours_at, (gray, bg, thr, params.smooth, box), regions[thr > params.ratio_threshold][0])
                for thr in more for box in regions[thr > params.ratio_threshold][1]]
        jobs += [(_local_contours, (gray, win, params.local_offset, params.smooth, box), regions[True][0])
                 for win in params.local_windows for box in regions[True][1]]
        # a faint seed (ink lifted towards its paper) can only show at the loosest ratio and in the local
        # masks; where a seed of the first threshold already lets them look, it adds nothing
        looked = regions[True][0]
        faint = [b for b in faint if not (looked[b[1] + b[3] // 2, b[0] + b[2] // 2]
                                          or covered[b[1] + b[3] // 2, b[0] + b[2] // 2])]
        if faint:
            f_region, f_boxes = _seed_regions(gray.shape, faint, True)
            jobs += [(_contours_at, (gray, bg, max(more), params.smooth, box), f_region) for box in f_boxes]
            jobs += [(_local_contours, (gray, win, params.local_offset, params.smooth, box), f_region)
                     for win in params.local_windows for box in f_boxes]
        traced = _threads.ordered_map(_call, [(fn, args) for fn, args, _ in jobs], threads)
        for (_, _, region), contours in zip(jobs, traced, strict=True):
            found = _mask_candidates(contours, params, max_side, max_hole_fraction,
                                     None if trace is None else rejected, covered, region, weak=weak)
            out.extend(found)
            if found:  # (the boxes may overlap: a blob in two of them is one candidate)
                _fill(covered, found)
    # the fallback quads of broken borders, where no sound candidate lies (the first of several wins)
    h, w = gray.shape
    cover = np.zeros(gray.shape, np.uint8)
    if out:
        cv2.fillPoly(cover, [np.round(q).astype(np.int32).reshape(-1, 1, 2) for q in out], 255)
    for q in weak:
        c = np.clip(np.round(q.mean(axis=0)).astype(int), 0, [w - 1, h - 1])
        if not cover[c[1], c[0]]:
            out.append(q)
            cv2.fillPoly(cover, [np.round(q).astype(np.int32).reshape(-1, 1, 2)], 255)
    if trace is not None:
        # a blob that failed at one threshold but gave a candidate at another is not a rejection
        for r in rejected:
            c = np.clip(np.round(r.quad_px.mean(axis=0)).astype(int), 0, [w - 1, h - 1])
            if not cover[c[1], c[0]]:
                trace.append(r)
    return out


#: the contours and hierarchy (``cv2.RETR_CCOMP``) of a dark mask, and the limits ``(x0, y0, x1, y1)``
#: of the part of the image they were traced in: a blob reaching one was cut (beyond the image's own
#: sides, when the part reaches them)
Contours = tuple[Sequence[NDArray[np.int32]], NDArray[np.int32] | None, tuple[int, int, int, int]]


def _contours_at(gray: NDArray[np.uint8], bg: NDArray[np.uint8], threshold: float, smooth: bool,
                 box: tuple[int, int, int, int] | None = None) -> Contours:
    """The contours of ``gray / bg < threshold`` (:func:`dark_mask`; 3 x 3 median-smoothed if
    ``smooth``) in the box ``(x0, y0, x1, y1)`` of the image (all of it by default), in image pixels."""
    x0, y0, x1, y1 = box if box is not None else (0, 0, gray.shape[1], gray.shape[0])
    g, b = gray[y0:y1, x0:x1], bg[y0:y1, x0:x1]
    mask = cv2.compare(g, cv2.LUT(b, _ratio_lut(threshold)), cv2.CMP_LT)
    return _traced(mask, smooth, gray.shape, (x0, y0, x1, y1))


def _traced(mask: NDArray[np.uint8], smooth: bool, shape: tuple[int, ...], box: tuple[int, int, int, int]
            ) -> Contours:
    """The :data:`Contours` of ``mask`` (0 / 255, the box ``(x0, y0, x1, y1)`` of an image of ``shape``),
    3 x 3 median-smoothed first if ``smooth``."""
    x0, y0, x1, y1 = box
    if smooth:
        mask = cv2.medianBlur(mask, 3)
    contours, hier = cv2.findContours(mask, cv2.RETR_CCOMP, cv2.CHAIN_APPROX_NONE, offset=(x0, y0))
    h, w = shape[:2]
    limits = (x0 if x0 > 0 else -1, y0 if y0 > 0 else -1, x1 - 1 if x1 < w else w, y1 - 1 if y1 < h else h)
    return contours, None if hier is None else hier[0], limits


def _call(fn: Callable[..., Contours], args: tuple[Any, ...]) -> Contours:
    """``fn(*args)``: one tracing job of :func:`find_candidates` (its masks come from two functions)."""
    return fn(*args)


def _fill(covered: NDArray[np.uint8], quads: Sequence[NDArray[np.float64]]) -> None:
    """Paint ``quads`` ((4, 2) px each) into ``covered`` (H, W), in place: a later mask's blob centred in
    one is the same marker."""
    cv2.fillPoly(covered, [np.round(q).astype(np.int32).reshape(-1, 1, 2) for q in quads], 255)


def _local_contours(gray: NDArray[np.uint8], win: int, offset: float, smooth: bool,
                    box: tuple[int, int, int, int]) -> Contours:
    """The contours of the pixels darker by more than ``offset`` grey levels than the mean of their
    ``win`` x ``win`` neighbourhood, in the box ``(x0, y0, x1, y1)`` of the image, in image pixels."""
    x0, y0, x1, y1 = box
    g = gray[y0:y1, x0:x1]
    mask = cv2.adaptiveThreshold(g, 255, cv2.ADAPTIVE_THRESH_MEAN_C, cv2.THRESH_BINARY_INV, win | 1, offset)
    return _traced(mask, smooth, gray.shape, (x0, y0, x1, y1))


def _seed_regions(shape: tuple[int, ...], seeds: list[tuple[int, int, int, int]], looser: bool
                  ) -> tuple[NDArray[np.uint8], list[tuple[int, int, int, int]]]:
    """Where a further threshold's blobs are tested (0 / 255, (H, W); a blob is when its bounding box
    is centred there), and the boxes ``(x0, y0, x1, y1)`` to trace its contours in.

    ``seeds`` are the bounding boxes ``(x, y, w, h)`` of the blobs the first threshold left
    unexplained. A stricter threshold's blobs lie within the first one's (the masks are nested, and
    so are their median-smoothed versions): a seed's box grows by 2 px. A looser threshold's blob
    holding a seed is the whole marker when the seed was a part of its border (one side of it, two,
    three): a box grows to a square (both ways along its shorter side, as the seed may be either side
    of the border) and then by an eighth. The contours are traced in the bounding boxes of the
    region's connected parts, 4 px larger.
    """
    h_img, w_img = shape[:2]
    region = np.zeros((h_img, w_img), np.uint8)
    x, y, w, h = np.array(seeds, np.int64).reshape(-1, 4).T
    if looser:
        big = np.maximum(w, h) // 8 + 2
        mx, my = np.maximum(h - w, 0) + big, np.maximum(w - h, 0) + big
    else:
        mx = my = np.full(len(x), 2, np.int64)
    boxes_px = np.column_stack([np.maximum(x - mx, 0), np.maximum(y - my, 0),
                                np.minimum(x + w + mx, w_img - 1), np.minimum(y + h + my, h_img - 1)])
    _kernels.fill_boxes(region, boxes_px)
    # parts less than 16 px apart share a box (on an 8 x coarser grid, dilated by one): each box costs a
    # few OpenCV calls, and clutter leaves tens of small seeds
    if h_img % 8 == 0 and w_img % 8 == 0:
        # the area average by a whole factor of 8 is each 8 x 8 block's mean (rounded; 255 / 64 rounds to
        # 4), non-zero exactly where a box reaches the block: filled on the coarse grid directly, without
        # the pass over the whole image (0.5 ms of a 1024 x 768 image's 50)
        small = np.zeros((h_img // 8, w_img // 8), np.uint8)
        _kernels.fill_boxes(small, boxes_px // 8)
    else:
        small = cv2.resize(region, ((w_img + 7) // 8, (h_img + 7) // 8), interpolation=cv2.INTER_AREA)
    coarse = cv2.dilate(small, np.ones((3, 3), np.uint8))
    parts, _ = cv2.findContours(coarse, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_SIMPLE)
    boxes = []
    for c in parts:
        x, y, w, h = cv2.boundingRect(c)
        boxes.append((max(8 * x - 4, 0), max(8 * y - 4, 0), min(8 * (x + w) + 4, w_img), min(8 * (y + h) + 4, h_img)))
    return region, boxes


def _mask_candidates(contours: Contours, params: CandidateParams, max_side: float,
                     max_hole_fraction: float | None, trace: list | None,
                     covered: NDArray[np.uint8] | None = None, region: NDArray[np.uint8] | None = None,
                     seeds: list[tuple[int, int, int, int]] | None = None,
                     weak: list[NDArray[np.float64]] | None = None) -> list[NDArray[np.float64]]:
    """:func:`find_candidates` on the contours of one dark mask (:func:`_contours_at`). Blobs whose
    bounding box is centred on a non-zero pixel of ``covered``, or on a zero pixel of ``region``, are
    skipped. ``seeds`` receives the bounding box ``(x, y, w, h)`` of every blob of a plausible size
    (outline length, and box at most ``max_side``) that gave no candidate, and of the blobs with
    outlines of a third to one plausible length. ``weak`` receives the fallback quads of blobs of
    low solidity (:func:`_broken_border_quad`)."""
    contours, hier, (x0, y0, x1, y1) = contours
    if hier is None:
        return []
    min_len = 4 * params.min_side_px * 0.8
    max_len = 4 * max_side * 1.5
    hole_frac_max = params.max_hole_fraction if max_hole_fraction is None else max_hole_fraction
    out = []
    lengths = np.fromiter(map(len, contours), int, len(contours))
    outer = hier[:, 3] < 0
    if seeds is not None:
        # a small blurred marker's border may break at this threshold into pieces shorter than a
        # marker's outline (down to a third of the shortest: on the hard bench's 20 px markers half of
        # it lost 4 of 45 markers that the whole-image passes find): those are seeds too
        seeds.extend(cv2.boundingRect(contours[i])
                     for i in np.flatnonzero(outer & (lengths >= min_len / 3) & (lengths < min_len)))

    def reject(c: NDArray[np.int32], why: str) -> None:
        if trace is not None:
            from gtrig.markers.detect import Rejection

            x, y, w, h = cv2.boundingRect(c)
            box = np.array([[x, y], [x + w, y], [x + w, y + h], [x, y + h]], np.float64)
            trace.append(Rejection(box, "candidate", why))

    for i in np.flatnonzero(outer & (lengths >= min_len) & (lengths <= max_len)):
        c = contours[i]
        box = cv2.boundingRect(c)
        centre = (box[1] + box[3] // 2, box[0] + box[2] // 2)
        if (covered is not None and covered[centre]) or (region is not None and not region[centre]):
            continue
        if box[0] <= x0 or box[1] <= y0 or box[0] + box[2] - 1 >= x1 or box[1] + box[3] - 1 >= y1:
            continue  # cut by a side of the part of the image it was traced in
        q, why = _blob_quad(c, contours, hier, i, params, hole_frac_max)
        if q is not None and why is None:
            out.append(q)
            continue
        if q is not None:
            # a fallback: kept apart, so that another threshold's sound blob of the same marker (the
            # seed below lets the further thresholds look) is preferred to it
            if weak is not None:
                weak.append(q)
            why = f"{why}, solidity under {params.min_solidity:g}"
        if seeds is not None and max(box[2], box[3]) <= max_side:
            seeds.append(box)
        if why is not None:
            reject(c, why)
    return out


#: the reason :func:`_blob_quad` gives with the quad of a blob of low solidity (:func:`_broken_border_quad`)
BROKEN = "broken border"


def _blob_quad(c: NDArray[np.int32], contours: tuple, hier: NDArray[np.int32], i: int, params: CandidateParams,
               hole_frac_max: float) -> tuple[NDArray[np.float64] | None, str | None]:
    """The candidate quad of the outer contour ``c`` (``contours[i]``, holes from ``hier``), or None
    and the first test it failed (None for a blob too small to mention). A quad with the reason
    :data:`BROKEN` is a fallback (:func:`_broken_border_quad`)."""
    area = cv2.contourArea(c)
    if area < 0.5 * params.min_side_px**2:
        return None, None
    hull = cv2.convexHull(c)
    hull_area = cv2.contourArea(hull)
    if hull_area <= 0:
        return None, "solidity 0.00"
    if area / hull_area < params.min_solidity:
        q = _broken_border_quad(c, hull, params)
        if q is not None:
            return q, BROKEN
        return None, f"solidity {area / hull_area:.2f} < {params.min_solidity:g}"
    holes = 0
    hole_area = 0.0
    j = hier[i, 2]
    while j >= 0:
        holes += 1
        hole_area += cv2.contourArea(contours[j])
        j = hier[j, 0]
    if holes > params.max_holes or hole_area > hole_frac_max * area:
        return None, (f"{holes} holes, {hole_area / area:.2f} of the area" if holes > params.max_holes
                      else f"holes {hole_area / area:.2f} of the area > {hole_frac_max:.2f}")
    peri = cv2.arcLength(hull, True)
    approx = cv2.approxPolyDP(hull, 0.05 * peri, True)
    if len(approx) != 4 or not cv2.isContourConvex(approx):
        return None, f"outline has {len(approx)} vertices, not 4"
    a = _ordered_cw(approx.reshape(4, 2).astype(np.float64))
    sides = np.hypot(*(a[_NEXT] - a).T)
    if sides.min() < params.min_side_px * 0.7 or sides.min() < 0.25 * sides.max():
        return None, f"sides {sides.min():.0f}-{sides.max():.0f} px"
    q = robust_quad(c, a)
    if q is None:
        return None, "no straight sides (robust quad failed)"
    return _ordered_cw(q), None


#: share of a candidate outline's perimeter the contour must trace (within ``robust_quad``'s side band)
#: for a blob of low solidity to be taken as a marker with a broken border
BROKEN_BORDER_TRACED = 0.8


def _broken_border_quad(c: NDArray[np.int32], hull: NDArray[np.int32], params: CandidateParams
                        ) -> NDArray[np.float64] | None:
    """The quad of a marker whose dark border is broken, from a blob that failed the solidity test.

    On a small blurred marker under Bayer demosaicing and JPEG (the hard bench's 20 px AprilTags, 2.5 px
    border), the white data cells next to the border lift it above the ratio threshold in places; the
    data area then joins the paper outside through those gaps, the outer contour runs into the marker
    and the blob's solidity falls to 0.6-0.8 although its outline is still the square's. Such a blob is
    kept when its convex hull is a convex quadrilateral whose four sides the contour traces over at
    least :data:`BROKEN_BORDER_TRACED` of their middle parts (clutter of low solidity rarely has four
    straight, traced sides); the cells read through the quad (the pre-decoder and the decoder) then
    decide, as for every candidate. Returns the quad (4, 2), clockwise on screen, or None.
    """
    peri = cv2.arcLength(hull, True)
    approx = cv2.approxPolyDP(hull, 0.05 * peri, True)
    if len(approx) != 4 or not cv2.isContourConvex(approx):
        return None
    a = _ordered_cw(approx.reshape(4, 2).astype(np.float64))
    sides = np.hypot(*(a[_NEXT] - a).T)
    if sides.min() < params.min_side_px * 0.7 or sides.min() < 0.25 * sides.max():
        return None
    pts = c.reshape(-1, 2).astype(np.float64)
    sel = _kernels.side_points(np.ascontiguousarray(pts), np.ascontiguousarray(a))
    # traced share of each side's middle 70 % (what side_points looks at): the 2 px bins along the side
    # that hold a contour point (an 8-connected contour steps by up to 1.41 px along a diagonal side);
    # compiled: tens of blobs per image fail the solidity test, and the NumPy form cost 3 % of the detector
    if not _kernels.sides_traced(pts, sel, a, sides, BROKEN_BORDER_TRACED):
        return None
    q = robust_quad(c, a)
    return None if q is None else _ordered_cw(q)
