"""Decoding after rectification: sample the cells through the homography of the refined corners."""

from __future__ import annotations

import functools

import cv2
import numpy as np
from numpy.typing import NDArray

from gtrig.markers.detect import _kernels
from gtrig.markers.detect._blas import gram, matmul
from gtrig.markers.detect.camera import Undistorter
from gtrig.markers.detect.edges import quad_homographies
from gtrig.markers.detect.sampling import bilinear

#: share of the design's entries set (:func:`._kernels.unblur_rows`) below which its normal matrix is summed
#: sparsely (:func:`._kernels.sparse_gram`), above which by BLAS's syrk
SPARSE_SHARE = 0.15

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
    vals = bilinear(gray, flat[:, 0], flat[:, 1])
    vals = vals.reshape(Q, m, 3, m, 3).transpose(0, 1, 3, 2, 4).reshape(Q, m, m, 9)
    if return_samples:
        return vals.mean(axis=3), vals
    return vals.mean(axis=3)


@functools.cache
def _data_samples(n: int, border: int) -> NDArray[np.float64]:
    """(S, 3) homogeneous marker-unit points of the 3 x 3 samples of every data cell of an ``n x n`` grid with a
    ``border``-cell border, row by row (the same for every quad; shared, not to be written)."""
    c = (np.arange(border, n - border)[:, None] + 0.5 + _OFFS[None, :]).ravel() / n  # (3 d,)
    gy, gx = np.meshgrid(c, c, indexing="ij")
    return np.ascontiguousarray(np.stack([gx.ravel(), gy.ravel(), np.ones(gx.size)], -1))


def unblur_cells(
    gray: NDArray[np.uint8],
    quads: NDArray[np.float64],
    n: int,
    border: int,
    sigma: NDArray[np.float64],
    black: NDArray[np.float64],
    contrast: NDArray[np.float64],
    undist: Undistorter | None = None,
) -> NDArray[np.float64]:
    """Whiteness of the data cells, solved from the blurred image by linear least squares.

    On small or blurred markers a white cell surrounded by black ones peaks below the midway
    threshold (20 px AprilTag 36h11 at 45 deg tilt and blur 1 px: about 45 % of the contrast), so
    cells read one by one flip. The blurred marker is linear in the cells' whiteness ``W``:
    ``I = black + contrast (1 - S + sum_ij W_ij Y_i X_j)`` with the blurred-box profiles of
    :func:`.edges.marker_context`; this solves that model for ``W`` from 3 x 3 samples per data cell
    (a small Tikhonov term towards 0.5 keeps it stable when the blur is large).

    Parameters
    ----------
    gray : (H, W) uint8 raw image.
    quads : (Q, 4, 2) refined corners, fit coordinates, clockwise on screen.
    n, border : cells per side (border included) and border width, cells.
    sigma, black, contrast : (Q,) blur (pixels) and levels (grey levels) from the edge fits.
    undist : as in :func:`sample_cells`.

    Returns
    -------
    (Q, n - 2 border, n - 2 border) float, about 0 for black and 1 for white cells, in the quads'
    orientation.
    """
    d = n - 2 * border
    Q = len(quads)
    mu = _data_samples(n, border)  # (S, 3) marker units
    Hm = quad_homographies(quads)  # fit coords -> marker units
    # every quad at once (the loop over quads with a dozen small array operations each was most of
    # the cost): the same element-wise formulas, and one batched solve
    p = mu @ np.linalg.inv(Hm).transpose(0, 2, 1)  # (Q, S, 3)
    px = p[..., :2] / p[..., 2:]
    flat = px.reshape(-1, 2)
    if undist is not None:
        flat = undist.to_raw(flat)
    vals = bilinear(gray, flat[:, 0], flat[:, 1]).reshape(Q, -1)
    # the design by the compiled kernel (every sample's product of the cells' profiles across the two
    # axes, 0 where negligible); its normal matrix by syrk where it is dense, by the products of each
    # row's non-zero entries where it is sparse (sharp markers: 1-4 of the d^2 per row)
    M, r, nnz = _kernels.unblur_rows(np.ascontiguousarray(px), mu, np.ascontiguousarray(Hm),
                                     np.ascontiguousarray(vals, np.float64), np.ascontiguousarray(sigma, np.float64),
                                     np.ascontiguousarray(black, np.float64),
                                     np.ascontiguousarray(contrast, np.float64), n, border)
    dense = nnz > SPARSE_SHARE * M.shape[1] * M.shape[2]
    A = np.empty((Q, d * d, d * d))
    if dense.any():
        A[dense] = gram(M[dense])
    for i in np.flatnonzero(~dense):
        A[i] = _kernels.sparse_gram(M[i])
    rhs = matmul(M.transpose(0, 2, 1), r[..., None])[..., 0]
    lam = 1e-2 * np.trace(A, axis1=1, axis2=2) / (d * d)
    w = np.linalg.solve(A + lam[:, None, None] * np.eye(d * d), rhs[..., None] + lam[:, None, None] * 0.5)
    return w.reshape(Q, d, d)


def soft_code_margin(
    whiteness: NDArray[np.floating], codes: NDArray[np.generic], codes_sq: NDArray[np.float64] | None = None
) -> tuple[NDArray[np.int64], NDArray[np.float64]]:
    """The code nearest the solved cells in the least-squares sense, and its lead over the runner-up.

    A hard decoder counts wrong cells and forgets by how much each was wrong; the blur model's cell
    estimates (:func:`unblur_cells`) keep it. A true marker's cells lie near 0 and 1 and its code's
    residual is small against the at least ``h_min`` cells that separate it from any other code; where
    the cells are lost (a motion streak longer than two cells, a defocus disk of most of a cell) they
    scatter across and beyond [0, 1] and the nearest code leads the next one by little, though its
    hard reading may still lie within the family's correction.

    Parameters
    ----------
    whiteness : (Q, d, d) float, the solved data cells (about 0 black, 1 white), in the quads' orientation.
    codes : (K, d, d) or (K, d^2) 0 / 1, every code in each rotation as read in a quad's orientation (float64
        rows are used as they are: :class:`.verify.CodeBook` keeps them so).
    codes_sq : (K,) float, each code's sum of squares, when the caller keeps it (computed otherwise).

    Returns
    -------
    best : (Q,) int, index into ``codes`` of the least sum of squared differences ``D1``.
    margin : (Q,) float, ``(D2 - D1) / (D1 / d^2)``, the runner-up's excess ``D2 - D1`` in units of the
        cells' residual variance estimated from the best code's own fit (chi-square units).
    """
    w = whiteness.reshape(len(whiteness), -1).astype(np.float64)
    c = np.asarray(codes.reshape(len(codes), -1), np.float64)
    c_sq = (c * c).sum(axis=1) if codes_sq is None else codes_sq
    # |w - c|^2 = |w|^2 - 2 w.c + |c|^2, one product for every code (4096 ids x 4 rotations for BCH)
    d2 = (w * w).sum(axis=1)[:, None] - 2.0 * (w @ c.T) + c_sq[None, :]
    two = np.argpartition(d2, 1, axis=1)[:, :2]
    pair = np.take_along_axis(d2, two, axis=1)
    order = np.argsort(pair, axis=1)
    best = np.take_along_axis(two, order[:, :1], axis=1)[:, 0]
    d1, d2nd = np.take_along_axis(pair, order, axis=1).T
    var = np.maximum(d1, 1e-12) / w.shape[1]
    return best.astype(np.int64), (d2nd - d1) / var
