"""GTlaser's predicted pose covariance at many poses: the beams that hit the hull, and the ICP's
information from them.

Each fixed scanner's beams are cast at the robot's hull (a convex box, ``rig.robot.hull``) at every
pose: the beams within the angle the hull subtends, up to the scanner's range, hit the first side
they meet, provided the scanning plane cuts the gown (the scanner's height between its bottom and
top). The noise-free hits enter the hull ICP's own normal equations (those of
:func:`gtrig.laser.hull_icp.side_bias_normal_equations`: point-to-line Jacobian, range noise
``range_sigma_m`` along the beam, the model error, the weak prior; both the cast and the sums are
compiled passes, :mod:`gtrig.plan._laser_kernels`), so the covariance is the one
the ICP reports for one scan, plus what GTlaser adds after smoothing and cannot average out: the
hull's surface bias (:func:`gtrig.laser.hull_icp.side_bias_sensitivity` with its prior) and the floor
``floor_std_m``/``floor_std_rad``. GTlaser smooths each track over its frames, so the scan noise's part
is the smoother's steady state (:mod:`gtrig.plan.smoothing`: frames at the scanners' rate, the smoother's
order and the geometric middle of the process noises its adaptation searches, ``process_noise_factor``),
not one scan's: one scan's covariance is kept beside it. A pose the ICP would call degenerate (too few
points, fewer than two sides, too wide a covariance) is not covered, judged on one scan as the ICP does.

The sums over beams are kept apart (:class:`LaserInformation`) so that the pieces of added scanners
add up: a suggested scanner's covariance is the rig's pieces plus its own.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from gtrig.laser.hull_icp import HullModel
from gtrig.laser.track import TrackSettings
from gtrig.plan._laser_kernels import cast_scanner, icp_blocks
from gtrig.rig.models import Rig


@dataclass(frozen=True)
class LaserPrediction:
    """GTlaser at K poses.

    Attributes
    ----------
    cov_xytheta : (K, 3, 3) predicted covariance of x, y (m) and yaw (rad); nan where not covered.
    cov_scan_xytheta : (K, 3, 3) one scan's covariance from its range noise alone (what the ICP reports
        for a scan that fits as its noise model says), for every pose with beams on the hull; its part in
        ``cov_xytheta`` is what smoothing leaves of it.
    beams : (K, n_scanners) beams of each scanner on the hull.
    sides : (K, n_scanners) hull sides each scanner sees with at least ``min_side_points`` beams.
    covered : (K,) the ICP would trust the fit (not degenerate).
    """

    cov_xytheta: np.ndarray
    cov_scan_xytheta: np.ndarray
    beams: np.ndarray
    sides: np.ndarray
    covered: np.ndarray


@dataclass(frozen=True)
class BeamHits:
    """Beams on the hull: pose index (M,), scanner index (M,), hit point (M, 2, world), beam direction
    (M, 2, unit), hull side hit (M,)."""

    pose: np.ndarray
    scanner: np.ndarray
    xy: np.ndarray
    dir: np.ndarray
    side: np.ndarray


def cast_beams(rig: Rig, model: HullModel, poses_xytheta: np.ndarray) -> BeamHits:
    """Every fixed scanner's beams that hit the hull at planar poses (K, 3) (module docstring)."""
    hull = rig.robot.hull
    parts = []
    poses = np.ascontiguousarray(poses_xytheta, dtype=float)
    for si, s in enumerate(rig.laser_scanners):
        T = s.T_world_scanner.matrix()
        if hull is None or not (hull.z_min_m < T[2, 3] < hull.z_max_m):
            continue
        a_lo = min(s.angle_min_rad, s.angle_min_rad + s.angle_increment_rad * (s.beams - 1))
        k, xy, u, side = cast_scanner(poses, np.ascontiguousarray(model.corners_xy, dtype=float),
                                      np.ascontiguousarray(T[:2, 3]), float(np.arctan2(T[1, 0], T[0, 0])), a_lo,
                                      abs(s.angle_increment_rad), s.beams, s.range_max_m)
        parts.append(BeamHits(k, np.full(k.size, si), xy, u, side))
    if not parts:
        z = np.zeros(0, dtype=int)
        return BeamHits(z, z, np.zeros((0, 2)), np.zeros((0, 2)), z)
    return BeamHits(*(np.concatenate([getattr(p, f) for p in parts]) for f in ("pose", "scanner", "xy", "dir", "side")))


