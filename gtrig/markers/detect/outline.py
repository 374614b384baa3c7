"""A candidate's outline moved onto the marker's outer edge, before the second path reads it.

The second path's reader (:func:`.blurred.read_blurred`) fits the corners and the blur of a small,
blurred marker by Gauss-Newton from the candidate's quad. Its basin is about a pixel: on the harder
bench's 20 px tags (2.5 px cells) the model at a geometry 1-1.5 px off leaves a misfit of 0.15-0.25 of
the contrast, above what its start screen lets through (a screen it needs, or clutter costs a fit
each), and the free fit from there converges to the wrong square half the time (BENCHMARKS.md,
issue 16, session 37: from the TRUE corners moved by 1 / 1.5 px RMS, 57 / 26 % of the 20 px tags of
seeds 0-1 read, against 82 % from the true corners). The candidates come 1-4 px off: a quiet-zone
hole is traced on the paper's innermost pixels, a dark blob's outline follows a threshold of a blurred
border, and a blob notched or bulged by a white cell or a neighbouring shape bends the quad.

The marker's outer edge is where the paper of the quiet zone meets the black border, a step from
bright to dark one cell wide on the dark side whatever the cells behind it, straight along the whole
side. Across each side, at every pixel along its middle, the mean of a cell's width of image outside
a line minus the mean of a cell's width inside peaks at that edge (for any symmetric blur, and whether
the cell behind the border is black or white); a robust line through the peaks and the four lines'
intersections give the outline (:func:`snap_to_border`). On those 20 px tags the snapped quads lie
0.8 px from the true corners (median of the largest corner error) from starts 0-1.5 px off, and 80 %
of them read, whatever the start's error.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from gtrig.markers.detect.sampling import bilinear

__all__ = ["snap_to_border"]

_NEXT = np.array([1, 2, 3, 0])


def snap_to_border(gray: NDArray[np.uint8], quad: NDArray[np.float64], cells: int, reach_px: float = 3.0,
                   step_px: float = 0.5, ends: float = 0.15) -> NDArray[np.float64] | None:
    """The quad ``quad`` with each side moved onto the marker's outer edge (module docstring).

    Parameters
    ----------
    gray : (H, W) uint8 image (pixel centres at integer coordinates).
    quad : (4, 2) candidate corners, pixels, either orientation.
    cells : cells per side of the marker, border included (its border is one cell wide).
    reach_px : how far (pixels) each side is searched either way along its normal.
    step_px : the search's step, pixels (each peak is then refined by a parabola).
    ends : share of each side left out at either end (near a corner the two sides' steps mix).

    Returns
    -------
    (4, 2) corners in the order of ``quad``, pixels, or None when a side shows no step from bright
    outside to dark inside at 4 places or more, the lines meet nowhere near ``quad`` (a corner moved
    more than ``2 reach_px``) or the quad is degenerate.
    """
    q = np.asarray(quad, np.float64)
    a, b = q, q[_NEXT]
    length = np.hypot(*(b - a).T)  # (4,)
    if length.min() < 4.0:
        return None
    cell = max(float(length.mean()) / cells, 1.0)
    tangent = (b - a) / length[:, None]
    normal = np.stack([tangent[:, 1], -tangent[:, 0]], -1)
    # outward: away from the centre
    normal[np.einsum("ij,ij->i", 0.5 * (a + b) - q.mean(axis=0), normal) < 0] *= -1.0
    n_t = max(int(length.min() * (1.0 - 2.0 * ends)), 4)
    t = np.linspace(ends, 1.0 - ends, n_t)
    s = np.arange(-reach_px, reach_px + 1e-9, step_px)  # (S,) the edge's trial offsets
    k = np.arange(0.5, cell + 1e-9, 1.0)  # (K,) sample depths within a cell's width
    depth = np.concatenate([s[:, None] + k, s[:, None] - k], axis=1)  # (S, 2K): outside, then inside
    base = a[:, None, :] + t[None, :, None] * (b - a)[:, None, :]  # (4, T, 2)
    pts = base[:, :, None, None, :] + depth[None, None, :, :, None] * normal[:, None, None, None, :]
    v = bilinear(gray, pts[..., 0].ravel(), pts[..., 1].ravel()).reshape(4, n_t, len(s), 2, len(k))
    resp = v[..., 0, :].mean(axis=-1) - v[..., 1, :].mean(axis=-1)  # (4, T, S) outside - inside
    off = _peaks(resp.reshape(4 * n_t, len(s)), s, step_px).reshape(4, n_t)
    ok = np.isfinite(off)
    if ok.sum(axis=1).min() < 4:
        return None
    lines = _robust_lines(base + np.where(ok, off, 0.0)[..., None] * normal[:, None, :], ok)
    # corner i on lines i - 1 and i, by Cramer's rule
    n1, n2 = lines[[3, 0, 1, 2], :2], lines[:, :2]
    c1, c2 = lines[[3, 0, 1, 2], 2], lines[:, 2]
    det = n1[:, 0] * n2[:, 1] - n1[:, 1] * n2[:, 0]
    if np.abs(det).min() < 1e-6:
        return None
    out = np.stack([(c1 * n2[:, 1] - c2 * n1[:, 1]) / det, (n1[:, 0] * c2 - n2[:, 0] * c1) / det], -1)
    return out if np.abs(out - q).max() <= 2.0 * reach_px else None


def _robust_lines(p: NDArray[np.float64], keep: NDArray[np.bool_]) -> NDArray[np.float64]:
    """Lines (L, 3) as ``(nx, ny, c)`` with ``n . x = c``, ``|n| = 1``, through the points ``p`` (L, P, 2)
    flagged in ``keep`` (L, P), at least 4 per line: the total least-squares line, refitted once without
    the points more than 1 px and 2.5 robust SDs off it (a peak caught by a cell's edge behind the
    border, or by a neighbouring shape)."""
    for it in range(2):
        w = keep.astype(np.float64)
        ctr = np.einsum("lp,lpk->lk", w, p) / w.sum(axis=1)[:, None]
        d = p - ctr[:, None, :]
        sxx = np.einsum("lp,lp->l", w, d[..., 0] ** 2)
        syy = np.einsum("lp,lp->l", w, d[..., 1] ** 2)
        sxy = np.einsum("lp,lp->l", w, d[..., 0] * d[..., 1])
        # the line's direction is the principal axis of the points' scatter, its normal at right angles
        ang = 0.5 * np.arctan2(2.0 * sxy, sxx - syy)
        n = np.stack([-np.sin(ang), np.cos(ang)], -1)
        if it == 1:
            break
        r = np.abs(np.einsum("lpk,lk->lp", d, n))
        # the median of each line's kept residuals (np.nanmedian is ten times slower on these sizes)
        srt = np.sort(np.where(keep, r, np.inf), axis=1)
        sd = 1.4826 * np.take_along_axis(srt, (keep.sum(axis=1, keepdims=True) - 1) // 2, axis=1)
        new = keep & (r <= np.maximum(1.0, 2.5 * sd))
        keep = np.where(new.sum(axis=1, keepdims=True) >= 4, new, keep)
    return np.concatenate([n, np.einsum("lk,lk->l", n, ctr)[:, None]], axis=1)


def _peaks(resp: NDArray[np.float64], s: NDArray[np.float64], step: float) -> NDArray[np.float64]:
    """Offset (T,) of the largest positive response of each row of ``resp`` (T, S) over the offsets
    ``s`` (S,), refined by a parabola through its neighbours; NaN where the peak is not positive or
    lies at an end of the range (the edge is beyond it)."""
    rows = np.arange(len(resp))
    j = np.argmax(resp, axis=1)
    r0 = resp[rows, j]
    inner = (j > 0) & (j < len(s) - 1) & (r0 > 0)
    rm, rp = resp[rows, np.maximum(j - 1, 0)], resp[rows, np.minimum(j + 1, len(s) - 1)]
    den = rm - 2.0 * r0 + rp
    frac = np.where(inner & (den < 0), 0.5 * (rm - rp) / np.where(den < 0, den, -1.0), 0.0)
    return np.where(inner, s[j] + frac * step, np.nan)
