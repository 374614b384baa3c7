"""Batch maximum a posteriori smoothing of a chain: Levenberg-Marquardt over every node at once.

The cost is the sum of the squared whitened process and prior residuals and the Huber loss of every
fix's whitened residual (IRLS weights); each step solves the bordered block-tridiagonal normal equations
(gtrig.fusion.blocktri) in time linear in the chain's length. The marginal covariance of each node is the
matching block of the inverse Gauss-Newton Hessian at the solution (Laplace approximation), parameters'
uncertainty included. This is the smoothing-and-mapping formulation of Dellaert and Kaess (2006), on a
chain.

Run-constant source errors (a camera network's or a scanner network's calibration, common to every fix of
a source) do not average out over fixes, while the marginals shrink as if they did. They are "considered"
(Schmidt's consider covariance; Bierman 1977, ch. VI): per source s a world-frame bias b_s with covariance
B_s, not estimated (one run cannot separate it from the truth), its effect on the solution carried into
the covariance. The solution's sensitivity to it is ``S_s = H^-1 J^T W^T W E_s`` (``E_s`` a unit bias on
every fix of s), one extra right-hand side per bias dof on the factorisation the marginals use, and each
node's covariance gains ``sum_s S_s B_s S_s^T`` (:func:`considered_covariance`).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from gtrig.fusion.blocktri import CHUNK, solve_chain, solve_chain_inplace
from gtrig.fusion.chain import FactorChain, assemble, bias_rhs


@dataclass(frozen=True)
class BatchResult:
    """X (N, d) node states, K (p,) parameters, cov_x (N, d, d), cov_k (p, p), fix_chi2 (M,) squared
    whitened residuals at the solution, robust_w (M,) their Huber weights, cost, iterations, converged;
    cov_x and cov_k include the considered biases' share, which cov_bias_x (N, d, d) and cov_bias_k (p, p)
    hold alone (zero without ``bias_cov``)."""

    X: np.ndarray
    K: np.ndarray
    cov_x: np.ndarray
    cov_k: np.ndarray
    fix_chi2: np.ndarray
    robust_w: np.ndarray
    cost: float
    iterations: int
    converged: bool
    cov_bias_x: np.ndarray | None = None
    cov_bias_k: np.ndarray | None = None


def _normal_equations(chain: FactorChain, X: np.ndarray, K: np.ndarray, fix_use: np.ndarray, huber_k: float,
                      ) -> tuple[float, tuple[np.ndarray, ...], np.ndarray, np.ndarray]:
    N, d = X.shape
    p = K.size
    Ad = np.zeros((N, d, d))
    Ao = np.zeros((max(N - 1, 0), d, d))
    Bb = np.zeros((N, d, p))
    C = np.zeros((p, p))
    g = np.zeros((N, d))
    gk = np.zeros(p)
    M = chain.fix_node.size
    chi2 = np.zeros(M)
    rw = np.zeros(M)
    dts = np.diff(chain.stamps_s)
    cost = assemble(X, K, chain.process, chain.proc_u, chain.proc_W, dts, chain.fix_node, chain.fix_alpha,
                    chain.fix_kind, chain.fix_z, chain.fix_W, chain.fix_lever, fix_use, float(huber_k),
                    chain.x0, chain.W0, chain.k0, chain.Wk, Ad, Ao, Bb, C, g, gk, chi2, rw)
    return float(cost), (Ad, Ao, Bb, C, g, gk), chi2, rw


def _bias_columns(chain: FactorChain, bias_cov: Sequence[np.ndarray | None] | None,
                  ) -> tuple[np.ndarray, list[tuple[int, np.ndarray]]]:
    """Per fix its source's first bias column (-1: none) and per considered source (first column, B_s)."""
    col = np.full(chain.fix_node.size, -1, np.int64)
    blocks: list[tuple[int, np.ndarray]] = []
    q = 0
    for k, B in enumerate(bias_cov or ()):
        if B is None:
            continue
        B = np.asarray(B, float)
        col[chain.fix_source == k] = q
        blocks.append((q, B))
        q += B.shape[0]
    return col, blocks


