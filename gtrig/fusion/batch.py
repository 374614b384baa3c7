"""Batch maximum a posteriori smoothing of a chain: Levenberg-Marquardt over every node at once.

The cost is the sum of the squared whitened process and prior residuals and the Huber loss of every
fix's whitened residual (IRLS weights); each step solves the bordered block-tridiagonal normal equations
(gtrig.fusion.blocktri) in time linear in the chain's length. The marginal covariance of each node is the
matching block of the inverse Gauss-Newton Hessian at the solution (Laplace approximation), parameters'
uncertainty included. This is the smoothing-and-mapping formulation of Dellaert and Kaess (2006), on a
chain.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from gtrig.fusion.blocktri import solve_chain
from gtrig.fusion.chain import FactorChain, assemble


@dataclass(frozen=True)
class BatchResult:
    """X (N, d) node states, K (p,) parameters, cov_x (N, d, d), cov_k (p, p), fix_chi2 (M,) squared
    whitened residuals at the solution, robust_w (M,) their Huber weights, cost, iterations, converged."""

    X: np.ndarray
    K: np.ndarray
    cov_x: np.ndarray
    cov_k: np.ndarray
    fix_chi2: np.ndarray
    robust_w: np.ndarray
    cost: float
    iterations: int
    converged: bool


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


def smooth_batch(chain: FactorChain, X_init: np.ndarray, K_init: np.ndarray, fix_use: np.ndarray | None = None,
                 huber_k: float = 3.0, max_iter: int = 20, tol: float = 1e-10) -> BatchResult:
    """Levenberg-Marquardt from ``(X_init, K_init)`` (the EKF + RTS estimate, or any close start).

    Parameters
    ----------
    chain : the factors.
    X_init : (N, d), K_init : (p,) the start.
    fix_use : (M,) bool, the fixes to use (the gate's verdict); all by default.
    huber_k : Huber threshold in sigmas of a fix's whitened residual norm; 0 for plain least squares.
    max_iter, tol : stop after ``max_iter`` steps or when the relative cost decrease is below ``tol``.

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
        Ad, Ao, Bb, C, g, gk = sys
        # Marquardt's scaling: damp each diagonal entry by itself
        d_idx = np.arange(Ad.shape[1])
        Ad_l = Ad.copy()
        Ad_l[:, d_idx, d_idx] *= 1.0 + lam
        C_l = C.copy()
        C_l[np.arange(C.shape[0]), np.arange(C.shape[0])] *= 1.0 + lam
        dx, dk, _, _ = solve_chain(Ad_l, Ao, Bb, C_l, g, gk)
        X_new, K_new = X + dx, K + dk
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
            if lam > 1e6:
                converged = True  # no descent left at this precision
                break
    Ad, Ao, Bb, C, g, gk = sys
    _, _, cov_x, cov_k = solve_chain(Ad, Ao, Bb, C, g, gk, marginals=True)
    assert cov_x is not None and cov_k is not None
    return BatchResult(X, K, cov_x, cov_k, chi2, rw, cost, it, converged)
