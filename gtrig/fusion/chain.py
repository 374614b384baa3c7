"""The factors of one chain (what both estimators smooth) and their normal equations.

A :class:`FactorChain` holds, as arrays, every factor of one continuous segment: the process factors
between consecutive nodes (odometry increments or constant velocity), the absolute fixes (each at its own
stamp, between two nodes), and the priors (the first node, the odometry parameters). Whitening matrices
``W`` are upper Cholesky factors of the information (``W^T W = cov^-1``), so a whitened residual
``e = W r`` is a standard normal vector when the model holds.
"""

from __future__ import annotations

from dataclasses import dataclass

import numba as nb
import numpy as np

from gtrig.fusion.kernels import cv_residual, fix_residual, huber, odo_residual

PROCESS_ODOMETRY = 0
PROCESS_CV = 1


@dataclass(frozen=True)
class FactorChain:
    """Factors of one chain of N nodes.

    Attributes
    ----------
    stamps_s : (N,) node stamps, seconds (the output clock).
    process : PROCESS_ODOMETRY (d = 3, p = 3) or PROCESS_CV (d = 6, p = 0).
    proc_u : (N-1, 3) odometry increments in the robot frame of the earlier node (m, m, rad); empty for CV.
    proc_W : (N-1, d, d) whitening of each process factor.
    fix_node, fix_alpha : (M,) left node of each fix and its interpolation weight in [0, 1].
    fix_kind : (M,) kernels.KIND_POSE or KIND_POSITION.
    fix_z : (M, 3) measured (x, y, yaw) or (x, y, 0); fix_cov (M, 3, 3) its covariance (the unused row and
        column of a position fix are zero, with 1 on the diagonal; the filter's alone: (0, 3, 3) once it
        has run, in a chain for the batch solve); fix_W (M, 3, 3) its whitening (zero third row for a
        position fix).
    fix_lever : (M, 2) the measured point in the robot frame (position fixes), metres.
    fix_source : (M,) index into ``sources``; fix_stamps_s : (M,) the fixes' stamps on the output clock.
    x0, W0 : prior on node 0 (d,), (d, d); k0, Wk : prior on the parameters (p,), (p, p).
    """

    stamps_s: np.ndarray
    process: int
    proc_u: np.ndarray
    proc_W: np.ndarray  # noqa: N815
    fix_node: np.ndarray
    fix_alpha: np.ndarray
    fix_kind: np.ndarray
    fix_z: np.ndarray
    fix_cov: np.ndarray
    fix_W: np.ndarray  # noqa: N815
    fix_lever: np.ndarray
    fix_source: np.ndarray
    fix_stamps_s: np.ndarray
    sources: tuple[str, ...]
    x0: np.ndarray
    W0: np.ndarray
    k0: np.ndarray
    Wk: np.ndarray

    @property
    def d(self) -> int:
        return 3 if self.process == PROCESS_ODOMETRY else 6

    @property
    def p(self) -> int:
        return 3 if self.process == PROCESS_ODOMETRY else 0

    def __len__(self) -> int:
        return int(self.stamps_s.size)


@nb.njit(cache=True, nogil=True)
def _acc(Ad, Ao, Bb, C, g, gk, i, Ea, Eb, Ek, e, w, pair):  # noqa: ANN001, ANN202
    """Add w * [Ea Eb Ek]^T [Ea Eb Ek] and -w * [..]^T e to the normal equations (nodes i, i+1)."""
    m = e.shape[0]
    d = Ea.shape[1]
    p = Ek.shape[1]
    for a in range(d):
        for b in range(d):
            saa = 0.0
            sbb = 0.0
            sab = 0.0
            for r in range(m):
                saa += Ea[r, a] * Ea[r, b]
                if pair:
                    sbb += Eb[r, a] * Eb[r, b]
                    sab += Ea[r, a] * Eb[r, b]
            Ad[i, a, b] += w * saa
            if pair:
                Ad[i + 1, a, b] += w * sbb
                Ao[i, a, b] += w * sab
        ga = 0.0
        gb = 0.0
        for r in range(m):
            ga += Ea[r, a] * e[r]
            if pair:
                gb += Eb[r, a] * e[r]
        g[i, a] -= w * ga
        if pair:
            g[i + 1, a] -= w * gb
        for b in range(p):
            sa = 0.0
            sb = 0.0
            for r in range(m):
                sa += Ea[r, a] * Ek[r, b]
                if pair:
                    sb += Eb[r, a] * Ek[r, b]
            Bb[i, a, b] += w * sa
            if pair:
                Bb[i + 1, a, b] += w * sb
    for a in range(p):
        for b in range(p):
            t = 0.0
            for r in range(m):
                t += Ek[r, a] * Ek[r, b]
            C[a, b] += w * t
        t = 0.0
        for r in range(m):
            t += Ek[r, a] * e[r]
        gk[a] -= w * t


@nb.njit(cache=True, nogil=True)
def _mul(W, r, J, e, E):  # noqa: ANN001, ANN202
    """e = W r, E = W J."""
    m = W.shape[0]
    for a in range(m):
        t = 0.0
        for k in range(m):
            t += W[a, k] * r[k]
        e[a] = t
        for b in range(J.shape[1]):
            t = 0.0
            for k in range(m):
                t += W[a, k] * J[k, b]
            E[a, b] = t


