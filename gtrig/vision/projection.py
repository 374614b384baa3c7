"""Projection of robot-frame points into many cameras at once, with analytic Jacobians.

The camera model is OpenCV's pinhole with radial (k1..k6, rational) and tangential (p1, p2) distortion,
as :func:`gtrig.geometry.project_points`, vectorised over points that each carry their own camera.

Pose perturbation (used by the refinement and the covariance): the robot pose ``T_world_robot = (R, t)``
is perturbed in the world frame, ``t <- t + dt``, ``R <- Exp(dphi) R``, with ``xi = (dt, dphi)`` (6,),
metres and radians. A covariance over ``xi`` is therefore the robot position's covariance in the world
and the small rotation's covariance about the world axes.
"""

from __future__ import annotations

import numpy as np

from gtrig.vision.observations import StackedCorners
from gtrig.vision.project_kernel import project_pose_into, whiten_into


def skew(v: np.ndarray) -> np.ndarray:
    """Cross-product matrices (..., 3, 3) of vectors (..., 3): ``skew(a) @ b == cross(a, b)``."""
    v = np.asarray(v, dtype=float)
    S = np.zeros(v.shape[:-1] + (3, 3))
    S[..., 0, 1], S[..., 0, 2] = -v[..., 2], v[..., 1]
    S[..., 1, 0], S[..., 1, 2] = v[..., 2], -v[..., 0]
    S[..., 2, 0], S[..., 2, 1] = -v[..., 1], v[..., 0]
    return S


def whiten(sc: StackedCorners, J: np.ndarray) -> np.ndarray:
    """Whitened residuals or Jacobians: ``L_i^T @ J_i`` for each corner (``J``: (N, 2) or (N, 2, k))."""
    out = np.empty(J.shape)
    if J.ndim == 2:
        whiten_into(sc.sqrt_info, J[:, :, None], out[:, :, None])
    else:
        whiten_into(sc.sqrt_info, J, out)
    return out


def project_cam(sc: StackedCorners, p_cam: np.ndarray, jacobian: bool = True
                ) -> tuple[np.ndarray, np.ndarray | None]:
    """Project camera-frame points (N, 3), each through its own camera of ``sc``.

    Returns
    -------
    uv : (N, 2) pixels
    J : (N, 2, 3) d uv / d p_cam, or None
    """
    X, Y, Z = p_cam[:, 0], p_cam[:, 1], p_cam[:, 2]
    iz = 1.0 / Z
    x, y = X * iz, Y * iz
    k1, k2, p1, p2, k3, k4, k5, k6 = sc.dist.T
    r2 = x * x + y * y
    a = 1 + r2 * (k1 + r2 * (k2 + r2 * k3))
    b = 1 + r2 * (k4 + r2 * (k5 + r2 * k6))
    rad = a / b
    xd = x * rad + 2 * p1 * x * y + p2 * (r2 + 2 * x * x)
    yd = y * rad + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y
    uv = np.column_stack([sc.fx * xd + sc.skew * yd + sc.cx, sc.fy * yd + sc.cy])
    if not jacobian:
        return uv, None
    da = k1 + r2 * (2 * k2 + 3 * k3 * r2)
    db = k4 + r2 * (2 * k5 + 3 * k6 * r2)
    drad = (da * b - a * db) / (b * b)  # d rad / d r2
    dxd_dx = rad + 2 * x * x * drad + 2 * p1 * y + 6 * p2 * x
    dxd_dy = 2 * x * y * drad + 2 * p1 * x + 2 * p2 * y
    dyd_dx = 2 * x * y * drad + 2 * p1 * x + 2 * p2 * y
    dyd_dy = rad + 2 * y * y * drad + 6 * p1 * y + 2 * p2 * x
    # d(x, y) / d p_cam
    n = p_cam.shape[0]
    Jn = np.zeros((n, 2, 3))
    Jn[:, 0, 0] = iz
    Jn[:, 0, 2] = -x * iz
    Jn[:, 1, 1] = iz
    Jn[:, 1, 2] = -y * iz
    Jd = np.empty((n, 2, 2))
    Jd[:, 0, 0] = sc.fx * dxd_dx + sc.skew * dyd_dx
    Jd[:, 0, 1] = sc.fx * dxd_dy + sc.skew * dyd_dy
    Jd[:, 1, 0] = sc.fy * dyd_dx
    Jd[:, 1, 1] = sc.fy * dyd_dy
    return uv, Jd @ Jn


