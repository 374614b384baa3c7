"""GTlaser's predicted pose covariance at many poses: the beams that hit the hull, and the ICP's
information from them.

Each fixed scanner's beams are cast at the robot's hull (a convex box, ``rig.robot.hull``) at every
pose: the beams within the angle the hull subtends, up to the scanner's range, hit the first side
they meet, provided the scanning plane cuts the gown (the scanner's height between its bottom and
top). The noise-free hits are handed to the hull ICP's own normal equations
(:func:`gtrig.laser.hull_icp.side_bias_normal_equations`: point-to-line Jacobian, range noise
``range_sigma_m`` along the beam, the model error, the weak prior), so the covariance is the one
the ICP reports for one scan, plus what GTlaser adds after smoothing and cannot average out: the
hull's surface bias (:func:`gtrig.laser.hull_icp.side_bias_sensitivity` with its prior) and the floor
``floor_std_m``/``floor_std_rad``. GTlaser smooths each track over its frames, so the scan noise's part
is the smoother's steady state (:mod:`gtrig.plan.smoothing`: frames at the scanners' rate, the smoother's
order and the geometric middle of the process noises its adaptation searches, ``process_noise_factor``),
not one scan's: one scan's covariance is kept beside it. A pose the ICP would call degenerate (too few
points, fewer than two sides, too wide a covariance) is not covered, judged on one scan as the ICP does.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from gtrig.laser.hull_icp import HullModel, side_bias_normal_equations
from gtrig.laser.track import TrackSettings
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


def _wrap(a: np.ndarray) -> np.ndarray:
    return (a + np.pi) % (2 * np.pi) - np.pi


def cast_beams(rig: Rig, model: HullModel, poses_xytheta: np.ndarray) -> BeamHits:
    """Every fixed scanner's beams that hit the hull at planar poses (K, 3) (module docstring)."""
    hull = rig.robot.hull
    parts = []
    for si, s in enumerate(rig.laser_scanners):
        T = s.T_world_scanner.matrix()
        if hull is None or not (hull.z_min_m < T[2, 3] < hull.z_max_m):
            continue
        o, yaw = T[:2, 3], float(np.arctan2(T[1, 0], T[0, 0]))
        c, sn = np.cos(poses_xytheta[:, 2]), np.sin(poses_xytheta[:, 2])
        R = np.stack([np.stack([c, -sn], -1), np.stack([sn, c], -1)], -2)  # (K, 2, 2)
        corners = np.einsum("kij,cj->kci", R, model.corners_xy) + poses_xytheta[:, None, :2]  # (K, 4, 2)
        d = corners - o
        centre = corners.mean(axis=1) - o
        ref = np.arctan2(centre[:, 1], centre[:, 0])
        rel = _wrap(np.arctan2(d[..., 1], d[..., 0]) - ref[:, None])
        # the hull's bearings (scanner frame), moved by whole turns next to the middle of the beams' fan
        inc = abs(s.angle_increment_rad)
        a_lo = min(s.angle_min_rad, s.angle_min_rad + s.angle_increment_rad * (s.beams - 1))
        fan_mid = a_lo + 0.5 * inc * (s.beams - 1)
        mid = ref - yaw
        shift = fan_mid + _wrap(mid - fan_mid) - mid
        lo, hi = ref + rel.min(axis=1) - yaw + shift, ref + rel.max(axis=1) - yaw + shift
        i0 = np.clip(np.ceil((lo - a_lo) / inc).astype(int), 0, s.beams - 1)
        i1 = np.clip(np.floor((hi - a_lo) / inc).astype(int), 0, s.beams - 1)
        inside = (np.ceil((lo - a_lo) / inc) <= s.beams - 1) & (np.floor((hi - a_lo) / inc) >= 0)
        n = np.where(inside & (i1 >= i0), i1 - i0 + 1, 0)
        k = np.repeat(np.arange(poses_xytheta.shape[0]), n)
        if k.size == 0:
            continue
        start = np.repeat(i0 - np.cumsum(n) + n, n)
        beam = start + np.arange(k.size)
        ang = yaw + a_lo + inc * beam
        u = np.column_stack([np.cos(ang), np.sin(ang)])
        # first side crossed: ray o + r u against each side c_j + s e_j, s in [0, 1]
        cj = corners[k]  # (M, 4, 2)
        e = np.roll(cj, -1, axis=1) - cj
        w = cj - o
        den = u[:, None, 0] * e[..., 1] - u[:, None, 1] * e[..., 0]
        with np.errstate(divide="ignore", invalid="ignore"):
            r = (w[..., 0] * e[..., 1] - w[..., 1] * e[..., 0]) / den
            sp = (w[..., 0] * u[:, None, 1] - w[..., 1] * u[:, None, 0]) / den
        valid = np.isfinite(r) & (r > 0) & (sp >= 0) & (sp <= 1)
        r = np.where(valid, r, np.inf)
        side = np.argmin(r, axis=1)
        rng = r[np.arange(k.size), side]
        hit = np.isfinite(rng) & (rng <= s.range_max_m)
        parts.append(BeamHits(k[hit], np.full(int(hit.sum()), si), o + rng[hit, None] * u[hit], u[hit], side[hit]))
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


