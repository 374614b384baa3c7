"""The matchers and the acceptance test on simulated scans of standing robots (truth scores only)."""

from __future__ import annotations

import numpy as np
import pytest

from gtrig.io.rosmap import read_map, write_map
from gtrig.io.scans import read_scans
from gtrig.rig.load import load_rig
from gtrig.scanmatch import se2
from gtrig.scanmatch.accept import AcceptParams, judge
from gtrig.scanmatch.genetic import match_genetic
from gtrig.scanmatch.icp import evaluate, match_icp
from gtrig.scanmatch.scan import ranges_to_scan
from gtrig.scanmatch.validate import load_stop_scans


@pytest.fixture(scope="module")
def raw(stop_rec):
    """Single raw scans (1 cm noise) of the first stop, front scanner, its own frame."""
    rec = stop_rec[0]
    rig = load_rig(rec / "rig.yaml")
    sc = rig.robot.onboard_scanners[0]
    lg = read_scans(rec / "validation" / "onboard" / f"{sc.name}.csv", sc)
    iv = np.loadtxt(rec / "validation" / "poses.csv", delimiter=",", skiprows=1)
    sel = (lg.stamps_s >= iv[0, 1]) & (lg.stamps_s <= iv[0, 2])
    return [ranges_to_scan(r, sc.angles_rad, np.zeros(3), 0.01, sc.range_max_m) for r in lg.ranges_m[sel]]


def test_icp_covariance_is_honest_on_noise(raw):
    # two scans of one standing robot: the truth is the identity, the error is the noise's alone
    # (people walking are the trimmed outliers)
    nees = []
    for k in range(1, len(raw)):
        res = match_icp(raw[0], raw[k], np.array([0.03, -0.02, np.radians(1.0)]))
        assert res.converged
        e = res.pose
        nees.append(e @ np.linalg.solve(res.cov, e))
        assert np.hypot(e[0], e[1]) < 0.01 and abs(np.degrees(e[2])) < 0.2
    assert len(nees) >= 8
    print(np.round(nees, 2))
    assert 0.4 < np.mean(nees) / 3 < 2.0


def test_icp_same_minimum_from_different_guesses(stop_rec):
    rec, truth, _ = stop_rec
    rig = load_rig(rec / "rig.yaml")
    st = load_stop_scans(rec, rig)
    rel = se2.relative(truth[0], truth[1])
    a = match_icp(st.merged[0], st.merged[1], rel).pose
    b = match_icp(st.merged[0], st.merged[1], rel + [0.08, -0.06, np.radians(4)]).pose
    assert np.hypot(*(a - b)[:2]) < 2e-4 and abs(a[2] - b[2]) < 1e-4


def test_acceptance_rejects_a_shifted_alignment(stop_rec):
    rec, truth, _ = stop_rec
    rig = load_rig(rec / "rig.yaml")
    st = load_stop_scans(rec, rig)
    rel = se2.relative(truth[0], truth[1])
    gc = np.diag([0.1, 0.1, 0.1]) ** 2
    res = match_icp(st.merged[0], st.merged[1], rel)
    assert judge(res, res.cov, rel, gc).accepted
    for off in ([0.03, 0.0, 0.0], [0.0, -0.03, 0.0], [0.0, 0.0, np.radians(1.0)]):
        bad = evaluate(st.merged[0], st.merged[1], res.pose + off)
        v = judge(bad, bad.cov, rel, gc, AcceptParams())
        assert not v.accepted, off


def test_genetic_recovers_a_poor_guess_deterministically(stop_rec):
    rec, truth, _ = stop_rec
    rig = load_rig(rec / "rig.yaml")
    st = load_stop_scans(rec, rig)
    rel = se2.relative(truth[0], truth[1])
    poor = rel + [0.4, -0.3, np.radians(25.0)]
    g1 = match_genetic(st.merged[0], st.merged[1], poor)
    g2 = match_genetic(st.merged[0], st.merged[1], poor)
    np.testing.assert_array_equal(g1.pose, g2.pose)
    assert np.all(np.diff(g1.history) <= 1e-15)  # elitism: the best never gets worse
    fine = match_icp(st.merged[0], st.merged[1], g1.pose).pose
    e = se2.relative(rel, fine)
    assert np.hypot(e[0], e[1]) < 0.005 and abs(np.degrees(e[2])) < 0.1


def test_rosmap_round_trip(tmp_path):
    occ = np.zeros((40, 60), bool)
    occ[5, 10:50] = True
    free = np.zeros_like(occ)
    free[6:30, 10:50] = True
    write_map(tmp_path / "m.yaml", occ, free, 0.05, (-1.0, 2.0, 0.0))
    m = read_map(tmp_path / "m.yaml")
    np.testing.assert_array_equal(m.occupied, occ)
    np.testing.assert_array_equal(m.free, free)
    # row 0 is the top: pixel (39, 0) has its centre half a pixel inside the origin corner
    np.testing.assert_allclose(m.pixel_centres(np.array([39]), np.array([0])), [[-0.975, 2.025]])
