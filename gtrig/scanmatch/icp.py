"""The local matcher: point-to-line ICP (Censi 2008) with a closed-form covariance.

Censi, "An ICP variant using a point-to-line metric", ICRA 2008: each current point is associated
with the reference surface through it and the error is its distance to that surface's line. Here the
reference's lines are scan-order line fits (:mod:`gtrig.scanmatch.scan`), the association is the
nearest reference point on a uniform grid (compiled, :mod:`gtrig.scanmatch._kernels`), the solver is
Gauss-Newton on (x, y, theta) with the exact rotation, and the worst ``trim`` share of residuals is
dropped each iteration (partial overlap, people).

Covariance: the fit's Hessian ``H = J^T J`` at the solution over the inliers, scaled by the measured
residual variance ``s^2 = sum e^2 / (m - 3)``: ``Sigma = s^2 H^-1`` (the Gauss-Newton / Censi 2007
closed form for independent point errors). It is the covariance of the world-frame perturbation of
the relative pose as gtrig.trajectory defines it (``dx, dy`` in the reference frame, ``dtheta``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from gtrig.scanmatch._kernels import evaluate_fit, icp_point_to_line
from gtrig.scanmatch.scan import PlanarScan


@dataclass(frozen=True)
class IcpParams:
    """Settings of the local matcher (metres, radians).

    cell_m : grid cell of the association search.
    r_start_m, r_min_m, shrink : association radius, first and last, and its factor per iteration.
    trim : share of the largest residuals dropped per iteration.
    max_iter, tol_m, tol_rad : stop rule.
    converged_step_m : a loop ending at ``max_iter`` with a last update below this (rotation at 1 m)
        still counts as converged (an association flipping between neighbours).
    inlier_sigma : a point is an inlier of the final fit when its residual is within this many of its
        pair's expected noise (both points' range noise) and its nearest reference point within
        ``r_min_m``.
    """

    cell_m: float = 0.1
    r_start_m: float = 0.5
    r_min_m: float = 0.08
    shrink: float = 0.7
    trim: float = 0.1
    max_iter: int = 60
    tol_m: float = 1e-5
    tol_rad: float = 1e-5
    inlier_sigma: float = 3.0
    converged_step_m: float = 2e-3


DEFAULT_ICP = IcpParams()


@dataclass(frozen=True)
class IcpResult:
    """A local match: the current scan's frame in the reference scan's frame.

    Attributes
    ----------
    pose : (3,) x, y (m), theta (rad): maps current points into the reference frame.
    cov : (3, 3) covariance of ``pose`` (x, y, theta), ``s^2 H^-1`` over the inliers; inf if singular.
    iterations : Gauss-Newton iterations run.
    n_points : current points with a finite coordinate.
    n_matched : current points with a reference point within the final association radius.
    n_inliers : points used for the covariance (see :class:`IcpParams`).
    residuals_m : (n_points,) point-to-line residuals at the solution (nan: no association or no normal).
    expected_sigma_m : (n_points,) each residual's expected noise from the two scans' range noise.
    inlier : (n_points,) bool.
    s_m : the measured residual standard deviation over the inliers.
    converged : the loop stopped on its tolerance with enough correspondences.
    hessian : (3, 3) ``J^T J`` over the inliers.
    jacobian : (n_points, 3) each residual's derivative with respect to (x, y, theta).
    """

    pose: np.ndarray
    cov: np.ndarray
    iterations: int
    n_points: int
    n_matched: int
    n_inliers: int
    residuals_m: np.ndarray
    expected_sigma_m: np.ndarray
    inlier: np.ndarray
    s_m: float
    converged: bool
    hessian: np.ndarray
    jacobian: np.ndarray


def evaluate(ref: PlanarScan, cur: PlanarScan, pose: np.ndarray, params: IcpParams = IcpParams(),
             iterations: int = 0, converged: bool = True) -> IcpResult:
    """Residuals, inliers and covariance of ``cur`` on ``ref`` at ``pose`` (no optimisation)."""
    pose = np.asarray(pose, dtype=float)
    e, sig, inl, J, H, n_matched, sse, cov = evaluate_fit(ref.xy, ref.normals, ref.normal_ok, ref.sigma_m, cur.xy,
                                                           cur.sigma_m, pose, params.cell_m, params.r_min_m,
                                                           params.inlier_sigma)
    m = int(np.count_nonzero(inl))
    s2 = sse / (m - 3) if m > 3 else float("nan")
    return IcpResult(pose=pose, cov=cov, iterations=iterations, n_points=len(cur), n_matched=int(n_matched),
                     n_inliers=m, residuals_m=e, expected_sigma_m=sig, inlier=inl, s_m=math.sqrt(s2),
                     converged=converged and m > 3, hessian=H, jacobian=J)


def match_icp(ref: PlanarScan, cur: PlanarScan, guess: np.ndarray, params: IcpParams = IcpParams()) -> IcpResult:
    """Align ``cur`` on ``ref`` from ``guess`` (the current frame in the reference frame, (3,)).

    Point-to-line ICP (Censi 2008), then :func:`evaluate` at the solution for the covariance and the
    acceptance test's statistics. About 0.2 ms for two 181-beam scans (see BENCHMARKS.md).
    """
    g = np.asarray(guess, dtype=float).reshape(3)
    pose, it, m, step = icp_point_to_line(ref.xy, ref.normals, ref.normal_ok, cur.xy, g, params.cell_m,
                                    params.r_start_m, params.r_min_m, params.shrink, params.trim,
                                    params.max_iter, params.tol_m, params.tol_rad)
    # an association that flips between two neighbours at the last step ends the loop at max_iter
    # with a sub-millimetre oscillation: still converged
    return evaluate(ref, cur, pose, params, iterations=int(it),
                    converged=m > 0 and (it < params.max_iter or step < params.converged_step_m))
