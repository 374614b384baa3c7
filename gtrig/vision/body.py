"""A rigid body of known points (a calibration board, any layout of markers' corners) tracked in 6-DoF from
fixed calibrated cameras, one pose and covariance per instant.

This is GTvision's estimator (:func:`gtrig.vision.refine.refine_pose`: robust weighted least squares over
all points of all cameras, covariance ``inv(J^T W J)``) applied to a body whose points are identified one
by one (ChArUco corners) instead of four per marker:

1. every camera's view of the body gives up to two poses by PnP (IPPE for a planar body, SQPnP otherwise);
   each becomes a candidate ``T_world_body`` through the camera's pose; each candidate is refined on all
   points of all cameras and the cheapest kept;
2. while a camera's view has a chi-square beyond ``BodyOptions.view_level`` (a wrong ID, a board seen at
   another instant), the view whose removal leaves the others the most consistent is dropped and the fit
   repeated, while more than one camera is left;
3. the points' chi-square over their redundancy is the instant's variance factor; where a chi-square test
   finds it significantly above 1 it scales the covariance (:func:`gtrig.vision.estimate.frame_scale`).

Frames: ``T_world_cam`` of every camera (the network calibration's world), ``T_world_body`` of the body;
``cov_6x6`` is over the world-frame perturbation ``(dt, dphi)`` (m, rad) of :mod:`gtrig.vision.projection`.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import cv2
import numpy as np
from scipy.stats import chi2 as chi2_dist

from gtrig import geometry as geo
from gtrig.errors import InputError
from gtrig.vision.covariance import RigUncertainty
from gtrig.vision.estimate import Status, frame_scale
from gtrig.vision.observations import CameraGeometry, StackedCorners
from gtrig.vision.refine import RefineOptions, RefineResult, refine_pose


@dataclass(frozen=True)
class PointBody:
    """A rigid body of identified points.

    Attributes
    ----------
    name : str
    points_body : (P, 3) point ``k`` in the body frame, metres (a board: z = 0).
    """

    name: str
    points_body: np.ndarray

    @property
    def planar(self) -> bool:
        """All points on the body's z = 0 plane (planar PnP applies)."""
        return bool(np.all(np.abs(self.points_body[:, 2]) < 1e-9))

    def scaled(self, factor: float) -> PointBody:
        """The same layout ``factor`` times larger (about the body's origin)."""
        return PointBody(self.name, self.points_body * float(factor))


@dataclass(frozen=True)
class BodyView:
    """The body's points seen in one image of one camera.

    Attributes
    ----------
    camera : str
    ids : (n,) int, indices into ``PointBody.points_body``
    points_px : (n, 2) pixels, OpenCV convention (pixel centres at integers)
    stamp_s : float, the image's time, seconds
    """

    camera: str
    ids: np.ndarray
    points_px: np.ndarray
    stamp_s: float = math.nan


@dataclass(frozen=True)
class BodyOptions:
    """Settings of a body pose.

    Attributes
    ----------
    sigma_px : one-sigma noise of a point's pixel coordinates (each axis); ChArUco corners of a 1280 x 720
        webcam fit a single view to 0.13-0.21 px RMS.
    min_points : fewest points of one camera's view for it to seed a pose.
    view_level : a camera's view whose chi-square exceeds the ``1 - view_level`` quantile (its 2 n dof) is
        dropped as an outlier.
    frame_scale_level : significance of the variance factor that scales the covariance.
    refine : the robust fit's settings.
    rig : the cameras' pose uncertainty (:class:`gtrig.vision.covariance.RigUncertainty`; its marker part
        is not used: the body's points are exact), a nuisance of each camera marginalised out; None: the
        cameras are exact.
    """

    sigma_px: float = 0.3
    min_points: int = 6
    view_level: float = 1e-6
    frame_scale_level: float = 0.05
    refine: RefineOptions = RefineOptions()
    rig: RigUncertainty | None = None


