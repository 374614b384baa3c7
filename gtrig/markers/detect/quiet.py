"""Candidates from the quiet zone: the bright ring of paper around a marker, traced as a ring.

A printed marker is a dark square inside a margin of bare paper (its quiet zone). The dark masks of
:mod:`.candidates` and :mod:`.blurred` look for the dark square itself, against an estimate of the
paper's brightness (a closing) or of the local mean. On the harder bench's 20 px tags on textured
backgrounds both fail in two ways (BENCHMARKS.md, issue 16, session 35): the closing follows the
texture's peaks, so the dark background and the marker become one dark region; and the 2.5 px border,
demosaiced and blurred, breaks next to white data cells, so the marker's blob is C-shaped or in
fragments. The paper around the marker is the one part of it that is brighter than everything near it,
whatever the background and whatever the cells: pixels brighter than the mean of a neighbourhood about
half a marker wide trace the quiet zone as a closed ring, and the hole of that ring is the marker's
outline. A border broken next to a white cell only notches that hole by a cell (its solidity stays
above 0.9 where the dark blob's was 0.4-0.8).
"""

from __future__ import annotations

import cv2
import numpy as np
from numpy.typing import NDArray

from gtrig.markers.detect.candidates import _NEXT, solid_quad

__all__ = ["quiet_zone_quads"]


def bright_mask(gray: NDArray[np.uint8], window: int, offset: float) -> NDArray[np.uint8]:
    """Pixels brighter by more than ``offset`` grey levels than the mean of their ``window`` x ``window``
    neighbourhood (``window`` made odd), 3 x 3 median-smoothed (the image noise leaves single pixels
    there), as a 0 / 255 (H, W) uint8 mask of the (H, W) uint8 image ``gray``."""
    mask = cv2.adaptiveThreshold(gray, 255, cv2.ADAPTIVE_THRESH_MEAN_C, cv2.THRESH_BINARY, window | 1, -offset)
    return cv2.medianBlur(mask, 3)


def quiet_zone_quads(gray: NDArray[np.uint8], window: int, offset: float, min_side_px: float, max_side_px: float,
                     min_solidity: float, max_ink_ratio: float) -> list[NDArray[np.float64]]:
    """Quads of the holes of the bright mask (:func:`bright_mask`) that are convex quadrilaterals inked
    as a marker is (:func:`_inked`).

    Parameters
    ----------
    gray : (H, W) uint8 image.
    window, offset : the bright mask's neighbourhood (pixels) and margin over its mean (grey levels).
    min_side_px, max_side_px : side range of the quads, pixels.
    min_solidity : least hole area / convex hull area.
    max_ink_ratio : the darkest tenth of a hole's pixels must be darker than this share of the ring's.

    Returns
    -------
    list of (4, 2) float64 quads, clockwise on screen, image pixels (OpenCV convention). A hole is the
    inner edge of the quiet zone, which is the marker's outer edge to within the blur.
    """
    contours, hier = cv2.findContours(bright_mask(gray, window, offset), cv2.RETR_CCOMP, cv2.CHAIN_APPROX_NONE)
    if hier is None:
        return []
    hier = hier[0]
    lengths = np.fromiter(map(len, contours), int, len(contours))
    # RETR_CCOMP: the holes are the contours with a parent, traced on the ring's innermost pixels, so
    # their outlines are about as long as the marker's
    lo, hi = 4 * min_side_px * 0.8, 4 * max_side_px * 1.3
    out = []
    for i in np.flatnonzero((hier[:, 3] >= 0) & (lengths >= lo) & (lengths <= hi)):
        q = _hole_quad(contours[i], min_side_px, max_side_px, min_solidity)
        if q is not None and _inked(gray, contours[i], max_ink_ratio):
            out.append(q)
    return out


def _inked(gray: NDArray[np.uint8], c: NDArray[np.int32], max_ratio: float) -> bool:
    """Whether the hole of contour ``c`` ((N, 1, 2) pixels, traced on the ring) holds ink: its darkest
    tenth of pixels below ``max_ratio`` times the ring's median level.

    The dark masks compare a pixel with an estimate of the paper around it; where that estimate fails (the
    closing on a texture) the ring itself is the paper, measured at the marker. A grey shape of the
    background enclosed by lighter surroundings makes a hole too (on the --quick set, two per image,
    which the second path's reads rejected at up to 20 ms each); ink on paper is darker than that.
    """
    pts = c.reshape(-1, 2)
    paper = float(np.median(gray[pts[:, 1], pts[:, 0]]))
    x0, y0, w, h = cv2.boundingRect(c)
    inside = np.zeros((h, w), np.uint8)
    cv2.fillPoly(inside, [pts - (x0, y0)], 255)
    ink = float(np.percentile(gray[y0:y0 + h, x0:x0 + w][inside > 0], 10))
    return ink < max_ratio * paper


def _hole_quad(c: NDArray[np.int32], min_side_px: float, max_side_px: float, min_solidity: float
               ) -> NDArray[np.float64] | None:
    """The quad (4, 2), clockwise on screen, of the hole contour ``c`` when it is a solid convex
    quadrilateral of the side range, else None."""
    q = solid_quad(c, min_side_px, max_side_px, min_solidity)
    if q is None:
        return None
    # OpenCV traces a hole on the ring's own pixels, the innermost bright ones, whose centres lie outside
    # the marker's edge (on the hard bench's 20-30 px tags the quads' sides came out 1.5 px long, median,
    # on the raw image; read from there the second path's fit started outside the border and lost 4 of 6
    # tags it reads from the true corners): the quad is shrunk by that much about its centre. (On the
    # second path's smoothed image the sides are 2.0 px long; shrunk by 2.0 it read 2 tags fewer of 720 on
    # seeds 1, 2, 5, 6 than by 1.5, within the scatter of such starts: the raw image's figure is kept.)
    ctr = q.mean(axis=0)
    side = float(np.hypot(*(q[_NEXT] - q).T).mean())
    return ctr + (q - ctr) * max(0.5, 1.0 - HOLE_EXCESS_PX / side)


#: how much longer (pixels) a side of a hole's quad is than the marker's (see :func:`_hole_quad`)
HOLE_EXCESS_PX = 1.5
