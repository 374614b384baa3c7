"""The robot's true motion: planar poses in time, lifted to 6-DoF by the uneven floor."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from gtrig.sim.floor import Floor


@dataclass(frozen=True)
class RobotMotion:
    """A densely sampled planar trajectory on a floor.

    Attributes
    ----------
    stamps_s : (N,) increasing seconds.
    xytheta : (N, 3) planar poses in the world (theta continuous, unwrapped).
    floor : the floor the robot rests on (gives z, roll and pitch).
    """

    stamps_s: np.ndarray
    xytheta: np.ndarray
    floor: Floor

    def planar(self, t: ArrayLike) -> np.ndarray:
        """Planar poses (M, 3) at times ``t`` (M,), linearly interpolated, clamped at the ends."""
        t = np.atleast_1d(np.asarray(t, dtype=float))
        return np.column_stack([np.interp(t, self.stamps_s, self.xytheta[:, k]) for k in range(3)])

    def velocity(self, t: ArrayLike) -> np.ndarray:
        """Planar velocity (M, 3) in the world: d(x, y, theta)/dt."""
        t = np.atleast_1d(np.asarray(t, dtype=float))
        d = np.gradient(self.xytheta, self.stamps_s, axis=0)
        return np.column_stack([np.interp(t, self.stamps_s, d[:, k]) for k in range(3)])

    def T_world_robot(self, t: float) -> np.ndarray:
        """The robot's 6-DoF pose (4, 4) at time ``t``."""
        x, y, th = self.planar(t)[0]
        return self.floor.robot_pose(x, y, th)

    def T_world_robot_many(self, t: ArrayLike) -> np.ndarray:
        """Poses (M, 4, 4) at times ``t``."""
        return np.stack([self.floor.robot_pose(*p) for p in self.planar(t)])


def static_motion(
    poses_xytheta: np.ndarray, floor: Floor, dwell_s: float, gap_s: float = 1.0
) -> tuple[RobotMotion, np.ndarray]:
    """The validation sequence: the robot stands still at each pose for ``dwell_s`` seconds.

    Between poses it is carried by hand during ``gap_s`` (sensors record nothing then).

    Returns
    -------
    motion : the piecewise-constant motion.
    intervals_s : (K, 2) start and end of each static interval.
    """
    period = dwell_s + gap_s
    starts = np.arange(len(poses_xytheta)) * period
    ends = starts + dwell_s
    # sample each pose at its interval's ends; interpolation inside an interval returns the pose itself
    stamps = np.column_stack([starts, ends]).ravel()
    xyth = np.repeat(poses_xytheta, 2, axis=0)
    return RobotMotion(stamps, xyth, floor), np.column_stack([starts, ends])


def limited_speed_profile(
    arc_m: np.ndarray,
    curvature_per_m: np.ndarray,
    v_max_mps: float,
    accel_mps2: float,
    lat_accel_mps2: float,
    yaw_rate_max_radps: float,
) -> np.ndarray:
    """Speed (N,) along a path, as a real robot drives it: as fast as ``v_max_mps`` allows, slowed
    where the path bends (lateral acceleration at most ``lat_accel_mps2``, yaw rate at most
    ``yaw_rate_max_radps``), accelerating and braking at most at ``accel_mps2``, from rest to rest.

    Parameters
    ----------
    arc_m : (N,) increasing arc length, metres.
    curvature_per_m : (N,) signed path curvature, 1/m.

    The limits are those of the velocity planners of indoor robots (a forward pass bounds the speed by
    what acceleration reaches, a backward pass by what braking can still stop): speed and the
    braking before a turn set the motion the tracker must follow.
    """
    k = np.abs(np.asarray(curvature_per_m, dtype=float))
    with np.errstate(divide="ignore"):
        v = np.minimum.reduce([
            np.full_like(k, v_max_mps),
            np.sqrt(lat_accel_mps2 / np.maximum(k, 1e-12)),
            yaw_rate_max_radps / np.maximum(k, 1e-12),
        ])
    v[0] = v[-1] = 0.0
    ds = np.diff(arc_m)
    for i in range(1, len(v)):  # what acceleration from the previous sample reaches
        v[i] = min(v[i], np.sqrt(v[i - 1] ** 2 + 2 * accel_mps2 * ds[i - 1]))
    for i in range(len(v) - 2, -1, -1):  # what braking to the next sample still allows
        v[i] = min(v[i], np.sqrt(v[i + 1] ** 2 + 2 * accel_mps2 * ds[i]))
    return v


def time_path(arc_m: np.ndarray, speed_mps: np.ndarray, rate_hz: float) -> tuple[np.ndarray, np.ndarray]:
    """Sample a path driven at ``speed_mps`` (N,) along ``arc_m`` (N,) at ``rate_hz``.

    Returns
    -------
    stamps_s : (M,) seconds from the start.
    arc_at_stamps_m : (M,) arc length reached at each stamp.
    """
    ds = np.diff(arc_m)
    v_mid = 0.5 * (speed_mps[1:] + speed_mps[:-1])
    # exact time of constant acceleration over each step (v_mid = ds / dt)
    t = np.r_[0.0, np.cumsum(ds / np.maximum(v_mid, 1e-9))]
    stamps = np.arange(0.0, t[-1], 1.0 / rate_hz)
    return stamps, np.interp(stamps, t, arc_m)


def agile_path(
    waypoints_xy: np.ndarray,
    v_max_mps: float = 1.5,
    accel_mps2: float = 1.0,
    lat_accel_mps2: float = 1.0,
    yaw_rate_max_radps: float = 2.0,
    rate_hz: float = 200.0,
    duration_s: float | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """A smooth path through ``waypoints_xy`` (K, 2), heading along it, driven with a speed profile
    limited by :func:`limited_speed_profile` (the same natural cubic spline as the default run's).

    Returns
    -------
    stamps_s : (N,) seconds from the start of the run.
    xytheta : (N, 3) planar poses in the world (theta unwrapped).
    """
    from scipy.interpolate import CubicSpline

    p = np.asarray(waypoints_xy, dtype=float)[:, :2]
    chord = np.r_[0, np.cumsum(np.linalg.norm(np.diff(p, axis=0), axis=1))]
    spline = CubicSpline(chord, p, bc_type="natural")
    s_fine = np.linspace(0, chord[-1], 20000)
    xy_fine = spline(s_fine)
    d1, d2 = spline(s_fine, 1), spline(s_fine, 2)
    arc = np.r_[0, np.cumsum(np.linalg.norm(np.diff(xy_fine, axis=0), axis=1))]
    curvature = (d1[:, 0] * d2[:, 1] - d1[:, 1] * d2[:, 0]) / np.maximum(np.hypot(*d1.T), 1e-12) ** 3
    v = limited_speed_profile(arc, curvature, v_max_mps, accel_mps2, lat_accel_mps2, yaw_rate_max_radps)
    stamps, arc_t = time_path(arc, v, rate_hz)
    s = np.interp(arc_t, arc, s_fine)
    xy, dxy = spline(s), spline(s, 1)
    out = np.column_stack([xy, np.unwrap(np.arctan2(dxy[:, 1], dxy[:, 0]))])
    if duration_s is not None:
        keep = stamps <= duration_s
        stamps, out = stamps[keep], out[keep]
    return stamps, out