@dataclass(frozen=True)
class LaserPlanSettings:
    """GTlaser's settings the prediction uses (its ICP's noise model and degeneracy thresholds, its
    smoother, and the terms added after smoothing); ``smooth`` False predicts one scan's fit, as for a
    single frame. ``process_noise_factor`` scales the smoother's base process noise (spectral density):
    GTlaser adapts it per frame between 1 and 100 times the base (:mod:`gtrig.laser.process_noise`); 10,
    the middle on a log scale, matches the GT room's simulated runs (docs/plan.md, honesty)."""

    track: TrackSettings = field(default_factory=TrackSettings)
    smooth: bool = True
    process_noise_factor: float = 10.0


def scanner_rate_hz(rig: Rig) -> float:
    """The rate GTlaser's frames come at: the median of the fixed scanners' rates, Hz."""
    return float(np.median([s.rate_hz for s in rig.laser_scanners]))


def _smoothed_scan_covariance(rate_hz: float, cov_scan: np.ndarray, st: TrackSettings, factor: float) -> np.ndarray:
    """What GTlaser's smoother leaves of one scan's covariance (K, 3, 3): frames at ``rate_hz``, the
    smoother's process noise times ``factor`` (module docstring)."""
    from gtrig.plan.smoothing import smoothed_covariance

    if st.smoother_order == 3 and st.adapt_process_noise:
        q_xy, q_yaw = st.jerk_std_mps3, st.ang_jerk_std_radps3
        order = 3
    else:  # a fixed white-acceleration model (rts_smooth)
        q_xy, q_yaw, factor = st.accel_std_mps2, st.ang_accel_std_radps2, 1.0
        order = 2
    qd = factor * np.array([q_xy**2, q_xy**2, q_yaw**2])
    return smoothed_covariance(cov_scan, qd, 1.0 / rate_hz, order)


@dataclass(frozen=True)
class LaserInformation:
    """The additive part of GTlaser's prediction at K poses: sums over beams, so that the pieces of two
    sets of scanners add up to those of their union.

    Attributes
    ----------
    H_pp : (K, 3, 3) the ICP's ``sum w J^T J`` over x, y (m), yaw (rad), without its weak prior, 1/m^2.
    H_pb : (K, 3, 4) ``sum w J c`` against each hull side's range bias.
    beams : (K, n_scanners) beams of each scanner on the hull.
    per_side : (K, n_scanners, 4) beams of each scanner on each hull side.
    """

    H_pp: np.ndarray
    H_pb: np.ndarray
    beams: np.ndarray
    per_side: np.ndarray

    def take(self, idx: np.ndarray) -> LaserInformation:
        """The pieces at the poses ``idx`` (n,)."""
        return LaserInformation(self.H_pp[idx], self.H_pb[idx], self.beams[idx], self.per_side[idx])

    def plus(self, other: LaserInformation) -> LaserInformation:
        """Both sets of scanners at the same poses (``other``'s scanners after this one's)."""
        return LaserInformation(self.H_pp + other.H_pp, self.H_pb + other.H_pb,
                                np.concatenate([self.beams, other.beams], axis=1),
                                np.concatenate([self.per_side, other.per_side], axis=1))


