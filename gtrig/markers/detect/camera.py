"""Lens distortion for the detector: raw pixels <-> undistorted pixels (OpenCV's model)."""

from __future__ import annotations

import cv2
import numpy as np
from numpy.typing import NDArray

from gtrig import geometry as geo


class Undistorter:
    """Maps between raw pixels and undistorted pixels of a camera ``K``, ``dist`` (OpenCV model).

    Undistorted pixels are ``K @ (x_n, y_n, 1)`` for the normalised undistorted coordinates, so a
    camera without distortion maps every pixel to itself. ``map_x``, ``map_y`` (H, W) hold the
    undistorted coordinates of every raw pixel centre (computed once, with ``cv2.undistortPoints``).
    """

    def __init__(self, K: NDArray[np.float64], dist: NDArray[np.float64], shape: tuple[int, int]) -> None:
        self.K = np.asarray(K, dtype=float)
        self.dist = np.asarray(dist, dtype=float).ravel()
        self.shape = shape
        h, w = shape
        gy, gx = np.mgrid[0:h, 0:w].astype(np.float32)
        pts = np.stack([gx.ravel(), gy.ravel()], -1).reshape(-1, 1, 2)
        und = _undistort(pts, self.K, self.dist, 1e-6)
        und = und.reshape(h, w, 2)
        self.map_x = np.ascontiguousarray(und[..., 0])
        self.map_y = np.ascontiguousarray(und[..., 1])

    def to_raw(self, uv: NDArray[np.float64]) -> NDArray[np.float64]:
        """Undistorted pixels (N, 2) -> raw pixels (N, 2)."""
        uv = np.asarray(uv, dtype=float).reshape(-1, 2)
        xn = np.linalg.solve(self.K, np.column_stack([uv, np.ones(len(uv))]).T).T
        return geo.project_points(xn, self.K, self.dist)

    def to_undistorted(self, uv: NDArray[np.float64]) -> NDArray[np.float64]:
        """Raw pixels (N, 2) -> undistorted pixels (N, 2)."""
        pts = np.asarray(uv, dtype=np.float64).reshape(-1, 1, 2)
        out = _undistort(pts, self.K, self.dist, 1e-10)
        return np.asarray(out, np.float64).reshape(-1, 2)

    def jacobian_to_raw(self, uv: NDArray[np.float64], h: float = 1e-3) -> NDArray[np.float64]:
        """d raw / d undistorted at points (N, 2): (N, 2, 2), by central differences."""
        uv = np.asarray(uv, dtype=float).reshape(-1, 2)
        J = np.empty((len(uv), 2, 2))
        for k in range(2):
            dp = np.zeros(2)
            dp[k] = h
            J[:, :, k] = (self.to_raw(uv + dp) - self.to_raw(uv - dp)) / (2 * h)
        return J


def _undistort(pts: NDArray[np.floating], K: NDArray[np.float64], dist: NDArray[np.float64], eps: float
               ) -> NDArray[np.floating]:
    """``cv2.undistortPoints`` to undistorted pixels, iterated to ``eps`` (normalised units), in the
    points' own precision (float32 for the maps, which ``cv2.remap`` takes)."""
    crit = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 50, eps)
    return np.asarray(cv2.undistortPoints(pts, K, dist, None, None, K, crit), pts.dtype)
