"""Synthetic marker observations: true corners projected through true cameras, plus Gaussian noise.

For testing and benchmarking the estimator without images (no detector, no renderer): the corner
noise has a known covariance, so accuracy and covariance consistency (NEES) can be checked exactly.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from gtrig import geometry as geo
from gtrig.rig.models import Rig
from gtrig.vision.observations import FrameObservations, MarkerView, marker_corners_marker


@dataclass(frozen=True)
class CornerNoise:
    """Gaussian corner noise: ``sigma_px`` at ``ref_side_px`` (a marker of that side in the image),
    growing as ``ref_side_px / side`` for smaller markers (fewer edge pixels per corner), and
    anisotropic by ``anisotropy`` (ratio of the two axes, random orientation)."""

    sigma_px: float = 0.08
    ref_side_px: float = 80.0
    anisotropy: float = 1.5


def _corner_cov(rng: np.random.Generator, side_px: float, noise: CornerNoise) -> np.ndarray:
    s = noise.sigma_px * max(1.0, noise.ref_side_px / max(side_px, 1e-6)) ** 0.5
    out = np.empty((4, 2, 2))
    for i in range(4):
        a = rng.uniform(0, np.pi)
        R = np.array([[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]])
        d = np.diag([s**2 * noise.anisotropy, s**2 / noise.anisotropy])
        out[i] = R @ d @ R.T
    return out


def visible_views(rig: Rig, T_world_robot: np.ndarray, margin_px: float = 2.0, min_side_px: float = 15.0
                  ) -> list[tuple[str, int, np.ndarray]]:
    """Markers fully visible in each camera at a robot pose: ``(camera, marker ID, corners_px (4, 2))``.

    Fully visible: all four corners in front of the camera and inside the image by ``margin_px``, the
    printed face towards the camera, and a side of at least ``min_side_px``. Markers lie on the robot's
    top plate, so they do not occlude each other.
    """
    out = []
    for cam in rig.cameras:
        T_cam_world = geo.inv_T(cam.T_world_cam.matrix())
        w, h = cam.resolution
        for m in rig.robot.markers:
            T_cm = T_cam_world @ T_world_robot @ m.T_robot_marker.matrix()
            p = geo.transform_points(T_cm, marker_corners_marker(m.side_m))
            if np.any(p[:, 2] <= 0.05):
                continue
            if T_cm[:3, 2] @ T_cm[:3, 3] >= 0:  # face normal must point at the camera
                continue
            uv = geo.project_points(p, cam.K, cam.dist)
            if np.any(uv < -0.5 + margin_px) or np.any(uv[:, 0] > w - 0.5 - margin_px) or \
                    np.any(uv[:, 1] > h - 0.5 - margin_px):
                continue
            side = float(np.mean(np.linalg.norm(uv - np.roll(uv, 1, axis=0), axis=1)))
            if side < min_side_px:
                continue
            out.append((cam.name, m.id, uv))
    return out


def synthetic_observations(rig_true: Rig, T_world_robot: np.ndarray, stamp_s: float,
                           rng: np.random.Generator, noise: CornerNoise = CornerNoise(),
                           cameras: tuple[str, ...] | None = None) -> FrameObservations:
    """Noisy corners of every fully visible marker in every camera (or only in ``cameras``).

    The covariances in the returned views are the ones the noise was drawn from.
    """
    views = []
    names = tuple(c.name for c in rig_true.cameras) if cameras is None else cameras
    for cam, mid, uv in visible_views(rig_true, T_world_robot):
        if cam not in names:
            continue
        side = float(np.mean(np.linalg.norm(uv - np.roll(uv, 1, axis=0), axis=1)))
        cov = _corner_cov(rng, side, noise)
        noisy = uv + np.stack([rng.multivariate_normal(np.zeros(2), c) for c in cov])
        views.append(MarkerView(cam, mid, noisy, cov))
    return FrameObservations(float(stamp_s), tuple(views), names)


def render_markers(rig_true: Rig, camera: str, T_world_robot: np.ndarray, rng: np.random.Generator,
                   supersample: int = 4, blur_px: float = 0.5, noise_grey: float = 1.5) -> np.ndarray:
    """A plain test image (8-bit grey) of the robot's markers seen by ``camera``.

    Not the simulator (``gtrig.sim.cameras``): each marker's printed pattern on a white label over a
    dark floor, ray-traced through the lens model (distortion included) at ``supersample`` x
    ``supersample`` samples per pixel, then a Gaussian blur and noise. Enough to run the detectors and
    the whole GTvision pipeline end to end in tests.
    """
    import cv2

    from gtrig.markers.families import marker_cells

    cam = rig_true.camera(camera)
    w, h = cam.resolution
    S = int(supersample)
    img = np.full((h, w), 90.0, np.float32)  # dark floor
    T_cam_world = geo.inv_T(cam.T_world_cam.matrix())
    labels = []
    for m in rig_true.robot.markers:
        T_cm = T_cam_world @ T_world_robot @ m.T_robot_marker.matrix()
        if T_cm[2, 3] <= 0 or T_cm[:3, 2] @ T_cm[:3, 3] >= 0:
            continue
        cells = marker_cells(m.family, m.id).astype(np.float32)
        pad = 1  # a one-cell white margin (labels of neighbouring markers must not overlap)
        lab = np.pad(cells, pad, constant_values=1.0) * 200.0 + 25.0  # (n + 2 pad) cells, black 25, white 225
        half = m.side_m / 2 * lab.shape[0] / cells.shape[0]
        p = geo.transform_points(T_cm, np.array([[-half, half, 0], [half, half, 0], [half, -half, 0],
                                                 [-half, -half, 0]]))
        if np.any(p[:, 2] <= 0.05):
            continue
        labels.append((lab, half, T_cm, geo.project_points(p, cam.K, cam.dist)))
    if labels:
        allp = np.concatenate([x[3] for x in labels])
        u0, v0 = np.maximum(np.floor(allp.min(axis=0)).astype(int) - 3, 0)
        u1, v1 = np.minimum(np.ceil(allp.max(axis=0)).astype(int) + 3, [w - 1, h - 1])
        if u1 > u0 and v1 > v0:
            us = u0 + (np.arange(S * (u1 - u0 + 1)) + 0.5) / S - 0.5
            vs = v0 + (np.arange(S * (v1 - v0 + 1)) + 0.5) / S - 0.5
            U, V = np.meshgrid(us, vs)
            pts = np.stack([U.ravel(), V.ravel()], axis=1).reshape(-1, 1, 2)
            xy = cv2.undistortPoints(pts, cam.K, cam.dist).reshape(U.shape + (2,))
            roi = np.full(U.shape, 90.0, np.float32)
            for lab, half, T_cm, uv in labels:
                n = lab.shape[0]
                # this label's box in the supersampled ROI
                a0 = np.clip((np.floor(uv.min(axis=0)) - 2 - [u0, v0]) * S, 0, None).astype(int)
                a1 = ((np.ceil(uv.max(axis=0)) + 3 - [u0, v0]) * S).astype(int)
                sl = (slice(a0[1], a1[1]), slice(a0[0], a1[0]))
                xyb = xy[sl]
                # normalised image point -> label plane (X, Y) by the plane's homography, then to cells
                Hn = np.column_stack([T_cm[:3, 0], T_cm[:3, 1], T_cm[:3, 3]])
                q = np.einsum("ij,hwj->hwi", np.linalg.inv(Hn), np.dstack([xyb, np.ones(xyb.shape[:2])]))
                X, Y = q[..., 0] / q[..., 2], q[..., 1] / q[..., 2]
                col = (X + half) / (2 * half) * n  # cell units, 0 at the label's left edge
                row = (half - Y) / (2 * half) * n
                inside = (col >= 0) & (col < n) & (row >= 0) & (row < n)
                ci = np.clip(col.astype(int), 0, n - 1)
                ri = np.clip(row.astype(int), 0, n - 1)
                roi[sl] = np.where(inside, lab[ri, ci], roi[sl])
            roi = roi.reshape(v1 - v0 + 1, S, u1 - u0 + 1, S).mean(axis=(1, 3))
            img[v0:v1 + 1, u0:u1 + 1] = roi
    if blur_px > 0:
        img = np.asarray(cv2.GaussianBlur(img, (0, 0), blur_px), dtype=np.float32)
    img = img + rng.normal(0, noise_grey, img.shape).astype(np.float32)
    return np.clip(np.rint(img), 0, 255).astype(np.uint8)
