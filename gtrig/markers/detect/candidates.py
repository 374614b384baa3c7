"""Candidate stage: a closure-normalised image, connected components, morphological tests and a
robust quadrilateral per candidate.

The normalisation follows the idea of the RAWSEEDS vision GT system (the image divided by its
morphological closing, which estimates the local brightness of the paper around dark objects), so a
single global threshold on the ratio works under uneven lighting. The closing is computed on an
image downsampled ``scale`` times for speed and upsampled bilinearly.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
from numpy.typing import NDArray


@dataclass(frozen=True)
class CandidateParams:
    """Tunables of the candidate stage (pixel units refer to the input image).

    ratio_threshold : a pixel is dark when image / closing < this.
    min_side_px, max_side_frac : accepted marker side range (max as a fraction of the image's
        smaller dimension).
    min_solidity : contour area / convex hull area.
    max_hole_fraction : total hole area / filled area (the white data area cannot exceed the grid).
    max_holes : bound on the number of holes (Euler number >= 1 - max_holes).
    scale : downsampling factor of the closing.
    smooth : smooth the image (3 x 3 Gaussian) before normalising and the dark mask (3 x 3 median)
        after thresholding. Where flat background sits near the threshold (dim light, noise sigma 3)
        the raw mask breaks into tens of thousands of specks, and tracing them cost most of the time
        of the candidate stage (94 ms on one 1024 x 768 image); smoothed, a few hundred remain. A
        2-px-wide border (20 px AprilTag) survives the median.
    """

    ratio_threshold: float = 0.6
    min_side_px: float = 12.0
    max_side_frac: float = 0.9
    min_solidity: float = 0.85
    max_hole_fraction: float = 0.6
    max_holes: int = 40
    scale: int = 4
    smooth: bool = True


def closure_normalised(gray: NDArray[np.uint8], max_side_px: float, scale: int = 4) -> NDArray[np.float32]:
    """``gray / closing(gray)`` in [0, ~1]: dark objects narrower than ``max_side_px`` get low values.

    Parameters
    ----------
    gray : (H, W) uint8
    max_side_px : largest dark object (marker side) to normalise, pixels.
    scale : the closing runs on an image ``scale`` times smaller.
    """
    h, w = gray.shape
    sw, sh = max(1, w // scale), max(1, h // scale)
    small = cv2.resize(gray, (sw, sh), interpolation=cv2.INTER_AREA)
    k = int(max_side_px / scale) | 1
    k = max(3, k + 2)
    closed = cv2.morphologyEx(small, cv2.MORPH_CLOSE, cv2.getStructuringElement(cv2.MORPH_RECT, (k, k)))
    bg = cv2.resize(closed, (w, h), interpolation=cv2.INTER_LINEAR).astype(np.float32)
    return gray.astype(np.float32) / np.maximum(bg, 1.0)


def _ordered_cw(quad: NDArray[np.float64]) -> NDArray[np.float64]:
    """Order 4 points clockwise on screen (image y down): positive shoelace sum."""
    x, y = quad[:, 0], quad[:, 1]
    area2 = float(np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y))
    return quad if area2 > 0 else quad[::-1].copy()


def _line_intersections(lines: NDArray[np.float64]) -> NDArray[np.float64]:
    """Corner i = intersection of lines i-1 and i; ``lines`` (4, 3) as (nx, ny, c) with n.x = c."""
    A = np.stack([np.roll(lines, 1, axis=0)[:, :2], lines[:, :2]], axis=1)  # (4, 2, 2)
    c = np.stack([np.roll(lines, 1, axis=0)[:, 2], lines[:, 2]], axis=1)
    return np.linalg.solve(A, c[..., None])[..., 0]


def robust_quad(contour: NDArray[np.int32], approx: NDArray[np.float64]) -> NDArray[np.float64] | None:
    """Refine 4 approximate vertices by Huber line fits to the contour points of each side.

    Points within 15 % of a side's length from its ends are left out (rounded corners).
    Returns (4, 2) corners ordered clockwise on screen, or None when a side has too few points.
    """
    pts = contour.reshape(-1, 2).astype(np.float64)
    lines = np.empty((4, 3))
    for i in range(4):
        p0, p1 = approx[i], approx[(i + 1) % 4]
        t = p1 - p0
        L = float(np.hypot(*t))
        if L < 3:
            return None
        t /= L
        n = np.array([t[1], -t[0]])
        s = (pts - p0) @ t
        d = (pts - p0) @ n
        sel = (s > 0.15 * L) & (s < 0.85 * L) & (np.abs(d) < max(2.0, 0.05 * L))
        if sel.sum() < 3:
            return None
        vx, vy, x0, y0 = cv2.fitLine(pts[sel].astype(np.float32), cv2.DIST_HUBER, 0, 0.01, 0.01).ravel()
        nn = np.array([vy, -vx], dtype=np.float64)
        lines[i] = (nn[0], nn[1], nn @ np.array([x0, y0]))
    try:
        q = _line_intersections(lines)
    except np.linalg.LinAlgError:
        return None
    moved = np.max(np.linalg.norm(q - approx, axis=1)) if np.all(np.isfinite(q)) else np.inf
    if moved > max(3.0, 0.1 * np.ptp(approx)):
        return None
    return q


def find_candidates(
    gray: NDArray[np.uint8], params: CandidateParams, max_hole_fraction: float | None = None
) -> list[NDArray[np.float64]]:
    """Candidate quadrilaterals (each (4, 2), clockwise on screen, pixel coordinates) of dark squares.

    Tests, in order of cost: contour length, area, solidity, holes (Euler number and hole fraction),
    four-vertex convex polygon, robust quadrilateral.
    """
    h, w = gray.shape
    max_side = params.max_side_frac * min(h, w)
    src = gray
    ratio = closure_normalised(src, max_side, params.scale)
    mask = (ratio < params.ratio_threshold).astype(np.uint8)
    if params.smooth:
        mask = cv2.medianBlur(mask, 3)
    contours, hier = cv2.findContours(mask, cv2.RETR_CCOMP, cv2.CHAIN_APPROX_NONE)
    if hier is None:
        return []
    hier = hier[0]
    min_len = 4 * params.min_side_px * 0.8
    max_len = 4 * max_side * 1.5
    hole_frac_max = params.max_hole_fraction if max_hole_fraction is None else max_hole_fraction
    out = []
    lengths = np.fromiter((len(c) for c in contours), int, len(contours))
    for i in np.flatnonzero((hier[:, 3] < 0) & (lengths >= min_len) & (lengths <= max_len)):
        c = contours[i]
        area = cv2.contourArea(c)
        if area < 0.5 * params.min_side_px**2:
            continue
        hull = cv2.convexHull(c)
        hull_area = cv2.contourArea(hull)
        if hull_area <= 0 or area / hull_area < params.min_solidity:
            continue
        holes = 0
        hole_area = 0.0
        j = hier[i, 2]
        while j >= 0:
            holes += 1
            hole_area += cv2.contourArea(contours[j])
            j = hier[j, 0]
        if holes > params.max_holes or hole_area > hole_frac_max * area:
            continue
        peri = cv2.arcLength(hull, True)
        approx = cv2.approxPolyDP(hull, 0.05 * peri, True)
        if len(approx) != 4 or not cv2.isContourConvex(approx):
            continue
        a = _ordered_cw(approx.reshape(4, 2).astype(np.float64))
        sides = np.linalg.norm(a - np.roll(a, -1, axis=0), axis=1)
        if sides.min() < params.min_side_px * 0.7 or sides.min() < 0.25 * sides.max():
            continue
        q = robust_quad(c, a)
        if q is None:
            continue
        out.append(_ordered_cw(q))
    return out
