"""The plan: GTvision's, GTlaser's and the fused pose covariance at every pose of a grid or path.

The fused covariance is what fusion's smoother makes of the two sources' fixes with odometry between
them (:mod:`gtrig.plan.fused`: the fixes of neighbouring instants averaged over the odometry's noise at
the robot's speed, the markers' pose errors kept, the clock offsets' error added); where only one
source covers a pose it is that source's, smoothed alike. On a path with time stamps, GTvision's
covariance also holds the cameras' time-stamp jitter times the robot's velocity
(:func:`gtrig.plan.motion.stamp_jitter_covariance`): an image stamped off by ``dt`` shows the robot
where it was ``dt`` earlier or later. Poses are processed in chunks so that memory stays bounded.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field

import numpy as np

from gtrig.errors import InputError
from gtrig.plan.fused import FusionPlanSettings, SourceRates, fused_covariance, plan_velocity
from gtrig.plan.grid import PlanGrid
from gtrig.plan.laser import LaserPlanSettings, predict_laser, scanner_rate_hz
from gtrig.plan.vision import VisionPlanSettings, after_calibration, predict_vision
from gtrig.rig.models import Rig
from gtrig.vision.observations import VisionModel

log = logging.getLogger(__name__)

SOURCES = ("vision", "laser", "fused")


@dataclass(frozen=True)
class PlanSettings:
    """Noise models of both sources and of fusion, and the chunk size (poses per chunk). GTvision's by
    default are a calibrated run's (:func:`gtrig.plan.vision.after_calibration`): what ``gtrig run``
    leaves after its calibration and noise estimation, not the rig's sigmas before them."""

    vision: VisionPlanSettings = field(default_factory=after_calibration)
    laser: LaserPlanSettings = field(default_factory=LaserPlanSettings)
    fusion: FusionPlanSettings = field(default_factory=FusionPlanSettings)
    chunk_poses: int = 2048


@dataclass(frozen=True)
class PlanResult:
    """The prediction at K poses (``grid.poses_xytheta()``, cell-major).

    Attributes
    ----------
    grid : where the poses are.
    camera_names, scanner_names : the rig's, in its order.
    cov : {"vision" | "laser" | "fused": (K, 3, 3)} covariance of x, y (m) and yaw (rad), world frame;
        nan where the source does not cover the pose. GTvision's is the covariance of one of its poses
        (:attr:`gtrig.plan.vision.VisionPlanSettings.instants`).
    views : (K, n_cameras) markers each camera sees whole.
    side_px : (K, n_cameras) smallest marker side each camera sees, pixels (0: none).
    beams : (K, n_scanners) beams each scanner puts on the hull.
    sides : (K, n_scanners) hull sides each scanner sees with enough beams for the ICP.
    vision_persistent : (K, 3, 3) the part of GTvision's covariance (all cameras seeing the pose) held by
        the markers' pose errors, the same in every image (:func:`gtrig.plan.vision.marker_part`; nan:
        uncovered), or None (none).
    vision_instant : (K, 3, 3) GTvision's covariance from all cameras seeing the pose at one instant,
        fusion's input, where ``cov["vision"]`` is another (instants per camera); None: ``cov["vision"]``.
    """

    grid: PlanGrid
    camera_names: tuple[str, ...]
    scanner_names: tuple[str, ...]
    cov: dict[str, np.ndarray]
    views: np.ndarray
    side_px: np.ndarray
    beams: np.ndarray
    sides: np.ndarray
    vision_persistent: np.ndarray | None = None
    vision_instant: np.ndarray | None = None

    @property
    def vision_for_fusion(self) -> np.ndarray:
        """(K, 3, 3) GTvision's covariance as fusion takes it (``vision_instant``, else ``cov["vision"]``)."""
        return self.cov["vision"] if self.vision_instant is None else self.vision_instant

    @property
    def poses_xytheta(self) -> np.ndarray:
        return self.grid.poses_xytheta()

    def sigma_xy_m(self, source: str) -> np.ndarray:
        """(K,) the position's largest standard deviation (sqrt of the largest eigenvalue), m; nan: uncovered."""
        C = self.cov[source][:, :2, :2]
        ok = np.all(np.isfinite(C), axis=(1, 2))
        out = np.full(C.shape[0], np.nan)
        if ok.any():
            out[ok] = np.sqrt(np.maximum(np.linalg.eigvalsh(C[ok])[:, -1], 0.0))
        return out

    def sigma_yaw_rad(self, source: str) -> np.ndarray:
        """(K,) the yaw's standard deviation, rad; nan: uncovered."""
        return np.sqrt(self.cov[source][:, 2, 2])


def source_rates(rig: Rig) -> SourceRates:
    """GTvision's fix rate (the median of the cameras' frame rates; None when no camera states one) and
    GTlaser's (:func:`gtrig.plan.laser.scanner_rate_hz`), Hz."""
    cam = [c.rate_hz for c in rig.cameras if c.rate_hz is not None]
    return SourceRates(float(np.median(cam)) if cam else None,
                       scanner_rate_hz(rig) if rig.laser_scanners else None)