def _considered(chain: FactorChain, X: np.ndarray, K: np.ndarray, sys: tuple[np.ndarray, ...], fix_w: np.ndarray,
                bias_cov: Sequence[np.ndarray | None] | None, marginals: bool,
                ) -> tuple[np.ndarray | None, np.ndarray | None, np.ndarray, np.ndarray]:
    """The marginals (when asked) and the considered biases' share of them, on one factorisation of the
    normal equations ``sys`` at ``(X, K)`` whose fixes were weighed by ``fix_w``."""
    Ad, Ao, Bb, C, g, gk = sys
    N, d = X.shape
    p = K.size
    col, blocks = _bias_columns(chain, bias_cov)
    q = sum(B.shape[0] for _, B in blocks)
    # the solve's work array [R, B]: the biases' right-hand sides R (N, d, q) made in place beside the border
    GB = np.zeros((N, d, q + p))
    GB[:, :, q:] = Bb
    if q:
        bias_rhs(X, chain.fix_node, chain.fix_alpha, chain.fix_kind, chain.fix_z, chain.fix_W, chain.fix_lever,
                 np.ascontiguousarray(fix_w, float), col, GB[:, :, :q])
    Sx, Sk, cov_x, cov_k = solve_chain_inplace(Ad, Ao, Bb, C, GB, np.zeros((p, q)), marginals=marginals)
    cb_x = np.zeros((N, d, d))
    cb_k = np.zeros((p, p))
    for c0, B in blocks:
        m = B.shape[0]
        Sxs, Sks = Sx[:, :, c0:c0 + m], Sk[:, c0:c0 + m]
        for a in range(0, N, CHUNK):  # by slices of nodes: no (N, d, d) temporary
            cb_x[a:a + CHUNK] += np.einsum("nak,kl,nbl->nab", Sxs[a:a + CHUNK], B, Sxs[a:a + CHUNK])
        cb_k += Sks @ B @ Sks.T
    return cov_x, cov_k, cb_x, cb_k


def considered_covariance(chain: FactorChain, X: np.ndarray, K: np.ndarray, fix_use: np.ndarray,
                          bias_cov: Sequence[np.ndarray | None]) -> tuple[np.ndarray, np.ndarray]:
    """The considered biases' share of the covariance of an estimate ``(X, K)`` of ``chain`` that weighed the
    fixes ``fix_use`` by their covariances alone (the EKF + RTS: to first order the same linear smoother
    as the least-squares solve, so its sensitivity to a bias is the same ``H^-1 J^T W^T W E_s``).

    Parameters
    ----------
    chain : the factors; X (N, d), K (p,) the estimate; fix_use (M,) bool, the fixes it used.
    bias_cov : per source of ``chain.sources``, its bias covariance (3, 3) over world (x, y, yaw) (m^2,
        rad^2) for pose fixes, (2, 2) over world (x, y) for position fixes, or None (not considered).

    Returns
    -------
    cov_bias_x (N, d, d), cov_bias_k (p, p): what to add to the estimate's covariances.
    """
    use = np.asarray(fix_use, bool)
    _, sys, _, _ = _normal_equations(chain, X, K, use, 0.0)
    _, _, cb_x, cb_k = _considered(chain, X, K, sys, use.astype(float), bias_cov, marginals=False)
    return cb_x, cb_k


def _damped_step(sys: tuple[np.ndarray, ...], lam: float) -> tuple[np.ndarray, np.ndarray]:
    """The Levenberg-Marquardt step (dx (N, d), dk (p,)) of the normal equations ``sys``, each diagonal
    entry damped by itself (Marquardt's scaling, ``* (1 + lam)``). The diagonal blocks are damped in
    place and their diagonal put back bit for bit afterwards, so that no copy of the (N, d, d) blocks is
    made for the damped system."""
    Ad, Ao, Bb, C, g, gk = sys
    d_idx = np.arange(Ad.shape[1])
    diag = Ad[:, d_idx, d_idx]  # (N, d), a copy (fancy indexing): the undamped diagonal, restored below
    Ad[:, d_idx, d_idx] *= 1.0 + lam
    C_l = C.copy()
    C_l[np.arange(C.shape[0]), np.arange(C.shape[0])] *= 1.0 + lam
    try:
        dx, dk, _, _ = solve_chain(Ad, Ao, Bb, C_l, g, gk)
    finally:
        Ad[:, d_idx, d_idx] = diag
    return dx, dk


