"""The seeds' estimator: a forward extended Kalman filter with a Rauch-Tung-Striebel backward pass.

The RAWSEEDS ground truth (journal paper, sections 4.4 and 8) is an Extended Kalman Smoother of the
vision and laser fixes with odometry. Here it runs over the very factors of
:class:`~gtrig.fusion.chain.FactorChain`: the state is ``(x_i, K)`` (node pose and odometry parameters);
between nodes i and i+1 the filter holds the joint ``(x_i, x_{i+1}, K)``, so that a fix stamped between
them updates both through its interpolation weights (each fix at its own stamp), and every fix is gated
by its normalised innovation squared against the chi-square quantile before it may update. The backward
pass conditions each ``x_i`` on ``(x_{i+1}, K)`` (exact for a Markov chain with shared parameters) and
smooths in O(N).
"""

from __future__ import annotations

from dataclasses import dataclass

import numba as nb
import numpy as np
from scipy.stats import chi2

from gtrig.errors import ConvergenceError
from gtrig.fusion.chain import FactorChain
from gtrig.fusion.kernels import chol_inv, fix_residual, odo_predict
from gtrig.fusion.process import CHUNK


@dataclass(frozen=True)
class EkfResult:
    """X (N, d) smoothed states, K (p,) parameters, cov_x (N, d, d) smoothed covariances ((0, d, d) when
    not kept), cov_k (p, p), X_filtered (N, d) the forward pass alone, accept (M,) the gate's verdict,
    nis (M,) each fix's normalised innovation squared."""

    X: np.ndarray
    K: np.ndarray
    cov_x: np.ndarray
    cov_k: np.ndarray
    X_filtered: np.ndarray
    accept: np.ndarray
    nis: np.ndarray


#: a fix whose predicted variance exceeds its own by more than this on an axis (the first fix after an
#: odometry jump, :data:`gtrig.fusion.process.JUMP_SIGMA`) updates the covariance in Joseph's form:
#: the subtraction's rounding there, the prediction's variance times 1e-16, is no longer small against
#: what is left (a lapped recording's filter lost positive definiteness 6 nodes after its 4th jump).
#: Elsewhere (a run's start, 0.1 m against 1 mm: 1e4) the cheaper subtraction, whose outputs it keeps.
JOSEPH_RATIO = 1.0e8


@nb.njit(cache=True, nogil=True)
def _mm(A, B, out, transpose_b=False):  # noqa: ANN001, ANN202
    """out = A @ B (or A @ B^T), small blocks, no allocation."""
    n, k = A.shape
    m = B.shape[0] if transpose_b else B.shape[1]
    for a in range(n):
        for b in range(m):
            t = 0.0
            if transpose_b:
                for c in range(k):
                    t += A[a, c] * B[b, c]
            else:
                for c in range(k):
                    t += A[a, c] * B[c, b]
            out[a, b] = t


@nb.njit(cache=True, nogil=True)
def _predict_joint(process, proc_u_i, proc_Q_i, dt, m, P, zi, mu, Pj, f, F, Gm, F3, G3, FP, GQ, FPF):  # noqa: ANN001, ANN202, PLR0913
    """The joint (x_i, x_{i+1}, K) of step i: the mean ``mu`` and covariance ``Pj`` from (x_i, K)'s ``m``,
    ``P`` and the process model (odometry, or constant velocity over ``dt``)."""
    d = f.shape[0]
    n = m.shape[0]
    if process == 0:
        odo_predict(m[:3], m[3:6], proc_u_i, f, F3, G3)
        F[:, :] = F3
        Gm[:, :] = G3
    else:
        F[:, :] = 0.0
        for a in range(6):
            F[a, a] = 1.0
        for a in range(3):
            F[a, 3 + a] = dt
        for a in range(d):
            f[a] = 0.0
            for b in range(d):
                f[a] += F[a, b] * m[b]
        Gm[:, :] = np.eye(d)
    _mm(F, P, FP)
    for a in range(n):
        mu[zi[a]] = m[a]
        for b in range(n):
            Pj[zi[a], zi[b]] = P[a, b]
    _mm(Gm, proc_Q_i, GQ)
    _mm(GQ, Gm, FPF, True)
    for a in range(d):
        for b in range(d):
            t = FPF[a, b]
            for c in range(n):
                t += FP[a, c] * F[b, c]
            FPF[a, b] = t
    for a in range(d):
        mu[d + a] = f[a]
        for b in range(n):
            Pj[d + a, zi[b]] = FP[a, b]
            Pj[zi[b], d + a] = FP[a, b]
        for b in range(d):
            Pj[d + a, d + b] = FPF[a, b]


