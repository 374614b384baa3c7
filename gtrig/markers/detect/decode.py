"""Decoding after rectification: sample the cells through the homography of the refined corners."""

from __future__ import annotations

import cv2
import numpy as np
from numpy.typing import NDArray

from gtrig.markers.detect.camera import Undistorter

# sub-samples per cell, as offsets from its centre in cell units (the middle half of the cell)
_OFFS = np.array([-0.25, 0.0, 0.25])


def sample_cells(
    gray: NDArray[np.uint8], quads: NDArray[np.float64], n: int, undist: Undistorter | None = None,
    ring: int = 0, return_samples: bool = False,
) -> NDArray[np.float64] | tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Mean intensity of every cell of ``n x n`` grids spanned by ``quads`` (Q, 4, 2).

    ``quads`` are fit coordinates, clockwise on screen; cell (0, 0) touches corner 0, cell (0, n-1)
    corner 1. Each cell is the mean of 3 x 3 bilinear samples in its middle half. With ``ring = 1``
    a ring of cells outside the square (the white quiet zone) is sampled too.

    Returns
    -------
    (Q, n + 2 ring, n + 2 ring) float, and with ``return_samples`` also the 9 samples of every cell,
    (Q, n + 2 ring, n + 2 ring, 9).
    """
    Q = len(quads)
    m = n + 2 * ring
    c = (np.arange(-ring, n + ring)[:, None] + 0.5 + _OFFS[None, :]).ravel() / n  # (m*3,)
    gy, gx = np.meshgrid(c, c, indexing="ij")
    unit = np.stack([gx.ravel(), gy.ravel(), np.ones(gx.size)], -1)  # (S, 3)
    src = np.array([[0, 0], [1, 0], [1, 1], [0, 1]], np.float32)
    pts = np.empty((Q, unit.shape[0], 2))
    for q in range(Q):
        H = cv2.getPerspectiveTransform(src, quads[q].astype(np.float32))
        p = unit @ H.T
        pts[q] = p[:, :2] / p[:, 2:]
    flat = pts.reshape(-1, 2)
    if undist is not None:
        flat = undist.to_raw(flat)
    mx = flat[:, 0].astype(np.float32).reshape(1, -1)
    my = flat[:, 1].astype(np.float32).reshape(1, -1)
    vals = cv2.remap(gray, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE).astype(np.float64)
    vals = vals.reshape(Q, m, 3, m, 3).transpose(0, 1, 3, 2, 4).reshape(Q, m, m, 9)
    if return_samples:
        return vals.mean(axis=3), vals
    return vals.mean(axis=3)