def smooth_batch(chain: FactorChain, X_init: np.ndarray, K_init: np.ndarray, fix_use: np.ndarray | None = None,
                 huber_k: float = 3.0, max_iter: int = 20, tol: float = 1e-10,
                 bias_cov: Sequence[np.ndarray | None] | None = None) -> BatchResult:
    """Levenberg-Marquardt from ``(X_init, K_init)`` (the EKF + RTS estimate, or any close start).

    Parameters
    ----------
    chain : the factors.
    X_init : (N, d), K_init : (p,) the start.
    fix_use : (M,) bool, the fixes to use (the gate's verdict); all by default.
    huber_k : Huber threshold in sigmas of a fix's whitened residual norm; 0 for plain least squares.
    max_iter, tol : stop after ``max_iter`` steps or when the relative cost decrease is below ``tol``.
    bias_cov : per source of ``chain.sources``, the covariance of a run-constant bias of its fixes (see
        :func:`considered_covariance`), or None; considered in the covariances, not estimated.

    Returns
    -------
    :class:`BatchResult`; ``cov_x`` is the marginal covariance of every node (d x d, world-frame
    perturbation), ``cov_k`` the parameters'.
    """
    X = np.array(X_init, float, copy=True)
    K = np.array(K_init, float, copy=True)
    use = np.ones(chain.fix_node.size, bool) if fix_use is None else np.asarray(fix_use, bool)
    cost, sys, chi2, rw = _normal_equations(chain, X, K, use, huber_k)
    lam = 1e-9
    converged = False
    it = 0
    for it in range(1, max_iter + 1):  # noqa: B007
        dx, dk = _damped_step(sys, lam)
        X_new, K_new = X + dx, K + dk
        # one system at a time (each is O(N), two at once would double the peak): the current one is
        # dropped before the trial's is made, and made again, bit for bit, if the trial is refused
        sys = sys_new = None  # type: ignore[assignment]
        cost_new, sys_new, chi2_new, rw_new = _normal_equations(chain, X_new, K_new, use, huber_k)
        if cost_new <= cost:
            rel = (cost - cost_new) / max(cost, 1e-300)
            cost_old = cost
            X, K, cost, sys, chi2, rw = X_new, K_new, cost_new, sys_new, chi2_new, rw_new
            lam = max(lam / 10.0, 1e-12)
            # converged: the cost stalls (by a thousandth of one chi-square unit: far below any statistical
            # meaning), or the step is far below any pose's precision (0.1 um / urad)
            if (rel < tol or cost_old - cost < 1e-3
                    or max(float(np.abs(dx).max()), float(np.abs(dk).max(initial=0.0))) < 1e-7):
                converged = True
                break
        else:
            lam *= 10.0
            sys_new = chi2_new = rw_new = None  # type: ignore[assignment]
            _, sys, _, _ = _normal_equations(chain, X, K, use, huber_k)
            if lam > 1e6:
                converged = True  # no descent left at this precision
                break
    del dx, X_new, sys_new, chi2_new, rw_new  # the last trial's, not needed through the marginals
    cov_x, cov_k, cb_x, cb_k = _considered(chain, X, K, sys, rw, bias_cov, marginals=True)
    assert cov_x is not None and cov_k is not None
    cov_x += cb_x  # in place: the marginals without the biases' share are not returned
    return BatchResult(X, K, cov_x, cov_k + cb_k, chi2, rw, cost, it, converged, cb_x, cb_k)
