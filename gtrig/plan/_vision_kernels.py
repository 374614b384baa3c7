"""Compiled assembly of GTvision's normal matrices from the whitened corner Jacobians (numba).

The Jacobians themselves come from the estimator's functions (:mod:`gtrig.plan.vision`); this pass
only sums their products into each pose's normal matrix over (pose, marker corrections) and
eliminates the camera's own correction, one (pose, camera) group at a time, in explicit loops on
small blocks (no batched temporaries, no LAPACK call per group).
"""

from __future__ import annotations

import numba as nb
import numpy as np

from gtrig.fusion.kernels import chol_factor, chol_inv

_jit = nb.njit(cache=True, fastmath=False, nogil=True)


@_jit
def _cholesky(A: np.ndarray) -> np.ndarray:
    """Lower Cholesky factor of a small symmetric positive-definite matrix (NaN if it is not one, so that
    what is computed from it is NaN too)."""
    n = A.shape[0]
    L = np.zeros((n, n))
    if not chol_factor(A, L):
        L[:] = np.nan
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
    n_max = 6 + 6 * V
    Hcc = np.empty((kc, kc))
    rows = np.empty(n_max, dtype=np.int64)
    Hxc = np.empty((n_max, kc))
    Y = np.empty((kc, n_max))
    a = 0
    while a < V:
        k = pose[a]
        b = a
        while b < V and pose[b] == k:
            b += 1
        # own blocks of the corners
        for v in range(a, b):
            m0 = 6 + 6 * slot[v]
            for i in range(6):
                for j in range(i, 6):
                    s_pp = 0.0
                    s_mm = 0.0
                    for r in range(8):
                        s_pp += Jp[v, r, i] * Jp[v, r, j]
                        s_mm += Jm[v, r, i] * Jm[v, r, j]
                    H[k, i, j] += s_pp
                    if j != i:
                        H[k, j, i] += s_pp
                    if slot[v] >= 0:
                        H[k, m0 + i, m0 + j] += s_mm
                        if j != i:
                            H[k, m0 + j, m0 + i] += s_mm
                if slot[v] >= 0:
                    for j in range(6):
                        s_pm = 0.0
                        for r in range(8):
                            s_pm += Jp[v, r, i] * Jm[v, r, j]
                        H[k, i, m0 + j] += s_pm
                        H[k, m0 + j, i] += s_pm
        if not eliminate:
            a = b
            continue
        # the camera's correction: H_xx -= H_xc H_cc^-1 H_cx over the active rows (pose, markers in view)
        for i in range(kc):
            for j in range(kc):
                Hcc[i, j] = P_cam[i, j]
        for v in range(a, b):
            for i in range(kc):
                for j in range(i, kc):
                    s = 0.0
                    for r in range(8):
                        s += Jc[v, r, i] * Jc[v, r, j]
                    Hcc[i, j] += s
                    if j != i:
                        Hcc[j, i] += s
        for i in range(6):
            rows[i] = i
            for j in range(kc):
                Hxc[i, j] = 0.0
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
        for c in range(na):
            for i in range(kc):
                t = Hxc[c, i]
                for q in range(i):
                    t -= L[i, q] * Y[q, c]
                Y[i, c] = t / L[i, i]
        for i in range(na):
            for j in range(i, na):
                s = 0.0
                for q in range(kc):
                    s += Y[q, i] * Y[q, j]
                H[k, rows[i], rows[j]] -= s
                if j != i:
                    H[k, rows[j], rows[i]] -= s
        a = b


@_jit
def pose_block_of_inverse(H: np.ndarray, n_pose: int) -> np.ndarray:
    """The leading ``n_pose`` block (K, n_pose, n_pose) of ``inv(H)`` for symmetric positive-definite
    normal matrices (K, D, D) (each symmetrised first), by a Cholesky Schur complement of the rest."""
    K, D = H.shape[0], H.shape[1]
    p = n_pose
    r = D - p
    out = np.empty((K, p, p))
    A = np.empty((r, r))
    Y = np.empty((r, p))
    S = np.empty((p, p))
    Sinv = np.empty((p, p))
    for k in range(K):
        for i in range(r):
            for j in range(r):
                A[i, j] = 0.5 * (H[k, p + i, p + j] + H[k, p + j, p + i])
        for i in range(p):
            for j in range(p):
                S[i, j] = 0.5 * (H[k, i, j] + H[k, j, i])
        if r > 0:
            L = _cholesky(A)
            # Y = L^-1 H_np, then S = H_pp - Y^T Y
            for c in range(p):
                for i in range(r):
                    t = 0.5 * (H[k, p + i, c] + H[k, c, p + i])
                    for q in range(i):
                        t -= L[i, q] * Y[q, c]
                    Y[i, c] = t / L[i, i]
            for i in range(p):
                for j in range(p):
                    t = 0.0
                    for q in range(r):
                        t += Y[q, i] * Y[q, j]
                    S[i, j] -= t
        chol_inv(S, Sinv)
        out[k] = Sinv
    return out
