"""Compiled (numba) mean grey level of an 8-bit image's square cells: the tracker's change test
(:func:`gtrig.vision.track.cell_means`) runs it on every image, where converting the whole image to float
and area-resizing it cost about a millisecond at 1024 x 768.
"""

from __future__ import annotations

import numba as nb
import numpy as np


@nb.njit(nb.void(nb.types.Array(nb.uint8, 2, "A", readonly=True), nb.int64, nb.float32[:, ::1]),
         cache=True, nogil=True)
def cell_means_into(image: np.ndarray, cell_px: int, out: np.ndarray) -> None:
    """Fill ``out`` (H // cell_px, W // cell_px) with the mean of each ``cell_px`` x ``cell_px`` cell of
    ``image`` (H, W) uint8, cells from the top-left corner (the rows and columns past the last whole cell
    are not read). Each mean is its cell's integer sum over the cell's pixel count, rounded once to float32:
    what OpenCV's area resize gives at an integer factor."""
    rows, cols = out.shape
    width = cols * cell_px
    column_sums = np.empty(width, np.uint32)
    inv = 1.0 / (cell_px * cell_px)
    for r in range(rows):
        column_sums[:] = 0
        for y in range(r * cell_px, (r + 1) * cell_px):
            line = image[y]
            for x in range(width):  # a row at a time: the compiler vectorises it
                column_sums[x] += line[x]
        for c in range(cols):
            s = np.uint32(0)
            for x in range(c * cell_px, (c + 1) * cell_px):
                s += column_sums[x]
            out[r, c] = np.float32(s * inv)
