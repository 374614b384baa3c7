"""Averages of rotations and rigid poses on SO(3) / SE(3), never element by element.

The seeds averaged the elements of the 4 x 4 matrices (AD2.3, "Calibration of the camera network"); the
result is not a rotation and is biased towards identity. Here the rotation mean is the geodesic (Karcher)
L2 mean: start from the chordal mean (the principal eigenvector of the weighted quaternion scatter
matrix; Markley et al., "Averaging quaternions", J. Guidance 2007), then iterate
``R <- R Exp(mean_i Log(R^T R_i))`` (Hartley et al., "Rotation averaging", IJCV 2013, Alg. 1).
Poses average the rotation that way and the translations arithmetically (each pose of the set is an
independent estimate of the same transform, so the mean translation is the estimate of ``t``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike
from scipy.spatial.transform import Rotation

from gtrig import geometry as geo
from gtrig.errors import InputError


def chordal_mean_rotation(R: ArrayLike, weights: ArrayLike | None = None) -> geo.Array:
    """Chordal L2 mean of rotations ``R`` (N, 3, 3) via the quaternion scatter matrix; returns (3, 3)."""
    Rs = np.asarray(R, dtype=float).reshape(-1, 3, 3)
    if Rs.shape[0] == 0:
        raise InputError("cannot average an empty set of rotations")
    w = np.ones(len(Rs)) if weights is None else np.asarray(weights, dtype=float).ravel()
    q = Rotation.from_matrix(Rs).as_quat()
    M = np.einsum("i,ij,ik->jk", w, q, q)
    _, vec = np.linalg.eigh(M)
    return Rotation.from_quat(vec[:, -1]).as_matrix()


def mean_rotation(
    R: ArrayLike, weights: ArrayLike | None = None, *, tol_rad: float = 1e-12, max_iter: int = 50
) -> geo.Array:
    """Geodesic L2 (Karcher) mean of rotations ``R`` (N, 3, 3) with optional weights (N,); (3, 3)."""
    Rs = np.asarray(R, dtype=float).reshape(-1, 3, 3)
    w = np.ones(len(Rs)) if weights is None else np.asarray(weights, dtype=float).ravel()
    if w.size != len(Rs) or np.any(w < 0) or w.sum() <= 0:
        raise InputError("rotation weights must be non-negative, one per rotation, not all zero")
    w = w / w.sum()
    Rm = chordal_mean_rotation(Rs, w)
    for _ in range(max_iter):
        v = Rotation.from_matrix(np.einsum("ji,njk->nik", Rm, Rs)).as_rotvec()
        step = w @ v
        Rm = Rm @ Rotation.from_rotvec(step).as_matrix()
        if np.linalg.norm(step) < tol_rad:
            break
    return Rm


@dataclass(frozen=True)
class PoseMean:
    """The mean of a set of poses and its spread.

    Attributes
    ----------
    T : (4, 4) mean transform.
    rot_rms_rad : RMS geodesic distance of the inputs' rotations to the mean (radians).
    trans_rms_m : RMS distance of the inputs' translations to the mean (metres).
    n : number of poses averaged.
    """

    T: np.ndarray
    rot_rms_rad: float
    trans_rms_m: float
    n: int


def mean_pose(T: ArrayLike, weights: ArrayLike | None = None) -> PoseMean:
    """Average rigid transforms ``T`` (N, 4, 4): Karcher mean of rotations, weighted mean of translations."""
    Ts = np.asarray(T, dtype=float).reshape(-1, 4, 4)
    if len(Ts) == 0:
        raise InputError("cannot average an empty set of poses")
    w = np.ones(len(Ts)) if weights is None else np.asarray(weights, dtype=float).ravel()
    R = mean_rotation(Ts[:, :3, :3], w)
    t = (w / w.sum()) @ Ts[:, :3, 3]
    dr = np.linalg.norm(Rotation.from_matrix(np.einsum("ji,njk->nik", R, Ts[:, :3, :3])).as_rotvec(), axis=1)
    dt = np.linalg.norm(Ts[:, :3, 3] - t, axis=1)
    return PoseMean(geo.make_T(R, t), float(np.sqrt(np.mean(dr**2))), float(np.sqrt(np.mean(dt**2))), len(Ts))


def elementwise_mean_pose(T: ArrayLike) -> geo.Array:
    """The seeds' average: the mean of the matrix elements (not a rigid transform). For comparison only."""
    return np.asarray(T, dtype=float).reshape(-1, 4, 4).mean(axis=0)
