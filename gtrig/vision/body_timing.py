"""Each camera's time offset, and a rolling shutter's line delay, from a tracked body's motion.

A camera whose image of an instant was exposed ``tau`` seconds after the instant's stamp sees the body moved
by its velocity times ``tau``: each point's pixels move by ``g tau``, ``g`` the point's image velocity
(the pose Jacobian times the body's world-frame twist). The exposure time of a point in camera ``c``'s
image is modelled as

    tau = (t_image - t_instant) + delta_c + rho_c (row - h / 2)

with ``t_image`` the image's stamp (the frame-time file's), ``delta_c`` the camera's unknown offset from its
stamps (relative to a reference camera, whose offset is 0: only differences are observable) and ``rho_c``
its line delay (seconds per image row; 0 for a global shutter). At each instant seen by two cameras or more
the pose is a nuisance: its six parameters are projected out of that instant's residuals, and ``delta``,
``rho`` solved by linear least squares over all instants (one Gauss-Newton step from the tracked poses,
which fitted the instants without timing). The velocity is the central difference of the neighbouring
instants' poses, so instants at the ends of the track or after a gap are left out.

The covariance is the residuals' variance factor times the inverse normal matrix: it includes whatever
the timing model leaves unexplained, but not the velocities' own error (a hand-moved board's velocity from
poses 1/6 s apart is good to a few tens of percent: an offset's interval is that much optimistic).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from gtrig.vision.body import BodyOptions, BodyPose, PointBody, stack_body
from gtrig.vision.body_track import BodyInstant
from gtrig.vision.observations import CameraGeometry
from gtrig.vision.projection import project_pose


@dataclass(frozen=True)
class CameraTiming:
    """The cameras' exposure timing.

    Attributes
    ----------
    reference : the camera whose offset is 0.
    cameras : the cameras, in the order of ``offset_s`` and ``line_delay_s``.
    offset_s, sigma_offset_s : (C,) each camera's offset from its stamps minus the reference's, seconds.
    line_delay_s, sigma_line_delay_s : (C,) seconds per image row (nan when not estimated).
    rms_px : {"stamps": residual RMS with the image stamps only, "model": with the offsets and line delays}
        over the instants used, after the poses were refitted.
    instants, points : instants and points used; variance_factor : the residuals' chi-square per dof.
    """

    reference: str
    cameras: tuple[str, ...]
    offset_s: np.ndarray
    sigma_offset_s: np.ndarray
    line_delay_s: np.ndarray
    sigma_line_delay_s: np.ndarray
    rms_px: dict[str, float]
    instants: int
    points: int
    variance_factor: float


def body_velocity(poses: Sequence[BodyPose], i: int, max_gap_s: float) -> np.ndarray | None:
    """World-frame twist (6,) ``(v, omega)`` (m/s, rad/s) of instant ``i`` by central differences of its
    neighbours' poses, or None without both within ``max_gap_s``."""
    if i == 0 or i + 1 >= len(poses):
        return None
    a, b = poses[i - 1], poses[i + 1]
    if not (a.ok and b.ok) or a.T_world_body is None or b.T_world_body is None:
        return None
    dt = b.stamp_s - a.stamp_s
    if dt <= 0 or b.stamp_s - poses[i].stamp_s > max_gap_s or poses[i].stamp_s - a.stamp_s > max_gap_s:
        return None
    v = (b.T_world_body[:3, 3] - a.T_world_body[:3, 3]) / dt
    w = Rotation.from_matrix(b.T_world_body[:3, :3] @ a.T_world_body[:3, :3].T).as_rotvec() / dt
    return np.r_[v, w]


