"""Linear algebra of a chain: a block-tridiagonal normal matrix with a dense border of global parameters.

The normal equations of a chain of nodes (one d x d block per node, one off-diagonal block per pair of
neighbours) plus p global parameters (odometry scales) are::

    [ A    B ] [dx]   [gx]          A: block tridiagonal (N blocks Ad[i], Ao[i] = A[i, i+1])
    [ B^T  C ] [dk] = [gk]          B: (N d, p) border, C: (p, p)

Solved by block elimination along the chain (the information-form Kalman filter forward, its
Rauch-Tung-Striebel pass backward) and a Schur complement on the p parameters, in O(N (d + p)^3):
linear in the chain's length. The diagonal blocks of the inverse (the marginal covariances) come from
the same recursion backward (Sigma_i = S_i^-1 + S_i^-1 Ao_i Sigma_{i+1} Ao_i^T S_i^-1, S_i the forward
Schur complements), plus the parameters' share ``(A^-1 B)_i (C - B^T A^-1 B)^-1 (A^-1 B)_i^T``.
"""

from __future__ import annotations

import numba as nb
import numpy as np

from gtrig.errors import ConvergenceError
from gtrig.fusion.kernels import chol_inv

_jit = nb.njit(cache=True, nogil=True)


@_jit
def _forward_backward(Ad: np.ndarray, Ao: np.ndarray, Y: np.ndarray, Sinv: np.ndarray) -> int:
    """Solve A X = Y for (N, d, c) right-hand sides ``Y``, in place: ``Y`` holds X on return (each block
    of the forward pass is read once by the backward one, so no second (N, d, c) array is needed); fills
    Sinv (N, d, d) with the inverse forward Schur complements. Returns -1 on success, else the index of
    the first block that is not positive definite (``Y`` then half eliminated)."""
    N, d, c = Y.shape
    S = np.empty((d, d))
    T = np.empty((d, d))  # Ao_i^T Sinv_i
    for i in range(N):
        for a in range(d):
            for b in range(d):
                S[a, b] = Ad[i, a, b]
        if i > 0:
            # S_i = Ad_i - Ao_{i-1}^T Sinv_{i-1} Ao_{i-1};  Y_i -= Ao_{i-1}^T Sinv_{i-1} Y_{i-1}
            for a in range(d):
                for b in range(d):
                    t = 0.0
                    for k in range(d):
                        t += Ao[i - 1, k, a] * Sinv[i - 1, k, b]
                    T[a, b] = t
            for a in range(d):
                for b in range(d):
                    t = 0.0
                    for k in range(d):
                        t += T[a, k] * Ao[i - 1, k, b]
                    S[a, b] -= t
                for b in range(c):
                    t = 0.0
                    for k in range(d):
                        t += T[a, k] * Y[i - 1, k, b]
                    Y[i, a, b] -= t
        if not chol_inv(S, Sinv[i]):
            return i
    # backward: X_i = Sinv_i (Y_i - Ao_i X_{i+1}), X_i written over Y_i (Y_{i+1} already holds X_{i+1})
    Z = np.empty((d, c))
    for i in range(N - 1, -1, -1):
        for a in range(d):
            for b in range(c):
                t = Y[i, a, b]
                if i < N - 1:
                    for k in range(d):
                        t -= Ao[i, a, k] * Y[i + 1, k, b]
                Z[a, b] = t
        for a in range(d):
            for b in range(c):
                t = 0.0
                for k in range(d):
                    t += Sinv[i, a, k] * Z[k, b]
                Y[i, a, b] = t
    return -1


@_jit
def _diag_inverse(Ao: np.ndarray, Sinv: np.ndarray, out: np.ndarray) -> None:
    """Diagonal blocks (N, d, d) of A^-1 from the forward pass's Sinv (the RTS covariance recursion)."""
    N, d, _ = Sinv.shape
    out[N - 1] = Sinv[N - 1]
    M = np.empty((d, d))
    P = np.empty((d, d))
    for i in range(N - 2, -1, -1):
        # M = Sinv_i Ao_i;  out_i = Sinv_i + M out_{i+1} M^T
        for a in range(d):
            for b in range(d):
                t = 0.0
                for k in range(d):
                    t += Sinv[i, a, k] * Ao[i, k, b]
                M[a, b] = t
        for a in range(d):
            for b in range(d):
                t = 0.0
                for k in range(d):
                    t += M[a, k] * out[i + 1, k, b]
                P[a, b] = t
        for a in range(d):
            for b in range(a + 1):
                t = Sinv[i, a, b]
                for k in range(d):
                    t += P[a, k] * M[b, k]
                out[i, a, b] = t
                out[i, b, a] = t