def lens_jacobian(sc: StackedCorners, T_world_robot: np.ndarray, n: int = 9) -> np.ndarray:
    """d uv / d (lens parameters) (N, 2, n) for each corner's own camera: the first ``n`` of fx, fy, cx,
    cy, k1, k2, p1, p2, k3 (:data:`gtrig.rig.models.LENS_PARAMETERS`), at the robot pose given."""
    R, t = T_world_robot[:3, :3], T_world_robot[:3, 3]
    p_c = np.einsum("nij,nj->ni", sc.R_cw, sc.p_robot @ R.T + t) + sc.t_cw
    x, y = p_c[:, 0] / p_c[:, 2], p_c[:, 1] / p_c[:, 2]
    k1, k2, p1, p2, k3, k4, k5, k6 = sc.dist.T
    r2 = x * x + y * y
    b = 1 + r2 * (k4 + r2 * (k5 + r2 * k6))
    rad = (1 + r2 * (k1 + r2 * (k2 + r2 * k3))) / b
    xd = x * rad + 2 * p1 * x * y + p2 * (r2 + 2 * x * x)
    yd = y * rad + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y
    one, zero = np.ones_like(x), np.zeros_like(x)
    # each parameter's effect on the distorted normalised point (dxd, dyd), then on the pixel
    d_norm = [(x * r2 / b, y * r2 / b), (x * r2**2 / b, y * r2**2 / b), (2 * x * y, r2 + 2 * y * y),
              (r2 + 2 * x * x, 2 * x * y), (x * r2**3 / b, y * r2**3 / b)]
    cols = [(xd, zero), (zero, yd), (one, zero), (zero, one)]
    cols += [(sc.fx * dx + sc.skew * dy, sc.fy * dy) for dx, dy in d_norm]
    return np.stack([np.column_stack(c) for c in cols[:n]], axis=2)


def project_pose(sc: StackedCorners, T_world_robot: np.ndarray, jacobian: bool = True
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    """Project the corners of ``sc`` for the robot at ``T_world_robot``.

    Returns
    -------
    uv : (N, 2) predicted pixels
    z_cam : (N,) depth of each corner in its camera, metres (negative: behind the camera)
    J : (N, 2, 6) d uv / d xi, with ``xi = (dt, dphi)`` the world-frame perturbation (module docstring)
    """
    n = sc.p_robot.shape[0]
    uv, z = np.empty((n, 2)), np.empty(n)
    J = np.empty((n if jacobian else 0, 2, 6))
    T = np.asarray(T_world_robot, dtype=float)
    project_pose_into(sc.p_robot, T[:3, :3], T[:3, 3], sc.R_cw, sc.t_cw, sc.fx, sc.fy, sc.skew, sc.cx, sc.cy,
                      sc.dist, jacobian, uv, z, J)
    return uv, z, J if jacobian else None


def project_pose_numpy(sc: StackedCorners, T_world_robot: np.ndarray, jacobian: bool = True
                       ) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    """:func:`project_pose` written with numpy arrays (the compiled kernel's reference)."""
    R, t = T_world_robot[:3, :3], T_world_robot[:3, 3]
    q = sc.p_robot @ R.T  # R p, robot point offsets in world axes
    p_w = q + t
    p_c = np.einsum("nij,nj->ni", sc.R_cw, p_w) + sc.t_cw
    uv, Jp = project_cam(sc, p_c, jacobian)
    if not jacobian:
        return uv, p_c[:, 2], None
    assert Jp is not None
    JR = Jp @ sc.R_cw  # (N, 2, 3) d uv / d p_world
    J = np.empty((uv.shape[0], 2, 6))
    J[:, :, :3] = JR
    J[:, :, 3:] = np.cross(q[:, None, :], JR)  # -JR @ skew(q), row by row
    return uv, p_c[:, 2], J


def camera_pose_jacobian(sc: StackedCorners, T_world_robot: np.ndarray) -> np.ndarray:
    """d uv / d (camera perturbation) (N, 2, 6) for each corner's own camera.

    The camera pose ``T_world_cam`` is perturbed in the world frame like the robot: centre ``c <- c + dc``,
    rotation ``R_wc <- Exp(deps) R_wc``, parameters ``(dc, deps)``.
    """
    R, t = T_world_robot[:3, :3], T_world_robot[:3, 3]
    p_w = sc.p_robot @ R.T + t
    _, _, J_robot = project_pose(sc, T_world_robot)
    assert J_robot is not None
    JR = J_robot[:, :, :3]  # d uv / d p_world
    J = np.empty_like(J_robot)
    J[:, :, :3] = -JR
    J[:, :, 3:] = JR @ skew(p_w - sc.cam_centre_w)
    return J


def marker_pose_jacobian(sc: StackedCorners, T_world_robot: np.ndarray) -> np.ndarray:
    """d uv / d (marker perturbation) (N, 2, 6): the marker's corners moved rigidly in the robot frame,
    ``p_robot <- Exp(deps) (p_robot - m) + m + dm`` about the marker centre ``m``, parameters
    ``(dm, deps)`` in robot axes (metres, radians)."""
    R = T_world_robot[:3, :3]
    _, _, J = project_pose(sc, T_world_robot, True)
    assert J is not None
    JR = J[:, :, :3]  # d uv / d p_world
    d_uv_d_probot = JR @ R
    centre = np.zeros_like(sc.p_robot)
    for v in np.unique(sc.view):
        m = sc.view == v
        centre[m] = sc.p_robot[m].mean(axis=0)
    out = np.empty_like(J)
    out[:, :, :3] = d_uv_d_probot
    out[:, :, 3:] = -d_uv_d_probot @ skew(sc.p_robot - centre)
    return out