@dataclass(frozen=True)
class BodyPose:
    """The body's pose at one instant.

    Attributes
    ----------
    stamp_s : float
    status : Status (OK or NO_MARKER: no view of ``min_points`` points)
    T_world_body : (4, 4) or None
    cov_6x6 : (6, 6) or None, over (dx, dy, dz, rx, ry, rz), world frame, m and rad
    cameras : the cameras used; rejected : the cameras dropped as outliers
    n_points : points used; rms_px : their reprojection RMS
    chi2, dof : the fit's; variance_factor : chi2 over the points' redundancy
    """

    stamp_s: float
    status: Status
    T_world_body: np.ndarray | None = None
    cov_6x6: np.ndarray | None = None
    cameras: tuple[str, ...] = ()
    rejected: tuple[str, ...] = ()
    n_points: int = 0
    rms_px: float = math.nan
    chi2: float = math.nan
    dof: int = 0
    variance_factor: float = math.nan

    @property
    def ok(self) -> bool:
        return self.status is Status.OK


def camera_geometry(name: str, K: np.ndarray, dist: np.ndarray, T_world_cam: np.ndarray,
                    size: tuple[int, int]) -> CameraGeometry:
    """GTvision's camera arrays from a lens (``K`` (3, 3), OpenCV ``dist`` of up to 8 terms) and its pose."""
    d = np.zeros(8)
    dc = np.asarray(dist, float).ravel()
    if dc.size > 8 and np.any(dc[8:] != 0):
        raise InputError(f"camera {name}: thin-prism and tilt distortion terms are not supported")
    d[: min(8, dc.size)] = dc[:8]
    T = np.asarray(T_world_cam, float)
    return CameraGeometry(name, np.asarray(K, float), d, T, geo.inv_T(T), (int(size[0]), int(size[1])))


def stack_body(cameras: Mapping[str, CameraGeometry], body: PointBody, views: Sequence[BodyView],
               sigma_px: float) -> StackedCorners:
    """All points of ``views`` as GTvision's stacked corners (``view``: index of the view, ``marker``: the
    point's ID), each with an isotropic covariance ``sigma_px^2 I``."""
    names = tuple(sorted({v.camera for v in views}))
    n_per = [len(v.ids) for v in views]
    n = int(sum(n_per))
    view = np.repeat(np.arange(len(views)), n_per)
    g = [cameras[v.camera] for v in views]

    def rep(per_view: list[np.ndarray]) -> np.ndarray:
        """One row per point from one array per view."""
        return np.repeat(np.stack(per_view), n_per, axis=0)

    K = rep([c.K for c in g])
    cov = np.tile(np.eye(2) * sigma_px**2, (n, 1, 1))
    L = np.tile(np.eye(2) / sigma_px, (n, 1, 1))
    return StackedCorners(
        p_robot=body.points_body[np.concatenate([v.ids for v in views])],
        uv=np.concatenate([np.asarray(v.points_px, float).reshape(-1, 2) for v in views]), cov=cov, sqrt_info=L,
        R_cw=rep([c.T_cam_world[:3, :3] for c in g]), t_cw=rep([c.T_cam_world[:3, 3] for c in g]),
        cam_centre_w=rep([c.T_world_cam[:3, 3] for c in g]), fx=K[:, 0, 0], fy=K[:, 1, 1], skew=K[:, 0, 1],
        cx=K[:, 0, 2], cy=K[:, 1, 2], dist=rep([c.dist for c in g]), view=view,
        cam=np.repeat([names.index(v.camera) for v in views], n_per), marker=np.concatenate([v.ids for v in views]),
        camera_names=names)


