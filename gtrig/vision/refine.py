"""One robust weighted least-squares fit of the robot pose to all corners of all markers in all cameras.

The cost is the sum over corners of a Huber loss of the whitened reprojection residual
``e_i = || L_i^T (uv_pred_i - uv_obs_i) ||`` where ``L_i L_i^T`` is the inverse of the corner's
covariance (so a corner the detector knows poorly counts less), solved by Gauss-Newton with
iteratively re-weighted least squares and step halving. Parameters are the world-frame perturbation
``xi = (dt, dphi)`` of :mod:`gtrig.vision.projection`.

Planar option (``--planar``): the robot stands on the floor, so its height and the tilt of its z axis
get a Gaussian prior, not a constraint: ``z ~ N(z_floor, sigma_z)`` and each horizontal component of
the robot's z axis in the world ``~ N(0, sin(sigma_tilt))``. Sigma is the floor's unevenness
(a few millimetres and a few tenths of a degree: DIN 18202 flatness tolerances), so the estimate stays
6-DoF and an uneven floor does not bias it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from gtrig.vision.covariance import RigUncertainty
from gtrig.vision.observations import StackedCorners
from gtrig.vision.projection import (
    camera_pose_jacobian,
    lens_jacobian,
    marker_pose_jacobian,
    project_pose,
    skew,
    whiten,
)


@dataclass(frozen=True)
class PlanarPrior:
    """The floor as a prior on the robot pose.

    Attributes
    ----------
    z_m : float
        Expected height of the robot frame's origin in the world (0: the floor's mean plane).
    sigma_z_m : float
        The floor's height deviation, metres.
    sigma_tilt_rad : float
        The floor's tilt deviation (applies to roll and pitch alike), radians.
    """

    z_m: float = 0.0
    sigma_z_m: float = 0.003
    sigma_tilt_rad: float = math.radians(0.3)


@dataclass(frozen=True)
class RefineOptions:
    """Settings of the robust fit: Huber threshold ``huber_k`` in whitened units (per corner),
    iteration limit and the step size (radians or metres) below which it has converged."""

    huber_k: float = 3.0
    max_iter: int = 30
    step_tol: float = 1e-7


@dataclass(frozen=True)
class RefineResult:
    """The fitted pose and what the fit says about itself.

    Attributes
    ----------
    T_world_robot : (4, 4)
    cov_6x6 : (6, 6) covariance of the pose in ``xi`` units (corner noise, prior and the rig's
        uncertainty included; robust weights applied): the marginal of ``inv(A^T W A)``
    J : (N, 2, 6) whitened Jacobian of the corner residuals in ``xi`` (without the robust weights)
    weights : (N,) final robust weight of each corner (1 = inlier)
    residuals_px : (N, 2) predicted minus observed pixels (nominal rig, no nuisance correction)
    whitened : (N,) per-corner whitened residual norm after the rig's nuisance corrections
    chi2 : float
        Sum of squared whitened residuals over all corners plus the nuisance priors' (no robust
        weights, no floor prior).
    robust_cost : float
        Huber cost of the corners plus the prior's squared residuals.
    dof : int
        ``2 N - 6`` plus the prior's 3 rows when planar.
    iterations : int
    converged : bool
    min_depth_m : float
        Smallest depth of a corner in its camera (negative: behind a camera, an invalid pose).
    redundancy : (N,) float
        Each corner's share of the redundancy, ``2 - tr(w_i A_i H^-1 A_i^T)`` over its two whitened
        rows (Foerstner's redundancy numbers; they sum to ``2 N`` minus the parameters the corners
        determine); they share a fit's chi-square among its cameras for the corner-noise estimate
        (:mod:`gtrig.vision.noise`).
    chi2_rig : float
        The rig's nuisance priors' share of ``chi2`` (``|S eta|^2``).
    redundancy_rig : float
        Their redundancy, ``P - tr(Lambda Q_eta)`` over the P nuisance parameters: what of the rig's
        stated uncertainty the corners checked (0 without nuisances).
    """

    T_world_robot: np.ndarray
    cov_6x6: np.ndarray
    J: np.ndarray
    weights: np.ndarray
    residuals_px: np.ndarray
    whitened: np.ndarray
    chi2: float
    robust_cost: float
    dof: int
    iterations: int
    converged: bool
    min_depth_m: float
    redundancy: np.ndarray
    chi2_rig: float = 0.0
    redundancy_rig: float = 0.0


def _sq(v: np.ndarray) -> float:
    return float(v @ v)


def huber_weights(e: np.ndarray, k: float) -> np.ndarray:
    """IRLS weights of the Huber loss for residual norms ``e`` (whitened)."""
    return np.where(e <= k, 1.0, k / np.maximum(e, 1e-300))


def huber_cost(e: np.ndarray, k: float) -> float:
    """Sum of the Huber loss ``e^2`` (``e <= k``) or ``2 k e - k^2``."""
    return float(np.sum(np.where(e <= k, e * e, 2 * k * e - k * k)))


def prior_residuals(T: np.ndarray, prior: PlanarPrior) -> tuple[np.ndarray, np.ndarray]:
    """Whitened prior residuals (3,) ``(z, n_x, n_y)`` and their Jacobian (3, 6) in ``xi``."""
    n = T[:3, 2]
    st = math.sin(prior.sigma_tilt_rad)
    r = np.array([(T[2, 3] - prior.z_m) / prior.sigma_z_m, n[0] / st, n[1] / st])
    Jp = np.zeros((3, 6))
    Jp[0, 2] = 1.0 / prior.sigma_z_m
    # Exp(dphi) n = n - skew(n) dphi: the first two rows of -skew(n), written out
    Jp[1, 3:] = (0.0, n[2] / st, -n[1] / st)
    Jp[2, 3:] = (-n[2] / st, 0.0, n[0] / st)
    return r, Jp


def rotvec_to_matrix(phi: np.ndarray) -> np.ndarray:
    """Rodrigues' formula for one rotation vector (3,), radians (faster than SciPy for one)."""
    a = math.sqrt(float(phi @ phi))
    K = skew(phi)
    if a < 1e-8:
        return np.eye(3) + K + 0.5 * K @ K
    return np.eye(3) + (math.sin(a) / a) * K + ((1 - math.cos(a)) / (a * a)) * K @ K