def _instant_system(cameras: Mapping[str, CameraGeometry], body: PointBody, inst: BodyInstant, pose: BodyPose,
                    vel: np.ndarray, names: list[str], sigma_px: float, line_delay: bool, all_views: bool
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Whitened ``(Q r_stamps, Q B, Q r_none)`` of one instant (pose projected out): the residuals with the
    image stamps, the timing parameters' columns, the residuals without any timing."""
    assert pose.T_world_body is not None
    views = [v for v in inst.views if (all_views or v.camera in pose.cameras) and v.camera in names]
    sc = stack_body(cameras, body, views, sigma_px)
    uv, _z, J = project_pose(sc, pose.T_world_body)
    assert J is not None
    g = J @ vel  # (N, 2) pixels per second
    cam_of = np.array([names.index(sc.camera_names[k]) for k in sc.cam])
    dt_img = np.repeat([v.stamp_s - inst.stamp_s for v in views], [len(v.ids) for v in views])
    r = (uv - sc.uv + g * dt_img[:, None]).reshape(-1) / sigma_px
    C = len(names)
    B = np.zeros((len(cam_of), 2, 2 * C if line_delay else C))
    rows = sc.uv[:, 1] - np.array([cameras[sc.camera_names[k]].size[1] / 2 for k in sc.cam])
    for k in range(C):
        m = cam_of == k
        B[m, :, k] = g[m]
        if line_delay:
            B[m, :, C + k] = g[m] * rows[m, None]
    B = B.reshape(-1, B.shape[2]) / sigma_px
    A = J.reshape(-1, 6) / sigma_px
    Q = np.eye(len(r)) - A @ np.linalg.pinv(A)
    return Q @ r, Q @ B, Q @ ((uv - sc.uv).reshape(-1) / sigma_px)


def estimate_timing(cameras: Mapping[str, CameraGeometry], body: PointBody, instants: Sequence[BodyInstant],
                    poses: Sequence[BodyPose], reference: str | None = None, *, line_delay: bool = True,
                    max_gap_s: float = 0.5, options: BodyOptions | None = None,
                    all_views: bool = True) -> CameraTiming:
    """The cameras' offsets (and line delays) from the body's motion over ``instants`` (module docstring).

    ``all_views``: the views the pose fit dropped as outliers count too (a camera whose offset is large
    is dropped at every instant where the body moves; the pose is refitted here with its offset).
    """
    options = options or BodyOptions()
    names = sorted({c for p in poses if p.ok for c in (*p.cameras, *(p.rejected if all_views else ()))})
    ref = reference or names[0]
    C = len(names)
    n_par = 2 * C if line_delay else C
    NtN, Ntb = np.zeros((n_par, n_par)), np.zeros(n_par)
    parts = []
    for i, (inst, pose) in enumerate(zip(instants, poses, strict=True)):
        vel = body_velocity(poses, i, max_gap_s)
        if vel is None or not pose.ok or len(pose.cameras) + (len(pose.rejected) if all_views else 0) < 2:
            continue
        qr, qB, q0 = _instant_system(cameras, body, inst, pose, vel, names, options.sigma_px, line_delay,
                                     all_views)
        NtN += qB.T @ qB
        Ntb += qB.T @ qr
        parts.append((qr, qB, q0))
    free = [k for k in range(n_par) if k != names.index(ref) and np.any(NtN[k] != 0)]
    theta = np.zeros(n_par)
    cov = np.full((n_par, n_par), np.nan)
    n_rows = sum(len(q) for q, _, _ in parts)
    if parts and free:
        Nf = NtN[np.ix_(free, free)]
        theta[free] = -np.linalg.solve(Nf, Ntb[free])
        ss = sum(float(np.sum((qr + qB @ theta) ** 2)) for qr, qB, _ in parts)
        dof = n_rows - 6 * len(parts) - len(free)
        s2 = ss / dof if dof > 0 else math.nan
        cov[np.ix_(free, free)] = max(s2, 1.0) * np.linalg.inv(Nf)
    sig = np.sqrt(np.clip(np.diag(cov), 0, None))
    sig[names.index(ref)] = 0.0
    rms = {k: float(np.sqrt(2 * np.mean(np.concatenate([f(*p) for p in parts]) ** 2)) * options.sigma_px)
           if parts else math.nan
           for k, f in (("none", lambda qr, qB, q0: q0), ("stamps", lambda qr, qB, q0: qr),
                        ("model", lambda qr, qB, q0: qr + qB @ theta))}
    vf = (sum(float(np.sum((qr + qB @ theta) ** 2)) for qr, qB, _ in parts)
          / max(n_rows - 6 * len(parts) - len(free), 1))
    nan = np.full(C, np.nan)
    return CameraTiming(ref, tuple(names), theta[:C], sig[:C], theta[C:] if line_delay else nan,
                        sig[C:] if line_delay else nan, rms, len(parts), n_rows // 2, vf)
