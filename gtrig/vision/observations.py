"""What GTvision sees at one instant: every marker detection of every camera, and the rig geometry.

Two records:

* :class:`MarkerView`: one marker seen by one camera, its four corners in pixels (OpenCV convention:
  pixel centres at integer coordinates), ordered top-left, top-right, bottom-right, bottom-left of
  the marker as printed, with a 2 x 2 covariance per corner.
* :class:`FrameObservations`: all the views of one instant, across cameras.

:class:`VisionModel` holds the rig arrays the estimators need (camera intrinsics, ``T_cam_world``,
marker corners in the robot frame), computed once per rig.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from gtrig import geometry as geo
from gtrig.errors import InputError
from gtrig.rig.models import Rig

#: Corners of a square of side 1 in its marker frame (x right, y up as printed, z out of the paper),
#: ordered top-left, top-right, bottom-right, bottom-left; multiply by the side. This is also the
#: order :data:`cv2.SOLVEPNP_IPPE_SQUARE` expects.
UNIT_SQUARE_CORNERS = np.array([[-0.5, 0.5, 0.0], [0.5, 0.5, 0.0], [0.5, -0.5, 0.0], [-0.5, -0.5, 0.0]])


def marker_corners_marker(side_m: float) -> geo.Array:
    """The four corners (4, 3) of a marker of side ``side_m`` in its own frame, metres, TL TR BR BL."""
    return UNIT_SQUARE_CORNERS * float(side_m)


@dataclass(frozen=True)
class MarkerView:
    """One marker seen by one camera.

    Attributes
    ----------
    camera : str
        Camera name in the rig.
    marker_id : int
        Marker ID (the rig's ``robot.markers[i].id``).
    corners_px : (4, 2) float
        Pixel coordinates, OpenCV convention, TL TR BR BL of the printed marker.
    corner_cov : (4, 2, 2) float
        Covariance of each corner, px^2.
    frame : int
        Row of the image in its camera's frame index (-1: unknown).
    blur_px : float
        The detector's fitted edge blur sigma of this marker, pixels (NaN: not known); with the
        marker's size in the image it sizes the blur's pull on the corners
        (:func:`gtrig.vision.covariance.blur_scale_sigma_px`).
    corner_common : (4, 2) float or None
        The corners' shared move, pixels, for one sigma of an error common to the marker's four corners
        (a clipped white level's offset of all its edges: ``gtrig.markers.detect.Detection.corner_common``);
        corners ``i != j`` covary by ``corner_common[i] corner_common[j]^T``. None: the corners' errors are
        independent (:func:`gtrig.vision.covariance.common_whitening` weighs them jointly otherwise).
    """

    camera: str
    marker_id: int
    corners_px: np.ndarray
    corner_cov: np.ndarray
    frame: int = -1
    blur_px: float = float("nan")
    corner_common: np.ndarray | None = None

    def __post_init__(self) -> None:
        c = np.array(self.corners_px, dtype=float).reshape(4, 2)
        s = np.array(self.corner_cov, dtype=float)
        if s.shape == (4, 2, 2):
            pass
        elif s.size == 1:
            s = np.tile(np.eye(2) * float(s.ravel()[0]), (4, 1, 1))
        else:
            raise InputError(f"marker {self.marker_id} in {self.camera}: corner_cov must be (4, 2, 2)")
        c.setflags(write=False)
        s.setflags(write=False)
        object.__setattr__(self, "corners_px", c)
        object.__setattr__(self, "corner_cov", s)
        if self.corner_common is not None:
            m = np.array(self.corner_common, dtype=float).reshape(4, 2)
            m.setflags(write=False)
            object.__setattr__(self, "corner_common", m if np.any(m) else None)


@dataclass(frozen=True)
class FrameObservations:
    """All marker views of one instant.

    Attributes
    ----------
    stamp_s : float
        The instant, seconds (recording clock).
    views : tuple of MarkerView
        In a deterministic order (camera, then marker ID).
    cameras : tuple of str
        The cameras that delivered an image for this instant (with or without detections).
    frames : tuple of (str, int)
        ``(camera, frame number)`` of every image that went into this instant.
    """

    stamp_s: float
    views: tuple[MarkerView, ...]
    cameras: tuple[str, ...] = ()
    frames: tuple[tuple[str, int], ...] = ()

    def __post_init__(self) -> None:
        views = tuple(sorted(self.views, key=lambda v: (v.camera, v.frame, v.marker_id)))
        object.__setattr__(self, "views", views)

    @property
    def n_corners(self) -> int:
        return 4 * len(self.views)

    def cameras_with_views(self) -> tuple[str, ...]:
        return tuple(sorted({v.camera for v in self.views}))


def views_from_detections(camera: str, detections: Iterable[Any], known_ids: set[int] | None = None,
                          default_sigma_px: float = 0.1) -> list[MarkerView]:
    """Wrap detector output (records with ``id``, ``corners_px`` and optionally ``corner_cov``).

    Detections of IDs not in ``known_ids`` (markers not on the robot) are dropped; of an ID seen twice in
    one image (a false detection or a duplicate print), none is kept, since neither can be trusted.
    """
    out: dict[int, MarkerView] = {}
    dup: set[int] = set()
    for d in detections:
        mid = int(d.id)
        if known_ids is not None and mid not in known_ids:
            continue
        cov = getattr(d, "corner_cov", None)
        if cov is None:
            cov = np.tile(np.eye(2) * default_sigma_px**2, (4, 1, 1))
        if mid in out:
            dup.add(mid)
        out[mid] = MarkerView(camera, mid, np.asarray(d.corners_px, dtype=float),
                              np.asarray(cov, dtype=float), blur_px=float(getattr(d, "blur_px", math.nan)),
                              corner_common=getattr(d, "corner_common", None))
    return [v for k, v in sorted(out.items()) if k not in dup]


@dataclass(frozen=True)
class CameraGeometry:
    """One camera's arrays: ``K`` (3, 3), ``dist`` (8,) OpenCV order (zero-padded), ``T_cam_world``,
    ``T_world_cam`` (4, 4), ``size`` (w, h) pixels."""

    name: str
    K: np.ndarray
    dist: np.ndarray
    T_world_cam: np.ndarray
    T_cam_world: np.ndarray
    size: tuple[int, int]


@dataclass(frozen=True)
class VisionModel:
    """The rig as GTvision uses it.

    Attributes
    ----------
    cameras : dict name -> CameraGeometry
    side_m : dict marker ID -> side of the black square, metres
    T_robot_marker : dict marker ID -> (4, 4)
    corners_robot : dict marker ID -> (4, 3) corners in the robot frame, metres, TL TR BR BL
    """

    cameras: dict[str, CameraGeometry]
    side_m: dict[int, float]
    T_robot_marker: dict[int, np.ndarray]
    corners_robot: dict[int, np.ndarray] = field(repr=False)

    @staticmethod
    def from_rig(rig: Rig) -> VisionModel:
        cams = {}
        for c in rig.cameras:
            d = np.zeros(8)
            dc = c.dist.ravel()
            if dc.size > 8 and np.any(dc[8:] != 0):
                raise InputError(f"camera {c.name}: thin-prism and tilt distortion terms are not supported")
            d[: min(8, dc.size)] = dc[:8]
            T = c.T_world_cam.matrix()
            cams[c.name] = CameraGeometry(c.name, c.K, d, T, geo.inv_T(T), (int(c.resolution[0]),
                                                                              int(c.resolution[1])))
        if not rig.robot.markers:
            raise InputError("the rig has no markers on the robot (robot.markers)")
        side, Trm, corners = {}, {}, {}
        for m in rig.robot.markers:
            side[m.id] = float(m.side_m)
            Trm[m.id] = m.T_robot_marker.matrix()
            corners[m.id] = geo.transform_points(Trm[m.id], marker_corners_marker(m.side_m))
        return VisionModel(cams, side, Trm, corners)

    def with_camera_motion(self, T_delta: dict[str, np.ndarray]) -> VisionModel:
        """The model as seen by an instant whose cameras exposed at other times than its stamp.

        ``T_delta[c]`` (4, 4) is the robot's world-frame motion from the instant's stamp to camera
        ``c``'s exposure (``T_world_robot(t_c) = T_delta[c] T_world_robot(t)``). Projecting the moved
        robot through camera ``c`` is projecting the robot at ``t`` through a camera at
        ``T_delta[c]^-1 T_world_cam``: those cameras are replaced, the others shared.
        """
        cams = dict(self.cameras)
        for name, D in T_delta.items():
            g = cams[name]
            T = geo.inv_T(D) @ g.T_world_cam
            cams[name] = replace(g, T_world_cam=T, T_cam_world=geo.inv_T(T))
        return replace(self, cameras=cams)

    def check(self, obs: FrameObservations) -> None:
        """Raise :class:`InputError` if a view names an unknown camera or marker."""
        for v in obs.views:
            if v.camera not in self.cameras:
                raise InputError(f"camera {v.camera!r} is not in the rig")
            if v.marker_id not in self.corners_robot:
                raise InputError(f"marker {v.marker_id} is not on the robot in the rig")


@dataclass(frozen=True)
class StackedCorners:
    """All corners of a frame as flat arrays, one row per corner (N = 4 x views).

    Attributes
    ----------
    p_robot : (N, 3) corner in the robot frame, m
    uv : (N, 2) observed pixels
    cov : (N, 2, 2) px^2
    sqrt_info : (N, 2, 2) ``L`` with ``L @ L.T = inv(cov)``; the whitened residual is ``L.T @ r``
    R_cw : (N, 3, 3), t_cw : (N, 3) the corner's camera, ``T_cam_world``
    cam_centre_w : (N, 3) the camera centre in the world
    fx, fy, skew, cx, cy : (N,) intrinsics; dist : (N, 8)
    view : (N,) index of the view in ``obs.views``; cam : (N,) index into ``camera_names``;
    marker : (N,) marker ID
    """

    p_robot: np.ndarray
    uv: np.ndarray
    cov: np.ndarray
    sqrt_info: np.ndarray
    R_cw: np.ndarray
    t_cw: np.ndarray
    cam_centre_w: np.ndarray
    fx: np.ndarray
    fy: np.ndarray
    skew: np.ndarray
    cx: np.ndarray
    cy: np.ndarray
    dist: np.ndarray
    view: np.ndarray
    cam: np.ndarray
    marker: np.ndarray
    camera_names: tuple[str, ...]

    def subset(self, keep: np.ndarray) -> StackedCorners:
        """The corners where ``keep`` (N,) bool is true (views renumbered in order)."""
        keep = np.asarray(keep, bool)
        _, view = np.unique(self.view[keep], return_inverse=True)
        kw = {k: getattr(self, k)[keep] for k in (
            "p_robot", "uv", "cov", "sqrt_info", "R_cw", "t_cw", "cam_centre_w", "fx", "fy", "skew",
            "cx", "cy", "dist", "cam", "marker")}
        return StackedCorners(view=view, camera_names=self.camera_names, **kw)


def stack_corners(model: VisionModel, views: Sequence[MarkerView]) -> StackedCorners:
    """Flatten the corners of ``views`` with their camera arrays (see :class:`StackedCorners`)."""
    names = tuple(sorted({v.camera for v in views}))
    n = 4 * len(views)
    p = np.empty((n, 3))
    uv = np.empty((n, 2))
    cov = np.empty((n, 2, 2))
    R = np.empty((n, 3, 3))
    t = np.empty((n, 3))
    ctr = np.empty((n, 3))
    K = np.empty((n, 3, 3))
    dist = np.empty((n, 8))
    view = np.repeat(np.arange(len(views)), 4)
    cam = np.empty(n, dtype=int)
    marker = np.empty(n, dtype=int)
    for i, v in enumerate(views):
        g = model.cameras[v.camera]
        s = slice(4 * i, 4 * i + 4)
        p[s] = model.corners_robot[v.marker_id]
        uv[s] = v.corners_px
        cov[s] = v.corner_cov
        R[s] = g.T_cam_world[:3, :3]
        t[s] = g.T_cam_world[:3, 3]
        ctr[s] = g.T_world_cam[:3, 3]
        K[s] = g.K
        dist[s] = g.dist
        cam[s] = names.index(v.camera)
        marker[s] = v.marker_id
    info = np.linalg.inv(cov)
    try:
        L = np.linalg.cholesky(info)
    except np.linalg.LinAlgError:
        raise InputError("a corner covariance is not positive definite") from None
    return StackedCorners(p, uv, cov, L, R, t, ctr, K[:, 0, 0], K[:, 1, 1], K[:, 0, 1], K[:, 0, 2],
                          K[:, 1, 2], dist, view, cam, marker, names)
