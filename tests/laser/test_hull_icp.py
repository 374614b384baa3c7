from __future__ import annotations

import numpy as np
import pytest

from gtrig.laser import synth
from gtrig.laser.fuse import beam_dirs_world
from gtrig.laser.hull_icp import BeamPoints, HullModel, IcpSettings, fit_hull, scanner_sensitivity


def _points(room, pose, rng, sigma=None, scanners=None):
    scs = room["scanners"] if scanners is None else scanners
    segs = synth.hull_segments_world(room["hull"], pose)
    P, I, D = [], [], []
    for i, s in enumerate(scs):
        r = synth.scan(s, segs, rng, sigma_m=sigma) if rng is not None else synth.scan(s, segs)
        d = beam_dirs_world(s)
        ok = np.isfinite(r)
        P.append(s.T_world_scanner.matrix()[:2, 3] + r[ok, None] * d[ok])
        I.append(np.full(ok.sum(), i))
        D.append(d[ok])
    S = np.array([s.T_world_scanner.matrix()[:2, 3] for s in scs])
    return (
        np.concatenate(P),
        np.concatenate(I),
        S,
        np.concatenate(D),
        np.array([s.range_sigma_m for s in scs]),
    )


def test_recovers_known_pose_noise_free(room):
    model = HullModel.from_hull(room["hull"])
    for truth in ([0.3, -0.4, 0.7], [-1.0, 1.2, -2.5], [1.5, 0.5, 3.0]):
        truth = np.array(truth)
        P, I, S, D, sig = _points(room, truth, None)
        f = fit_hull(model, P, I, S, D, sig, truth + [0.04, -0.03, np.radians(5)])
        assert not f.degenerate
        assert np.hypot(*(f.xytheta[:2] - truth[:2])) < 1e-3
        assert abs(f.xytheta[2] - truth[2]) < np.radians(0.01)


def test_covariance_consistent_monte_carlo(room):
    model = HullModel.from_hull(room["hull"])
    rng = np.random.default_rng(0)
    truth = np.array([0.2, 0.1, 0.4])
    settings = IcpSettings(sigma_model_m=0.0)
    nees = []
    for _ in range(200):
        P, I, S, D, sig = _points(room, truth, rng)
        f = fit_hull(model, P, I, S, D, sig, truth, settings)
        e = f.xytheta - truth
        nees.append(e @ np.linalg.solve(f.cov_xytheta, e))
    # chi-square with 3 dof: mean 3; the 200-trial mean has a standard deviation of about 0.17
    assert 2.5 < np.mean(nees) < 3.6


def test_one_visible_side_is_flagged(room, scanner_factory):
    model = HullModel.from_hull(room["hull"])
    truth = np.array([0.0, 0.0, 0.0])
    # one scanner straight in front of the hull's long side sees that side only
    s = scanner_factory("front", 0.0, -2.5, np.pi / 2)
    P, I, S, D, sig = _points(room, truth, np.random.default_rng(1), scanners=(s,))
    f = fit_hull(model, P, I, S, D, sig, truth + [0.02, 0.0, 0.0])
    assert f.degenerate and "one side" in f.reason
    assert f.n_sides == 1


def test_scanner_sensitivity_matches_refit(room):
    """The first-order effect of a scanner's pose error on the fitted pose equals a refit."""
    model = HullModel.from_hull(room["hull"])
    truth = np.array([0.3, -0.2, 0.6])
    P, I, S, D, sig = _points(room, truth, None)
    settings = IcpSettings()
    A = scanner_sensitivity(model, BeamPoints.one_frame(P, I, S, D, sig), truth[None], settings)[0]
    assert A.shape == (3, 3 * len(S))
    # every scanner moved by the same translation moves the hull by it
    common = np.tile([0.002, -0.001, 0.0], len(S))
    assert np.allclose(A @ common, [0.002, -0.001, 0.0], atol=1e-5)
    for s, dc in ((0, [0.002, 0.0, 0.0]), (1, [0.0, 0.0, np.radians(0.05)])):
        m = I == s
        Q = P.copy()
        lever = Q[m] - S[s]
        Q[m] += np.asarray(dc[:2]) + dc[2] * np.column_stack([-lever[:, 1], lever[:, 0]])
        f = fit_hull(model, Q, I, S, D, sig, truth, settings)
        delta = np.zeros(3 * len(S))
        delta[3 * s : 3 * s + 3] = dc
        assert np.allclose(f.xytheta - truth, A @ delta, atol=2e-5)


def test_batch_of_frames_fits_each_as_alone(room):
    """Two frames' points in one BeamPoints fit as each frame alone does (to the stopping tolerance), and
    points whose per-point arrays disagree in length are refused."""
    from gtrig.laser.hull_icp import fit_hull_batch

    model = HullModel.from_hull(room["hull"])
    truths = np.array([[0.3, -0.4, 0.7], [-1.0, 1.2, -2.5]])
    frames = [_points(room, t, np.random.default_rng(k)) for k, t in enumerate(truths)]
    S, sig = frames[0][2], frames[0][4]
    starts = truths + [0.03, -0.02, np.radians(3)]
    pts = BeamPoints(np.concatenate([f[0] for f in frames]),
                     np.concatenate([np.full(len(f[0]), k) for k, f in enumerate(frames)]),
                     np.concatenate([f[1] for f in frames]), S, np.concatenate([f[3] for f in frames]), sig)
    batch = fit_hull_batch(model, pts, starts)
    for k, (P, I, _, D, _) in enumerate(frames):
        alone = fit_hull(model, P, I, S, D, sig, starts[k])
        assert batch.n_points[k] == alone.n_points > 20
        assert np.allclose(batch.xytheta[k], alone.xytheta, atol=2e-4)
        assert np.allclose(batch.cov_xytheta[k], alone.cov_xytheta, rtol=0.05)
    with pytest.raises(ValueError, match="BeamPoints"):
        BeamPoints(pts.xy_world, pts.frame_index[:-1], pts.scanner_index, S, pts.dir_world, sig)
