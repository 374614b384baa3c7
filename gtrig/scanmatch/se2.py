"""Planar rigid transforms as ``(x, y, theta)`` triples: compose, invert, relative pose, apply.

All functions broadcast over leading axes: ``(..., 3)`` poses, ``(..., N, 2)`` points. Angles are
radians, wrapped to (-pi, pi] on output where a function says so.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike


def wrap(a: ArrayLike) -> np.ndarray:
    """Angles wrapped to (-pi, pi]."""
    a = np.asarray(a, dtype=float)
    return np.pi - np.mod(np.pi - a, 2 * np.pi)


def compose(a: ArrayLike, b: ArrayLike) -> np.ndarray:
    """``a (+) b``: pose ``b`` expressed in frame ``a``, returned in ``a``'s parent frame. (..., 3)."""
    a = np.asarray(a, dtype=float)
    b = np.asarray(b, dtype=float)
    c, s = np.cos(a[..., 2]), np.sin(a[..., 2])
    x = a[..., 0] + c * b[..., 0] - s * b[..., 1]
    y = a[..., 1] + s * b[..., 0] + c * b[..., 1]
    return np.stack([x, y, wrap(a[..., 2] + b[..., 2])], axis=-1)


def inverse(a: ArrayLike) -> np.ndarray:
    """``(-) a``: the inverse transform. (..., 3)."""
    a = np.asarray(a, dtype=float)
    c, s = np.cos(a[..., 2]), np.sin(a[..., 2])
    x = -c * a[..., 0] - s * a[..., 1]
    y = s * a[..., 0] - c * a[..., 1]
    return np.stack([x, y, wrap(-a[..., 2])], axis=-1)


def relative(a: ArrayLike, b: ArrayLike) -> np.ndarray:
    """``(-) a (+) b``: pose ``b`` in the frame of pose ``a`` (both in one parent frame). (..., 3)."""
    return compose(inverse(a), b)


def apply(pose: ArrayLike, xy: ArrayLike) -> np.ndarray:
    """Points ``xy`` (..., N, 2) in frame ``pose`` mapped to its parent frame (pose (..., 3))."""
    p = np.asarray(pose, dtype=float)
    q = np.asarray(xy, dtype=float)
    c, s = np.cos(p[..., 2])[..., None], np.sin(p[..., 2])[..., None]
    x = p[..., 0][..., None] + c * q[..., 0] - s * q[..., 1]
    y = p[..., 1][..., None] + s * q[..., 0] + c * q[..., 1]
    return np.stack([x, y], axis=-1)


def adjoint(pose: ArrayLike) -> np.ndarray:
    """(3, 3) adjoint of ``pose``: maps a perturbation expressed in the pose's own frame to its parent
    frame, for poses used as ``T (+) delta`` (local) and ``delta (+) T`` (world) respectively."""
    x, y, th = np.asarray(pose, dtype=float)
    c, s = np.cos(th), np.sin(th)
    return np.array([[c, -s, y], [s, c, -x], [0.0, 0.0, 1.0]])


def from_matrix(T: ArrayLike) -> np.ndarray:
    """(..., 3) planar poses from (..., 4, 4) or (..., 3, 3) homogeneous transforms (yaw of the x axis)."""
    T = np.asarray(T, dtype=float)
    t = T[..., :2, -1]
    th = np.arctan2(T[..., 1, 0], T[..., 0, 0])
    return np.concatenate([t, th[..., None]], axis=-1)