def apply_step(T: np.ndarray, xi: np.ndarray) -> np.ndarray:
    """``T`` moved by the world-frame perturbation ``xi = (dt, dphi)``."""
    out = T.copy()
    out[:3, :3] = rotvec_to_matrix(xi[3:]) @ T[:3, :3]
    out[:3, 3] = T[:3, 3] + xi[:3]
    return out


def evaluate(sc: StackedCorners, T: np.ndarray, prior: PlanarPrior | None, k: float
             ) -> tuple[float, np.ndarray, np.ndarray]:
    """Robust cost, residuals (N, 2) px and whitened norms (N,) at pose ``T`` (no Jacobian)."""
    uv, z, _ = project_pose(sc, T, jacobian=False)
    r = uv - sc.uv
    e = np.linalg.norm(whiten(sc, r), axis=1)
    e = np.where(z > 0, e, 1e6)
    cost = huber_cost(e, k)
    if prior is not None:
        rp, _ = prior_residuals(T, prior)
        cost += float(rp @ rp)
    return cost, r, e


def _nuisance_blocks(sc: StackedCorners, T: np.ndarray, rig: RigUncertainty | None
                     ) -> tuple[np.ndarray, np.ndarray]:
    """Whitened Jacobian (2N, P) of the corners in the rig's nuisance parameters and their prior's
    square-root information (P, P), block diagonal: one block per camera in view (its pose, and its
    lens when its covariance covers the lens), then one per marker in view (none for a camera or
    marker known exactly)."""
    n = sc.uv.shape[0]
    if rig is None:
        return np.zeros((2 * n, 0)), np.zeros((0, 0))
    cols, sqrt_info = [], []
    for kind, group in (("camera", sc.cam), ("marker", sc.marker)):
        blocks = []
        for g in np.unique(group):
            key = sc.camera_names[g] if kind == "camera" else int(g)
            S = rig.sqrt_information(kind, key)
            if S is not None:
                blocks.append((group == g, S))
        if not blocks:
            continue
        if kind == "camera":
            n_lens = max(S.shape[0] for _, S in blocks) - 6
            J = camera_pose_jacobian(sc, T)
            if n_lens > 0:
                J = np.concatenate([J, lens_jacobian(sc, T, n_lens)], axis=2)
        else:
            J = marker_pose_jacobian(sc, T)
        B = whiten(sc, J)  # (N, 2, 6 + lens)
        for m, S in blocks:
            k = S.shape[0]
            blk = np.zeros((n, 2, k))
            blk[m] = B[m, :, :k]
            cols.append(blk.reshape(2 * n, k))
            sqrt_info.append(S)
    if not cols:
        return np.zeros((2 * n, 0)), np.zeros((0, 0))
    return np.hstack(cols), _block_diagonal(sqrt_info)


