"""Exact, vectorised 2D ray casting against line segments and circles.

Every function broadcasts: rays have shape ``(..., 2)`` and the geometry ``(..., S, 2, 2)`` (segments)
or ``(..., C, 2)`` (circle centres), where the leading axes broadcast against the rays' leading axes.
So one call can cast a whole batch of scans against a static scene (geometry without leading axes) or
against per-ray moving geometry (geometry with the rays' leading axes).

Distances are along the ray in units of ``|dirs|`` (metres for unit directions); ``inf`` means no hit.
A ray never hits geometry behind its origin or a segment parallel to it (a grazing ray sees no
surface, as a real beam gets no echo from a surface seen edge-on).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

Array = NDArray[np.float64]

# Hits closer than this to the origin are ignored: a surface through the scanner's own centre is not seen.
MIN_DISTANCE = 1e-12


def _cross(ax: Array, ay: Array, bx: Array, by: Array) -> Array:
    return ax * by - ay * bx


def cast_segments(
    origins: ArrayLike,
    dirs: ArrayLike,
    segments: ArrayLike,
    z0: ArrayLike | None = None,
    dz: ArrayLike | None = None,
    z_top: ArrayLike | None = None,
) -> tuple[Array, NDArray[np.intp]]:
    """First hit of each ray among line segments.

    Parameters
    ----------
    origins : (..., 2) ray origins.
    dirs : (..., 2) ray directions (need not be unit; distances are in multiples of them).
    segments : (..., S, 2, 2) segment end points ``[[x0, y0], [x1, y1]]``; leading axes broadcast
        against those of the rays.
    z0, dz, z_top : optional 2.5D test for vertical faces of finite height: a hit at distance ``t`` is
        at height ``z0 + t * dz`` ((...,) each, per ray) and only counts if that height is at most
        ``z_top`` ((..., S), per segment; ``inf`` for full-height walls).

    Returns
    -------
    dist : (...,) distance to the first hit, ``inf`` if none.
    index : (...,) index of the segment hit, -1 if none.
    """
    o = np.asarray(origins, dtype=float)[..., None, :]
    d = np.asarray(dirs, dtype=float)[..., None, :]
    seg = np.asarray(segments, dtype=float)
    p = seg[..., 0, :]
    e = seg[..., 1, :] - p
    wx = p[..., 0] - o[..., 0]
    wy = p[..., 1] - o[..., 1]
    den = _cross(d[..., 0], d[..., 1], e[..., 0], e[..., 1])
    with np.errstate(divide="ignore", invalid="ignore"):
        t = _cross(wx, wy, e[..., 0], e[..., 1]) / den
        u = _cross(wx, wy, d[..., 0], d[..., 1]) / den
    ok = (den != 0) & (t > MIN_DISTANCE) & (u >= 0.0) & (u <= 1.0)
    if z_top is not None:
        if z0 is None or dz is None:
            raise ValueError("z_top needs z0 and dz")
        z = np.asarray(z0, dtype=float)[..., None] + t * np.asarray(dz, dtype=float)[..., None]
        ok &= z <= np.asarray(z_top, dtype=float)
    t = np.where(ok, t, np.inf)
    if t.shape[-1] == 0:
        shape = t.shape[:-1]
        return np.full(shape, np.inf), np.full(shape, -1, dtype=np.intp)
    idx = np.argmin(t, axis=-1)
    dist = np.take_along_axis(t, idx[..., None], axis=-1)[..., 0]
    return dist, np.where(np.isfinite(dist), idx, -1)


def cast_circles(
    origins: ArrayLike, dirs: ArrayLike, centres: ArrayLike, radii: ArrayLike
) -> tuple[Array, NDArray[np.intp]]:
    """First hit of each ray among circles (vertical cylinders cut by the scan plane).

    Parameters
    ----------
    origins : (..., 2) ray origins.
    dirs : (..., 2) unit ray directions.
    centres : (..., C, 2) circle centres; leading axes broadcast against those of the rays.
    radii : (C,) or (..., C) radii.

    Returns
    -------
    dist : (...,) distance to the first entry point, ``inf`` if none. A ray starting inside a circle
        does not see it (a scanner cannot look out of an object).
    index : (...,) index of the circle hit, -1 if none.
    """
    o = np.asarray(origins, dtype=float)[..., None, :]
    d = np.asarray(dirs, dtype=float)[..., None, :]
    c = np.asarray(centres, dtype=float)
    r = np.asarray(radii, dtype=float)
    wx = o[..., 0] - c[..., 0]
    wy = o[..., 1] - c[..., 1]
    b = d[..., 0] * wx + d[..., 1] * wy
    cc = wx * wx + wy * wy - r * r
    disc = b * b - cc
    with np.errstate(invalid="ignore"):
        t = -b - np.sqrt(disc)
    ok = (disc >= 0) & (cc > 0) & (t > MIN_DISTANCE)
    t = np.where(ok, t, np.inf)
    if t.shape[-1] == 0:
        shape = t.shape[:-1]
        return np.full(shape, np.inf), np.full(shape, -1, dtype=np.intp)
    idx = np.argmin(t, axis=-1)
    dist = np.take_along_axis(t, idx[..., None], axis=-1)[..., 0]
    return dist, np.where(np.isfinite(dist), idx, -1)


def cast(
    origins: ArrayLike,
    dirs: ArrayLike,
    segments: ArrayLike | None = None,
    centres: ArrayLike | None = None,
    radii: ArrayLike | None = None,
) -> tuple[Array, NDArray[np.intp]]:
    """First hit among segments and circles together.

    Returns
    -------
    dist : (...,) distance, ``inf`` if nothing is hit.
    index : (...,) index of the object hit: segments first (0 .. S-1), then circles (S .. S+C-1);
        -1 if none.
    """
    o = np.asarray(origins, dtype=float)
    d = np.asarray(dirs, dtype=float)
    shape = np.broadcast_shapes(o.shape[:-1], d.shape[:-1])
    dist: Array = np.full(shape, np.inf)
    index: NDArray[np.intp] = np.full(shape, -1, dtype=np.intp)
    n_seg = 0
    if segments is not None:
        segments = np.asarray(segments, dtype=float)
        n_seg = segments.shape[-3]
        dist, index = cast_segments(o, d, segments)
    if centres is not None:
        if radii is None:
            raise ValueError("circles need radii")
        dc, jc = cast_circles(o, d, centres, radii)
        closer = dc < dist
        dist = np.where(closer, dc, dist)
        index = np.where(closer, jc + n_seg, index)
    return dist, index
