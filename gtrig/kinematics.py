"""Velocities of pose sequences, for the stages that correct or propagate timing errors.

Core: GTvision uses it to move each camera's view to its instant's stamp and to add the motion hidden
by time-stamp jitter to a pose's covariance (gtrig.vision.sequence); fusion and the time-sync checks of
later stages use the same velocities. Vectorised: about 10^6 poses/s.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from gtrig.trajectory import PoseTrack


def pose_velocities(stamps_s: np.ndarray, T_world_robot: np.ndarray, max_gap_s: float = 0.5
                    ) -> np.ndarray:
    """World-frame velocities (M, 6), ``(v, omega)`` in m/s and rad/s, of poses (M, 4, 4) at increasing
    ``stamps_s`` (M,): central differences of the nearest neighbours (one-sided at the ends and
    across gaps longer than ``max_gap_s``; zero for an isolated pose). ``omega`` is the rotation
    vector of ``R_next R_prev^T`` per second, the ``dphi`` of :mod:`gtrig.vision.projection`."""
    t = np.asarray(stamps_s, float)
    M = len(t)
    out = np.zeros((M, 6))
    if M < 2:
        return out
    gap = np.diff(t) > max_gap_s
    prev = np.arange(M) - 1
    nxt = np.arange(M) + 1
    prev[1:][gap] = np.arange(1, M)[gap]  # no usable neighbour before: the pose itself
    prev[0] = 0
    nxt[:-1][gap] = np.arange(M - 1)[gap]
    nxt[-1] = M - 1
    dt = t[nxt] - t[prev]
    ok = dt > 0
    a, b = prev[ok], nxt[ok]
    out[ok, :3] = (T_world_robot[b, :3, 3] - T_world_robot[a, :3, 3]) / dt[ok, None]
    dR = np.einsum("nij,nkj->nik", T_world_robot[b, :3, :3], T_world_robot[a, :3, :3])
    out[ok, 3:] = Rotation.from_matrix(dR).as_rotvec() / dt[ok, None]
    return out


def track_velocities(track: PoseTrack, max_gap_s: float = 0.5) -> np.ndarray:
    """:func:`pose_velocities` (M, 6) of the usable poses of a pose track (world frame, m/s and rad/s)."""
    use = track.usable()
    return pose_velocities(use.stamps_s, use.matrices(), max_gap_s)