def _block_diagonal(blocks: list[np.ndarray]) -> np.ndarray:
    """The square blocks on the diagonal of one matrix (``scipy.linalg.block_diag`` costs 20 times more
    for the handful of small blocks of a frame)."""
    n = sum(b.shape[0] for b in blocks)
    out = np.zeros((n, n))
    k = 0
    for b in blocks:
        m = b.shape[0]
        out[k:k + m, k:k + m] = b
        k += m
    return out


#: What one trial pose of :func:`refine_pose` leaves for the next iteration: the Jacobian (N, 2, 6), the
#: whitened residuals (2 N,) with the nuisances' share, their norms per corner (N,; the robust weights take
#: them as they are, the cost puts a corner behind its camera at 1e6) and the prior's residuals and Jacobian
#: (None without a prior).
_Trial = tuple[np.ndarray | None, np.ndarray, np.ndarray, tuple[np.ndarray, np.ndarray] | None]


def _mix(M: np.ndarray | None, X: np.ndarray) -> np.ndarray:
    """Whitened rows ``X`` (2 N,) or (2 N, k) mixed per view by ``M`` (V, 8, 8) (None: as they are)."""
    if M is None:
        return X
    V = M.shape[0]
    return np.matmul(M, X.reshape(V, 8, -1)).reshape(X.shape)


