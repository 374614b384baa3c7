"""GTvision's predicted pose covariance at many poses: the estimator's information, without images.

At a pose, GTvision's fit (:func:`gtrig.vision.refine.refine_pose`) minimises the whitened corner
residuals over the robot pose ``xi = (dt, dphi)`` together with a correction of every camera and marker
in view (the rig's uncertainty, Gaussian priors of :class:`gtrig.vision.covariance.RigUncertainty`),
plus the floor prior in planar mode; its covariance is the pose block of the inverse normal matrix.
Here the same normal matrix is built from the noise-free corners of the markers seen whole
(:mod:`gtrig.plan.visibility`), with the estimator's own Jacobians
(:func:`gtrig.vision.projection.project_pose`, :func:`~gtrig.vision.projection.lens_jacobian`; the
camera's and the marker's are the formulas of :func:`~gtrig.vision.projection.camera_pose_jacobian` and
:func:`~gtrig.vision.projection.marker_pose_jacobian` evaluated from the pose Jacobian, which the tests
check equal those functions) and priors
(:meth:`~gtrig.vision.covariance.RigUncertainty.sqrt_information`,
:func:`gtrig.vision.refine.prior_residuals`).

To do so for every pose at once, each corner is projected with its robot pose moved into its camera:
the robot at ``(R, t)`` seen by a camera ``T_cam_world`` is the robot at ``(I, 0)`` with the corner at
``R p`` seen by the camera ``T_cam_world`` translated by ``t``, which the projection functions accept
corner by corner. The camera nuisances are eliminated camera by camera (Schur complement: each
camera's correction touches only its own corners), leaving the pose and the markers' corrections,
whose normal matrix is inverted per pose.

Corner noise. The detector's corner covariance is not known before there are images; the model is
the one GTvision's synthetic corners are drawn with (:class:`gtrig.vision.synthetic.CornerNoise`:
``sigma_px`` at ``ref_side_px``, growing as the square root of ``ref_side_px / side``, anisotropic by
``anisotropy`` at a random angle), plus the estimator's floor (``VisionOptions.corner_floor_px``).
A random orientation of the anisotropy is averaged over in the information: each axis gets the mean
of the two principal informations.

What a calibrated run gives (:func:`after_calibration`). GTvision scales its
floored corner covariances by a per-camera factor fitted to the recording's residuals
(:mod:`gtrig.vision.noise`), so its corners end up weighted at the scatter the residuals show, whatever
the floor; the run's errors follow the detector's scatter, not the floor. The prediction of a run
therefore takes the detector's scatter (:data:`DETECTOR_SCATTER`) without the floor, and the rig's
camera and marker sigmas the calibration reaches (:data:`CALIBRATED_RIG`), not a rig's nominal
uncertainty before calibration. It is the plan's default (:class:`gtrig.plan.predict.PlanSettings`):
on the GT room's runs GTvision's error over sigma per region is 0.69-1.03 on the regions without
sunlit, clipped markers, where the rig's stated sigmas with GTvision's corner model and floor give
0.34-0.91 (docs/plan.md). :class:`VisionPlanSettings`' own defaults are GTvision's options before a
recording's noise is known (the stated corner model, the floor, hand-measured markers).

Instants. GTvision makes one pose of the images of one instant (images of different cameras within
its sync tolerance). Cameras triggered together put every camera seeing the robot in one instant
(``instants="together"``). Free-running cameras (the simulator's: their images tens of ms apart) make
one pose of each camera's image (``instants="per_camera"``): a GTvision pose there holds one camera's
information, and the covariance of GTvision's poses at a place is the mean of the covariances of the
cameras seeing it (each makes as many poses). Either way the information per second is the same (the
sum over the cameras), which is what fusion's prediction takes (:attr:`VisionPrediction.cov_xytheta`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Literal

import numpy as np

from gtrig.plan.grid import points_in_polygon
from gtrig.plan.visibility import MARGIN_PX, MIN_SIDE_PX, camera_sight
from gtrig.rig.models import Rig
from gtrig.vision.covariance import PLANAR_INDEX, UNCALIBRATED_MARKERS, RigUncertainty
from gtrig.vision.estimate import VisionOptions
from gtrig.vision.observations import CameraGeometry, StackedCorners, VisionModel
from gtrig.vision.projection import lens_jacobian, project_pose, skew
from gtrig.vision.refine import PlanarPrior, prior_residuals
from gtrig.vision.synthetic import CornerNoise

#: The detector's corner scatter on well-exposed markers: 0.03 px per axis at an 80 px marker, about its
#: corner RMS on rendered markers (``bench/markers.py``; the runs' well-exposed markers, 55-80 px, show
#: 0.012-0.019 px against the true projection).
DETECTOR_SCATTER = CornerNoise(sigma_px=0.03, ref_side_px=80.0)

#: The camera and marker pose sigmas (per axis) gtrig's calibration reaches in the GT room: the RMS
#: error of the calibrated rigs of three simulated recordings against their true rigs, 12 cameras
#: (0.33 mm, 0.0072 deg) and 18 markers on the robot (0.12 mm, 0.0097 deg; mostly an offset common
#: to a robot's markers). A planned rig's own ``pose_cov`` entries override them.
CALIBRATED_RIG = RigUncertainty(camera_xyz_m=0.00033, camera_rot_rad=math.radians(0.0072),
                                marker_xyz_m=0.00012, marker_rot_rad=math.radians(0.0097))


#: The detector's corners on markers whose white clips (sunlit paper): each corner's own scatter per axis and
#: the offset the four edges of a marker share along their outward normals, px. The simulated GT room's runs
#: (seeds 0-2, 1848 sunlit markers of 45-85 px, moving at 0.3 m/s): corners 0.21 px RMS off, the edges' offsets
#: 0.14 px RMS with a correlation of 0.94 within a marker (a mean of -0.10 px: the marker shrinks), their
#: own part 0.035 px; ``gtrig.markers.detect`` states the common part at 0.12 px RMS.
SUNLIT_OWN_PX = 0.05
SUNLIT_COMMON_PX = 0.14


@dataclass(frozen=True)
class VisionPlanSettings:
    """The noise models of the prediction.

    Attributes
    ----------
    corner_noise : the detector's corner noise as a function of the marker's size in the image.
    corner_floor_px : isotropic sigma added to it (GTvision's default floor).
    rig_uncertainty : the cameras' and markers' pose sigmas (GTvision's default: calibrated cameras,
        hand-measured markers); the rig's own ``pose_cov`` entries override them.
    prior : the floor prior (GTvision's planar mode).
    margin_px, min_side_px : a marker closer to the image border or smaller is not seen.
    instants : "together" (cameras triggered together: one GTvision pose of every camera seeing the
        robot) or "per_camera" (free-running cameras: one pose of each camera's image; module docstring).
    sunlit_xy : a floor polygon ((x, y), ...) in metres, world frame, where the markers' white clips (sun
        through a window): a marker whose centre lies over it has corners of :data:`SUNLIT_OWN_PX` each
        plus an offset of :data:`SUNLIT_COMMON_PX` common to its four edges (:func:`sunlit_whitening`);
        empty: no sun.
    """

    corner_noise: CornerNoise = field(default_factory=CornerNoise)
    corner_floor_px: float = VisionOptions().corner_floor_px
    rig_uncertainty: RigUncertainty = UNCALIBRATED_MARKERS
    prior: PlanarPrior = field(default_factory=PlanarPrior)
    margin_px: float = MARGIN_PX
    min_side_px: float = MIN_SIDE_PX
    instants: Literal["together", "per_camera"] = "together"
    sunlit_xy: tuple[tuple[float, float], ...] = ()


def after_calibration(rig_uncertainty: RigUncertainty = CALIBRATED_RIG) -> VisionPlanSettings:
    """The settings that predict a calibrated ``gtrig run`` (module docstring): the detector's scatter,
    no floor, the rig's sigmas ``rig_uncertainty``."""
    return VisionPlanSettings(corner_noise=DETECTOR_SCATTER, corner_floor_px=0.0, rig_uncertainty=rig_uncertainty)


@dataclass(frozen=True)
class VisionPrediction:
    """GTvision at K poses.

    Attributes
    ----------
    cov_xytheta : (K, 3, 3) predicted covariance of x, y (m) and yaw (rad); nan where no marker is seen.
    cov_6x6 : (K, 6, 6) the full one over (dt, dphi), world axes (GTvision's ``cov_6x6``).
    views : (K, n_cameras) markers each camera sees whole.
    side_px : (K, n_cameras) smallest marker side each camera sees, pixels (0: none).
    cov_persistent_xytheta : (K, 3, 3) the part of ``cov_xytheta`` held by the markers' pose errors on the
        robot (:func:`marker_part`), the same in every image of a run; nan where no marker is seen.
    cov_pose_xytheta : (K, 3, 3) the covariance of one GTvision pose as the instants make it
        (:attr:`VisionPlanSettings.instants`): ``cov_xytheta`` for cameras triggered together, the mean
        over the cameras seeing the pose of each one's own for free-running cameras; None: the same as
        ``cov_xytheta``.
    """

    cov_xytheta: np.ndarray
    cov_6x6: np.ndarray
    views: np.ndarray
    side_px: np.ndarray
    cov_persistent_xytheta: np.ndarray
    cov_pose_xytheta: np.ndarray | None = None

    @property
    def cov_of_a_pose(self) -> np.ndarray:
        """(K, 3, 3) the covariance of one GTvision pose (``cov_pose_xytheta``, else ``cov_xytheta``)."""
        return self.cov_xytheta if self.cov_pose_xytheta is None else self.cov_pose_xytheta


def corner_information(side_px: np.ndarray, noise: CornerNoise, floor_px: float) -> np.ndarray:
    """Information (1/px^2) of one corner coordinate of a marker whose side is ``side_px`` in the image."""
    s2 = noise.sigma_px**2 * np.maximum(1.0, noise.ref_side_px / np.maximum(side_px, 1e-6))
    a = noise.anisotropy
    f2 = floor_px**2
    return 0.5 * (1.0 / (s2 * a + f2) + 1.0 / (s2 / a + f2))


@dataclass(frozen=True)
class _CameraViews:
    """The views of one camera over a chunk of poses: pose index (V,), marker slot (V,) (-1: no nuisance),
    marker ID (V,), corners (V, 4, 2) px, side (V,) px, sunlit (V,) bool (the marker's white clips)."""

    pose: np.ndarray
    slot: np.ndarray
    marker: np.ndarray
    uv: np.ndarray
    side_px: np.ndarray
    sunlit: np.ndarray | None = None


def _corners_of(model: VisionModel, marker_ids: np.ndarray) -> np.ndarray:
    """The robot-frame corners (4 V, 3) of the markers ``marker_ids`` (V,), four per marker."""
    ids = np.array(sorted(model.corners_robot))
    table = np.stack([model.corners_robot[int(i)] for i in ids])
    return table[np.searchsorted(ids, marker_ids)].reshape(-1, 3)


def _stack(cam: CameraGeometry, model: VisionModel, cv: _CameraViews, poses: np.ndarray,
           info: np.ndarray) -> tuple[StackedCorners, np.ndarray]:
    """The views' corners as :class:`StackedCorners` with each robot pose moved into its camera (module
    docstring), and the rotations (N, 3, 3) of the robot poses, corner by corner."""
    n = 4 * cv.pose.shape[0]
    k = np.repeat(cv.pose, 4)
    th = poses[k, 2]
    c, s = np.cos(th), np.sin(th)
    Rk = np.zeros((n, 3, 3))
    Rk[:, 0, 0], Rk[:, 0, 1], Rk[:, 1, 0], Rk[:, 1, 1], Rk[:, 2, 2] = c, -s, s, c, 1.0
    t = np.column_stack([poses[k, :2], np.zeros(n)])
    p_robot = _corners_of(model, cv.marker)
    R_cw, t_cw = cam.T_cam_world[:3, :3], cam.T_cam_world[:3, 3]
    L = np.sqrt(info)[:, None, None] * np.eye(2)
    K = cam.K
    p_rot = np.column_stack([c * p_robot[:, 0] - s * p_robot[:, 1], s * p_robot[:, 0] + c * p_robot[:, 1],
                             p_robot[:, 2]])
    sc = StackedCorners(
        p_robot=p_rot, uv=cv.uv.reshape(-1, 2), cov=(1.0 / info)[:, None, None] * np.eye(2),
        sqrt_info=L, R_cw=np.broadcast_to(R_cw, (n, 3, 3)), t_cw=t_cw + t @ R_cw.T,
        cam_centre_w=cam.T_world_cam[:3, 3] - t, fx=np.full(n, K[0, 0]), fy=np.full(n, K[1, 1]),
        skew=np.full(n, K[0, 1]), cx=np.full(n, K[0, 2]), cy=np.full(n, K[1, 2]),
        dist=np.broadcast_to(cam.dist, (n, 8)), view=np.repeat(np.arange(cv.pose.shape[0]), 4),
        cam=np.zeros(n, dtype=int), marker=np.repeat(cv.marker, 4), camera_names=(cam.name,))
    return sc, Rk


def marker_jacobian(J_pose: np.ndarray, R_world_robot: np.ndarray, p_robot: np.ndarray,
                    centre_robot: np.ndarray) -> np.ndarray:
    """d uv / d (marker perturbation) (N, 2, 6) as :func:`gtrig.vision.projection.marker_pose_jacobian`
    (the marker moved rigidly about its centre, robot axes), from the pose Jacobian ``J_pose`` (N, 2, 6),
    each corner's robot rotation (N, 3, 3), its robot-frame point (N, 3) and its marker's centre (N, 3)."""
    d = J_pose[:, :, :3] @ R_world_robot
    return np.concatenate([d, -d @ skew(p_robot - centre_robot)], axis=2)


def camera_jacobian(J_pose: np.ndarray, p_world: np.ndarray, centre_world: np.ndarray) -> np.ndarray:
    """d uv / d (camera perturbation) (N, 2, 6) as :func:`gtrig.vision.projection.camera_pose_jacobian`
    (the camera's centre and rotation perturbed in the world frame), from the pose Jacobian ``J_pose``
    (N, 2, 6), each corner's world point (N, 3) and its camera's centre (N, 3), metres."""
    JR = J_pose[:, :, :3]  # d uv / d p_world
    return np.concatenate([-JR, JR @ skew(p_world - centre_world)], axis=2)


def _camera_normal_equations(H: np.ndarray, cam: CameraGeometry, model: VisionModel, cv: _CameraViews,
                             poses: np.ndarray, settings: VisionPlanSettings, rig_u: RigUncertainty) -> None:
    """Add one camera's corners to the normal matrices ``H`` (K, D, D) over (pose, marker corrections),
    its own correction eliminated (:func:`gtrig.plan._vision_kernels.add_camera_views`). ``cv.pose``
    indexes ``H``'s rows, in non-decreasing order."""
    from gtrig.plan._vision_kernels import add_camera_views

    V = cv.pose.shape[0]
    info_v = corner_information(cv.side_px, settings.corner_noise, settings.corner_floor_px)
    lit = np.zeros(V, dtype=bool) if cv.sunlit is None else cv.sunlit
    info_v = np.where(lit, 1.0 / (SUNLIT_OWN_PX**2 + settings.corner_floor_px**2), info_v)
    info = np.repeat(info_v, 4)
    sc, Rk = _stack(cam, model, cv, poses, info)
    eye = np.eye(4)
    _, _, Jp = project_pose(sc, eye, True)
    assert Jp is not None
    w = np.sqrt(info)[:, None, None]
    p_r = _corners_of(model, cv.marker)
    ctr = np.repeat(p_r.reshape(V, 4, 3).mean(axis=1), 4, axis=0)
    Jm = w * marker_jacobian(Jp, Rk, p_r, ctr)
    S_c = rig_u.sqrt_information("camera", cam.name)
    if S_c is None:
        Jc, P_cam = np.zeros((V * 4, 2, 1)), np.zeros((1, 1))
    else:
        Jc = camera_jacobian(Jp, sc.p_robot, sc.cam_centre_w)  # the robot at the origin: p_world = p_robot
        if S_c.shape[0] > 6:
            Jc = np.concatenate([Jc, lens_jacobian(sc, eye, S_c.shape[0] - 6)], axis=2)
        Jc, P_cam = w * Jc, S_c.T @ S_c
    Jp = w * Jp
    if lit.any():
        M = sunlit_whitening(cv.uv, np.where(lit, SUNLIT_COMMON_PX, 0.0), np.sqrt(info_v))
        Jp, Jm, Jc = ((M @ J.reshape(V, 8, -1)).reshape(J.shape) for J in (Jp, Jm, Jc))
    add_camera_views(H, cv.pose.astype(np.int64), cv.slot.astype(np.int64), np.ascontiguousarray(Jp.reshape(V, 8, 6)),
                     np.ascontiguousarray(Jm.reshape(V, 8, 6)), np.ascontiguousarray(Jc.reshape(V, 8, -1)),
                     np.ascontiguousarray(P_cam, dtype=float), S_c is not None)


def _sunlit(poses_xytheta: np.ndarray, centre_robot_xy: np.ndarray, sunlit_xy: tuple[tuple[float, float], ...]
            ) -> np.ndarray | None:
    """(V,) bool: the markers whose centres (V, 2, robot frame, m) lie over the sunlit polygon at the robot
    poses (V, 3); None without a polygon."""
    if not sunlit_xy:
        return None
    th = poses_xytheta[:, 2]
    c, s = np.cos(th), np.sin(th)
    x = poses_xytheta[:, 0] + c * centre_robot_xy[:, 0] - s * centre_robot_xy[:, 1]
    y = poses_xytheta[:, 1] + s * centre_robot_xy[:, 0] + c * centre_robot_xy[:, 1]
    return points_in_polygon(np.column_stack([x, y]), np.asarray(sunlit_xy, dtype=float))


def sunlit_whitening(uv: np.ndarray, common_px: np.ndarray, sqrt_info: np.ndarray) -> np.ndarray:
    """(V, 8, 8) ``M`` with ``M^T M = (I + c c^T)^-1``: applied to a view's whitened rows (its corners
    (V, 4, 2) px, each coordinate whitened by ``sqrt_info`` (V,)), it turns the four corners' independent
    errors into those plus an offset of ``common_px`` (V,) shared by the marker's four edges along their
    outward normals (``c`` the corners' whitened move for it, :func:`gtrig.vision.covariance.edge_pull_jacobian`).
    By Sherman-Morrison, ``M = I - (1 - 1 / sqrt(1 + |c|^2)) c c^T / |c|^2``."""
    from gtrig.vision.covariance import edge_pull_jacobian

    c = np.zeros((uv.shape[0], 8))
    for v in np.flatnonzero(common_px):  # the views out of the sun keep M = I
        c[v] = -(edge_pull_jacobian(uv[v]) @ np.full(4, common_px[v])) * sqrt_info[v]
    n2 = np.sum(c**2, axis=1)
    beta = np.where(n2 > 0, (1.0 - 1.0 / np.sqrt(1.0 + n2)) / np.where(n2 > 0, n2, 1.0), 0.0)
    return np.eye(8)[None] - beta[:, None, None] * np.einsum("vi,vj->vij", c, c)


def pose_covariance(H: np.ndarray) -> np.ndarray:
    """The pose block (K, 6, 6) of ``inv(H)`` for normal matrices (K, D, D) over (pose, marker
    corrections), by eliminating the corrections (Schur complement, compiled)."""
    from gtrig.plan._vision_kernels import pose_block_of_inverse

    return pose_block_of_inverse(np.ascontiguousarray(H, dtype=float), 6)


@dataclass(frozen=True)
class VisionInformation:
    """GTvision's normal matrices at K poses, the cameras' corrections eliminated: a sum over cameras, so
    that a camera added to a rig adds its own matrices.

    Attributes
    ----------
    seen : (K,) bool, some camera sees a marker whole.
    H : (n_seen, D, D) normal matrices at the seen poses over the robot pose ``(dt, dphi)`` (world axes,
        m and rad) and the corrections of the markers that have a prior (6 each, in the rig's order),
        with or without the priors (:func:`prior_information`).
    views : (K, n_cameras) markers each camera sees whole.
    side_px : (K, n_cameras) smallest marker side each camera sees, pixels (0: none).
    """

    seen: np.ndarray
    H: np.ndarray
    views: np.ndarray
    side_px: np.ndarray


def prior_information(rig: Rig, settings: VisionPlanSettings = VisionPlanSettings()) -> np.ndarray:
    """The priors' part (D, D) of every pose's normal matrix: GTvision's floor prior on the pose and
    each marker's pose prior (the rig's uncertainty) on its correction."""
    rig_u = settings.rig_uncertainty.with_rig(rig)
    S_m = [S for S in (rig_u.sqrt_information("marker", m.id) for m in rig.robot.markers) if S is not None]
    D = 6 + 6 * len(S_m)
    P = np.zeros((D, D))
    _, Jprior = prior_residuals(np.eye(4), settings.prior)
    P[:6, :6] = Jprior.T @ Jprior
    for i, S in enumerate(S_m):
        P[6 + 6 * i:12 + 6 * i, 6 + 6 * i:12 + 6 * i] = S.T @ S
    return P


def vision_information(rig: Rig, poses_xytheta: np.ndarray, settings: VisionPlanSettings = VisionPlanSettings(),
                       model: VisionModel | None = None, camera_names: tuple[str, ...] | None = None,
                       priors: bool = True) -> VisionInformation:
    """GTvision's normal matrices at planar poses (K, 3) on a flat floor from the cameras ``camera_names``
    of ``rig`` (default: all), with the priors or without them (module docstring)."""
    poses = np.asarray(poses_xytheta, dtype=float).reshape(-1, 3)
    model = VisionModel.from_rig(rig) if model is None else model
    rig_u = settings.rig_uncertainty.with_rig(rig)
    mids = [m.id for m in rig.robot.markers]
    corners = np.stack([model.corners_robot[m] for m in mids])
    names = [c.name for c in rig.cameras] if camera_names is None else list(camera_names)
    K = poses.shape[0]
    sights = [camera_sight(model.cameras[n], corners, poses, rig.robot.hull, settings.margin_px, settings.min_side_px)
              for n in names]
    views = np.stack([s.visible.sum(axis=1) for s in sights], axis=1) if names else np.zeros((K, 0), int)
    side_min = np.stack([np.where(s.visible, s.side_px, np.inf).min(axis=1) for s in sights], axis=1) \
        if names else np.zeros((K, 0))
    side_min[~np.isfinite(side_min)] = 0.0
    seen = views.sum(axis=1) > 0
    P = prior_information(rig, settings)
    H = np.zeros((int(seen.sum()),) + P.shape)
    if priors:
        H += P
    if H.shape[0]:
        slot_of = np.full(len(mids), -1)
        with_prior = [rig_u.sqrt_information("marker", m) is not None for m in mids]
        slot_of[np.flatnonzero(with_prior)] = np.arange(sum(with_prior))
        ps = poses[seen]
        centres_xy = corners.mean(axis=1)[:, :2]
        for name, sg in zip(names, sights, strict=True):
            k, m = np.nonzero(sg.visible[seen])
            if k.size:
                lit = _sunlit(ps[k], centres_xy[m], settings.sunlit_xy)
                cv = _CameraViews(k, slot_of[m], np.asarray(mids)[m], sg.uv[seen][k, m], sg.side_px[seen][k, m], lit)
                _camera_normal_equations(H, model.cameras[name], model, cv, ps, settings, rig_u)
    return VisionInformation(seen, H, views, side_min)


def marker_part(H: np.ndarray, cov_6x6: np.ndarray) -> np.ndarray:
    """(K, 3, 3) the part of the planar pose covariance that the markers' corrections add: ``cov_6x6`` (K, 6, 6,
    from the normal matrices ``H`` (K, D, D)) less the pose covariance with the markers held at their poses
    (the inverse of the pose block of ``H``), x, y (m) and yaw (rad). A marker's pose error on the robot is
    the same in every image, so this part does not average over a run's images; it is positive
    semi-definite (a marginal of the difference of the Schur complement's inverse and the block's)."""
    fixed = planar_covariance(np.linalg.inv(H[:, :6, :6]))
    return planar_covariance(cov_6x6) - fixed


def planar_covariance(cov_6x6: np.ndarray) -> np.ndarray:
    """The x, y, yaw block (K, 3, 3) of pose covariances (K, 6, 6) over (dt, dphi)."""
    i = np.array(PLANAR_INDEX)
    return cov_6x6[:, i[:, None], i[None, :]]


def predict_vision(rig: Rig, poses_xytheta: np.ndarray, settings: VisionPlanSettings = VisionPlanSettings(),
                   model: VisionModel | None = None) -> VisionPrediction:
    """GTvision's predicted covariance at planar poses (K, 3) on a flat floor (module docstring)."""
    model = VisionModel.from_rig(rig) if model is None else model
    info = vision_information(rig, poses_xytheta, settings, model)
    cov6 = np.full((info.seen.shape[0], 6, 6), np.nan)
    persistent = np.full((info.seen.shape[0], 3, 3), np.nan)
    if info.H.shape[0]:
        cov6[info.seen] = pose_covariance(info.H)
        persistent[info.seen] = marker_part(info.H, cov6[info.seen])
    per_pose = per_camera_covariance(rig, poses_xytheta, settings, model) if settings.instants == "per_camera" \
        else None
    return VisionPrediction(planar_covariance(cov6), cov6, info.views, info.side_px, persistent, per_pose)


def per_camera_covariance(rig: Rig, poses_xytheta: np.ndarray, settings: VisionPlanSettings,
                          model: VisionModel) -> np.ndarray:
    """(K, 3, 3) the mean over the cameras seeing each planar pose (K, 3) of the covariance (x, y in m,
    yaw in rad, world frame) GTvision has from that camera's image alone: the covariance of GTvision's
    poses there when the cameras run free (module docstring); nan where no camera sees a marker whole."""
    K = np.asarray(poses_xytheta).reshape(-1, 3).shape[0]
    total, count = np.zeros((K, 3, 3)), np.zeros(K)
    for cam in rig.cameras:
        info = vision_information(rig, poses_xytheta, settings, model, (cam.name,))
        if info.H.shape[0]:
            total[info.seen] += planar_covariance(pose_covariance(info.H))
            count[info.seen] += 1
    out = np.full((K, 3, 3), np.nan)
    ok = count > 0
    out[ok] = total[ok] / count[ok, None, None]
    return out
