"""A GT source's run-constant error as a world-frame covariance for fusion's considered bias (gtrig.fusion.fuse).

Fusion considers per source one bias b_s of every fix, constant in the world frame over the run. A
source's calibration gives its error in other frames or per pose; these helpers say what such an error
is as one world-frame covariance.
"""

from __future__ import annotations

import numpy as np


def heading_averaged(cov_robot: np.ndarray) -> np.ndarray:
    """(3, 3) world-frame covariance of an error fixed in the robot frame, ``cov_robot`` (3, 3) over robot
    (x, y) (m) and yaw (rad), averaged over the robot's heading: the world error ``R(yaw) e`` turns with
    the robot, so over headings its position part is isotropic (half the trace each axis) and its
    position-yaw covariance averages to zero; the yaw part stays."""
    c = np.asarray(cov_robot, float)
    out = np.zeros((3, 3))
    out[0, 0] = out[1, 1] = 0.5 * (c[0, 0] + c[1, 1])
    out[2, 2] = c[2, 2]
    return out
