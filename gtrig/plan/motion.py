"""What a moving robot adds to GTvision's pose covariance: the cameras' time-stamp jitter.

An image whose stamp is off by ``dt`` shows the robot where it was ``dt`` away from the stamp, so the pose
GTvision gives for the stamp is off by ``v dt`` (``v`` the planar velocity, x, y and heading). With the
jitter's standard deviation ``sigma_t`` of the cameras that see the robot (the rig's ``stamp_sigma_s``),
the covariance gains ``sigma_t^2 v v^T``.
"""

from __future__ import annotations

import numpy as np


def stamp_jitter_covariance(views: np.ndarray, stamp_sigma_s: np.ndarray, velocity_xytheta: np.ndarray
                            ) -> np.ndarray:
    """(K, 3, 3) covariance of x, y (m) and yaw (rad) from time-stamp jitter.

    Parameters
    ----------
    views : (K, n_cameras) markers each camera sees at each pose (0: none).
    stamp_sigma_s : (n_cameras,) each camera's stamp jitter, seconds.
    velocity_xytheta : (K, 3) the robot's velocity, m/s and rad/s, world frame.

    The jitter variance at a pose is the mean over the cameras that see a marker (their images are
    fitted together); zero where none does.
    """
    seen = (np.asarray(views) > 0).astype(float)
    n = seen.sum(axis=1)
    var_t = np.where(n > 0, seen @ np.square(np.asarray(stamp_sigma_s, dtype=float)) / np.maximum(n, 1), 0.0)
    v = np.asarray(velocity_xytheta, dtype=float)
    return var_t[:, None, None] * v[:, :, None] * v[:, None, :]
