"""Weighted nonlinear least squares over independent blocks, with correlated readings inside a block.

Every world point (or pose) is one block: its own unknowns and its own readings, whose covariance
``Sigma_i`` is full (readings of one block share the reference or world points' errors). All blocks are
solved in one call of :func:`scipy.optimize.least_squares` on the whitened residuals
``L_i^-1 (f_i(x) - d_i)`` with ``Sigma_i = L_i L_i^T``; ``Sigma_i`` depends on the state through the
directions of the lines of sight, so it is evaluated at the start, and once more at the solution.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
from scipy import sparse
from scipy.optimize import least_squares

from gtrig.errors import ConvergenceError


@dataclass(frozen=True)
class Block:
    """Rows (readings) and columns (unknowns) of one item; both contiguous."""

    rows: slice
    cols: slice


def whitener(covs: Sequence[np.ndarray]) -> sparse.csr_matrix:
    """Block-diagonal ``L^-1`` with ``Sigma_i = L_i L_i^T`` for every block."""
    inv = []
    for C in covs:
        L = np.linalg.cholesky(C)
        inv.append(np.linalg.inv(L))
    return sparse.block_diag(inv, format="csr")


def solve_blocks(
    resid: Callable[[np.ndarray], np.ndarray],
    jac: Callable[[np.ndarray], np.ndarray],
    x0: np.ndarray,
    covs: Callable[[np.ndarray], list[np.ndarray]],
    what: str = "survey",
    passes: int = 2,
) -> np.ndarray:
    """Minimise ``sum_i |L_i^-1 (f_i(x) - d_i)|^2``.

    Parameters
    ----------
    resid : x (n,) -> f(x) - d (m,), readings ordered block after block.
    jac : x -> (m, n) Jacobian of ``resid``.
    covs : x -> list of the blocks' reading covariances.
    passes : how many times the weights are re-evaluated at the current solution.
    """
    x = np.asarray(x0, dtype=float).copy()
    for _ in range(passes):
        W = whitener(covs(x))
        res = least_squares(
            lambda z, W=W: W @ resid(z),
            x,
            jac=lambda z, W=W: np.asarray(W @ jac(z)),
            method="lm" if W.shape[0] >= x.size else "trf",
            xtol=1e-12,
            ftol=1e-12,
            gtol=1e-12,
            max_nfev=200 * (x.size + 1),
        )
        if res.status <= 0 or not np.all(np.isfinite(res.x)):
            raise ConvergenceError(f"{what}: least squares did not converge ({res.message})")
        x = res.x
    return x
