"""Compiled assembly of GTvision's normal matrices from the whitened corner Jacobians (numba).

The Jacobians themselves come from the estimator's functions (:mod:`gtrig.plan.vision`); this pass
only sums their products into each pose's normal matrix over (pose, marker corrections) and
eliminates the camera's own correction, one (pose, camera) group at a time, in explicit loops on
small blocks (no batched temporaries, no LAPACK call per group).
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

_jit = nb.njit(cache=True, fastmath=False, nogil=True)


@_jit
def _cholesky(A: np.ndarray) -> np.ndarray:
    """Lower Cholesky factor of a small symmetric positive-definite matrix."""
    n = A.shape[0]
    L = np.zeros((n, n))
    for j in range(n):
        s = A[j, j]
        for q in range(j):
            s -= L[j, q] * L[j, q]
        L[j, j] = math.sqrt(s)
        for i in range(j + 1, n):
            t = A[i, j]
            for q in range(j):
                t -= L[i, q] * L[j, q]
            L[i, j] = t / L[j, j]
    return L


@_jit
def add_camera_views(H: np.ndarray, pose: np.ndarray, slot: np.ndarray, Jp: np.ndarray, Jm: np.ndarray,
                     Jc: np.ndarray, P_cam: np.ndarray, eliminate: bool) -> None:
    """Add one camera's views to the normal matrices ``H`` (K, D, D) over (pose, marker corrections).

    Parameters
    ----------
    H : (K, D, D) normal matrices, updated in place; rows 0-5 the robot pose, ``6 + 6 s`` the marker of slot s.
    pose : (V,) pose index of each view, non-decreasing (a pose's views are consecutive).
    slot : (V,) marker slot of each view (-1: the marker has no correction).
    Jp, Jm : (V, 8, 6) whitened Jacobians of the view's 8 corner coordinates in the robot pose and in the
        marker's correction.
    Jc : (V, 8, kc) whitened Jacobian in the camera's correction (pose and lens).
    P_cam : (kc, kc) the camera correction's prior information.
    eliminate : whether the camera has a correction to eliminate (else ``Jc`` and ``P_cam`` are unused).
    """
    V = pose.shape[0]
    kc = P_cam.shape[0]
    a = 0
    while a < V:
        k = pose[a]
        b = a
        while b < V and pose[b] == k:
            b += 1
        n = b - a
        # own blocks of the corners
        for v in range(a, b):
            m0 = 6 + 6 * slot[v]
            for i in range(6):
                for j in range(6):
                    s_pp = 0.0
                    s_pm = 0.0
                    s_mm = 0.0
                    for r in range(8):
                        s_pp += Jp[v, r, i] * Jp[v, r, j]
                        s_pm += Jp[v, r, i] * Jm[v, r, j]
                        s_mm += Jm[v, r, i] * Jm[v, r, j]
                    H[k, i, j] += s_pp
                    if slot[v] >= 0:
                        H[k, i, m0 + j] += s_pm
                        H[k, m0 + j, i] += s_pm
                        H[k, m0 + i, m0 + j] += s_mm
        if not eliminate:
            a = b
            continue
        # the camera's correction: H_xx -= H_xc H_cc^-1 H_cx over the active rows (pose, markers in view)
        Hcc = P_cam.copy()
        for v in range(a, b):
            for i in range(kc):
                for j in range(kc):
                    s = 0.0
                    for r in range(8):
                        s += Jc[v, r, i] * Jc[v, r, j]
                    Hcc[i, j] += s
        rows = np.empty(6 + 6 * n, dtype=np.int64)
        Hxc = np.zeros((6 + 6 * n, kc))
        for i in range(6):
            rows[i] = i
        na = 6
        for v in range(a, b):
            for i in range(6):
                for j in range(kc):
                    s = 0.0
                    for r in range(8):
                        s += Jp[v, r, i] * Jc[v, r, j]
                    Hxc[i, j] += s
            if slot[v] >= 0:
                for i in range(6):
                    rows[na + i] = 6 + 6 * slot[v] + i
                    for j in range(kc):
                        s = 0.0
                        for r in range(8):
                            s += Jm[v, r, i] * Jc[v, r, j]
                        Hxc[na + i, j] = s
                na += 6
        L = _cholesky(Hcc)
        # Y = L^-1 H_cx (kc, na); the elimination is Y^T Y
        Y = np.zeros((kc, na))
        for c in range(na):
            for i in range(kc):
                t = Hxc[c, i]
                for q in range(i):
                    t -= L[i, q] * Y[q, c]
                Y[i, c] = t / L[i, i]
        for i in range(na):
            for j in range(na):
                s = 0.0
                for q in range(kc):
                    s += Y[q, i] * Y[q, j]
                H[k, rows[i], rows[j]] -= s
        a = b
