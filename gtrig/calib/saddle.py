"""Sub-pixel refinement of chessboard saddles on boards that print more than the chessboard near them.

Method
------
A saddle (the corner where two black squares touch) is found as ``cv2.cornerSubPix`` finds it: at an
ideal corner ``p`` every image gradient ``g(q)`` at a pixel ``q`` nearby is orthogonal to ``q - p``
(it is zero inside a square and across the edge elsewhere), so ``p`` solves the 2 x 2 normal equations
``sum w g g^T p = sum w g g^T q``, which are iterated while the window and mask follow ``p``.

A ChArUco board's white squares hold markers, whose edges break that orthogonality. The pixels are
therefore mapped into the board by a local homography (from the neighbouring corners) and only those
on the two board lines through the saddle are kept: a pixel counts when it lies within ``band`` squares
of one of the lines and within ``reach`` squares of the saddle along it. A marker of side ``marker_m``
centred in its square leaves a strip of ``(square_m - marker_m) / 2`` along the square's edges, so with
``band`` under that strip by :data:`GUARD_PX` (the blur of the print's edges) no marker edge enters,
while the window reaches as far along the edges as the chessboard's
(:func:`gtrig.calib.chessboard.detect_corners`).

Covariance
----------
Each corner's covariance carries the image's noise through the normal equations: a gradient error
``n`` moves the solution by ``A^-1 sum w g n . (q - p)`` (``A = sum w g g^T``), so the covariance is
``A^-1 (sigma_g^2 sum w^2 |q - p|^2 g g^T) A^-1``, with ``sigma_g`` the gradients' noise from the
image's (:func:`image_noise_grey`). Residuals ``g . (q - p)`` are not used: on a blurred saddle they
measure the edges' width more than the noise (Förstner's ``s^2 A^-1`` from them overstated the
variance about 16-fold on the simulator's sweeps).
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

#: corners moved farther than this share of the strip's width from their seed are not trusted
MAX_SHIFT_OF_BAND = 0.75
#: pixels of blur kept off a marker's edge
GUARD_PX = 2.0
#: iterations of the normal equations (each re-centres the window and the mask)
MAX_ITERATIONS = 8
#: stop when the corner moves less than this, pixels
TOLERANCE_PX = 1e-3


@dataclass(frozen=True)
class SaddleFit:
    """Refined saddles.

    Attributes
    ----------
    corners_px : (N, 2) refined pixel positions (pixel centres at integers); the seed where not ``ok``.
    cov_px : (N, 2, 2) covariance of each corner, px^2 (NaN where not ``ok``).
    ok : (N,) the refinement converged near its seed on enough edge pixels.
    """

    corners_px: np.ndarray
    cov_px: np.ndarray
    ok: np.ndarray


def local_homographies(board_uv: np.ndarray, corners_px: np.ndarray, max_dist: float = 1.0) -> np.ndarray:
    """Per corner, the homography (N, 3, 3) from board offsets ``(u, v)`` in squares from that corner to pixels.

    Parameters
    ----------
    board_uv : (N, 2) the corners' board positions, in squares.
    corners_px : (N, 2) their pixels.
    max_dist : the corners within this many squares (Chebyshev) of a corner fit its homography; with
        fewer than 4 corners not on a line, the neighbourhood is widened, up to the whole view.
    """
    n = len(board_uv)
    out = np.full((n, 3, 3), np.nan)
    if n < 4:
        return out
    for i in range(n):
        d = np.max(np.abs(board_uv - board_uv[i]), axis=1)
        for reach in (max_dist, 2 * max_dist, np.inf):
            sel = d <= reach
            uv = board_uv[sel] - board_uv[i]
            if sel.sum() >= 4 and np.ptp(uv[:, 0]) > 0 and np.ptp(uv[:, 1]) > 0:
                H, _ = cv2.findHomography(uv, corners_px[sel], 0)
                if H is not None:
                    out[i] = H
                    break
    return out


def _grid_to_board(H: np.ndarray, q: np.ndarray) -> np.ndarray:
    """Pixels (M, 2) to board offsets (M, 2) in squares by the inverse of ``H``."""
    Hi = np.linalg.inv(H)
    x = q @ Hi[:2, :2].T + Hi[:2, 2]
    w = q @ Hi[2, :2] + Hi[2, 2]
    return x / w[:, None]


def _window(grey: np.ndarray, centre: np.ndarray, half: int) -> tuple[np.ndarray, np.ndarray] | None:
    """The pixels (M, 2), their gradients (M, 2) in a square window of ``half`` pixels about ``centre``;
    None when the window leaves the image."""
    cx, cy = int(round(centre[0])), int(round(centre[1]))
    h, w = grey.shape
    if cx - half - 1 < 0 or cy - half - 1 < 0 or cx + half + 2 > w or cy + half + 2 > h:
        return None
    patch = grey[cy - half - 1:cy + half + 2, cx - half - 1:cx + half + 2].astype(np.float64)
    gx = 0.5 * (patch[1:-1, 2:] - patch[1:-1, :-2])
    gy = 0.5 * (patch[2:, 1:-1] - patch[:-2, 1:-1])
    ys, xs = np.mgrid[cy - half:cy + half + 1, cx - half:cx + half + 1]
    q = np.column_stack([xs.ravel(), ys.ravel()]).astype(np.float64)
    return q, np.column_stack([gx.ravel(), gy.ravel()])


def _solve(q: np.ndarray, g: np.ndarray, wt: np.ndarray, noise_grey: float
           ) -> tuple[np.ndarray, np.ndarray] | None:
    """The point ``p`` (2,) minimising ``sum wt (g . (q - p))^2`` and its covariance (2, 2), or None.

    The covariance carries the image noise (``noise_grey``, grey levels) through the gradients:
    ``A^-1 (sigma_g^2 sum wt^2 |q - p|^2 g g^T) A^-1`` with ``sigma_g^2 = noise_grey^2 / 2`` for central
    differences (module docstring).
    """
    G = g * np.sqrt(wt)[:, None]
    A = G.T @ G
    if np.linalg.cond(A) > 1e4:
        return None
    b = (g * (wt * np.einsum("ij,ij->i", g, q))[:, None]).sum(axis=0)
    p = np.linalg.solve(A, b)
    d2 = np.sum((q - p) ** 2, axis=1)
    Gb = g * (wt * np.sqrt(d2))[:, None]
    Ai = np.linalg.inv(A)
    return p, 0.5 * noise_grey**2 * Ai @ (Gb.T @ Gb) @ Ai


def image_noise_grey(grey: np.ndarray) -> float:
    """The image's noise, grey levels (1 sigma), robust to its edges: the median absolute value of the
    3 x 3 Laplacian-difference filter that cancels planes (Immerkær's), whose noise gain is 6."""
    k = np.array([[1.0, -2.0, 1.0], [-2.0, 4.0, -2.0], [1.0, -2.0, 1.0]])
    L = cv2.filter2D(np.asarray(grey, dtype=np.float32), cv2.CV_32F, k)[1:-1, 1:-1]
    return max(1.4826 * float(np.median(np.abs(L))) / 6.0, 0.1)


def refine_one(grey: np.ndarray, seed_px: np.ndarray, H_board_px: np.ndarray, margin: float, reach: float,
               noise_grey: float, guard_px: float = GUARD_PX) -> tuple[np.ndarray, np.ndarray] | None:
    """One saddle refined from ``seed_px`` (2,) (module docstring): its pixel (2,) and covariance (2, 2).

    Parameters
    ----------
    H_board_px : (3, 3) board offsets in squares from this corner to pixels (:func:`local_homographies`).
    margin : the strip free of anything but the chessboard along each board line through the saddle,
        half-width, squares; the kept strip is narrower by ``guard_px`` pixels (the blur of the print's edges).
    reach : how far along the lines the window reaches, squares.
    noise_grey : the image's noise, grey levels (:func:`image_noise_grey`), for the covariance.

    Returns None when the window leaves the image, the edges do not fix the point, or it moved farther
    than :data:`MAX_SHIFT_OF_BAND` of the strip from the seed.
    """
    # the window's size in pixels: the reach along either board axis, at the seed
    J = _jacobian(H_board_px)
    scale = np.linalg.norm(J, axis=0)  # pixels per square along u and v
    half = int(np.ceil(reach * float(scale.max())))
    band_px = margin * float(scale.min()) - guard_px
    if half < 2 or band_px < 1.0:
        return None
    band = band_px / float(scale.min())
    p = np.asarray(seed_px, dtype=np.float64)
    out = None
    for _ in range(MAX_ITERATIONS):
        win = _window(grey, p, half)
        if win is None:
            return None
        q, g = win
        # the homography follows the saddle: the board's origin moved onto the current estimate
        H = _translated(H_board_px, p)
        uv = _grid_to_board(H, q)
        a = np.abs(uv)
        keep = (np.minimum(a[:, 0], a[:, 1]) < band) & (np.maximum(a[:, 0], a[:, 1]) < reach)
        wt = keep * np.exp(-0.5 * (np.maximum(a[:, 0], a[:, 1]) / (0.6 * reach)) ** 2)
        if keep.sum() < 12:
            return None
        out = _solve(q, g, wt, noise_grey)
        if out is None:
            return None
        moved = float(np.linalg.norm(out[0] - p))
        p = out[0]
        if np.linalg.norm(p - seed_px) > max(MAX_SHIFT_OF_BAND * band_px, 0.75):
            return None
        if moved < TOLERANCE_PX:
            break
    return out


def _translated(H: np.ndarray, origin_px: np.ndarray) -> np.ndarray:
    """``H`` followed by the image translation that takes its origin's pixel onto ``origin_px``."""
    d = np.asarray(origin_px, dtype=np.float64) - H[:2, 2] / H[2, 2]
    T = np.array([[1.0, 0.0, d[0]], [0.0, 1.0, d[1]], [0.0, 0.0, 1.0]])
    return T @ H


def _jacobian(H: np.ndarray) -> np.ndarray:
    """d pixel / d (u, v) (2, 2) of a homography at the board origin."""
    w = H[2, 2]
    return (H[:2, :2] * w - np.outer(H[:2, 2], H[2, :2])) / w**2


def refine_saddles(grey: np.ndarray, seeds_px: np.ndarray, H_board_px: np.ndarray, margin: float,
                   reach: float, guard_px: float = GUARD_PX) -> SaddleFit:
    """Saddles (N, 2) refined from ``seeds_px`` with :func:`refine_one` (module docstring).

    Parameters
    ----------
    grey : (H, W) 8-bit grey image.
    seeds_px : (N, 2) starting pixels.
    H_board_px : (N, 3, 3) per corner, board offsets in squares to pixels (:func:`local_homographies`).
    margin, reach, guard_px : the strip and window (:func:`refine_one`).
    """
    seeds = np.asarray(seeds_px, dtype=np.float64).reshape(-1, 2)
    corners = seeds.copy()
    cov = np.full((len(seeds), 2, 2), np.nan)
    ok = np.zeros(len(seeds), dtype=bool)
    img = np.asarray(grey)
    noise = image_noise_grey(img)
    for i, s in enumerate(seeds):
        if not np.all(np.isfinite(H_board_px[i])):
            continue
        r = refine_one(img, s, H_board_px[i], margin, reach, noise, guard_px)
        if r is not None:
            corners[i], cov[i], ok[i] = r[0], r[1], True
    return SaddleFit(corners, cov, ok)