def fuse_sources(rig: Rig, poses_xytheta: np.ndarray, path_velocity: np.ndarray | None, cov_vision: np.ndarray,
                 cov_laser: np.ndarray, persistent_vision: np.ndarray | None, settings: FusionPlanSettings
                 ) -> np.ndarray:
    """Fusion's covariance (K, 3, 3) at poses (K, 3) from the sources' covariances there and GTvision's
    persistent part (each (K, 3, 3), nan: uncovered; :func:`gtrig.plan.fused.fused_covariance`), the robot
    moving at ``path_velocity`` (K, 3) or, None, forward at ``settings.speed_mps``. GTlaser's covariance
    is averaged whole, as fusion averages its track's."""
    theta = np.asarray(poses_xytheta, dtype=float)[:, 2]
    return fused_covariance(cov_vision, cov_laser, persistent_vision, None, theta,
                            plan_velocity(theta, path_velocity, settings.speed_mps), source_rates(rig), settings)


def _predict_block(rig: Rig, poses: np.ndarray, settings: PlanSettings) -> tuple[np.ndarray, ...]:
    """Both sources at poses (K, 3), chunk by chunk: vision and laser covariances (K, 3, 3), views,
    smallest sides, beams and sides per sensor, vision's persistent part (K, 3, 3) and the covariance of
    one GTvision pose (K, 3, 3, :attr:`gtrig.plan.vision.VisionPrediction.cov_of_a_pose`)."""
    K = poses.shape[0]
    n_c, n_s = len(rig.cameras), len(rig.laser_scanners)
    cov_v, cov_l, per_v = np.full((K, 3, 3), np.nan), np.full((K, 3, 3), np.nan), np.full((K, 3, 3), np.nan)
    pose_v = np.full((K, 3, 3), np.nan)
    views, side_px = np.zeros((K, n_c), dtype=np.int16), np.zeros((K, n_c), dtype=np.float32)
    beams, sides = np.zeros((K, n_s), dtype=np.int32), np.zeros((K, n_s), dtype=np.int8)
    model = VisionModel.from_rig(rig) if rig.cameras and rig.robot.markers else None
    step = max(1, int(settings.chunk_poses))
    for a in range(0, K, step):
        b = min(K, a + step)
        if model is not None:
            pv = predict_vision(rig, poses[a:b], settings.vision, model)
            cov_v[a:b], views[a:b], side_px[a:b] = pv.cov_xytheta, pv.views, pv.side_px
            per_v[a:b], pose_v[a:b] = pv.cov_persistent_xytheta, pv.cov_of_a_pose
        if n_s:
            pl = predict_laser(rig, poses[a:b], settings.laser)
            cov_l[a:b], beams[a:b], sides[a:b] = pl.cov_xytheta, pl.beams, pl.sides
    return cov_v, cov_l, views, side_px, beams, sides, per_v, pose_v


def predict_plan(rig: Rig, grid: PlanGrid, settings: PlanSettings = PlanSettings(), workers: int = 1) -> PlanResult:
    """GTvision, GTlaser and fusion at every pose of ``grid`` for the planned ``rig`` (module docstring),
    in ``workers`` processes."""
    if not rig.cameras and not rig.laser_scanners:
        raise InputError("the rig has neither cameras nor fixed laser scanners: nothing to plan")
    poses = grid.poses_xytheta()
    K = poses.shape[0]
    if workers <= 1 or K < 4 * settings.chunk_poses:
        parts = [_predict_block(rig, poses, settings)]
    else:
        from gtrig.parallel import process_pool

        edges = np.linspace(0, K, 4 * workers + 1).astype(int)
        with process_pool(workers) as ex:
            futures = [ex.submit(_predict_block, rig, poses[a:b], settings)
                       for a, b in zip(edges[:-1], edges[1:], strict=True)]
            parts = [f.result() for f in futures]
    cov_v, cov_l, views, side_px, beams, sides, per_v, pose_v = (np.concatenate(x) for x in zip(*parts, strict=True))
    if grid.path_velocity is not None and rig.cameras:
        from gtrig.plan.motion import stamp_jitter_covariance

        jitter = stamp_jitter_covariance(views, np.array([c.stamp_sigma_s for c in rig.cameras]), grid.path_velocity)
        cov_v, pose_v = cov_v + jitter, pose_v + jitter
    # fusion takes GTvision's information per instant of all cameras: the same per second either way
    fused = fuse_sources(rig, poses, grid.path_velocity, cov_v, cov_l, per_v, settings.fusion)
    log.info("plan: %d poses (%d cells x %d headings)", K, grid.n_cells, grid.n_headings)
    return PlanResult(grid, tuple(c.name for c in rig.cameras), tuple(s.name for s in rig.laser_scanners),
                      {"vision": pose_v, "laser": cov_l, "fused": fused}, views, side_px, beams, sides, per_v,
                      cov_v if settings.vision.instants == "per_camera" else None)
