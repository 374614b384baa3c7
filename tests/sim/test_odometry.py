"""Simulated wheel odometry: exact without errors, drift within the documented bounds, deterministic."""

from __future__ import annotations

import numpy as np
import pytest

from gtrig.io.odometry import read_odometry
from gtrig.sim.config import SimConfig
from gtrig.sim.gtroom import continuous_path, make_scene
from gtrig.sim.motion import RobotMotion
from gtrig.sim.odometry import OdometryErrors, simulate_odometry, write_odometry


@pytest.fixture(scope="module")
def scene():  # type: ignore[no-untyped-def]
    return make_scene(1)


@pytest.fixture(scope="module")
def run(scene):  # type: ignore[no-untyped-def]
    st, xy = continuous_path()
    return RobotMotion(st + 300.0, xy, scene.floor)


def _rel(P: np.ndarray, i: int, j: int) -> np.ndarray:
    c, s = np.cos(P[i, 2]), np.sin(P[i, 2])
    d = P[j, :2] - P[i, :2]
    return np.array([c * d[0] + s * d[1], -s * d[0] + c * d[1], P[j, 2] - P[i, 2]])


def _drift(run: RobotMotion, errors: OdometryErrors, seed: int) -> tuple[float, float, float]:
    """Whole-run end-point error per metre travelled (m/m, deg/m) and the path length."""
    o = simulate_odometry(run, run.stamps_s[0], run.stamps_s[-1], 50.0, errors, np.random.default_rng(seed))
    T = run.planar(o.stamps_s)
    length = float(np.sum(np.hypot(*np.diff(T[:, :2], axis=0).T)))
    a, b = _rel(T, 0, len(T) - 1), o.xytheta[-1]
    return float(np.hypot(*(a[:2] - b[:2]))) / length, float(np.degrees(abs(a[2] - b[2]))) / length, length


def test_error_free_odometry_has_no_drift(run) -> None:  # type: ignore[no-untyped-def]
    pos, head, length = _drift(run, OdometryErrors(), 0)
    assert length > 20
    assert pos * length < 1e-4 and head < 1e-9
    o = simulate_odometry(run, run.stamps_s[0], run.stamps_s[0] + 2, 50.0, OdometryErrors(),
                          np.random.default_rng(0))
    np.testing.assert_array_equal(o.xytheta[0], [0, 0, 0])
    np.testing.assert_allclose(np.diff(o.stamps_s), 0.02)
    v_true = np.linalg.norm(run.velocity(o.stamps_s[1:])[:, :2], axis=1)
    np.testing.assert_allclose(o.v_mps[1:], v_true, atol=0.01)


def test_drift_within_documented_bounds(run) -> None:  # type: ignore[no-untyped-def]
    # docs/simulator.md: over the 22 m run, 0.3-2.6 % of the distance and 0.05-0.4 deg per metre
    res = np.array([_drift(run, OdometryErrors.draw(np.random.default_rng([s, 1])), s)[:2] for s in range(8)])
    assert np.all(res[:, 0] < 0.03) and np.all(res[:, 1] < 0.5)
    assert np.all(res[:, 0] > 0.001)  # systematic errors do show


def test_same_seed_same_file(tmp_path, scene, run) -> None:  # type: ignore[no-untyped-def]
    t0, t1 = run.stamps_s[0], run.stamps_s[0] + 5
    for name, seed in (("a", 3), ("b", 3), ("c", 4)):
        write_odometry(scene, run, t0, t1, tmp_path / f"{name}.csv", SimConfig(), seed)
    assert (tmp_path / "a.csv").read_bytes() == (tmp_path / "b.csv").read_bytes()
    assert (tmp_path / "a.csv").read_bytes() != (tmp_path / "c.csv").read_bytes()
    log = read_odometry(tmp_path / "a.csv")
    assert len(log) == 251


def test_robot_clock_offset_shifts_only_the_stamps(tmp_path, scene, run) -> None:  # type: ignore[no-untyped-def]
    """--odometry-offset-s: the same samples, stamped on the robot's clock (GT clock + offset)."""
    t0, t1 = run.stamps_s[0], run.stamps_s[0] + 5.0
    write_odometry(scene, run, t0, t1, tmp_path / "a.csv", SimConfig(), 3)
    write_odometry(scene, run, t0, t1, tmp_path / "b.csv", SimConfig(odometry_clock_offset_s=0.3), 3)
    a, b = read_odometry(tmp_path / "a.csv"), read_odometry(tmp_path / "b.csv")
    np.testing.assert_allclose(b.stamps_s - a.stamps_s, 0.3, atol=1e-6)
    np.testing.assert_array_equal(a.xytheta, b.xytheta)
