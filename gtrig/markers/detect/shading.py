"""Reading a marker's cells under glare: black and white levels that vary smoothly across the print.

A specular highlight on a glossy print (or a lamp's veil on laminated paper) adds light that changes
across the marker: in its middle the black cells rise towards the paper's level, at its edge they do
not. One level midway between the border's black and the paper's white (:meth:`MarkerDetector._bits`),
and the blur model's constant levels (:func:`.decode.unblur_cells`), then read black cells under the
highlight as white, or as split between the two (renders made apart from the project, issue 16,
session 42: 40-70 px markers under a highlight a third of their side wide, which OpenCV reads by
Otsu's threshold on its warped marker). Here each level is a quadratic surface over the marker, fitted
to the cells of that colour (the paper ring and the white data cells; the border and the black data
cells), and each cell is judged against the level midway between the two surfaces at that cell
(an EM-like alternation of fitting and labelling, a few rounds). A cell's samples must lie on one side
of its own midway level, and every cell within ``max_rel_residual`` of the contrast from its surface:
clutter's cells rarely fit two smooth surfaces, a glared print's do.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

__all__ = ["ShadedReading", "read_shaded"]


@dataclass(frozen=True)
class ShadedReading:
    """Cells read against the fitted surfaces, for Q candidates.

    Attributes
    ----------
    bits : (Q, n, n) uint8, 1 = white, the black square's cells (border included).
    mixed : (Q,) int, cells whose samples lie on both sides of their midway level (3 of 9 or more).
    contrast : (Q,) float, the least white - black difference of the surfaces over the square's cells.
    rel_residual : (Q,) float, the largest distance of a square's cell from its colour's surface, over the
        contrast at that cell.
    """

    bits: NDArray[np.uint8]
    mixed: NDArray[np.int64]
    contrast: NDArray[np.float64]
    rel_residual: NDArray[np.float64]


def _basis(m: int) -> NDArray[np.float64]:
    """(m * m, 6) quadratic monomials of the cell centres of an m x m grid, scaled to [-1, 1]."""
    t = np.linspace(-1.0, 1.0, m)
    gy, gx = np.meshgrid(t, t, indexing="ij")
    x, y = gx.ravel(), gy.ravel()
    return np.column_stack([np.ones_like(x), x, y, x * x, x * y, y * y])


def _fit(A: NDArray[np.float64], v: NDArray[np.float64], w: NDArray[np.bool_]) -> NDArray[np.float64]:
    """The surface ``A @ c`` fitted by least squares to the values ``v`` where ``w`` holds, at every cell."""
    c, *_ = np.linalg.lstsq(A[w], v[w], rcond=None)
    return A @ c


def read_shaded(vals: NDArray[np.float64], samples: NDArray[np.float64], n: int, border: int,
                rounds: int = 3) -> ShadedReading:
    """Read the cells of Q candidates against two quadratic surfaces of light (module docstring).

    Parameters
    ----------
    vals : (Q, n + 2, n + 2) float, cell means with the ring of paper outside (:func:`.decode.sample_cells`,
        ``ring=1``), grey levels.
    samples : (Q, n, n, 9) float, the 9 samples of each of the square's cells.
    n, border : cells per side of the black square, and of its border.
    rounds : label-and-fit rounds after the first fit (border black, ring white).
    """
    q_n, m = len(vals), n + 2
    A = _basis(m)
    ring = np.zeros((m, m), bool)
    ring[[0, -1], :] = ring[:, [0, -1]] = True
    frame = np.zeros((m, m), bool)
    frame[1:-1, 1:-1] = True
    frame[1 + border:-1 - border, 1 + border:-1 - border] = False
    data = ~(ring | frame)
    bits = np.zeros((q_n, n, n), np.uint8)
    mixed = np.zeros(q_n, np.int64)
    contrast = np.zeros(q_n)
    rel = np.full(q_n, np.inf)
    for k in range(q_n):
        v = vals[k].ravel()
        white = ring.ravel().copy()
        black = frame.ravel().copy()
        for _ in range(rounds + 1):
            lo, hi = _fit(A, v, black), _fit(A, v, white)
            mid = 0.5 * (lo + hi)
            is_white = v > mid
            # the ring is paper and the border ink whatever they read: only the data cells are labelled
            white = ring.ravel() | (data.ravel() & is_white)
            black = frame.ravel() | (data.ravel() & ~is_white)
        inner = ~ring.ravel()
        span = (hi - lo)[inner]
        contrast[k] = float(span.min())
        if contrast[k] <= 0:
            continue
        own = np.where(is_white, hi, lo)[inner]
        rel[k] = float(np.max(np.abs(v[inner] - own) / span))
        bits[k] = is_white[inner].reshape(n, n)
        above = (samples[k] > mid[inner].reshape(n, n)[..., None]).sum(axis=2)
        mixed[k] = int((np.minimum(above, samples.shape[3] - above) >= 3).sum())
    return ShadedReading(bits, mixed, contrast, rel)