@nb.njit(cache=True, nogil=True)
def assemble(X, K, process, proc_u, proc_W, dts, fix_node, fix_alpha, fix_kind, fix_z, fix_W, fix_lever, fix_use,  # noqa: ANN001, ANN201, PLR0913
             huber_k, x0, W0, k0, Wk, Ad, Ao, Bb, C, g, gk, fix_chi2, robust_w):
    """Normal equations (Gauss-Newton, IRLS weights for the Huber loss on fixes) at (X, K), added into the
    zeroed blocks; returns the total cost (sum of rho of the whitened fixes plus squared process and prior
    residuals). Fills fix_chi2 (M,) with each fix's squared whitened residual and robust_w with its weight."""
    N, d = X.shape
    p = K.shape[0]
    cost = 0.0
    r = np.empty(d)
    e = np.empty(d)
    Ja = np.empty((d, d))
    Jb = np.empty((d, d))
    Jk = np.empty((d, p))
    Ea = np.empty((d, d))
    Eb = np.empty((d, d))
    Ek = np.empty((d, p))
    Jk3 = np.empty((3, 3))
    for i in range(N - 1):
        if process == 0:
            odo_residual(X[i], X[i + 1], K, proc_u[i], r, Ja, Jb, Jk3)
            for a in range(3):
                for b in range(p):
                    Jk[a, b] = Jk3[a, b]
        else:
            cv_residual(X[i], X[i + 1], dts[i], r, Ja, Jb)
        _mul(proc_W[i], r, Ja, e, Ea)
        _mul(proc_W[i], r, Jb, e, Eb)
        _mul(proc_W[i], r, Jk, e, Ek)
        s2 = 0.0
        for a in range(d):
            s2 += e[a] * e[a]
        cost += s2
        _acc(Ad, Ao, Bb, C, g, gk, i, Ea, Eb, Ek, e, 1.0, True)
    # fixes: only the first 3 state components are seen
    r3 = np.empty(3)
    e3 = np.empty(3)
    Jq = np.empty((3, 3))
    E3 = np.empty((3, 3))
    Fa = np.zeros((3, d))
    Fb = np.zeros((3, d))
    Fk = np.zeros((3, p))
    qb = np.empty(3)
    hb = np.empty(3)
    for j in range(fix_node.shape[0]):
        i = fix_node[j]
        al = fix_alpha[j]
        fix_residual(X[i], X[i + 1], al, fix_kind[j], fix_z[j], fix_lever[j], r3, Jq, qb, hb)
        _mul(fix_W[j], r3, Jq, e3, E3)
        s2 = e3[0] * e3[0] + e3[1] * e3[1] + e3[2] * e3[2]
        fix_chi2[j] = s2
        if not fix_use[j]:
            robust_w[j] = 0.0
            continue
        rho, w = huber(s2, huber_k)
        robust_w[j] = w
        cost += rho
        for a in range(3):
            for b in range(3):
                Fa[a, b] = (1.0 - al) * E3[a, b]
                Fb[a, b] = al * E3[a, b]
        _acc(Ad, Ao, Bb, C, g, gk, i, Fa, Fb, Fk, e3, w, True)
    # priors
    for a in range(d):
        r[a] = X[0, a] - x0[a]
    Iv = np.eye(d)
    _mul(W0, r, Iv, e, Ea)
    for a in range(d):
        cost += e[a] * e[a]
    _acc(Ad, Ao, Bb, C, g, gk, 0, Ea, Eb, np.zeros((d, p)), e, 1.0, False)
    if p:
        rk = np.empty(p)
        ek = np.empty(p)
        Ekk = np.empty((p, p))
        for a in range(p):
            rk[a] = K[a] - k0[a]
        _mul(Wk, rk, np.eye(p), ek, Ekk)
        for a in range(p):
            cost += ek[a] * ek[a]
            for b in range(p):
                t = 0.0
                for r_ in range(p):
                    t += Ekk[r_, a] * Ekk[r_, b]
                C[a, b] += t
            t = 0.0
            for r_ in range(p):
                t += Ekk[r_, a] * ek[r_]
            gk[a] -= t
    return cost


@nb.njit(cache=True, nogil=True)
def bias_rhs(X, fix_node, fix_alpha, fix_kind, fix_z, fix_W, fix_lever, fix_w, fix_col, out):  # noqa: ANN001, ANN201, PLR0913
    """Right-hand sides (N, d, Q) of the solution's sensitivity to run-constant fix biases, added into the
    zeroed ``out``: a bias ``b`` added to every measured value of a source moves the residuals
    ``h - z`` by ``-b``, so the normal equations' right-hand side by ``J^T w W^T W`` per unit bias.
    ``fix_col`` (M,) is the first of the fix's source's bias columns (-1: no bias considered); a pose
    fix's bias has 3 columns (x, y, yaw), a position fix's 2 (x, y); ``fix_w`` (M,) the weight each fix
    had in the solve (the robust loss's, 0 for fixes left out)."""
    d = X.shape[1]
    r3 = np.empty(3)
    Jq = np.empty((3, 3))
    E3 = np.empty((3, 3))
    qb = np.empty(3)
    hb = np.empty(3)
    for j in range(fix_node.shape[0]):
        c0 = fix_col[j]
        w = fix_w[j]
        if c0 < 0 or w == 0.0:
            continue
        i = fix_node[j]
        al = fix_alpha[j]
        m = fix_residual(X[i], X[i + 1], al, fix_kind[j], fix_z[j], fix_lever[j], r3, Jq, qb, hb)
        _mul(fix_W[j], r3, Jq, qb, E3)  # E3 = W Jq
        for a in range(min(d, 3)):
            for k in range(m):
                # (Jq^T W^T W)[a, k] = sum_r E3[r, a] W[r, k]
                t = 0.0
                for r_ in range(3):
                    t += E3[r_, a] * fix_W[j, r_, k]
                out[i, a, c0 + k] += w * (1.0 - al) * t
                out[i + 1, a, c0 + k] += w * al * t
