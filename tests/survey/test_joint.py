"""The joint adjustment of world points and validation poses: accuracy, consistency, bad readings."""

from __future__ import annotations

import numpy as np
import pytest

from gtrig import geometry as geo
from gtrig.errors import InputError
from gtrig.io.survey_csv import Distances, NamedPoints
from gtrig.sim.gtroom import REFERENCE_SIGMA_M
from gtrig.sim.survey import simulate_survey
from gtrig.survey import run_survey
from gtrig.survey.joint import adjust_jointly
from gtrig.survey.robust import residual_test

from .mc import scene_and_poses, to_inputs

POSES = [str(i + 1) for i in range(26)]
POINTS = [str(i + 1) for i in range(16)]


def _fresh_reference(rng: np.random.Generator, nominal: dict) -> dict:
    return {k: (v[0] + rng.normal(0, REFERENCE_SIGMA_M), v[1] + rng.normal(0, REFERENCE_SIGMA_M)) if k != "O" else v
            for k, v in nominal.items()}


def test_monte_carlo_accuracy_and_consistency() -> None:
    """40 surveys of the 26 validation stops with fresh reference and hand-laser errors: every world point
    within 2 mm in nearly all of them (the two stages reach that in about 70 %), and the covariances
    consistent (mean NEES within [0.7, 1.4] x dof; bench/survey.py runs 200)."""
    sc, T, truth = scene_and_poses(0)
    nominal = {r.name: r.xy for r in sc.rig_nominal.survey.reference_points}
    rng = np.random.default_rng(21)
    worst, nees_w, nees_p, pose_err = [], [], [], []
    for _ in range(40):
        sv = simulate_survey(sc, T, rng, reference_true_xy=_fresh_reference(rng, nominal))
        ref, wd, rp, pd = to_inputs(sv)
        # start a few millimetres off, as the two stages leave it
        r = adjust_jointly(POINTS, sc.world_points_xy + rng.normal(0, 0.003, (16, 2)), ref, wd, POSES,
                           truth + rng.normal(0, 0.003, truth.shape), rp, pd, on_outlier="keep", warnings=[])
        e = r.points_xy - sc.world_points_xy
        worst.append(np.linalg.norm(e, axis=1).max())
        nees_w.append(np.einsum("pi,pij,pj->p", e, np.linalg.inv(r.points_cov_xy), e).mean())
        ep = r.poses_xytheta - truth
        ep[:, 2] = geo.wrap_angle(ep[:, 2])
        nees_p.append(np.einsum("pi,pij,pj->p", ep, np.linalg.inv(r.poses_cov), ep).mean())
        pose_err.append(np.hypot(ep[:, 0], ep[:, 1]).max())
    assert np.mean(np.array(worst) < 0.002) >= 0.9, np.percentile(worst, [50, 90])
    assert np.median(worst) < 0.0013
    assert np.median(pose_err) < 0.0012
    assert 0.7 * 2 <= np.mean(nees_w) <= 1.4 * 2, np.mean(nees_w)
    assert 0.7 * 3 <= np.mean(nees_p) <= 1.4 * 3, np.mean(nees_p)


def test_better_than_two_stages_through_run_survey() -> None:
    sc, T, truth = scene_and_poses(1)
    inputs = to_inputs(simulate_survey(sc, T, np.random.default_rng(0)))
    two = run_survey(*inputs, joint=False, multistart=False)
    one = run_survey(*inputs, multistart=False)
    assert one.joint is not None and two.joint is None
    e2 = np.linalg.norm(two.points.xy - sc.world_points_xy, axis=1).max()
    e1 = np.linalg.norm(one.points.xy - sc.world_points_xy, axis=1).max()
    assert e1 < 0.7 * e2 and e1 < 0.002
    assert np.all(np.linalg.eigvalsh(one.poses.cov_xytheta) > 0)
    # the poses' readings also measure the world points: their variance drops by about 40 %
    assert np.mean(one.points.cov_xy[:, 0, 0]) < 0.75 * np.mean(two.points.cov_xy[:, 0, 0])


def test_bad_pose_reading_is_named_excluded_or_refused() -> None:
    sc, T, truth = scene_and_poses(0)
    ref, wd, rp, pd = to_inputs(simulate_survey(sc, T[:6], np.random.default_rng(3)))
    k = 16 * 3 * 2 + 16 + 4  # pose 3, robot point X, world point 5
    d = pd.distance_m.copy()
    d[k] += 0.02  # 2 cm: a spot on the wrong edge of the mark
    bad = Distances(pd.group, pd.a, pd.b, d, pd.sigma_m, pd.source)
    args = (POINTS, sc.world_points_xy, ref, wd, POSES[:6], truth[:6], rp, bad)
    r = adjust_jointly(*args, warnings=[])
    assert [(b.kind, b.item, b.a, b.b, b.source) for b in r.excluded] == [("pose", "3", "X", "5", pd.source[k])]
    assert abs(r.excluded[0].error_m - 0.02) < 0.004 and not r.pose_active[k]
    assert np.hypot(*(r.poses_xytheta[2, :2] - truth[2, :2])) < 0.002
    with pytest.raises(InputError, match="pose 3, robot point X to world point 5"):
        adjust_jointly(*args, on_outlier="refuse")


