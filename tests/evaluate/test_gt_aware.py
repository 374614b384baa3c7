"""GT-aware scores: the truth scored against a noisy GT is indistinguishable from it, a 1 cm bias is not, the
intervals cover at their nominal rate in repeated simulations, a lever arm is found (bench/evaluate.py
does the same on simulated gtrig runs, GTlaser and GTvision with their own covariances)."""

from __future__ import annotations

import numpy as np
from scipy.signal import lfilter

from gtrig.evaluate.gt_aware import lever_arm, score
from gtrig.evaluate.slam import evaluate_slam
from gtrig.trajectory import PoseTrack

N = 2000


def _truth() -> tuple[np.ndarray, np.ndarray]:
    t = np.arange(N) * 0.05
    x, y = 3 * np.sin(0.05 * t), 2 * np.sin(0.1 * t)
    yaw = np.arctan2(np.gradient(y), np.gradient(x))
    return t, np.column_stack([x, y, yaw])


def _gt_cov(rng: np.random.Generator) -> np.ndarray:
    """Per-pose covariances that vary along the run (1-4 mm, 0.1-0.4 deg, correlated x-y)."""
    s = rng.uniform(1e-3, 4e-3, (N, 2))
    r = rng.uniform(-0.5, 0.5, N)
    C = np.zeros((N, 3, 3))
    C[:, 0, 0], C[:, 1, 1] = s[:, 0] ** 2, s[:, 1] ** 2
    C[:, 0, 1] = C[:, 1, 0] = r * s[:, 0] * s[:, 1]
    C[:, 2, 2] = np.radians(rng.uniform(0.1, 0.4, N)) ** 2
    return C


def _noisy_gt(rng, t, truth, C) -> PoseTrack:
    g = np.einsum("nij,nj->ni", np.linalg.cholesky(C), rng.standard_normal((N, 3)))
    return PoseTrack.from_xytheta(t, truth + g, cov=C)


def _ar1(rng: np.random.Generator, phi: float, sigma: float, dims: int) -> np.ndarray:
    """A stationary AR(1) error process (SLAM drift-like), marginal std ``sigma``."""
    w = rng.standard_normal((N, dims)) * sigma * np.sqrt(1 - phi**2)
    w[0] = rng.standard_normal(dims) * sigma
    zi = np.zeros((1, dims))
    return lfilter([1.0], [1.0, -phi], w, axis=0, zi=zi)[0]


def test_truth_indistinguishable_bias_distinguished() -> None:
    rng = np.random.default_rng(1)
    t, truth = _truth()
    C = _gt_cov(rng)
    n_indist = 0
    for _ in range(20):
        gt = _noisy_gt(rng, t, truth, C)
        s = score(gt, PoseTrack.from_xytheta(t, truth))
        assert s is not None and abs(s.share_resolved - 0.95) < 0.03 and abs(s.mean_d2_per_dof - 1) < 0.1
        n_indist += s.indistinguishable
        biased = score(gt, PoseTrack.from_xytheta(t, truth + [0.01, 0, 0]))
        assert biased is not None and not biased.indistinguishable and biased.bias_resolved == ("x",)
        assert biased.bias["x"].contains(0.01) or abs(biased.bias["x"].value - 0.01) < 3e-4
    assert n_indist >= 17  # each interval at 95 %: the verdict holds in most runs


def test_intervals_cover_at_nominal_rate() -> None:
    """Repeated runs: fresh GT noise and a fresh SLAM error process (bias b, AR(1) drift of 5 mm, 0.3 deg); the
    bias and RMSE-against-truth intervals cover the process's true values 95 % of the time (within 5 points)."""
    rng = np.random.default_rng(7)
    t, truth = _truth()
    C = _gt_cov(rng)
    b = np.array([0.002, -0.001, np.radians(0.05)])
    s_xy, s_yaw = 0.005, np.radians(0.3)
    rmse_true = np.sqrt(b[0] ** 2 + b[1] ** 2 + 2 * s_xy**2)
    rmse_rot_true = np.sqrt(b[2] ** 2 + s_yaw**2)
    hits = {"x": 0, "y": 0, "yaw": 0, "rmse": 0, "rmse_rot": 0}
    reps = 300
    for _ in range(reps):
        err = np.column_stack([_ar1(rng, 0.8, s_xy, 2), _ar1(rng, 0.8, s_yaw, 1)]) + b
        s = score(_noisy_gt(rng, t, truth, C), PoseTrack.from_xytheta(t, truth + err))
        assert s is not None
        for i, ax in enumerate(("x", "y", "yaw")):
            hits[ax] += s.bias[ax].contains(b[i])
        hits["rmse"] += s.rmse_trans_m.contains(rmse_true)
        hits["rmse_rot"] += s.rmse_rot_rad is not None and s.rmse_rot_rad.contains(rmse_rot_true)
    for k, v in hits.items():
        assert abs(v / reps - 0.95) <= 0.05, (k, v / reps)


def test_lever_arm_found_and_not_invented() -> None:
    rng = np.random.default_rng(3)
    t, truth = _truth()
    C = _gt_cov(rng)
    gt = _noisy_gt(rng, t, truth, C)
    L = np.array([0.05, -0.02])
    c, s = np.cos(truth[:, 2]), np.sin(truth[:, 2])
    off = np.column_stack([c * L[0] - s * L[1], s * L[0] + c * L[1], np.zeros(N)])
    est = PoseTrack.from_xytheta(t, truth + off + np.column_stack([_ar1(rng, 0.8, 0.003, 2), np.zeros(N)]))
    la = lever_arm(gt, est)
    assert la is not None and la.resolved and np.allclose(la.xy_m, L, atol=3e-3)
    ev = evaluate_slam(gt, est, align="se3", metrics="evo")
    assert any("lever arm" in w for w in ev.warnings)
    clean = lever_arm(gt, PoseTrack.from_xytheta(t, truth))
    assert clean is not None and not clean.resolved
