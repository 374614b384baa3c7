"""The plan's fused covariance is fusion's smoother's: its steady state equals a long chain solved whole,
and on a simulated drive fusion's errors agree with it (RMS error over predicted sigma near 1), also with
the sources' clocks off by the plan's clock sigma."""

from __future__ import annotations

import numpy as np

from gtrig.fusion import FusionOptions, fuse_tracks
from gtrig.fusion.process import OdometryNoise, odometry_increments
from gtrig.io.odometry import OdometryLog
from gtrig.plan.fused import (
    FusionPlanSettings,
    SourceRates,
    fused_covariance,
    odometry_step_covariance,
    smoothed_walk_covariance,
)
from gtrig.trajectory import PoseTrack


def _spd(rng: np.random.Generator, scales: np.ndarray) -> np.ndarray:
    A = rng.normal(size=(3, 3)) * scales[:, None]
    return A @ A.T + np.diag(0.1 * scales**2)


def _chain_middle(R: np.ndarray, Q: np.ndarray, n: int) -> np.ndarray:
    """The middle node's covariance (3, 3) of n nodes, each observed with covariance R, consecutive ones
    tied by a step of covariance Q: the whole information matrix inverted."""
    Ri, Qi = np.linalg.inv(R), np.linalg.inv(Q)
    H = np.zeros((3 * n, 3 * n))
    for k in range(n):
        H[3 * k:3 * k + 3, 3 * k:3 * k + 3] += Ri
    for k in range(n - 1):
        a, b = slice(3 * k, 3 * k + 3), slice(3 * k + 3, 3 * k + 6)
        H[a, a] += Qi
        H[b, b] += Qi
        H[a, b] -= Qi
        H[b, a] -= Qi
    m = 3 * (n // 2)
    return np.linalg.inv(H)[m:m + 3, m:m + 3]


def test_steady_state_equals_a_long_chain_solved_whole():
    rng = np.random.default_rng(3)
    Rs, Qs, ref = [], [], []
    # steps from far below the fixes' noise (many fixes averaged) to far above it (each fix alone)
    for q_over_r in (1e-2, 0.3, 1.0, 10.0, 300.0):
        R = _spd(rng, np.array([1e-3, 1e-3, 5e-4]))
        Q = q_over_r * _spd(rng, np.array([1e-3, 1e-3, 5e-4]))
        Rs.append(R)
        Qs.append(Q)
        ref.append(_chain_middle(R, Q, 401))
    got = smoothed_walk_covariance(np.array(Rs), np.array(Qs))
    for g, r, R in zip(got, ref, Rs, strict=True):
        np.testing.assert_allclose(g, r, rtol=1e-5, atol=1e-6 * np.abs(r).max())
        assert np.all(np.linalg.eigvalsh(R - g) > 0)  # never wider than one fix


def _truth(t: np.ndarray) -> np.ndarray:
    """A gently curving drive at about 0.3 m/s, heading along the motion (x, y in m, yaw in rad)."""
    x, y = 0.3 * t, 0.4 * np.sin(0.08 * t)
    return np.column_stack([x, y, np.arctan2(0.4 * 0.08 * np.cos(0.08 * t), 0.3)])


def _odometry(t: np.ndarray, xyt: np.ndarray, noise: OdometryNoise, rng: np.random.Generator) -> OdometryLog:
    """Dead reckoning from the true increments plus noise drawn from fusion's own slip model."""
    u, cov = odometry_increments(xyt, t, noise)
    u = u + np.einsum("nij,nj->ni", np.linalg.cholesky(cov), rng.normal(size=u.shape))
    odo = np.zeros_like(xyt)
    odo[0, 2] = xyt[0, 2]
    odo[1:, 2] = xyt[0, 2] + np.cumsum(u[:, 2])
    c, s = np.cos(odo[:-1, 2]), np.sin(odo[:-1, 2])
    odo[1:, 0] = np.cumsum(c * u[:, 0] - s * u[:, 1])
    odo[1:, 1] = np.cumsum(s * u[:, 0] + c * u[:, 1])
    dt = np.diff(t)
    return OdometryLog(t, odo, np.r_[0.0, np.hypot(u[:, 0], u[:, 1]) / dt], np.r_[0.0, u[:, 2] / dt])


def _fixes(rate_hz: float, t0: float, t1: float, cov: np.ndarray, block_s: float, rng: np.random.Generator,
           clock_s: float = 0.0) -> PoseTrack:
    """Fixes whose error is one draw per ``block_s`` (errors correlated over that span, as fusion assumes),
    stamped ``clock_s`` late."""
    st = np.arange(t0, t1, 1.0 / rate_hz)
    block = np.floor((st - t0) / block_s).astype(int)
    draws = rng.multivariate_normal(np.zeros(3), cov, int(block.max()) + 1)
    z = _truth(st) + draws[block]
    return PoseTrack.from_xytheta(st + clock_s, z, cov=np.broadcast_to(cov, (st.size, 3, 3)).copy())


COV_V = np.diag(np.square([0.0015, 0.0011, np.radians(0.035)]))
COV_L = np.array([[1.0e-6, 2e-7, 0.0], [2e-7, 0.7e-6, 0.0], [0.0, 0.0, np.radians(0.075) ** 2]])


def _drive_errors(seed: int, clock_s: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Fusion of a 150 s drive (vision at 10 Hz, laser at 75 Hz, both stamped ``clock_s`` late): the fused
    errors (K, 3), the true poses (K, 3) and velocities (K, 3) at its poses 10 s from either end."""
    rng = np.random.default_rng(seed)
    t = np.arange(0.0, 150.0, 0.02)
    odo = _odometry(t, _truth(t), OdometryNoise(), rng)
    step_s = FusionOptions().correlation_s
    vision = _fixes(10.0, 0.013, 149.9, COV_V, step_s, rng, clock_s)
    laser = _fixes(75.0, 0.007, 149.9, COV_L, step_s, rng, clock_s)
    track, _ = fuse_tracks({"vision": vision, "laser": laser}, odo)
    mid = (track.stamps_s > 10.0) & (track.stamps_s < 140.0)
    st = track.stamps_s[mid]
    true = _truth(st)
    return track.xytheta()[mid] - true, true, np.gradient(true, st, axis=0)


def _ratios(err: np.ndarray, pred: np.ndarray) -> tuple[float, float]:
    var = np.diagonal(pred, axis1=1, axis2=2)
    return (float(np.sqrt(np.mean(err[:, :2] ** 2) / np.mean(var[:, :2]))),
            float(np.sqrt(np.mean(err[:, 2] ** 2) / np.mean(var[:, 2]))))


def test_fusion_errors_agree_with_the_predicted_sigma():
    err, true, vel = _drive_errors(8, 0.0)
    K = err.shape[0]
    # the fixes' clocks are right here: no clock share
    settings = FusionPlanSettings(clock_sigma_s=0.0)
    pred = fused_covariance(np.broadcast_to(COV_V, (K, 3, 3)), np.broadcast_to(COV_L, (K, 3, 3)), None, None,
                            true[:, 2], vel, SourceRates(10.0, 75.0), settings)
    pos, yaw = _ratios(err, pred)
    print(f"fused RMS error / predicted sigma: position {pos:.2f}, yaw {yaw:.2f}")
    assert 0.75 <= pos <= 1.33 and 0.75 <= yaw <= 1.33, (pos, yaw)
    # the instant's information alone (no smoother) would be cautious here by more than the tolerance
    inst = fused_covariance(COV_V[None], COV_L[None], None, None, np.zeros(1), np.zeros((1, 3)),
                            SourceRates(10.0, 75.0), FusionPlanSettings(smooth=False, clock_sigma_s=0.0))[0]
    assert np.sqrt(np.mean(err[:, :2] ** 2) / np.mean(np.diag(inst)[:2])) < 0.75


def test_a_clock_off_by_its_sigma_is_what_the_plan_adds():
    # both sources stamped 3 ms late, as a clock offset wrong by one sigma of 3 ms leaves them: the fused
    # pose trails by the velocity times 3 ms, which the plan's clock share predicts (without it the
    # position would be 2 sigma off)
    clock_s = 0.003
    err, true, vel = _drive_errors(9, clock_s)
    K = err.shape[0]
    args = (np.broadcast_to(COV_V, (K, 3, 3)), np.broadcast_to(COV_L, (K, 3, 3)), None, None, true[:, 2], vel,
            SourceRates(10.0, 75.0))
    pos, yaw = _ratios(err, fused_covariance(*args, FusionPlanSettings(clock_sigma_s=clock_s)))
    pos_0, _ = _ratios(err, fused_covariance(*args, FusionPlanSettings(clock_sigma_s=0.0)))
    print(f"clock 3 ms late: fused RMS error / predicted sigma {pos:.2f} / {yaw:.2f}; without the clock {pos_0:.2f}")
    assert 0.75 <= pos <= 1.33 and 0.75 <= yaw <= 1.33, (pos, yaw)
    assert pos_0 > 1.6, pos_0


def test_odometry_step_turns_with_the_heading():
    noise = OdometryNoise()
    v = np.array([[0.3, 0.0, 0.0], [0.0, 0.3, 0.0]])
    Q = odometry_step_covariance(np.array([0.0, np.pi / 2]), v, 0.5, noise)
    # forward slip along the heading: x for heading 0, y for heading 90 deg; lateral half of it across
    assert np.isclose(Q[0, 0, 0], Q[1, 1, 1]) and np.isclose(Q[0, 1, 1], Q[1, 0, 0])
    assert Q[0, 1, 1] < Q[0, 0, 0]
    assert np.isclose(Q[0, 2, 2], Q[1, 2, 2])
