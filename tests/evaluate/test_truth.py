"""Scoring any pose track against truth (gtrig.evaluate.truth): known errors come out exact, errors
drawn from the covariance give NEES / dof of one, the body-frame correction, coverage and span."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from gtrig.evaluate.truth import score_track
from gtrig.laser.track import AMBIGUOUS, DEGENERATE, LOST, OK, TrackResult, to_pose_track
from gtrig.trajectory import PoseStatus, PoseTrack


def truth_circle(n: int = 2001) -> PoseTrack:
    """A robot driving a circle of 2 m at 0.3 m/s, heading along it, 100 Hz."""
    t = np.linspace(0, 20, n)
    a = 0.15 * t
    xy = np.column_stack([2 * np.cos(a), 2 * np.sin(a)])
    return PoseTrack.from_xytheta(t, np.column_stack([xy, a + np.pi / 2]))


def test_planar_known_errors() -> None:
    truth = truth_circle()
    t = np.linspace(1, 19, 50)
    true_p = truth.select(np.searchsorted(truth.stamps_s, t)).xytheta()  # stamps on truth samples
    t = truth.stamps_s[np.searchsorted(truth.stamps_s, t)]
    est = true_p + np.array([0.003, -0.004, np.radians(0.1)])
    cov = np.tile(np.diag([0.003**2, 0.004**2, np.radians(0.1) ** 2]), (50, 1, 1))
    track = PoseTrack.from_xytheta(t, est, cov=cov)
    s = score_track(track, truth, expected_stamps_s=np.r_[t, 25.0, 30.0])  # two asked for outside the span
    assert s.n_scored == 50 and s.n_expected == 50 and s.localized_fraction == 1.0
    np.testing.assert_allclose(s.pos_err_m, 0.005, atol=1e-9)
    np.testing.assert_allclose(s.yaw_err_rad, np.radians(0.1), atol=1e-9)
    np.testing.assert_allclose(s.nees, 3.0, rtol=1e-6)  # one sigma on each axis
    assert s.n_pos_over(0.004) == 50 and s.n_pos_over(0.006) == 0


def test_planar_nees_is_dof_when_errors_follow_the_covariance() -> None:
    rng = np.random.default_rng(5)
    truth = truth_circle()
    n = 4000
    t = np.sort(rng.uniform(0.5, 19.5, n))
    t = t[np.r_[True, np.diff(t) > 0]]
    C = np.array([[4e-6, 1e-6, 0], [1e-6, 2e-6, 1e-7], [0, 1e-7, 3e-6]])
    true_p = np.column_stack([2 * np.cos(0.15 * t), 2 * np.sin(0.15 * t), 0.15 * t + np.pi / 2])
    est = true_p + rng.multivariate_normal(np.zeros(3), C, len(t))
    s = score_track(PoseTrack.from_xytheta(t, est, cov=np.tile(C, (len(t), 1, 1))), truth)
    assert s.mean_nees / s.nees_dof == pytest.approx(1.0, abs=0.06)
    # a covariance twice too small shows as NEES / dof of two
    s2 = score_track(PoseTrack.from_xytheta(t, est, cov=np.tile(C / 2, (len(t), 1, 1))), truth)
    assert s2.mean_nees / s2.nees_dof == pytest.approx(2.0, abs=0.12)


def test_se3_world_perturbation_and_body_frame() -> None:
    """6-DoF errors drawn as gtrig.trajectory's world-frame perturbation give NEES / dof of one, on all
    six axes and on the planar block; a known body-frame offset is taken out by ``T_true_body``."""
    rng = np.random.default_rng(2)
    truth = truth_circle()
    idx = np.arange(5, 1995, 2)
    Tt = truth.matrices()[idx]
    L = np.diag([2e-3, 3e-3, 1e-3, 1e-3, 2e-3, 4e-3])
    C = L @ L.T
    xi = rng.multivariate_normal(np.zeros(6), C, len(idx))
    Te = Tt.copy()
    Te[:, :3, 3] += xi[:, :3]
    Te[:, :3, :3] = Rotation.from_rotvec(xi[:, 3:]).as_matrix() @ Tt[:, :3, :3]
    track = PoseTrack.from_matrices(truth.stamps_s[idx], Te, cov=np.tile(C, (len(idx), 1, 1)), cov_kind="se3")
    full = score_track(track, truth, dof="full")
    planar = score_track(track, truth)
    assert full.nees_dof == 6 and planar.nees_dof == 3
    assert full.mean_nees / 6 == pytest.approx(1.0, abs=0.1)
    assert planar.mean_nees / 3 == pytest.approx(1.0, abs=0.12)
    np.testing.assert_allclose(planar.pos_err_m, np.hypot(xi[:, 0], xi[:, 1]), atol=1e-9)
    # the markers' frame off by B from the true robot frame: scored against T_true @ B it is exact
    B = np.eye(4)
    B[:3, :3] = Rotation.from_euler("z", 0.02).as_matrix()
    B[:3, 3] = [0.01, -0.02, 0]
    exact = PoseTrack.from_matrices(truth.stamps_s[idx], Tt @ B, cov=np.tile(C, (len(idx), 1, 1)), cov_kind="se3")
    assert score_track(exact, truth).mean_pos_m > 0.01
    s = score_track(exact, truth, T_true_body=B)
    assert s.max_pos_m < 1e-9 and s.max_abs_yaw_rad < 1e-9


def test_only_usable_poses_inside_the_span_are_scored() -> None:
    truth = truth_circle()
    t = np.array([-1.0, 5.0, 6.0, 7.0, 25.0])
    p = np.column_stack([2 * np.cos(0.15 * t), 2 * np.sin(0.15 * t), 0.15 * t + np.pi / 2])
    p[2, :2] += 1.0  # a rejected outlier
    status = np.array([PoseStatus.OK, PoseStatus.OK, PoseStatus.REJECTED, PoseStatus.FLAGGED, PoseStatus.OK])
    track = PoseTrack.from_xytheta(t, p, status=status, reasons=("", "", "jump", "thin fit", ""))
    s = score_track(track, truth, expected_stamps_s=np.arange(0, 20.0, 0.5))
    np.testing.assert_array_equal(s.stamps_s, [5.0, 7.0])
    assert s.max_pos_m < 1e-5 and s.n_expected == 40 and s.localized_fraction == 2 / 40
    assert s.nees.size == 0  # no covariance, no NEES


def test_gtlaser_statuses_on_the_pose_track() -> None:
    F = 5
    xy = np.column_stack([np.arange(F) * 0.1, np.zeros(F), np.linspace(0, 0.4, F)])
    xy[2] = np.nan  # lost: no pose
    cov = np.tile(np.eye(3) * 1e-6, (F, 1, 1))
    cov[2] = np.nan
    status = np.array([OK, DEGENERATE, LOST, AMBIGUOUS, OK], np.int8)
    reasons = ("", "two sides only", "no points", "heading ambiguous (pi symmetry)", "")
    res = TrackResult(np.arange(F) * 0.1, xy, cov, status, xy, cov, np.zeros(F, int), np.zeros(F, int), np.zeros(F),
                      np.zeros(F, int), reasons, np.zeros((F, 3, 3)))
    tr = to_pose_track(res)
    np.testing.assert_allclose(tr.stamps_s, [0.0, 0.1, 0.3, 0.4])
    assert list(tr.status) == [PoseStatus.OK, PoseStatus.REJECTED, PoseStatus.REJECTED, PoseStatus.OK]
    assert tr.reasons[1] == "degenerate: two sides only" and tr.reasons[2].startswith("ambiguous: heading")
    assert len(tr.usable()) == 2 and tr.cov_kind == "xyyaw" and tr.source == "GTlaser"
    np.testing.assert_allclose(tr.xytheta(), xy[[0, 1, 3, 4]], atol=1e-12)