@nb.njit(cache=True, nogil=True)
def _apply_fix(j, d, fix_alpha, fix_kind, fix_z, fix_cov, fix_gcov, fix_lever, gate, mu, Pj, r, Jq, qb, hb, PHt,  # noqa: ANN001, ANN202, PLR0913
               Kg, S, nu, accept, nis):
    """Fix ``j`` on the joint of its step: its innovation gated (the prediction's covariance plus the fix's
    gate covariance), then applied to ``mu`` and ``Pj`` when accepted; ``accept[j]`` and ``nis[j]`` set."""
    nj = mu.shape[0]
    al = fix_alpha[j]
    mdim = fix_residual(mu[:d], mu[d:2 * d], al, fix_kind[j], fix_z[j], fix_lever[j], r, Jq, qb, hb)
    # P H^T with H = [(1 - al) Jq, al Jq, 0] on (x_i[:3], x_{i+1}[:3], K)
    for a in range(nj):
        for b in range(mdim):
            t = 0.0
            for c in range(3):
                t += ((1.0 - al) * Pj[a, c] + al * Pj[a, d + c]) * Jq[b, c]
            PHt[a, b] = t
    for a in range(mdim):
        for b in range(mdim):
            t = fix_cov[j, a, b]
            for c in range(3):
                t += Jq[a, c] * ((1.0 - al) * PHt[c, b] + al * PHt[d + c, b])
            S[a, b] = t
    Sm = S[:mdim, :mdim].copy()
    Si = np.empty((mdim, mdim))
    # the gate's innovation covariance: the prediction's plus the fix's own (gate_cov)
    Sg = Sm.copy()
    for a in range(mdim):
        for b in range(mdim):
            Sg[a, b] += fix_gcov[j, a, b] - fix_cov[j, a, b]
    Sgi = np.empty((mdim, mdim))
    if not chol_inv(Sm, Si) or not chol_inv(Sg, Sgi):
        accept[j] = False
        nis[j] = np.nan
        return
    for a in range(mdim):
        nu[a] = -r[a]
    q = 0.0
    for a in range(mdim):
        for b in range(mdim):
            q += nu[a] * Sgi[a, b] * nu[b]
    nis[j] = q
    if q > gate[mdim]:
        accept[j] = False
        return
    accept[j] = True
    # K = P H^T S^-1;  mean += K nu;  P -= K S K^T = PHt S^-1 PHt^T (symmetric update)
    for a in range(nj):
        t = 0.0
        for b in range(mdim):
            kab = 0.0
            for c in range(mdim):
                kab += PHt[a, c] * Si[c, b]
            Kg[a, b] = kab
            t += kab * nu[b]
        mu[a] += t
    for a in range(mdim):
        if S[a, a] > JOSEPH_RATIO * fix_cov[j, a, a]:
            _joseph_update(Pj, Kg, Jq, al, d, mdim, fix_cov[j])
            return
    for a in range(nj):
        for b in range(a + 1):
            t = 0.0
            for c in range(mdim):
                t += Kg[a, c] * PHt[b, c]
            Pj[a, b] -= t
            if b != a:
                Pj[b, a] -= t


@nb.njit(cache=True, nogil=True)
def _joseph_update(Pj, Kg, Jq, al, d, mdim, R):  # noqa: ANN001, ANN202
    """``Pj <- (I - K H) Pj (I - K H)^T + K R K^T`` (Joseph's form) for a fix with ``H = [(1 - al) Jq, al Jq,
    0]`` on (x_i[:3], x_{i+1}[:3], K): a sum of two positive semi-definite terms, where ``Pj - K S K^T``
    would subtract two numbers of the prediction's size to leave one of the fix's."""
    nj = Pj.shape[0]
    A = np.eye(nj)
    for a in range(nj):
        for c in range(3):
            t = 0.0
            for b in range(mdim):
                t += Kg[a, b] * Jq[b, c]
            A[a, c] -= (1.0 - al) * t
            A[a, d + c] -= al * t
    AP = np.empty((nj, nj))
    _mm(A, Pj, AP)
    _mm(AP, A, Pj, True)
    for a in range(nj):
        for b in range(nj):
            t = 0.0
            for c in range(mdim):
                for e in range(mdim):
                    t += Kg[a, c] * R[c, e] * Kg[b, e]
            Pj[a, b] += t
    for a in range(nj):  # exactly symmetric, as the subtraction above keeps it
        for b in range(a):
            t = 0.5 * (Pj[a, b] + Pj[b, a])
            Pj[a, b] = t
            Pj[b, a] = t


