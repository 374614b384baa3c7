"""Rigid transforms in 2D and 3D: the one place where frames are composed.

Conventions
-----------
* ``T_a_b`` is a 4 x 4 homogeneous matrix that maps coordinates in frame ``b`` to frame ``a``:
  ``p_a = T_a_b @ p_b``. Hence ``T_a_c = T_a_b @ T_b_c``.
* Quaternions are ``quat_xyzw`` (scalar last), as in SciPy and ROS.
* Planar poses are ``(x, y, theta)`` with theta in radians; ``wrap_angle`` maps to [-pi, pi).
* Camera frames follow OpenCV: x right, y down, z forward (optical axis).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.spatial.transform import Rotation

Array = NDArray[np.float64]


def make_T(R: ArrayLike, t: ArrayLike) -> Array:
    """Build a 4 x 4 transform from a 3 x 3 rotation ``R`` and a translation ``t`` (3,)."""
    T = np.eye(4)
    T[:3, :3] = np.asarray(R, dtype=float)
    T[:3, 3] = np.asarray(t, dtype=float).reshape(3)
    return T


def yaw_of_quats(quat_xyzw: ArrayLike, rows: int = 65536) -> Array:
    """(N,) heading of the body x axis projected on the world x-y plane (``atan2(R10, R00)``) of (N, 4)
    quaternions, ``rows`` at a time: the rotation matrices of an hour's truth (700,000 poses, 50 MB) and
    their temporaries are never held at once; the same numbers as all at once."""
    q = np.asarray(quat_xyzw, dtype=float).reshape(-1, 4)
    out = np.empty(len(q))
    for a in range(0, len(q), rows):
        R = Rotation.from_quat(q[a:a + rows]).as_matrix()
        out[a:a + rows] = np.arctan2(R[:, 1, 0], R[:, 0, 0])
    return out


def inv_T(T: ArrayLike) -> Array:
    """Inverse of a rigid transform (or a stack ``(..., 4, 4)``) without a general matrix inverse."""
    T = np.asarray(T, dtype=float)
    R = T[..., :3, :3]
    t = T[..., :3, 3]
    Ti = np.zeros_like(T)
    Rt = np.swapaxes(R, -1, -2)
    Ti[..., :3, :3] = Rt
    Ti[..., :3, 3] = -np.einsum("...ij,...j->...i", Rt, t)
    Ti[..., 3, 3] = 1.0
    return Ti


def transform_points(T: ArrayLike, p: ArrayLike) -> Array:
    """Apply ``T`` (4 x 4) to points ``p`` of shape (N, 3) (or (3,)); returns the same shape."""
    T = np.asarray(T, dtype=float)
    p = np.asarray(p, dtype=float)
    return p @ T[:3, :3].T + T[:3, 3]


def T_from_xyz_quat(xyz: ArrayLike, quat_xyzw: ArrayLike) -> Array:
    """Transform from a translation (3,) and a unit quaternion ``quat_xyzw`` (4,)."""
    return make_T(Rotation.from_quat(np.asarray(quat_xyzw, dtype=float)).as_matrix(), xyz)


def T_from_xyz_rpy(xyz: ArrayLike, rpy_rad: ArrayLike) -> Array:
    """Transform from a translation and roll, pitch, yaw (radians; R = Rz(yaw) Ry(pitch) Rx(roll))."""
    return make_T(Rotation.from_euler("ZYX", np.asarray(rpy_rad, dtype=float)[::-1]).as_matrix(), xyz)


def xyz_quat_from_T(T: ArrayLike) -> tuple[Array, Array]:
    """Split a transform into translation (3,) and ``quat_xyzw`` (4,) with qw >= 0."""
    T = np.asarray(T, dtype=float)
    q = Rotation.from_matrix(T[:3, :3]).as_quat()
    if q[3] < 0:
        q = -q
    return T[:3, 3].copy(), q


def rpy_from_T(T: ArrayLike) -> Array:
    """Roll, pitch, yaw (radians) of a transform, the inverse of :func:`T_from_xyz_rpy`."""
    T = np.asarray(T, dtype=float)
    return Rotation.from_matrix(T[:3, :3]).as_euler("ZYX")[::-1].copy()


def wrap_angle(a: ArrayLike) -> Array:
    """Wrap angles (radians) to [-pi, pi)."""
    a = np.asarray(a, dtype=float)
    return (a + np.pi) % (2.0 * np.pi) - np.pi


def se2_to_T(x: float, y: float, theta: float, z: float = 0.0) -> Array:
    """Planar pose (x, y, theta) as a 4 x 4 transform (rotation about z)."""
    c, s = np.cos(theta), np.sin(theta)
    T = np.eye(4)
    T[:2, :2] = [[c, -s], [s, c]]
    T[:3, 3] = [x, y, z]
    return T


def T_to_se2(T: ArrayLike) -> Array:
    """Planar pose (x, y, yaw) of a 4 x 4 transform; yaw of the projected x axis, wrapped."""
    T = np.asarray(T, dtype=float)
    return np.array([T[0, 3], T[1, 3], float(np.arctan2(T[1, 0], T[0, 0]))])


def look_at(eye: ArrayLike, target: ArrayLike, up: ArrayLike = (0.0, 0.0, 1.0)) -> Array:
    """``T_world_cam`` of an OpenCV camera at ``eye`` whose optical axis points at ``target``.

    The image x axis is kept horizontal (perpendicular to ``up``).
    """
    eye = np.asarray(eye, dtype=float)
    z = np.asarray(target, dtype=float) - eye
    z /= np.linalg.norm(z)
    x = np.cross(z, np.asarray(up, dtype=float))
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    return make_T(np.column_stack([x, y, z]), eye)


def rotation_angle(R: ArrayLike) -> float:
    """Angle (radians) of a rotation matrix, robust near 0 and pi."""
    R = np.asarray(R, dtype=float)
    return float(np.linalg.norm(Rotation.from_matrix(R[:3, :3]).as_rotvec()))


def pose_error(T_est: ArrayLike, T_true: ArrayLike) -> tuple[float, float]:
    """Position error (m) and rotation error (rad) between two 4 x 4 transforms."""
    T_est = np.asarray(T_est, dtype=float)
    T_true = np.asarray(T_true, dtype=float)
    dt = float(np.linalg.norm(T_est[:3, 3] - T_true[:3, 3]))
    return dt, rotation_angle(T_est[:3, :3].T @ T_true[:3, :3])


def project_points(
    p_cam: ArrayLike, camera_matrix: ArrayLike, dist_coeffs: ArrayLike
) -> Array:
    """Project points in the camera frame (N, 3) to pixels (N, 2) with OpenCV's distortion model.

    Pixel centres are at integer coordinates (OpenCV's convention). Vectorised NumPy, so it can be
    differentiated and used in the simulator without calling OpenCV per point.
    """
    p = np.asarray(p_cam, dtype=float).reshape(-1, 3)
    K = np.asarray(camera_matrix, dtype=float)
    d = np.zeros(8)
    dc = np.asarray(dist_coeffs, dtype=float).ravel()
    d[: min(8, dc.size)] = dc[:8]
    k1, k2, p1, p2, k3, k4, k5, k6 = d
    x = p[:, 0] / p[:, 2]
    y = p[:, 1] / p[:, 2]
    r2 = x * x + y * y
    radial = (1 + r2 * (k1 + r2 * (k2 + r2 * k3))) / (1 + r2 * (k4 + r2 * (k5 + r2 * k6)))
    xd = x * radial + 2 * p1 * x * y + p2 * (r2 + 2 * x * x)
    yd = y * radial + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y
    u = K[0, 0] * xd + K[0, 1] * yd + K[0, 2]
    v = K[1, 1] * yd + K[1, 2]
    return np.column_stack([u, v])
