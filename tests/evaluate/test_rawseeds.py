"""The RAWSEEDS ATE and RPE equal a line-by-line re-implementation of the toolkit's get_ATE.m / get_RPE.m
(RAWSEEDS Metrics Computation Toolkit v1.1, doge-of-the-day/rawseeds_evaluation) on the published files."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from scipy.optimize import least_squares

from gtrig.evaluate import metrics_rawseeds as mr
from gtrig.io.formats import read_trajectory
from gtrig.io.relations import read_relations

DATA = Path(__file__).resolve().parents[2] / ".." / "shared" / "data" / "rawseeds"
B25 = DATA / "Bicocca_2009-02-25b"
pytestmark = pytest.mark.skipif(not B25.is_dir(), reason="RAWSEEDS data missing")
SOLUTIONS = ("SOLUTION_CI-GRAPH_Stereo", "SOLUTION_GraphSLAM_Laser", "SOLUTION_H-SLAM_Trinocular")


# --- the toolkit, as its MATLAB text reads --------------------------------------------------------------

def normalize_ang(a):
    return a + (2 * np.pi) * np.floor((np.pi - a) / (2 * np.pi))


def tcomp(tab, tbc):  # tab (3,), tbc (3, n)
    s, c = np.sin(tab[2]), np.cos(tab[2])
    return np.vstack([tab[0] + c * tbc[0] - s * tbc[1], tab[1] + s * tbc[0] + c * tbc[1],
                      normalize_ang(tab[2] + tbc[2])])


def trel(t1, t2):  # (3, n) each
    s, c = np.sin(t1[2]), np.cos(t1[2])
    dx, dy = t2[0] - t1[0], t2[1] - t1[1]
    return np.vstack([c * dx + s * dy, -s * dx + c * dy, normalize_ang(t2[2] - t1[2])])


def alignment_error(vloc, p1, p2):  # p (2, n)
    s, c = np.sin(vloc[2]), np.cos(vloc[2])
    p2a = np.vstack([vloc[0] + c * p2[0] - s * p2[1], vloc[1] + s * p2[0] + c * p2[1]])
    return (p1 - p2a).ravel(order="F")


def interp1(t, Y, tq):
    return np.column_stack([np.interp(tq, t, Y[:, k]) for k in range(Y.shape[1])])


def get_ATE(X, GT):
    tini, tend = X[0, 0], X[-1, 0]
    good = (GT[:, 0] >= tini) & (GT[:, 0] <= tend)
    GT = GT[good]
    X = X.copy()
    X[:, 3] = np.unwrap(X[:, 3])
    X_e = interp1(X[:, 0], X[:, 1:4], GT[:, 0])
    GT_e = GT[:, 1:]
    loc_f = least_squares(alignment_error, np.zeros(3), method="lm", xtol=1e-15, ftol=1e-15, gtol=1e-15,
                          args=(GT_e[:, :2].T, X_e[:, :2].T)).x
    X_e = tcomp(loc_f, X_e.T).T
    n = GT_e.shape[1]
    errors = X_e[:, :n] - GT_e[:, :n]
    errors[:, 2] = normalize_ang(errors[:, 2])
    d = np.sqrt(np.sum(errors[:, :2].T ** 2, axis=0))
    md, sd = np.mean(d), np.std(d, ddof=1)
    return np.array([md, sd, md - 3 * sd, md + 3 * sd]), errors


def get_RPE(X, GT_rel):
    tini, tend = X[0, 0], X[-1, 0]
    t_i, t_j, xGT_ij = GT_rel[:, 0], GT_rel[:, 1], GT_rel[:, 2:5]
    good = (t_i >= tini) & (t_i <= tend) & (t_j >= tini) & (t_j <= tend)
    t_i, t_j, xGT_ij = t_i[good], t_j[good], xGT_ij[good]
    X = X.copy()
    X[:, 3] = np.unwrap(X[:, 3])
    x_i = interp1(X[:, 0], X[:, 1:4], t_i)
    x_j = interp1(X[:, 0], X[:, 1:4], t_j)
    x_ij = trel(x_i.T, x_j.T).T
    e_ij = trel(xGT_ij.T, x_ij.T).T
    return np.sqrt(np.mean(np.sum(e_ij[:, :2] ** 2, axis=1))), np.sqrt(np.mean(e_ij[:, 2] ** 2)) * 180 / np.pi


# --- gtrig against it ------------------------------------------------------------------------------------

def _load(p: Path) -> np.ndarray:
    return np.loadtxt(p, delimiter=",")[:, :4]


CASES = [(s, g) for g in ("GROUNDTRUTH", "GT-extended") for s in SOLUTIONS] + [
    ("Bicocca_2009-02-25b-GT-extended", "GROUNDTRUTH")]


@pytest.mark.parametrize("solution, gt_name", CASES)
def test_ate_rpe_equal_toolkit(solution: str, gt_name: str) -> None:
    X = _load(B25 / f"{solution}.csv")
    GT = _load(B25 / f"Bicocca_2009-02-25b-{gt_name}.csv")
    rel = np.loadtxt(B25 / "Bicocca_2009-02-25b.relations")[:, [0, 1, 2, 3, 7]]
    ref_ate, ref_err = get_ATE(X, GT)
    ours = mr.ate(GT[:, 0], GT[:, 1:4], X[:, 0], X[:, 1:4])
    assert np.allclose(ours.ate, ref_ate, atol=1e-6, rtol=0), (ours.ate, ref_ate)
    assert np.allclose(ours.errors, ref_err, atol=1e-6)
    t_rpe, r_rpe = get_RPE(X, rel)
    r = mr.rpe(X[:, 0], X[:, 1:4], rel)
    assert abs(r.t_rpe_m - t_rpe) < 1e-6 and abs(r.r_rpe_deg - r_rpe) < 1e-6


def test_readers_give_the_same_numbers() -> None:
    """gtrig's readers (format from the extension) hand the metrics the same arrays as loadtxt."""
    tr = read_trajectory(B25 / "Bicocca_2009-02-25b-GROUNDTRUTH.csv")
    a = np.loadtxt(B25 / "Bicocca_2009-02-25b-GROUNDTRUTH.csv", delimiter=",")
    assert tr.cov_kind == "xyyaw" and tr.cov is not None
    assert np.allclose(tr.xytheta()[:, :2], a[:, 1:3]) and np.allclose(tr.cov[:, 0, 0], a[:, 4])
    assert np.allclose(mr.normalize_angle(tr.xytheta()[:, 2] - a[:, 3]), 0, atol=1e-12)
    rel = read_relations(B25 / "Bicocca_2009-02-25b.relations")
    assert rel.shape[1] == 5 and np.allclose(rel[:, 4], np.loadtxt(B25 / "Bicocca_2009-02-25b.relations")[:, 7])