def refine_pose(sc: StackedCorners, T0: np.ndarray, prior: PlanarPrior | None = None,
                options: RefineOptions = RefineOptions(), rig: RigUncertainty | None = None,
                view_whitening: np.ndarray | None = None) -> RefineResult:
    """Fit ``T_world_robot`` to the corners ``sc`` starting from ``T0`` (see the module docstring).

    Parameters
    ----------
    sc : the stacked corners of one instant (any number of cameras and markers, N corners).
    T0 : (4, 4) initial ``T_world_robot`` (from :mod:`gtrig.vision.init`).
    prior : the planar prior, or None for a free 6-DoF fit.
    options : robust loss and stopping settings.
    rig : the rig's uncertainty. Each camera and marker in view then gets a small pose correction
        (linearised, with a Gaussian prior of that sigma) estimated with the robot pose and
        marginalised out, so that the residuals, the robust weights and the covariance account for
        calibration errors that are common to all corners of one camera or one marker.
    view_whitening : (V, 8, 8) per view, what turns its separately whitened corner rows into rows whitened
        with the view's joint covariance (:func:`gtrig.vision.covariance.common_whitening`: the corners'
        error common to the view); None: the corners are independent. The residual norms, robust weights,
        chi-square, redundancies and covariance are those of the mixed rows; ``J`` stays per corner.
    """
    k = options.huber_k
    M = view_whitening
    T = np.asarray(T0, dtype=float).copy()
    N = sc.uv.shape[0]
    Bn, S_eta = _nuisance_blocks(sc, T, rig)
    Bn = _mix(M, Bn)
    Lam = S_eta.T @ S_eta
    P = 6 + Bn.shape[1]
    eta = np.zeros(P - 6)

    def cost_at(Tx: np.ndarray, etax: np.ndarray) -> tuple[float, _Trial]:
        """Robust cost at ``Tx`` and what the next iteration takes from there if the step is taken (the
        projection with its Jacobian, the whitened residuals and their norms, the prior's rows)."""
        uv, z, J = project_pose(sc, Tx)
        rw = _mix(M, whiten(sc, uv - sc.uv).reshape(-1)) + Bn @ etax
        e = np.linalg.norm(rw.reshape(N, 2), axis=1)
        c = huber_cost(np.where(z > 0, e, 1e6), k) + _sq(S_eta @ etax)
        rp_jp = None
        if prior is not None:
            rp_jp = prior_residuals(Tx, prior)
            c += float(rp_jp[0] @ rp_jp[0])
        return c, (J, rw, e, rp_jp)

    cost, trial = cost_at(T, eta)
    converged = False
    it = 0
    lam = 0.0
    dx = np.zeros(P)
    A = np.empty((2 * N, P))  # whitened Jacobian: the pose's columns change, the nuisances' do not
    A[:, 6:] = Bn
    for it in range(1, options.max_iter + 1):  # noqa: B007
        J, rw, e, rp_jp = trial
        assert J is not None
        A[:, :6] = _mix(M, whiten(sc, J).reshape(-1, 6))
        ww = np.repeat(huber_weights(e, k), 2)
        H = A.T @ (A * ww[:, None])
        g = A.T @ (rw * ww)
        if P > 6:
            H[6:, 6:] += Lam
            g[6:] += Lam @ eta
        if rp_jp is not None:
            rp, Jp = rp_jp
            H[:6, :6] += Jp.T @ Jp
            g[:6] += Jp.T @ rp
        step_ok = False
        for _ in range(12):
            Hd = H + lam * np.diag(np.diag(H))
            try:
                dx = -np.linalg.solve(Hd, g)
            except np.linalg.LinAlgError:
                lam = max(lam * 10, 1e-6)
                continue
            T_new = apply_step(T, dx[:6])
            c_new, trial_new = cost_at(T_new, eta + dx[6:])
            if c_new <= cost * (1 + 1e-12) + 1e-12:
                T, eta, cost, trial = T_new, eta + dx[6:], c_new, trial_new
                lam = lam / 10 if lam > 1e-9 else 0.0
                step_ok = True
                break
            lam = max(lam * 10, 1e-6)
        if not step_ok:
            converged = True  # no descent direction left: at a minimum (to numerical precision)
            break
        if np.max(np.abs(dx[:6])) < options.step_tol:
            converged = True
            break
    # re-orthonormalise (many small rotations accumulate rounding)
    U, _, Vt = np.linalg.svd(T[:3, :3])
    T[:3, :3] = U @ Vt
    uv, z, J_final = project_pose(sc, T)
    assert J_final is not None
    J = J_final
    r = uv - sc.uv
    rw = _mix(M, whiten(sc, r).reshape(-1)) + Bn @ eta
    Jw = whiten(sc, J)
    e = np.linalg.norm(rw.reshape(N, 2), axis=1)
    w = huber_weights(e, k)
    A = np.hstack([_mix(M, Jw.reshape(-1, 6)), Bn])
    H = A.T @ (A * np.repeat(w, 2)[:, None])
    if P > 6:
        H[6:, 6:] += Lam
    dof = 2 * N - 6
    if prior is not None:
        rp, Jp = prior_residuals(T, prior)
        H[:6, :6] += Jp.T @ Jp
        dof += 3
    cost = huber_cost(e, k) + _sq(S_eta @ eta)
    if prior is not None:
        cost += float(rp @ rp)
    chi2 = float(np.sum(e * e)) + _sq(S_eta @ eta)
    try:
        Hinv = np.linalg.inv(H)
        cov = Hinv[:6, :6]
        # leverage of each whitened row, robust weight included: diag(w A H^-1 A^T)
        lev = np.repeat(w, 2) * np.einsum("ij,ij->i", A @ Hinv, A)
        red = 2.0 - lev.reshape(N, 2).sum(axis=1)
        red_rig = float(P - 6 - np.sum(Lam * Hinv[6:, 6:])) if P > 6 else 0.0
    except np.linalg.LinAlgError:
        cov = np.full((6, 6), np.nan)
        red = np.full(N, np.nan)
        red_rig = float("nan")
    return RefineResult(T, cov, Jw, w, r, e, chi2, cost, dof, it, converged,
                        float(np.min(z)) if z.size else 0.0, red, _sq(S_eta @ eta), red_rig)


def whitened_cost(sc: StackedCorners, T: np.ndarray) -> float:
    """Plain (non-robust) chi-square of all corners at ``T``."""
    uv, _, _ = project_pose(sc, T, jacobian=False)
    e = whiten(sc, uv - sc.uv)
    return float(np.sum(e * e))


__all__ = ["PlanarPrior", "RefineOptions", "RefineResult", "refine_pose", "evaluate", "apply_step",
           "prior_residuals", "huber_weights", "huber_cost", "whitened_cost"]