def laser_information(rig: Rig, poses_xytheta: np.ndarray, settings: LaserPlanSettings = LaserPlanSettings()
                      ) -> LaserInformation:
    """The ICP's normal equations at planar poses (K, 3) from the beams of ``rig``'s scanners on the hull
    (:func:`cast_beams`; blocks as :func:`gtrig.laser.hull_icp.side_bias_normal_equations`, compiled)."""
    poses = np.asarray(poses_xytheta, dtype=float).reshape(-1, 3)
    K, n_s = poses.shape[0], len(rig.laser_scanners)
    if rig.robot.hull is None or n_s == 0:
        return LaserInformation(np.zeros((K, 3, 3)), np.zeros((K, 3, 4)), np.zeros((K, n_s), int),
                                np.zeros((K, n_s, 4), int))
    model = HullModel.from_hull(rig.robot.hull)
    hits = cast_beams(rig, model, poses)
    beams = np.bincount(hits.pose * n_s + hits.scanner, minlength=K * n_s).reshape(K, n_s)
    per_side = np.bincount((hits.pose * n_s + hits.scanner) * 4 + hits.side, minlength=K * n_s * 4).reshape(K, n_s, 4)
    icp = settings.track.icp
    S_xy = np.array([s.T_world_scanner.xyz[:2] for s in rig.laser_scanners], dtype=float)
    var_r = np.array([s.range_sigma_m for s in rig.laser_scanners], dtype=float) ** 2
    t0 = np.einsum("ij,ij->i", model.tangents, model.corners_xy)
    H, H_pb, _ = icp_blocks(hits.pose.astype(np.int64), hits.scanner.astype(np.int64), hits.xy, hits.dir, poses,
                            S_xy, var_r, model.normals, model.offsets, model.tangents, t0, model.lengths,
                            float(icp.gate_m), float(icp.end_margin_m), float(icp.sigma_model_m), float(icp.huber_k))
    return LaserInformation(H, H_pb, beams, per_side)


def laser_covariance(info: LaserInformation, rate_hz: float, settings: LaserPlanSettings = LaserPlanSettings()
                     ) -> LaserPrediction:
    """GTlaser's covariance from the ICP's normal equations (module docstring): the scan's smoothed over
    frames at ``rate_hz`` (:func:`scanner_rate_hz`), plus the hull's surface bias and the floor; not covered
    where the ICP would call the fit degenerate."""
    st = settings.track
    icp = st.icp
    H = info.H_pp.copy()
    H[:, [0, 1, 2], [0, 1, 2]] += [1 / icp.prior_std_m**2, 1 / icp.prior_std_m**2, 1 / icp.prior_std_rad**2]
    cov_scan = np.linalg.inv(H)
    A = cov_scan @ info.H_pb
    bias = st.surface_bias_std_m**2 * np.ones((4, 4)) + st.side_bias_std_m**2 * np.eye(4)
    floor = np.diag([st.floor_std_m**2, st.floor_std_m**2, st.floor_std_rad**2])
    persistent = A @ bias @ np.swapaxes(A, 1, 2) + floor  # what smoothing cannot average out
    cov_one = cov_scan + persistent
    n_pts = info.beams.sum(axis=1)
    sides = np.sum(info.per_side >= icp.min_side_points, axis=2)
    n_sides = np.sum(info.per_side.sum(axis=1) >= icp.min_side_points, axis=1)
    std_xy = np.sqrt(np.linalg.eigvalsh(cov_one[:, :2, :2])[:, -1])
    covered = (n_pts >= icp.min_points) & (n_sides >= 2) & (std_xy <= icp.max_std_m) & (
        np.sqrt(cov_one[:, 2, 2]) <= icp.max_std_rad)
    cov = cov_one
    if settings.smooth and st.smooth:
        cov = _smoothed_scan_covariance(rate_hz, cov_scan, st, settings.process_noise_factor) + persistent
    return LaserPrediction(np.where(covered[:, None, None], cov, np.nan),
                           np.where(n_pts[:, None, None] > 0, cov_scan, np.nan), info.beams, sides, covered)


def predict_laser(rig: Rig, poses_xytheta: np.ndarray, settings: LaserPlanSettings = LaserPlanSettings()
                  ) -> LaserPrediction:
    """GTlaser's predicted covariance at planar poses (K, 3) (module docstring)."""
    rate_hz = scanner_rate_hz(rig) if rig.laser_scanners else 1.0  # no scanner: nothing is covered
    return laser_covariance(laser_information(rig, poses_xytheta, settings), rate_hz, settings)