@nb.njit(cache=True, nogil=True)
def _rts_backward(m, P, mu_a, mu_b, Gs, Cs, Xs, Ps, Ks, Pks):  # noqa: ANN001, ANN202
    """The Rauch-Tung-Striebel pass from the last step's (x_N, K) ``m``, ``P``: each x_i from the stored
    conditionals ``x_i | (x_{i+1}, K)``; the smoothed states ``Xs``, covariances ``Ps`` (when kept) and K."""
    N, d = Xs.shape
    n = m.shape[0]
    p = n - d
    Xs[N - 1] = m[:d]
    keep_cov = Ps.shape[0] == N  # an empty Ps: the smoothed covariances are not kept
    if keep_cov:
        Ps[N - 1] = P[:d, :d]
    Pz = P.copy()
    mz = m.copy()
    GP = np.empty((d, n))
    Pxi = np.empty((d, d))
    for i in range(N - 2, -1, -1):
        G = Gs[i]
        # x_i = mu_a + G (z_{i+1} - mu_b);  P_i = C + G Pz G^T;  cross with K = G Pz[:, K]
        for a in range(d):
            t = mu_a[i, a]
            for c in range(n):
                t += G[a, c] * (mz[c] - mu_b[i, c])
            Xs[i, a] = t
        _mm(G, Pz, GP)
        _mm(GP, G, Pxi, True)
        for a in range(d):
            for b in range(d):
                Pxi[a, b] += Cs[i, a, b]
        for a in range(d):
            for b in range(p):
                Pz[a, d + b] = GP[a, d + b]
                Pz[d + b, a] = GP[a, d + b]
            for b in range(d):
                Pz[a, b] = Pxi[a, b]
            mz[a] = Xs[i, a]
        if keep_cov:
            Ps[i] = Pxi
    Ks[:] = mz[d:]
    Pks[:, :] = Pz[d:, d:]


@nb.njit(cache=True, nogil=True)
def _ekf_rts(process, proc_u, proc_Q, dts, fix_node, fix_alpha, fix_kind, fix_z, fix_cov, fix_gcov, fix_lever,  # noqa: ANN001, ANN201, PLR0913
             fix_use, gate, x0, P0, k0, Pk, Xs, Xf, Ps, Ks, Pks, accept, nis):
    N, d = Xs.shape
    p = k0.shape[0]
    n = d + p
    nj = 2 * d + p
    zi = np.empty(n, np.int64)  # where (x, K) sit in the joint (x_i, x_{i+1}, K)
    bi = np.empty(n, np.int64)  # where (x_{i+1}, K) sit
    for a in range(d):
        zi[a] = a
        bi[a] = d + a
    for a in range(p):
        zi[d + a] = 2 * d + a
        bi[d + a] = 2 * d + a
    m = np.empty(n)
    P = np.zeros((n, n))
    m[:d] = x0
    m[d:] = k0
    P[:d, :d] = P0
    P[d:, d:] = Pk
    mu_a = np.empty((N - 1, d))
    mu_b = np.empty((N - 1, n))
    Gs = np.empty((N - 1, d, n))
    Cs = np.empty((N - 1, d, d))
    mu = np.empty(nj)
    Pj = np.zeros((nj, nj))
    f = np.empty(d)
    F = np.zeros((d, n))
    Gm = np.zeros((d, d))
    F3 = np.empty((3, 6))
    G3 = np.empty((3, 3))
    r = np.empty(3)
    Jq = np.empty((3, 3))
    Xf[0] = x0
    FP = np.empty((d, n))
    GQ = np.empty((d, d))
    FPF = np.empty((d, d))
    Pbb = np.empty((n, n))
    Pab = np.empty((d, n))
    Pbb_inv = np.empty((n, n))
    PHt = np.empty((nj, 3))
    Kg = np.empty((nj, 3))
    S = np.empty((3, 3))
    nu = np.empty(3)
    qb = np.empty(3)
    hb = np.empty(3)
    j = 0
    M = fix_node.shape[0]
    for i in range(N - 1):
        # --- predict x_{i+1} from (x_i, K)
        _predict_joint(process, proc_u[i], proc_Q[i], dts[i] if process != 0 else 0.0, m, P, zi, mu, Pj, f, F, Gm,
                       F3, G3, FP, GQ, FPF)
        # --- the fixes stamped in (t_i, t_{i+1}], each gated, then applied
        while j < M and fix_node[j] == i:
            if not fix_use[j]:
                accept[j] = False
                nis[j] = np.nan
            else:
                _apply_fix(j, d, fix_alpha, fix_kind, fix_z, fix_cov, fix_gcov, fix_lever, gate, mu, Pj, r, Jq, qb,
                           hb, PHt, Kg, S, nu, accept, nis)
            j += 1
        # --- condition x_i on (x_{i+1}, K) for the backward pass; keep (x_{i+1}, K)
        for a in range(n):
            for b in range(n):
                Pbb[a, b] = Pj[bi[a], bi[b]]
        for a in range(d):
            for b in range(n):
                Pab[a, b] = Pj[a, bi[b]]
        if not chol_inv(Pbb, Pbb_inv):
            return i
        _mm(Pab, Pbb_inv, Gs[i])
        _mm(Gs[i], Pab, Cs[i], True)
        for a in range(d):
            for b in range(d):
                Cs[i, a, b] = Pj[a, b] - Cs[i, a, b]
        mu_a[i] = mu[:d]
        for a in range(n):
            mu_b[i, a] = mu[bi[a]]
            m[a] = mu[bi[a]]
        P[:, :] = Pbb
        Xf[i + 1] = m[:d]
    # --- backward (Rauch-Tung-Striebel)
    _rts_backward(m, P, mu_a, mu_b, Gs, Cs, Xs, Ps, Ks, Pks)
    return -1


