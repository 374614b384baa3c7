"""Which markers a camera sees whole at a robot pose, and how large, for many poses at once.

The test is GTvision's synthetic one (:func:`gtrig.vision.synthetic.visible_views`), vectorised over
poses: all four corners in front of the camera and inside the image by ``margin_px``, the printed
face towards the camera, a side of at least ``min_side_px``; in addition, a corner whose line of sight
passes through the robot's hull (the gown's box) is hidden.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from gtrig.plan._visibility_kernels import sight
from gtrig.rig.models import Hull
from gtrig.vision.observations import CameraGeometry

#: the margin and smallest side of GTvision's synthetic views (``visible_views``' defaults)
MARGIN_PX = 2.0
MIN_SIDE_PX = 15.0
MIN_DEPTH_M = 0.05


@dataclass(frozen=True)
class MarkerSight:
    """One marker in one camera over K poses.

    Attributes
    ----------
    visible : (K,) bool, the marker is seen whole.
    uv : (K, 4, 2) its corners in the image, pixels (OpenCV convention), TL TR BR BL.
    side_px : (K,) mean side length in the image, pixels.
    """

    visible: np.ndarray
    uv: np.ndarray
    side_px: np.ndarray


def robot_to_world(poses_xytheta: np.ndarray, p_robot: np.ndarray) -> np.ndarray:
    """Robot-frame points (P, 3) at planar poses (K, 3) on a flat floor: world points (K, P, 3)."""
    c, s = np.cos(poses_xytheta[:, 2])[:, None], np.sin(poses_xytheta[:, 2])[:, None]
    x = c * p_robot[None, :, 0] - s * p_robot[None, :, 1] + poses_xytheta[:, 0:1]
    y = s * p_robot[None, :, 0] + c * p_robot[None, :, 1] + poses_xytheta[:, 1:2]
    z = np.broadcast_to(p_robot[None, :, 2], x.shape)
    return np.stack([x, y, z], axis=2)


def _project(cam: CameraGeometry, p_cam: np.ndarray) -> np.ndarray:
    """Pixels (..., 2) of camera-frame points (..., 3) through ``cam``'s lens (OpenCV model)."""
    k1, k2, p1, p2, k3, k4, k5, k6 = cam.dist
    x, y = p_cam[..., 0] / p_cam[..., 2], p_cam[..., 1] / p_cam[..., 2]
    r2 = x * x + y * y
    rad = (1 + r2 * (k1 + r2 * (k2 + r2 * k3))) / (1 + r2 * (k4 + r2 * (k5 + r2 * k6)))
    xd = x * rad + 2 * p1 * x * y + p2 * (r2 + 2 * x * x)
    yd = y * rad + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y
    K = cam.K
    return np.stack([K[0, 0] * xd + K[0, 1] * yd + K[0, 2], K[1, 1] * yd + K[1, 2]], axis=-1)


def marker_sight(cam: CameraGeometry, corners_robot: np.ndarray, poses_xytheta: np.ndarray, hull: Hull | None,
                 margin_px: float = MARGIN_PX, min_side_px: float = MIN_SIDE_PX) -> MarkerSight:
    """Whether camera ``cam`` sees the marker of corners ``corners_robot`` (4, 3, robot frame, TL TR BR
    BL) whole at each planar pose (K, 3) on a flat floor, and where (see the module docstring)."""
    cs = camera_sight(cam, np.asarray(corners_robot, dtype=float)[None], poses_xytheta, hull, margin_px, min_side_px)
    return MarkerSight(cs.visible[:, 0], cs.uv[:, 0], cs.side_px[:, 0])


@dataclass(frozen=True)
class CameraSight:
    """All markers in one camera over K poses: ``visible`` (K, M) bool, ``uv`` (K, M, 4, 2) pixels (nan
    where not computed), ``side_px`` (K, M) (0 where not seen)."""

    visible: np.ndarray
    uv: np.ndarray
    side_px: np.ndarray


def camera_sight(cam: CameraGeometry, corners_robot: np.ndarray, poses_xytheta: np.ndarray, hull: Hull | None,
                 margin_px: float = MARGIN_PX, min_side_px: float = MIN_SIDE_PX) -> CameraSight:
    """:func:`marker_sight` for M markers at once (``corners_robot`` (M, 4, 3)), with a first cut on the
    markers' bounding sphere so that poses where the camera cannot see any of them cost little."""
    K, M = poses_xytheta.shape[0], corners_robot.shape[0]
    vis = np.zeros((K, M), dtype=bool)
    uv = np.full((K, M, 4, 2), np.nan)
    side = np.zeros((K, M))
    flat = corners_robot.reshape(-1, 3)
    centre = flat.mean(axis=0)
    radius = float(np.max(np.linalg.norm(flat - centre, axis=1)))
    cw = robot_to_world(poses_xytheta, centre[None])[:, 0]
    cc = cw @ cam.T_cam_world[:3, :3].T + cam.T_cam_world[:3, 3]
    # the sphere must reach in front of the camera and, when well in front, near the image
    near = cc[:, 2] > MIN_DEPTH_M - radius
    far = cc[:, 2] > 2 * radius
    if far.any():
        uvc = _project(cam, cc[far])
        r_px = 2.0 * max(cam.K[0, 0], cam.K[1, 1]) * radius / cc[far, 2] + margin_px
        w, h = cam.size
        ok = (uvc[:, 0] > -r_px) & (uvc[:, 1] > -r_px) & (uvc[:, 0] < w + r_px) & (uvc[:, 1] < h + r_px)
        near[np.flatnonzero(far)[~ok]] = False
    cand = np.flatnonzero(near)
    if cand.size == 0:
        return CameraSight(vis, uv, side)
    if hull is not None:
        ox, oy = hull.offset_xy_m
        lo = np.array([ox - hull.length_m / 2, oy - hull.width_m / 2, hull.z_min_m]) + 1e-6
        hi = np.array([ox + hull.length_m / 2, oy + hull.width_m / 2, hull.z_max_m]) - 1e-6
    else:
        lo, hi = np.zeros(3), np.zeros(3)
    w, h = cam.size
    sight(np.ascontiguousarray(poses_xytheta, dtype=float), cand.astype(np.int64),
          np.ascontiguousarray(corners_robot, dtype=float), np.ascontiguousarray(cam.T_cam_world[:3, :3]),
          np.ascontiguousarray(cam.T_cam_world[:3, 3]), np.ascontiguousarray(cam.K, dtype=float),
          np.ascontiguousarray(cam.dist, dtype=float), float(w), float(h),
          np.ascontiguousarray(cam.T_world_cam[:3, 3]), lo, hi, hull is not None, float(margin_px), float(min_side_px),
          MIN_DEPTH_M, vis, uv, side)
    return CameraSight(vis, uv, side)
