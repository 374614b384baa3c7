"""Checks of a tracked rigid body that need no other truth than its known shape.

A board's corners are reconstructed two ways:

* independently of its shape, by triangulation at each instant (:func:`triangulate_points`: every point
  seen by two cameras or more, linear then Gauss-Newton on the pixels, with a covariance);
* from the tracked poses (:func:`shape_from_poses`): each point's position in the body frame from every
  camera's ray at every instant, the rays carried into the body frame by the tracked ``T_world_body``.

Either reconstruction gives the body's size and flatness (:func:`edge_errors`, :func:`plane_rms`);
:func:`rigidity_nees` and :func:`split_pose_nees` test the covariances against the body's rigidity and
against a second pose of the same instant from other cameras.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import cv2
import numpy as np

from gtrig import geometry as geo
from gtrig.vision.body import BodyOptions, BodyPose, BodyView, PointBody, estimate_body_pose
from gtrig.vision.covariance import nees, pose_error_xi
from gtrig.vision.observations import CameraGeometry


@dataclass(frozen=True)
class TriangulatedPoints:
    """Points of one instant triangulated from two cameras or more.

    Attributes
    ----------
    ids : (m,) point IDs; X_world : (m, 3) metres; cov : (m, 3, 3) m^2 (pixel noise ``sigma_px``)
    n_cameras : (m,) cameras that saw each
    """

    ids: np.ndarray
    X_world: np.ndarray
    cov: np.ndarray
    n_cameras: np.ndarray


def _normalized(cam: CameraGeometry, uv: np.ndarray) -> np.ndarray:
    return cv2.undistortPoints(np.asarray(uv, float).reshape(-1, 1, 2), cam.K, cam.dist).reshape(-1, 2)


def _project_with_jacobian(cam: CameraGeometry, X_world: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Pixels (2,) of a world point and their Jacobian (2, 3) in the point."""
    R, t = cam.T_cam_world[:3, :3], cam.T_cam_world[:3, 3]
    p_cam = R @ X_world + t
    uv, jac = cv2.projectPoints(p_cam.reshape(1, 1, 3), np.zeros(3), np.zeros(3), cam.K, cam.dist)
    return uv.reshape(2), jac[:, 3:6] @ R


def _linear_point(rows: list[tuple[np.ndarray, np.ndarray]]) -> np.ndarray:
    """DLT point from (``P`` (3, 4) normalized projection, ``xy`` (2,)) pairs."""
    A = np.concatenate([np.stack([xy[0] * P[2] - P[0], xy[1] * P[2] - P[1]]) for P, xy in rows])
    X = np.linalg.svd(A)[2][-1]
    return X[:3] / X[3]


def triangulate_points(cameras: Mapping[str, CameraGeometry], views: Sequence[BodyView], sigma_px: float,
                       iterations: int = 5) -> TriangulatedPoints:
    """Every point of one instant seen by two cameras or more, in the world frame (module docstring)."""
    seen: dict[int, list[tuple[str, np.ndarray, np.ndarray]]] = {}
    for v in views:
        xy = _normalized(cameras[v.camera], v.points_px)
        for k, uv, n in zip(v.ids, np.asarray(v.points_px, float), xy, strict=True):
            seen.setdefault(int(k), []).append((v.camera, uv, n))
    ids, Xs, covs, ncam = [], [], [], []
    for k, obs in sorted(seen.items()):
        if len({c for c, _, _ in obs}) < 2:
            continue
        X = _linear_point([(cameras[c].T_cam_world[:3], n) for c, _, n in obs])
        for _ in range(iterations):
            JJ, Jr = np.zeros((3, 3)), np.zeros(3)
            for c, uv, _ in obs:
                pred, J = _project_with_jacobian(cameras[c], X)
                JJ += J.T @ J
                Jr += J.T @ (pred - uv)
            X = X - np.linalg.solve(JJ, Jr)
        ids.append(k)
        Xs.append(X)
        covs.append(sigma_px**2 * np.linalg.inv(JJ))
        ncam.append(len(obs))
    return TriangulatedPoints(np.array(ids, int), np.array(Xs).reshape(-1, 3), np.array(covs).reshape(-1, 3, 3),
                              np.array(ncam, int))


