"""Seeded invariant loops for the transform core."""

from __future__ import annotations

import cv2
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from gtrig import geometry as geo


def _random_T(rng: np.random.Generator) -> np.ndarray:
    return geo.make_T(Rotation.random(random_state=rng.integers(1 << 31)).as_matrix(), rng.normal(0, 3, 3))


@pytest.mark.parametrize("seed", range(5))
def test_inverse_and_composition(seed: int) -> None:
    rng = np.random.default_rng(seed)
    A, B = _random_T(rng), _random_T(rng)
    np.testing.assert_allclose(geo.inv_T(A) @ A, np.eye(4), atol=1e-12)
    np.testing.assert_allclose(geo.inv_T(A @ B), geo.inv_T(B) @ geo.inv_T(A), atol=1e-12)
    p = rng.normal(size=(7, 3))
    np.testing.assert_allclose(geo.transform_points(geo.inv_T(A), geo.transform_points(A, p)), p, atol=1e-12)
    stack = np.stack([A, B])
    np.testing.assert_allclose(geo.inv_T(stack)[1], geo.inv_T(B), atol=1e-12)


@pytest.mark.parametrize("seed", range(5))
def test_representations_round_trip(seed: int) -> None:
    rng = np.random.default_rng(seed)
    T = _random_T(rng)
    t, q = geo.xyz_quat_from_T(T)
    assert q[3] >= 0
    np.testing.assert_allclose(geo.T_from_xyz_quat(t, q), T, atol=1e-12)
    rpy = geo.rpy_from_T(T)
    np.testing.assert_allclose(geo.T_from_xyz_rpy(t, rpy), T, atol=1e-12)
    x, y, th = rng.normal(size=3)
    np.testing.assert_allclose(geo.T_to_se2(geo.se2_to_T(x, y, th)), [x, y, geo.wrap_angle(th)], atol=1e-12)


def test_wrap_angle_range() -> None:
    a = geo.wrap_angle(np.array([np.pi, -np.pi, 3 * np.pi, 0.1, -7.0]))
    assert np.all(a >= -np.pi) and np.all(a < np.pi)
    np.testing.assert_allclose(np.cos(a), np.cos([np.pi, -np.pi, 3 * np.pi, 0.1, -7.0]), atol=1e-12)


def test_pose_error() -> None:
    T = geo.T_from_xyz_rpy([1, 2, 3], [0.1, 0.2, 0.3])
    dT = geo.T_from_xyz_rpy([0.003, -0.004, 0], [0, 0, np.radians(0.5)])
    dt, dr = geo.pose_error(T @ dT, T)
    assert dt == pytest.approx(0.005)
    assert dr == pytest.approx(np.radians(0.5))


def test_look_at_points_the_optical_axis() -> None:
    T = geo.look_at([0, 0, 3], [2, 1, 0])
    z = T[:3, 2]
    np.testing.assert_allclose(z, np.array([2, 1, -3]) / np.linalg.norm([2, 1, -3]), atol=1e-12)
    assert abs(T[2, 0]) < 1e-12  # image x axis horizontal


@pytest.mark.parametrize("seed", range(3))
def test_projection_matches_opencv(seed: int) -> None:
    rng = np.random.default_rng(seed)
    K = np.array([[1400.0, 0.0, 510.0], [0, 1390.0, 380.0], [0, 0, 1]])
    dist = np.array([-0.2, 0.1, 1e-3, -5e-4, -0.02, 0.01, 0.002, 0.001])
    p = np.column_stack([rng.uniform(-1, 1, 50), rng.uniform(-1, 1, 50), rng.uniform(2, 6, 50)])
    ref, _ = cv2.projectPoints(p, np.zeros(3), np.zeros(3), K, dist)
    np.testing.assert_allclose(geo.project_points(p, K, dist), ref.reshape(-1, 2), atol=1e-6)