def view_poses(camera: CameraGeometry, body: PointBody, view: BodyView) -> list[np.ndarray]:
    """The candidate ``T_world_body`` (4, 4) of one view: both IPPE solutions (planar body) or SQPnP's."""
    obj = body.points_body[view.ids].astype(np.float64)
    img = np.asarray(view.points_px, np.float64).reshape(-1, 1, 2)
    flag = cv2.SOLVEPNP_IPPE if body.planar else cv2.SOLVEPNP_SQPNP
    n, rvecs, tvecs, _ = cv2.solvePnPGeneric(obj, img, camera.K, camera.dist, flags=flag)
    return [camera.T_world_cam @ geo.make_T(cv2.Rodrigues(r)[0], t.ravel()) for r, t in zip(rvecs[:n], tvecs[:n],
                                                                                            strict=True)]


def _best_fit(cameras: Mapping[str, CameraGeometry], body: PointBody, views: list[BodyView],
              options: BodyOptions) -> tuple[StackedCorners, RefineResult]:
    sc = stack_body(cameras, body, views, options.sigma_px)
    best: RefineResult | None = None
    for v in views:
        if len(v.ids) < options.min_points:
            continue
        for T0 in view_poses(cameras[v.camera], body, v):
            fit = refine_pose(sc, T0, None, options.refine, options.rig)
            if fit.min_depth_m > 0 and (best is None or fit.robust_cost < best.robust_cost):
                best = fit
    if best is None:
        raise InputError("no view seeds a pose")
    return sc, best


def _worst_view(cameras: Mapping[str, CameraGeometry], body: PointBody, views: list[BodyView], T0: np.ndarray,
                options: BodyOptions) -> int | None:
    """The view whose removal leaves the others the most consistent (the smallest chi-square per dof of a
    fit from ``T0`` without it): an off view drags the robust fit, so that its own chi-square alone does
    not always single it out. None when no removal leaves a view that can seed a pose."""
    best, best_score = None, math.inf
    for i in range(len(views)):
        rest = views[:i] + views[i + 1:]
        if not any(len(v.ids) >= options.min_points for v in rest):
            continue
        f = refine_pose(stack_body(cameras, body, rest, options.sigma_px), T0, None, options.refine, options.rig)
        score = f.chi2 / max(f.dof, 1)
        if score < best_score:
            best, best_score = i, score
    return best


def estimate_body_pose(cameras: Mapping[str, CameraGeometry], body: PointBody, views: Sequence[BodyView],
                       stamp_s: float, options: BodyOptions = BodyOptions()) -> BodyPose:
    """The body's pose at one instant from every camera's view of it (see the module docstring)."""
    for v in views:
        if v.camera not in cameras:
            raise InputError(f"camera {v.camera!r} has no calibration")
    kept = [v for v in views if len(v.ids) > 0]
    if not any(len(v.ids) >= options.min_points for v in kept):
        return BodyPose(stamp_s, Status.NO_MARKER)
    sc, fit = _best_fit(cameras, body, kept, options)
    rejected: list[str] = []
    while len(kept) > 1:
        per_view = np.bincount(sc.view, weights=fit.whitened**2, minlength=len(kept))
        gate = np.array([chi2_dist.ppf(1 - options.view_level, 2 * len(v.ids)) for v in kept])
        if np.all(per_view <= gate):
            break
        worst = _worst_view(cameras, body, kept, fit.T_world_robot, options)
        if worst is None:
            break
        rejected.append(kept.pop(worst).camera)
        sc, fit = _best_fit(cameras, body, kept, options)
    red = float(np.sum(fit.redundancy))
    factor = float(np.sum(fit.whitened**2)) / red if red > 0.5 else math.inf
    scale = frame_scale(factor, red, options.frame_scale_level) if math.isfinite(factor) else 1.0
    return BodyPose(stamp_s, Status.OK, fit.T_world_robot, fit.cov_6x6 * scale,
                    tuple(v.camera for v in kept), tuple(rejected), int(sc.uv.shape[0]),
                    float(np.sqrt(np.mean(np.sum(fit.residuals_px**2, axis=1)))), fit.chi2, fit.dof, factor)