def test_drawn_robot_points_carry_their_sigma() -> None:
    """Robot points drawn on the floor 1 mm off their place (one offset per stop, shared by the readings
    from it): with the drawing sigma given, the poses' covariance covers the error."""
    sc, T, truth = scene_and_poses(0)
    rng = np.random.default_rng(4)
    P, A = 10, 3
    nees = []
    for _ in range(12):
        sv = simulate_survey(sc, T[:P], rng)
        ref, wd, rp, pd = to_inputs(sv)
        qi = {n: i for i, n in enumerate(rp.names)}
        off = rng.normal(0, 0.001, (P, A, 2))
        d = pd.distance_m.copy()
        for k in range(d.size):
            p, a, w = int(pd.group[k]) - 1, qi[pd.a[k]], int(pd.b[k]) - 1
            s = T[p][:2, :2] @ rp.xy[a] + T[p][:2, 3] + off[p, a]
            d[k] = np.linalg.norm(sc.world_points_xy[w] - s) + rng.normal(0, pd.sigma_m[k])
        rp1 = NamedPoints(rp.names, rp.xy, np.full(A, 0.001))
        r = adjust_jointly(POINTS, sc.world_points_xy, ref, wd, POSES[:P], truth[:P], rp1,
                           Distances(pd.group, pd.a, pd.b, d, pd.sigma_m, pd.source), on_outlier="keep",
                           warnings=[])
        ep = r.poses_xytheta - truth[:P]
        ep[:, 2] = geo.wrap_angle(ep[:, 2])
        nees.append(np.einsum("pi,pij,pj->p", ep, np.linalg.inv(r.poses_cov), ep).mean())
    assert 0.6 * 3 <= np.mean(nees) <= 1.5 * 3, np.mean(nees)


def test_whitened_residual_test_equals_the_general_one() -> None:
    rng = np.random.default_rng(0)
    J = rng.normal(size=(200, 30))
    C = np.linalg.inv(J.T @ J)
    r = rng.normal(size=200)
    r[11] += 7.0
    a, b = residual_test(r, np.eye(200), J, C), residual_test(r, None, J, C)
    assert a.worst == b.worst == 11 and a.identifiable == b.identifiable
    np.testing.assert_allclose(b.w, a.w, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(b.error_m, a.error_m, rtol=1e-9, atol=1e-12)
    assert abs(a.chi2 - b.chi2) < 1e-9 and a.dof == b.dof


def test_cli_adjust_writes_both_tables(tmp_path) -> None:
    from typer.testing import CliRunner

    from gtrig.cli.main import app
    from gtrig.io.survey_csv import read_points, read_pose_table
    from gtrig.sim.survey import write_survey

    sc, T, truth = scene_and_poses(0)
    write_survey(sc, T[:8], tmp_path, None, seed=0)
    sv = tmp_path / "survey"
    out_w, out_p = tmp_path / "points.csv", tmp_path / "poses.csv"
    r = CliRunner().invoke(app, [
        "survey", "adjust", "--reference", str(sv / "reference_points.csv"), "--distances",
        str(sv / "world_distances.csv"), "--robot-points", str(sv / "robot_points.csv"), "--pose-distances",
        str(sv / "pose_distances.csv"), "--sigma", "0.00075", "--out-points", str(out_w), "--out-poses", str(out_p)])
    assert r.exit_code == 0, r.output
    assert "16 world points" in r.output and "8 poses" in r.output
    w, p = read_points(out_w), read_pose_table(out_p)
    assert np.abs(w.xy - sc.world_points_xy).max() < 0.002
    assert np.hypot(*(p.xytheta[:, :2] - truth[:8, :2]).T).max() < 0.002
    # a user mistake is one line and a non-zero exit
    r = CliRunner().invoke(app, [
        "survey", "adjust", "--reference", str(sv / "reference_points.csv"), "--distances",
        str(sv / "world_distances.csv"), "--robot-points", str(tmp_path / "missing.csv"), "--pose-distances",
        str(sv / "pose_distances.csv"), "--out-points", str(out_w), "--out-poses", str(out_p)])
    assert r.exit_code != 0 and "missing.csv" in r.output and "Traceback" not in r.output
