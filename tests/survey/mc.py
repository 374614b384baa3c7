"""Vectorised Monte-Carlo of the simulated survey (shared by the tests; not collected by pytest)."""

from __future__ import annotations

import numpy as np

from gtrig import geometry as geo
from gtrig.sim.gtroom import REFERENCE_SIGMA_M, VALIDATION_POSES, make_scene
from gtrig.sim.survey import SurveySimConfig, as_inputs, simulate_survey
from gtrig.survey import multistart as ms


def scene_and_poses(seed: int = 0):
    sc = make_scene(seed)
    T = np.array([sc.T_world_robot(*p) for p in VALIDATION_POSES])
    truth = np.array([geo.T_to_se2(t) for t in T])
    return sc, T, truth


to_inputs = as_inputs  # the four survey tables in memory


SEEDS_DESIGN = SurveySimConfig(network_max_m=None)  # readings to the reference points only, as AD2.3


def vectorised_trials(
    sc, T, n_trials: int, seed: int, pose_cov_readings: list[np.ndarray], ref_sigma: float | None = None
):
    """Run ``n_trials`` surveys at once: the same weighted least squares as the library, solved for all
    trials together with :func:`gtrig.survey.multistart.batched_lm` (one problem per trial).

    The surveys follow the seeds' design (:data:`SEEDS_DESIGN`: no readings between world points), whose
    points are independent trilaterations that vectorise across trials.
    ``pose_cov_readings`` are the readings' covariances of every pose (from one library run); they
    depend on the geometry only, so they are the same for all trials to first order.
    Returns world points (S, W, 2) and poses (S, P, 3).
    """
    rng = np.random.default_rng(seed)
    if ref_sigma is None:
        ref_sigma = REFERENCE_SIGMA_M
    nominal = {r.name: r.xy for r in sc.rig_nominal.survey.reference_points}
    svs = []
    for _ in range(n_trials):
        # redraw the reference points' error as make_scene does (O defines the origin, so it is exact)
        ref_true = {
            k: (v[0] + rng.normal(0, ref_sigma), v[1] + rng.normal(0, ref_sigma)) if k != "O" else v
            for k, v in nominal.items()
        }
        svs.append(simulate_survey(sc, T, rng, SEEDS_DESIGN, reference_true_xy=ref_true))
    R = svs[0].reference_nominal_xy
    var = svs[0].sigma_m ** 2 + svs[0].reference_sigma_m ** 2
    Wt = sc.world_points_xy
    W_est = np.empty((n_trials, Wt.shape[0], 2))
    for i in range(Wt.shape[0]):
        d = np.array([s.world_d[i] for s in svs])  # (S, 4)

        def model(X, d=d):
            diff = X[:, None, :] - R[None]
            rg = np.linalg.norm(diff, axis=2)
            w = 1 / np.sqrt(var)
            return (rg - d) * w, diff / rg[..., None] * w[:, None]

        X, _ = ms.batched_lm(model, np.repeat(Wt[i][None], n_trials, axis=0) + 0.05)
        W_est[:, i] = X
    Q = svs[0].robot_xy
    P_est = np.empty((n_trials, T.shape[0], 3))
    A, N = Q.shape[0], Wt.shape[0]
    qi = np.repeat(np.arange(A), N)
    wi = np.tile(np.arange(N), A)
    for p in range(T.shape[0]):
        d = np.array([s.pose_d[p].reshape(-1) for s in svs])  # (S, A*N)
        Linv = np.linalg.inv(np.linalg.cholesky(pose_cov_readings[p]))
        Wk = W_est[:, wi]  # (S, m, 2)
        Qk = Q[qi]

        def model(X, d=d, Wk=Wk, Qk=Qk, Linv=Linv):
            c, s = np.cos(X[:, 2:3]), np.sin(X[:, 2:3])
            qx = c * Qk[None, :, 0] - s * Qk[None, :, 1]
            qy = s * Qk[None, :, 0] + c * Qk[None, :, 1]
            dx = Wk[..., 0] - X[:, 0:1] - qx
            dy = Wk[..., 1] - X[:, 1:2] - qy
            rg = np.hypot(dx, dy)
            ux, uy = dx / rg, dy / rg
            J = np.stack([-ux, -uy, ux * qy - uy * qx], axis=2)
            return (rg - d) @ Linv.T, np.einsum("km,smi->ski", Linv, J, optimize=True)

        from gtrig.sim.gtroom import VALIDATION_POSES

        x0 = np.repeat(VALIDATION_POSES[p][None], n_trials, axis=0).copy()
        x0[:, 2] = geo.wrap_angle(x0[:, 2])
        X, _ = ms.batched_lm(model, x0, angle_index=2)
        P_est[:, p] = X
    return W_est, P_est, svs