#: nodes per slice of the per-node products after the solve (their temporaries stay a slice's, not the
#: chain's; each node's arithmetic is the same as over the whole chain)
CHUNK = 4096


def solve_chain(Ad: np.ndarray, Ao: np.ndarray, Bb: np.ndarray, C: np.ndarray, gx: np.ndarray, gk: np.ndarray,
                marginals: bool = False) -> tuple[np.ndarray, np.ndarray, np.ndarray | None, np.ndarray | None]:
    """Solve the bordered block-tridiagonal system.

    Parameters
    ----------
    Ad : (N, d, d) diagonal blocks; Ao : (N-1, d, d) blocks A[i, i+1]; Bb : (N, d, p) border;
    C : (p, p); gx : (N, d), gk : (p,) right-hand side, or (N, d, c) and (p, c) for c right-hand sides
        solved on one factorisation (the considered biases' sensitivities, gtrig.fusion.batch).
    marginals : also return the diagonal blocks of the inverse.

    Returns
    -------
    dx (N, d) or (N, d, c), dk (p,) or (p, c), cov_x (N, d, d) or None, cov_k (p, p) or None.

    Raises
    ------
    ConvergenceError : the system is singular (a node or a parameter no factor constrains).
    """
    multi = gx.ndim == 3
    G = gx if multi else gx[:, :, None]
    GB = np.concatenate([G, Bb], axis=2)
    dx, dk, cov, cov_k = solve_chain_inplace(Ad, Ao, Bb, C, GB, np.asarray(gk, float).reshape(C.shape[0], G.shape[2]),
                                             marginals)
    if not multi:
        return dx[:, :, 0].copy(), dk[:, 0], cov, cov_k  # the (N, d, 1 + p) work array freed
    return dx, dk, cov, cov_k


def solve_chain_inplace(Ad: np.ndarray, Ao: np.ndarray, Bb: np.ndarray, C: np.ndarray, GB: np.ndarray,
                        gk: np.ndarray, marginals: bool = False,
                        ) -> tuple[np.ndarray, np.ndarray, np.ndarray | None, np.ndarray | None]:
    """:func:`solve_chain` on a work array ``GB`` (N, d, c + p) that holds ``[G, B]`` (the c right-hand
    sides, then the border ``Bb``) and is overwritten (``A^-1 [G, B]``, then the solution in its first c
    columns): no copy of the right-hand sides is made. ``gk`` (p, c). Returns dx (N, d, c), a view of
    ``GB``; dk (p, c); cov_x (N, d, d) and cov_k (p, p), or None."""
    N, d, _ = Ad.shape
    p = C.shape[0]
    c = GB.shape[2] - p
    X = GB
    Sinv = np.empty((N, d, d))
    bad = _forward_backward(Ad, np.ascontiguousarray(Ao), X, Sinv)
    if bad >= 0:
        raise ConvergenceError(f"fusion: node {bad} of the chain is unconstrained (no fix, no motion model)")
    AinvB = X[:, :, c:]
    dx = X[:, :, :c]
    if p:
        Sk = C - np.einsum("nda,ndb->ab", Bb, AinvB)
        Sk_inv = np.empty((p, p))
        if not chol_inv(Sk, Sk_inv):
            raise ConvergenceError("fusion: the odometry parameters are not observable from these data")
        dk = Sk_inv @ (gk - np.einsum("nda,ndc->ac", Bb, dx))
        for a in range(0, N, CHUNK):
            dx[a:a + CHUNK] -= np.einsum("ndp,pc->ndc", AinvB[a:a + CHUNK], dk)
    else:
        Sk_inv = np.zeros((0, 0))
        dk = np.zeros((0, c))
    if not marginals:
        return dx, dk, None, None
    cov = np.empty((N, d, d))
    _diag_inverse(np.ascontiguousarray(Ao), Sinv, cov)
    del Sinv
    if p:
        for a in range(0, N, CHUNK):
            cov[a:a + CHUNK] += np.einsum("nap,pq,nbq->nab", AinvB[a:a + CHUNK], Sk_inv, AinvB[a:a + CHUNK])
    return dx, dk, cov, Sk_inv
