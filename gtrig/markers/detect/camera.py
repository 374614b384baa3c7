"""Lens distortion for the detector: raw pixels <-> undistorted pixels (OpenCV's model).

A crop of a camera's image is detected with the camera matrix shifted by the crop's corner; its maps are the
whole image's maps over the crop, shifted by the same corner. Computing them costs about 45 ms for a crop of
512 x 512 (``cv2.undistortPoints`` of every pixel), as much as a few whole-image detections, so a caller that
searches crops of a camera's images (GTvision's tracker) declares each crop once (:func:`declare_crop`) and
its maps are cut from the whole image's, computed once per camera and process. A cut is the same whatever
crops came before it, so the detections do not depend on the order in which a process met them.
"""

from __future__ import annotations

from collections import OrderedDict

import cv2
import numpy as np
from numpy.typing import NDArray

from gtrig import geometry as geo

_Key = tuple[bytes, bytes, tuple[int, int]]

#: crops declared by :func:`declare_crop`: (crop's K, dist, crop's shape) -> (whole image's K, its shape, corner);
#: never forgotten (a crop's detector may outlive any cache), a few hundred bytes for each of a rig's windows
_CROPS: dict[_Key, tuple[NDArray[np.float64], tuple[int, int], tuple[int, int]]] = {}
#: the maps of the last whole images cut from (a few cameras' worth)
_WHOLE_MAPS: OrderedDict[_Key, tuple[NDArray[np.float32], NDArray[np.float32]]] = OrderedDict()
_MAX_WHOLE_MAPS = 8


def _key(K: NDArray[np.float64], dist: NDArray[np.float64], shape: tuple[int, int]) -> _Key:
    return (np.asarray(K, float).tobytes(), np.asarray(dist, float).ravel().tobytes(), (int(shape[0]), int(shape[1])))


def declare_crop(K: NDArray[np.float64], dist: NDArray[np.float64], shape: tuple[int, int],
                 box: tuple[int, int, int, int]) -> NDArray[np.float64]:
    """Declare the crop ``box`` ``(x0, y0, x1, y1)`` of a camera's images (``K``, ``dist``, image ``shape``
    (H, W)): the :class:`Undistorter` of its camera matrix (returned: ``K`` with ``cx - x0``, ``cy - y0``)
    and size is then cut from the whole image's maps."""
    x0, y0, x1, y1 = (int(v) for v in box)
    if not (0 <= x0 < x1 <= shape[1] and 0 <= y0 < y1 <= shape[0]):
        raise ValueError(f"crop {box} is not inside an image of {shape[1]} x {shape[0]}")
    K_crop = np.array(K, float)
    K_crop[0, 2] -= x0
    K_crop[1, 2] -= y0
    _CROPS[_key(K_crop, dist, (y1 - y0, x1 - x0))] = (np.array(K, float), (int(shape[0]), int(shape[1])), (x0, y0))
    return K_crop


def _whole_maps(K: NDArray[np.float64], dist: NDArray[np.float64], shape: tuple[int, int]
                ) -> tuple[NDArray[np.float32], NDArray[np.float32]]:
    """The maps of a whole image (:meth:`Undistorter._compute`), the last few kept."""
    key = _key(K, dist, shape)
    maps = _WHOLE_MAPS.get(key)
    if maps is None:
        maps = _WHOLE_MAPS[key] = Undistorter._compute(np.asarray(K, float), np.asarray(dist, float).ravel(), shape)
        while len(_WHOLE_MAPS) > _MAX_WHOLE_MAPS:
            _WHOLE_MAPS.popitem(last=False)
    else:
        _WHOLE_MAPS.move_to_end(key)
    return maps


class Undistorter:
    """Maps between raw pixels and undistorted pixels of a camera ``K``, ``dist`` (OpenCV model).

    Undistorted pixels are ``K @ (x_n, y_n, 1)`` for the normalised undistorted coordinates, so a
    camera without distortion maps every pixel to itself. ``map_x``, ``map_y`` (H, W) hold the
    undistorted coordinates of every raw pixel centre (computed with ``cv2.undistortPoints`` once per
    camera matrix, distortion and size in a process; a declared crop's are cut from its whole image's,
    module docstring).
    """

    def __init__(self, K: NDArray[np.float64], dist: NDArray[np.float64], shape: tuple[int, int]) -> None:
        self.K = np.asarray(K, dtype=float)
        self.dist = np.asarray(dist, dtype=float).ravel()
        self.shape = shape
        self.map_x: NDArray[np.floating]
        self.map_y: NDArray[np.floating]
        crop = _CROPS.get(_key(self.K, self.dist, shape))
        if crop is None:
            self.map_x, self.map_y = _whole_maps(self.K, self.dist, shape)
        else:
            K_whole, whole_shape, (x0, y0) = crop
            map_x, map_y = _whole_maps(K_whole, self.dist, whole_shape)
            h, w = shape
            # float32 maps less an integer corner: exact
            self.map_x = (map_x[y0:y0 + h, x0:x0 + w] - np.float32(x0)).astype(np.float32, copy=False)
            self.map_y = (map_y[y0:y0 + h, x0:x0 + w] - np.float32(y0)).astype(np.float32, copy=False)

    @staticmethod
    def _compute(K: NDArray[np.float64], dist: NDArray[np.float64], shape: tuple[int, int]
                 ) -> tuple[NDArray[np.float32], NDArray[np.float32]]:
        """``map_x``, ``map_y`` (H, W) float32: the undistorted pixel of every raw pixel centre."""
        h, w = shape
        gy, gx = np.mgrid[0:h, 0:w].astype(np.float32)
        pts = np.stack([gx.ravel(), gy.ravel()], -1).reshape(-1, 1, 2)
        und = _undistort(pts, K, dist, 1e-6).reshape(h, w, 2)
        return np.ascontiguousarray(und[..., 0]), np.ascontiguousarray(und[..., 1])

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
        n = len(uv)
        steps = np.array([[h, 0.0], [0.0, h]])
        # the four displaced copies mapped in one call: each point's arithmetic is its own, so the values
        # are those of one call per copy, at a quarter of the calls' overhead
        shifted = np.concatenate([uv + steps[0], uv - steps[0], uv + steps[1], uv - steps[1]])
        raw = self.to_raw(shifted).reshape(4, n, 2)
        J = np.empty((n, 2, 2))
        J[:, :, 0] = (raw[0] - raw[1]) / (2 * h)
        J[:, :, 1] = (raw[2] - raw[3]) / (2 * h)
        return J


def _undistort(pts: NDArray[np.floating], K: NDArray[np.float64], dist: NDArray[np.float64], eps: float
               ) -> NDArray[np.floating]:
    """``cv2.undistortPoints`` to undistorted pixels, iterated to ``eps`` (normalised units), in the
    points' own precision (float32 for the maps, which ``cv2.remap`` takes)."""
    crit = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 50, eps)
    return np.asarray(cv2.undistortPoints(pts, K, dist, None, None, K, crit), pts.dtype)
