"""The robot frame tied to the survey at the validation stops: estimate, covariance, outliers, rig."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from gtrig import geometry as geo
from gtrig.errors import InputError
from gtrig.sim.gtroom import make_scene
from gtrig.vision.robot_frame import (
    correct_pose,
    fit_frame_offset,
    frame_error_covariance,
    rig_in_surveyed_frame,
)

K = 26


def _stops(rng: np.random.Generator, D: np.ndarray, shared_mm: float = 0.5) -> tuple:
    """K stops: true poses, GTvision's view of them (the markers' frame, off by D^-1) and the survey's,
    with the survey's errors correlated through a common world shift of ``shared_mm``."""
    S_true = np.c_[rng.uniform(-3, 3, (K, 2)), rng.uniform(-np.pi, np.pi, K)]
    Cv = np.array([np.diag([0.4e-3, 0.4e-3, math.radians(0.02)]) ** 2] * K)
    Cs_block = np.diag([0.5e-3, 0.5e-3, math.radians(0.03)]) ** 2
    Cs = np.kron(np.eye(K), Cs_block)
    common = np.zeros((3 * K, 3))
    common[0::3, 0] = common[1::3, 1] = shared_mm * 1e-3
    Cs = Cs + common @ common.T
    Dinv = geo.inv_T(geo.se2_to_T(*D))
    V_true = np.array([geo.T_to_se2(geo.se2_to_T(*s) @ Dinv) for s in S_true])
    V = V_true + np.array([rng.multivariate_normal(np.zeros(3), c) for c in Cv])
    S = S_true + rng.multivariate_normal(np.zeros(3 * K), Cs).reshape(K, 3)
    return S_true, V, Cv, S, Cs


def test_offset_recovered_with_a_consistent_covariance() -> None:
    rng = np.random.default_rng(1)
    D = np.array([0.0004, -0.0003, math.radians(0.12)])
    nees, nees_loo = [], []
    for _ in range(300):
        _, V, Cv, S, Cs = _stops(rng, D)
        fit = fit_frame_offset([str(k) for k in range(K)], V, Cv, S, Cs)
        e = fit.d_xytheta - D
        nees.append(e @ np.linalg.solve(fit.cov_d, e))
        e0 = fit.loo_d[0] - D
        nees_loo.append(e0 @ np.linalg.solve(fit.loo_cov[0], e0))
        assert fit.used.all() and not fit.excluded
    # the shared world shift does not average out over stops; the joint covariance says so
    assert 0.7 * 3 <= np.mean(nees) <= 1.3 * 3
    assert 0.7 * 3 <= np.mean(nees_loo) <= 1.3 * 3
    assert math.degrees(math.sqrt(fit.cov_d[2, 2])) < 0.02  # 26 stops: well below the hand's 0.1 deg


def test_shared_survey_error_ignored_is_overconfident() -> None:
    """The same stops with the survey's poses taken as independent: the estimate claims too much."""
    rng = np.random.default_rng(2)
    D = np.zeros(3)
    nees = []
    for _ in range(200):
        _, V, Cv, S, Cs = _stops(rng, D, shared_mm=1.5)
        blocks = np.array([Cs[3 * k:3 * k + 3, 3 * k:3 * k + 3] - np.diag([1.5e-3**2, 1.5e-3**2, 0]) for k in
                           range(K)])
        fit = fit_frame_offset([str(k) for k in range(K)], V, Cv, S, blocks)
        nees.append(fit.d_xytheta @ np.linalg.solve(fit.cov_d, fit.d_xytheta))
    assert np.mean(nees) > 2 * 3


def test_a_bad_stop_is_named_and_left_out() -> None:
    rng = np.random.default_rng(3)
    D = np.array([0.0, 0.0, math.radians(0.1)])
    _, V, Cv, S, Cs = _stops(rng, D)
    S[7, 2] += math.radians(0.5)  # a stop surveyed with a robot point misread
    V[11] = np.nan  # a stop GTvision did not localize
    names = [f"p{k}" for k in range(K)]
    fit = fit_frame_offset(names, V, Cv, S, Cs)
    assert fit.excluded == ("p7",)
    assert not fit.used[7] and not fit.used[11] and fit.used.sum() == K - 2
    assert abs(math.degrees(fit.d_xytheta[2] - D[2])) < 0.02
    assert np.all(np.isfinite(fit.loo_d[11]))  # a stop without GTvision can still be checked


def test_too_few_stops_refused() -> None:
    with pytest.raises(InputError, match="at least 2"):
        fit_frame_offset(["a"], np.zeros((1, 3)), np.eye(3)[None], np.zeros((1, 3)), np.eye(3)[None])


def test_corrected_rig_gives_the_corrected_poses() -> None:
    """Markers moved by D^-1 on the robot: a marker's world pose is the same, seen from ``T D``."""
    rig = make_scene(0).rig_true
    D = geo.se2_to_T(0.001, -0.002, math.radians(0.3))
    rig2 = rig_in_surveyed_frame(rig, D)
    T_world_robot = geo.se2_to_T(1.0, 2.0, 0.7)
    for m, m2 in zip(rig.robot.markers, rig2.robot.markers, strict=True):
        np.testing.assert_allclose(T_world_robot @ m.T_robot_marker.matrix(),
                                   (T_world_robot @ D) @ m2.T_robot_marker.matrix(), atol=1e-12)
    T, C = correct_pose(T_world_robot, np.eye(6) * 1e-6, D)
    np.testing.assert_allclose(T, T_world_robot @ D)
    assert np.allclose(C, C.T) and np.all(np.linalg.eigvalsh(C) > 0)


def test_correct_pose_covariance_by_sampling() -> None:
    rng = np.random.default_rng(4)
    T0 = geo.se2_to_T(1.0, -1.0, 2.0, 0.3)
    D = geo.se2_to_T(0.3, 0.2, 0.4)  # a large offset, so the lever arm shows
    C = np.diag([1e-6, 2e-6, 1e-6, 1e-5, 1e-5, 4e-5])
    _, C1 = correct_pose(T0, C, D)
    xs = rng.multivariate_normal(np.zeros(6), C, 20000)
    errs = []
    for x in xs:
        T = T0.copy()
        T[:3, 3] += x[:3]
        T[:3, :3] = Rotation.from_rotvec(x[3:]).as_matrix() @ T0[:3, :3]
        Tc, T0c = T @ D, T0 @ D
        errs.append(np.r_[Tc[:3, 3] - T0c[:3, 3], Rotation.from_matrix(Tc[:3, :3] @ T0c[:3, :3].T).as_rotvec()])
    np.testing.assert_allclose(np.cov(np.array(errs).T), C1, rtol=0.06, atol=3e-7)


def test_frame_covariance_takes_the_planar_part_from_the_fit() -> None:
    hand = np.diag(np.arange(1.0, 7.0)) + 0.1
    C = frame_error_covariance(np.diag([7.0, 8.0, 9.0]), hand)
    np.testing.assert_allclose(np.diag(C), [7, 8, hand[2, 2], hand[3, 3], hand[4, 4], 9])
    assert C[0, 2] == 0 and C[2, 3] == hand[2, 3]
