"""The onboard scanners' mountings from matched validation stops against the survey (planar hand-eye).

The seeds called the laser-to-robot mounting "the weak ring of the chain" and tweaked it by hand.
Here, for one scanner, the robot's motion ``A_ij`` between two stops comes from the survey's poses and
the scanner's motion ``B_ij`` from matching the scanner's own stop scans; the mounting ``X`` (the
scanner in the robot frame) satisfies ``A X = X B`` for every pair. In the plane the rotations commute,
so the rotation part says nothing about ``X``; the translation part

    (R_A - I) t_X - R(phi_X) t_B = -t_A

is linear in ``(t_X, cos phi_X, sin phi_X)`` (as in the planar hand-eye of Chou and Kamel 1991, here
by least squares over all pairs). It is solved linearly, then refined by weighted Gauss-Newton on
``(t_X, phi_X)`` with each pair's residual covariance from the match and the survey; the covariance
is the inverse normal matrix, scaled up by the reduced chi-square when that exceeds one.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from gtrig.errors import InputError
from gtrig.scanmatch import se2


@dataclass(frozen=True)
class MountingResult:
    """A scanner's planar mounting (3,) x, y, yaw in the robot frame, its covariance (3, 3), the pairs
    used and the reduced chi-square of the fit."""

    mounting: np.ndarray
    cov: np.ndarray
    n_pairs: int
    chi2_dof: float
    residuals_m: np.ndarray


def _rot(a: float) -> np.ndarray:
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, -s], [s, c]])


def solve_mounting(A: np.ndarray, B: np.ndarray, cov_A_t: np.ndarray, cov_B_t: np.ndarray,
                   iterations: int = 10) -> MountingResult:
    """Planar hand-eye ``A_k X = X B_k``.

    Parameters
    ----------
    A : (K, 3) robot motions between stop pairs (pose of stop j in the robot frame at stop i).
    B : (K, 3) the scanner's motions over the same pairs (its own frame).
    cov_A_t, cov_B_t : (K, 2, 2) covariances of the translations of ``A`` and ``B``.
    """
    A = np.asarray(A, dtype=float)
    B = np.asarray(B, dtype=float)
    K = len(A)
    if K < 2:
        raise InputError(f"mounting calibration needs at least 2 matched stop pairs with a turn, got {K}")
    rows, rhs = [], []
    for k in range(K):
        RA = _rot(A[k, 2])
        tb = B[k, :2]
        rows.append(np.hstack([RA - np.eye(2), -np.array([[tb[0], -tb[1]], [tb[1], tb[0]]])]))
        rhs.append(-A[k, :2])
    M = np.vstack(rows)
    sol, *_ = np.linalg.lstsq(M, np.concatenate(rhs), rcond=None)
    x = np.array([sol[0], sol[1], np.arctan2(sol[3], sol[2])])
    for _ in range(iterations):
        R = _rot(x[2])
        dR = np.array([[-np.sin(x[2]), -np.cos(x[2])], [np.cos(x[2]), -np.sin(x[2])]])
        H = np.zeros((3, 3))
        g = np.zeros(3)
        chi2 = 0.0
        res = np.zeros(K)
        for k in range(K):
            RA = _rot(A[k, 2])
            r = (RA - np.eye(2)) @ x[:2] + A[k, :2] - R @ B[k, :2]
            J = np.hstack([RA - np.eye(2), -(dR @ B[k, :2])[:, None]])
            C = cov_A_t[k] + R @ cov_B_t[k] @ R.T
            W = np.linalg.inv(C)
            H += J.T @ W @ J
            g += J.T @ W @ r
            chi2 += float(r @ W @ r)
            res[k] = float(np.hypot(*r))
        dx = -np.linalg.solve(H, g)
        x = x + dx
        if np.max(np.abs(dx)) < 1e-10:
            break
    dof = max(1, 2 * K - 3)
    chi2_dof = chi2 / dof
    cov = np.linalg.inv(H) * max(1.0, chi2_dof)
    x[2] = float(se2.wrap(x[2]))
    return MountingResult(x, cov, K, float(chi2_dof), res)


def mounting_pairs(survey_xyth: np.ndarray, min_turn_rad: float = np.radians(15.0),
                   max_turn_rad: float = np.radians(75.0), max_dist_m: float = 2.5) -> np.ndarray:
    """(P, 2) stop pairs that constrain a mounting: a turn between ``min_turn_rad`` and
    ``max_turn_rad`` (one 180-degree scanner still sees the same walls) within ``max_dist_m``."""
    p = np.asarray(survey_xyth, dtype=float)
    i, j = np.triu_indices(len(p), 1)
    dth = np.abs(se2.wrap(p[j, 2] - p[i, 2]))
    d = np.hypot(p[j, 0] - p[i, 0], p[j, 1] - p[i, 1])
    keep = (dth >= min_turn_rad) & (dth <= max_turn_rad) & (d <= max_dist_m)
    return np.column_stack([i[keep], j[keep]])


def calibrate_mounting(scans: tuple, survey_xyth: np.ndarray, survey_cov: np.ndarray, nominal: np.ndarray,
                       range_sigma_m: float = 0.01, tilt_shift_m: float = 0.0) -> tuple[MountingResult, int, int]:
    """One scanner's mounting from its stop scans (K, in its own frame) and the survey's poses (K, 3)
    with covariances (K, 3, 3); ``nominal`` (3,) seeds the pair guesses. Returns the result, the
    pairs tried and the pairs accepted by the acceptance test."""
    from gtrig.scanmatch.accept import AcceptParams
    from gtrig.scanmatch.validate import ErrorModel, match_pair

    model = ErrorModel(range_sigma_m=range_sigma_m)
    pairs = mounting_pairs(survey_xyth)
    X0 = np.asarray(nominal, dtype=float)
    A_l, B_l, cA, cB = [], [], [], []
    for i, j in pairs:
        A = se2.relative(survey_xyth[i], survey_xyth[j])
        guess = se2.compose(se2.compose(se2.inverse(X0), A), X0)
        gc = np.diag([0.05**2, 0.05**2, np.radians(2.0) ** 2])
        pose, cov, _res, v, _name = match_pair(scans[i], scans[j], guess, gc, model, tilt_shift_m,
                                               accept=AcceptParams(min_explained=0.4), genetic=None)
        if not v.accepted:
            continue
        Ri = _rot(survey_xyth[i, 2]).T
        A_l.append(A)
        B_l.append(pose)
        cA.append(Ri @ (survey_cov[i, :2, :2] + survey_cov[j, :2, :2]) @ Ri.T)
        cB.append(cov[:2, :2])
    res = solve_mounting(np.array(A_l).reshape(-1, 3), np.array(B_l).reshape(-1, 3), np.array(cA).reshape(-1, 2, 2),
                         np.array(cB).reshape(-1, 2, 2))
    return res, len(pairs), len(A_l)
