"""Align an estimate to the ground truth: ``p_gt ~ s R p_est + t`` by least squares on positions.

Kinds (``AlignKind``):

- ``none``: identity.
- ``se3`` / ``sim3``: Umeyama (IEEE PAMI 13(4), 1991), closed form by SVD, as evo's
  ``geometry.umeyama_alignment`` (same formulas, so the same numbers to rounding).
- ``yaw``: a rotation about the world z axis plus a 3-D translation (4 DoF: gravity is observable, as for
  visual-inertial odometry and every ground robot); Umeyama in the x-y plane, translation from the
  centroids.
- ``se2``: a rotation about z plus an x-y translation (3 DoF, z untouched): the RAWSEEDS toolkit's 2-D
  alignment (get_ATE.m minimizes the same position residuals with Levenberg-Marquardt; the least-squares
  optimum is this closed form).
- ``sim2``: ``se2`` plus a scale (get_ATE.m with ``unknown_scale``, monocular SLAM).

All run in O(N) with one 3 x 3 (or 2 x 2) SVD; 10^6 poses take ~50 ms.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Literal

import numpy as np
from scipy.spatial.transform import Rotation

from gtrig.errors import InputError
from gtrig.evaluate import _kernels
from gtrig.trajectory import PLANAR_INDEX, PoseTrack

AlignKind = Literal["none", "se3", "sim3", "yaw", "se2", "sim2"]
ALIGN_KINDS: tuple[str, ...] = ("none", "se3", "sim3", "yaw", "se2", "sim2")


@dataclass(frozen=True)
class Alignment:
    """``p_gt = scale * R @ p_est + t``; ``R_gt = R @ R_est``.

    Attributes
    ----------
    kind : which family was fitted.
    R : (3, 3) rotation, estimate world frame -> GT world frame.
    t : (3,) metres.
    scale : 1 unless ``sim3`` / ``sim2``.
    n_used : poses the fit used.
    """

    kind: str
    R: np.ndarray
    t: np.ndarray
    scale: float
    n_used: int

    @property
    def yaw_rad(self) -> float:
        return float(np.arctan2(self.R[1, 0], self.R[0, 0]))

    def matrix(self) -> np.ndarray:
        """(4, 4) Sim(3) matrix."""
        T = np.eye(4)
        T[:3, :3] = self.scale * self.R
        T[:3, 3] = self.t
        return T


def umeyama(x: np.ndarray, y: np.ndarray, with_scale: bool) -> tuple[np.ndarray, np.ndarray, float]:
    """``R, t, c`` minimizing ``sum |y_i - (c R x_i + t)|^2`` (Umeyama 1991).

    Parameters
    ----------
    x, y : (n, m) points (m = 2 or 3), row i of one matched with row i of the other.
    """
    n, m = x.shape
    mx, my = x.mean(axis=0), y.mean(axis=0)
    xc, yc = x - mx, y - my
    sigma_x = float(np.einsum("ij,ij->", xc, xc)) / n
    # einsum, not yc.T @ xc: BLAS's threads cost more than this (n, m) product at 10^6 rows on a busy machine
    cov_xy = np.einsum("ni,nj->ij", yc, xc) / n
    u, d, vt = np.linalg.svd(cov_xy)
    if np.count_nonzero(d > np.finfo(d.dtype).eps) < m - 1:
        raise InputError("degenerate trajectory (all positions on a line or a point): alignment impossible")
    s = np.eye(m)
    if np.linalg.det(u) * np.linalg.det(vt) < 0.0:
        s[m - 1, m - 1] = -1
    R = u @ s @ vt
    c = float(np.trace(np.diag(d) @ s)) / sigma_x if with_scale else 1.0
    return R, my - c * R @ mx, c


def fit_alignment(gt_xyz: np.ndarray, est_xyz: np.ndarray, kind: AlignKind, mask: np.ndarray | None = None
                  ) -> Alignment:
    """The ``kind`` alignment of ``est_xyz`` onto ``gt_xyz`` ((N, 3) each), over ``mask`` when given."""
    if kind not in ALIGN_KINDS:
        raise InputError(f"--align must be one of {', '.join(ALIGN_KINDS)}, got {kind!r}")
    g = np.asarray(gt_xyz, float)
    e = np.asarray(est_xyz, float)
    if mask is not None:
        g, e = g[mask], e[mask]
    n = len(g)
    if kind == "none":
        return Alignment(kind, np.eye(3), np.zeros(3), 1.0, n)
    if n < 3:
        raise InputError(f"{n} paired poses in the alignment interval: at least 3 are needed for --align {kind}")
    if kind in ("se3", "sim3"):
        R, t, c = umeyama(e, g, kind == "sim3")
        return Alignment(kind, R, t, c, n)
    R2, t2, c = umeyama(e[:, :2], g[:, :2], kind == "sim2")
    R = np.eye(3)
    R[:2, :2] = R2
    t = np.zeros(3)
    t[:2] = t2
    if kind == "yaw":
        t[2] = float(np.mean(g[:, 2] - e[:, 2]))
    return Alignment(kind, R, t, c, n)


def apply_alignment(track: PoseTrack, a: Alignment) -> PoseTrack:
    """A new track moved by ``a``: positions ``s R p + t``, rotations ``R R_i``, covariances rotated into the
    new world axes (world-frame perturbations: ``C' = J C J^T`` with ``J = diag(sR, R)``)."""
    if a.kind == "none":
        return track
    xyz, q = _kernels.transform_poses(float(a.scale), np.ascontiguousarray(a.R, dtype=float),
                                      np.asarray(a.t, dtype=float), Rotation.from_matrix(a.R).as_quat(),
                                      np.ascontiguousarray(track.xyz), np.ascontiguousarray(track.quat_xyzw))
    cov = None
    if track.cov is not None:
        if track.cov_kind == "se3":
            J = np.zeros((6, 6))
            J[:3, :3] = a.scale * a.R
            J[3:, 3:] = a.R
        elif track.cov_kind == "xyz":
            J = a.scale * a.R
        else:
            # a yaw-only alignment keeps (x, y, yaw) planar: rotate x-y, yaw is unchanged
            J = np.eye(3)
            J[:2, :2] = a.scale * a.R[:2, :2]
        cov = J @ track.cov @ J.T
    return replace(track, xyz=xyz, quat_xyzw=q, cov=cov)


__all__ = ["ALIGN_KINDS", "AlignKind", "Alignment", "apply_alignment", "fit_alignment", "umeyama", "PLANAR_INDEX"]
