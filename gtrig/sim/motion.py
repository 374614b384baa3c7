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