def smooth_ekf(chain: FactorChain, P0: np.ndarray, Pk: np.ndarray, fix_use: np.ndarray | None = None,
               gate_prob: float = 0.9999, gate_cov: np.ndarray | None = None, covariances: bool = True,
               ) -> EkfResult:
    """Forward EKF (gated) and RTS smoother over ``chain``.

    Parameters
    ----------
    chain : the factors (``chain.x0``, ``chain.k0`` start the filter).
    P0 : (d, d) covariance of the first node's start; Pk : (p, p) the parameters' prior covariance.
    fix_use : (M,) bool, fixes allowed in (all by default).
    gate_prob : a fix whose normalised innovation squared exceeds the chi-square quantile of this
        probability (its own dimension's degrees of freedom) is rejected.
    gate_cov : (M, 3, 3) the fixes' covariances the gate tests against (the prediction's added); by default
        ``chain.fix_cov``, the ones that weigh the update.
    covariances : keep the smoothed covariances (False: ``cov_x`` is (0, d, d), for a start of the batch
        solve, which makes its own; N d^2 doubles not held).
    """
    N = len(chain)
    d, p = chain.d, chain.p
    # the process covariances (W^T W)^-1, a slice of nodes at a time (no (N, d, d) temporary beside them)
    proc_Q = np.empty(chain.proc_W.shape)
    for a in range(0, len(proc_Q), CHUNK):
        Wa = chain.proc_W[a:a + CHUNK]
        proc_Q[a:a + CHUNK] = np.linalg.inv(np.einsum("nki,nkj->nij", Wa, Wa))
    gate = np.array([0.0] + [float(chi2.ppf(gate_prob, k)) for k in (1, 2, 3)])
    M = chain.fix_node.size
    use = np.ones(M, bool) if fix_use is None else np.asarray(fix_use, bool)
    Xs = np.empty((N, d))
    Xf = np.empty((N, d))
    Ps = np.empty((N if covariances else 0, d, d))
    Ks = np.empty(p)
    Pks = np.empty((p, p))
    accept = np.zeros(M, bool)
    nis = np.full(M, np.nan)
    bad = _ekf_rts(chain.process, chain.proc_u, proc_Q, np.diff(chain.stamps_s), chain.fix_node, chain.fix_alpha,
                   chain.fix_kind, chain.fix_z, chain.fix_cov,
                   chain.fix_cov if gate_cov is None else np.ascontiguousarray(gate_cov, float), chain.fix_lever, use,
                   gate, chain.x0,
                   np.asarray(P0, float), chain.k0, np.asarray(Pk, float).reshape(p, p), Xs, Xf, Ps, Ks, Pks,
                   accept, nis)
    if bad >= 0:
        raise ConvergenceError(f"fusion: the filter's covariance lost positive definiteness at node {bad}")
    return EkfResult(Xs, Ks, Ps, Pks, Xf, accept, nis)
