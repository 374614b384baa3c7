"""Bilinear sampling of an image at arbitrary points, safe for any image size.

``cv2.remap`` asserts that both its source and its destination are smaller than ``SHRT_MAX``
(32767) in each dimension: the detector's batched reads (every cell of every candidate in one
call) exceed that on a busy 12-megapixel photo. :func:`bilinear` lays the points out as rows of
at most :data:`CHUNK` samples, calls ``cv2.remap`` on blocks of at most :data:`CHUNK` rows, and
falls back to the same interpolation in NumPy for a source image with a side of 32767 px or more.
"""

from __future__ import annotations

import cv2
import numpy as np
from numpy.typing import NDArray

__all__ = ["CHUNK", "bilinear"]

#: Largest side of one ``cv2.remap`` destination (below OpenCV's ``SHRT_MAX`` limit).
CHUNK = 16384
_SHRT_MAX = 32767


def bilinear(gray: NDArray[np.uint8], x: NDArray[np.floating], y: NDArray[np.floating]) -> NDArray[np.float64]:
    """Bilinearly interpolated ``gray`` at the points ``(x, y)``, replicating the border.

    Parameters
    ----------
    gray : (H, W) uint8 image, pixel centres at integer coordinates (OpenCV's convention).
    x, y : (N,) pixel coordinates (any float dtype; converted to float32 as ``cv2.remap`` needs).

    Returns
    -------
    (N,) float64 intensities. Points outside the image read the nearest border pixel; non-finite
    coordinates read the border too (``cv2.remap`` does so), never raise.
    """
    mx = np.asarray(x, np.float32).ravel()
    my = np.asarray(y, np.float32).ravel()
    n = mx.size
    if n == 0:
        return np.zeros(0, np.float64)
    h, w = gray.shape[:2]
    if h >= _SHRT_MAX or w >= _SHRT_MAX:
        return _bilinear_numpy(gray, mx, my)
    rows = -(-n // CHUNK)
    cols = min(n, CHUNK)
    pad = rows * cols - n
    if pad:
        mx = np.concatenate([mx, np.zeros(pad, np.float32)])
        my = np.concatenate([my, np.zeros(pad, np.float32)])
    mx2 = mx.reshape(rows, cols)
    my2 = my.reshape(rows, cols)
    out = np.empty((rows, cols), np.uint8 if gray.dtype == np.uint8 else np.float32)
    for r0 in range(0, rows, CHUNK):
        r1 = min(rows, r0 + CHUNK)
        out[r0:r1] = cv2.remap(gray, mx2[r0:r1], my2[r0:r1], cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
    return out.ravel()[:n].astype(np.float64)


def _bilinear_numpy(gray: NDArray[np.uint8], x: NDArray[np.float32], y: NDArray[np.float32]) -> NDArray[np.float64]:
    """:func:`bilinear` for sources beyond ``cv2.remap``'s limit, in blocks of ``CHUNK**2`` points."""
    h, w = gray.shape[:2]
    out = np.empty(x.size, np.float64)
    step = CHUNK * CHUNK
    for s in range(0, x.size, step):
        xs = np.nan_to_num(x[s : s + step].astype(np.float64), nan=0.0, posinf=w - 1, neginf=0.0)
        ys = np.nan_to_num(y[s : s + step].astype(np.float64), nan=0.0, posinf=h - 1, neginf=0.0)
        xs = np.clip(xs, 0.0, w - 1.0)
        ys = np.clip(ys, 0.0, h - 1.0)
        x0 = np.minimum(np.floor(xs).astype(np.intp), max(w - 2, 0))
        y0 = np.minimum(np.floor(ys).astype(np.intp), max(h - 2, 0))
        x1 = np.minimum(x0 + 1, w - 1)
        y1 = np.minimum(y0 + 1, h - 1)
        fx, fy = xs - x0, ys - y0
        g = gray
        top = g[y0, x0] * (1.0 - fx) + g[y0, x1] * fx
        bot = g[y1, x0] * (1.0 - fx) + g[y1, x1] * fx
        out[s : s + step] = top * (1.0 - fy) + bot * fy
    return out