def _smoothed_scan_covariance(rig: Rig, cov_scan: np.ndarray, st: TrackSettings, factor: float) -> np.ndarray:
    """What GTlaser's smoother leaves of one scan's covariance (K, 3, 3): frames at the scanners' median
    rate, the smoother's process noise times ``factor`` (module docstring)."""
    from gtrig.plan.smoothing import smoothed_covariance

    rate_hz = float(np.median([s.rate_hz for s in rig.laser_scanners]))
    if st.smoother_order == 3 and st.adapt_process_noise:
        q_xy, q_yaw = st.jerk_std_mps3, st.ang_jerk_std_radps3
        order = 3
    else:  # a fixed white-acceleration model (rts_smooth)
        q_xy, q_yaw, factor = st.accel_std_mps2, st.ang_accel_std_radps2, 1.0
        order = 2
    qd = factor * np.array([q_xy**2, q_xy**2, q_yaw**2])
    return smoothed_covariance(cov_scan, qd, 1.0 / rate_hz, order)


def predict_laser(rig: Rig, poses_xytheta: np.ndarray, settings: LaserPlanSettings = LaserPlanSettings()
                  ) -> LaserPrediction:
    """GTlaser's predicted covariance at planar poses (K, 3) (module docstring)."""
    poses = np.asarray(poses_xytheta, dtype=float).reshape(-1, 3)
    K, n_s = poses.shape[0], len(rig.laser_scanners)
    nan = np.full((K, 3, 3), np.nan)
    if rig.robot.hull is None or n_s == 0:
        return LaserPrediction(nan, nan, np.zeros((K, n_s), int), np.zeros((K, n_s), int), np.zeros(K, bool))
    model = HullModel.from_hull(rig.robot.hull)
    hits = cast_beams(rig, model, poses)
    beams = np.bincount(hits.pose * n_s + hits.scanner, minlength=K * n_s).reshape(K, n_s)
    per_side = np.bincount((hits.pose * n_s + hits.scanner) * 4 + hits.side, minlength=K * n_s * 4).reshape(K, n_s, 4)
    st = settings.track
    icp = st.icp
    sides = np.sum(per_side >= icp.min_side_points, axis=2)
    S_xy = np.array([s.T_world_scanner.xyz[:2] for s in rig.laser_scanners], dtype=float)
    sigma = np.array([s.range_sigma_m for s in rig.laser_scanners], dtype=float)
    H, H_pb, _, _, _ = side_bias_normal_equations(model, hits.xy, hits.pose, hits.scanner, S_xy, hits.dir, sigma,
                                                  poses, icp)
    cov_scan = np.linalg.inv(H)
    A = np.linalg.solve(H, H_pb)
    bias = st.surface_bias_std_m**2 * np.ones((4, 4)) + st.side_bias_std_m**2 * np.eye(4)
    floor = np.diag([st.floor_std_m**2, st.floor_std_m**2, st.floor_std_rad**2])
    persistent = A @ bias @ np.swapaxes(A, 1, 2) + floor  # what smoothing cannot average out
    cov_one = cov_scan + persistent
    n_pts = beams.sum(axis=1)
    n_sides = np.sum(per_side.sum(axis=1) >= icp.min_side_points, axis=1)
    std_xy = np.sqrt(np.linalg.eigvalsh(cov_one[:, :2, :2])[:, -1])
    covered = (n_pts >= icp.min_points) & (n_sides >= 2) & (std_xy <= icp.max_std_m) & (
        np.sqrt(cov_one[:, 2, 2]) <= icp.max_std_rad)
    cov = cov_one
    if settings.smooth and st.smooth:
        cov = _smoothed_scan_covariance(rig, cov_scan, st, settings.process_noise_factor) + persistent
    return LaserPrediction(np.where(covered[:, None, None], cov, np.nan),
                           np.where(n_pts[:, None, None] > 0, cov_scan, np.nan), beams, sides, covered)