def shape_from_poses(cameras: Mapping[str, CameraGeometry], poses: Sequence[BodyPose],
                     views: Sequence[Sequence[BodyView]], min_cameras: int = 2) -> dict[int, np.ndarray]:
    """Each point's position (3,) in the body frame, metres, from the rays of every camera at every
    instant whose pose used ``min_cameras`` cameras or more, carried into the body frame by its
    ``T_world_body`` (linear least squares on the normalized image coordinates)."""
    rows: dict[int, list[tuple[np.ndarray, np.ndarray]]] = {}
    for p, vs in zip(poses, views, strict=True):
        if not p.ok or p.T_world_body is None or len(p.cameras) < min_cameras:
            continue
        for v in vs:
            if v.camera not in p.cameras:
                continue
            P = (cameras[v.camera].T_cam_world @ p.T_world_body)[:3]
            for k, n in zip(v.ids, _normalized(cameras[v.camera], v.points_px), strict=True):
                rows.setdefault(int(k), []).append((P, n))
    return {k: _linear_point(r) for k, r in sorted(rows.items()) if len(r) >= 2}


def plane_rms(X: np.ndarray) -> float:
    """RMS distance (m) of points (n, 3) from their least-squares plane."""
    c = np.asarray(X, float) - np.mean(X, axis=0)
    return float(np.linalg.svd(c, compute_uv=False)[-1] / np.sqrt(len(c)))


def edge_errors(points: Mapping[int, np.ndarray], body: PointBody, edge_m: float, tol: float = 1e-6) -> np.ndarray:
    """Reconstructed minus designed length (m) of every edge of length ``edge_m`` between points of
    ``points`` ({ID: (3,)}) in the body's layout (a board's squares: ``edge_m`` = the square's side)."""
    P = body.points_body
    ids = sorted(points)
    out = []
    for i, a in enumerate(ids):
        for b in ids[i + 1:]:
            if abs(np.linalg.norm(P[a] - P[b]) - edge_m) < tol:
                out.append(np.linalg.norm(points[a] - points[b]) - edge_m)
    return np.array(out)


def rigidity_nees(tri: TriangulatedPoints, pose: BodyPose, body: PointBody) -> np.ndarray:
    """Per triangulated point, ``d^T cov^-1 d`` of ``d = X_triangulated - T_world_body p_body`` (3 dof each
    when the points' noise model is right and the body rigid)."""
    assert pose.T_world_body is not None
    pred = geo.transform_points(pose.T_world_body, body.points_body[tri.ids])
    d = tri.X_world - pred
    return np.array([nees(e, C) for e, C in zip(d, tri.cov, strict=True)])


def split_pose_nees(cameras: Mapping[str, CameraGeometry], body: PointBody, views: Sequence[BodyView],
                    options: BodyOptions | None = None) -> list[float]:
    """For each camera with a view of ``options.min_points`` points: the NEES (6 dof) of the pose from that
    camera alone against the pose from the other cameras, with the sum of their covariances (independent
    pixels, so the sum is the difference's covariance when both are right)."""
    options = options or BodyOptions()
    out = []
    for v in views:
        rest = [w for w in views if w.camera != v.camera]
        if len(v.ids) < options.min_points or not any(len(w.ids) >= options.min_points for w in rest):
            continue
        a = estimate_body_pose(cameras, body, [v], 0.0, options)
        b = estimate_body_pose(cameras, body, rest, 0.0, options)
        if a.ok and b.ok and a.T_world_body is not None and b.T_world_body is not None:
            assert a.cov_6x6 is not None and b.cov_6x6 is not None
            out.append(nees(pose_error_xi(a.T_world_body, b.T_world_body), a.cov_6x6 + b.cov_6x6))
    return out
