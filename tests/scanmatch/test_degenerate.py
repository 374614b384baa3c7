"""Matches good along some directions and degenerate along others (a corridor), and the independence
of a pair's match from its place among the pairs."""

from __future__ import annotations

import numpy as np
import pytest

from gtrig.rig.load import load_rig
from gtrig.scanmatch import se2
from gtrig.scanmatch.pairs import guess_cov_for, match_pairs
from gtrig.scanmatch.scan import ranges_to_scan
from gtrig.scanmatch.validate import ErrorModel, load_stop_scans, match_pair

ANGLES = np.radians(np.arange(-180.0, 180.0, 0.5))


def corridor_scan(pose: np.ndarray, rng: np.random.Generator, niche_x: float | None):
    """A 360-degree scan (1 cm noise) from ``pose`` in a 2 m wide corridor along x (walls y = +-1, 8 m
    range), with a 0.4 m wide, 0.2 m deep niche in the y = +1 wall at ``niche_x`` (None: no niche)."""
    x0, y0, th = pose
    a = ANGLES + th
    c, s = np.cos(a), np.sin(a)
    with np.errstate(divide="ignore"):
        r = np.where(s > 0, (1.0 - y0) / s, np.where(s < 0, (-1.0 - y0) / s, np.inf))
    if niche_x is not None:  # the beams hitting the upper wall inside the niche go 0.2 m deeper
        hit_x = x0 + r * c
        inside = (s > 0) & (np.abs(hit_x - niche_x) < 0.2)
        deep = (1.2 - y0) / np.where(s > 0, s, 1.0)
        r = np.where(inside & (np.abs(x0 + deep * c - niche_x) < 0.2), deep, r)
    r = np.where(r > 8.0, np.nan, r) + rng.normal(0.0, 0.01, a.size)
    return ranges_to_scan(r, ANGLES, np.zeros(3), 0.01, 8.0)


@pytest.mark.parametrize("niche", [None, 0.3])
def test_a_corridor_is_reported_wide_along_its_axis(niche):
    rng = np.random.default_rng(7)
    p1, p2 = np.array([0.0, 0.1, 0.0]), np.array([0.6, -0.05, np.radians(2.0)])
    ref, cur = corridor_scan(p1, rng, niche), corridor_scan(p2, rng, niche)
    truth = se2.relative(p1, p2)
    guess = truth + np.array([0.07, -0.02, np.radians(1.5)])  # odometry 7 cm off along the corridor
    gc = guess_cov_for(guess)
    pose, cov, _res, v, _name = match_pair(ref, cur, guess, gc, ErrorModel(), 0.0, genetic=None)
    assert v.accepted and v.degenerate, v.reason
    w, U = np.linalg.eigh(cov[:2, :2])
    # wide along the corridor's axis (x in the first robot frame), tight across it and in heading
    assert abs(U[0, 1]) > 0.99 and np.sqrt(w[1]) > 0.02
    assert np.sqrt(w[0]) < 0.005 and np.degrees(np.sqrt(cov[2, 2])) < 0.2
    e = se2.compose(pose, se2.inverse(truth))  # the covariance's perturbation: x, y in the first frame
    assert abs(e[1]) < 0.01 and abs(np.degrees(e[2])) < 0.2
    # and honest: the error along the axis within 3 standard deviations of the reported covariance
    assert e @ np.linalg.solve(cov, e) < 14.2  # chi-square(3) 0.997


def test_a_pair_matches_alike_wherever_it_stands(stop_rec):
    # poor guesses send the pairs to the genetic matcher: its seed comes from the pair itself
    rec, truth, _ = stop_rec
    st = load_stop_scans(rec, load_rig(rec / "rig.yaml"))
    scans = [st.merged[k] for k in range(5)]
    pairs = np.array([[0, 1], [1, 2], [2, 3], [0, 4]])
    rel = np.array([se2.relative(truth[i], truth[j]) + [0.35, -0.3, np.radians(20.0)] for i, j in pairs])
    a = match_pairs(scans, truth[:5], pairs, rel_guesses=rel)
    assert sum(r.matcher.startswith("genetic") for r in a) >= 2
    order = np.array([3, 1, 0, 2])
    b = match_pairs(scans, truth[:5], pairs[order], rel_guesses=rel[order])
    for k, r in zip(order, b, strict=True):
        np.testing.assert_array_equal(a[k].pose, r.pose)
        np.testing.assert_array_equal(a[k].cov, r.cov)
        assert a[k].verdict == r.verdict
