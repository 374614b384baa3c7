"""Pairs of a moving robot's scans: de-skewed with the guessed motion, matched, judged, against truth."""

from __future__ import annotations

import numpy as np

from gtrig.scanmatch import se2
from gtrig.scanmatch.pairs import Guess, candidate_pairs, match_pairs, sequence_scans
from gtrig.scanmatch.validate import scanner_pose_xyth
from gtrig.sim.config import SimConfig
from gtrig.sim.gtroom import continuous_path, make_scene
from gtrig.sim.lasers import simulate_onboard_scans
from gtrig.sim.motion import RobotMotion


def _run(seed: int = 7):
    scene = make_scene(seed)
    st, xy = continuous_path(duration_s=5.0)
    motion = RobotMotion(st + 1000.0, xy, scene.floor)
    cfg = SimConfig(seed=seed, laser={"people": 0})
    logs, _ = simulate_onboard_scans(scene, motion, np.array([[1000.2, 1004.8]]), cfg, seed=seed)
    return scene, motion, logs


def test_deskewed_pairs_match_truth():
    scene, motion, logs = _run()
    sc = scene.rig_nominal.robot.onboard_scanners
    guess = Guess(motion.stamps_s, motion.xytheta)
    mounts = {s.name: scanner_pose_xyth(s) for s in sc}
    scans = sequence_scans(sc, logs, guess, mounts, 0.01, every=4)
    stamps = np.array([s.stamp_s for s in scans])
    true = motion.planar(stamps)
    pairs = candidate_pairs(true, 1.0, np.radians(30.0), min_index_gap=1)
    pairs = pairs[:: max(1, len(pairs) // 40)]
    rels = match_pairs(scans, true, pairs, genetic=None)
    ref = se2.relative(true[pairs[:, 0]], true[pairs[:, 1]])
    e = np.array([se2.relative(ref[k], r.pose) for k, r in enumerate(rels)])
    acc = np.array([r.verdict.accepted for r in rels])
    assert acc.mean() > 0.9
    assert np.max(np.hypot(e[acc, 0], e[acc, 1])) < 0.01
    assert np.degrees(np.max(np.abs(e[acc, 2]))) < 0.2


def test_candidate_pairs_respect_distance_and_angle():
    rng = np.random.default_rng(0)
    p = np.column_stack([rng.uniform(0, 5, 200), rng.uniform(0, 5, 200), rng.uniform(-np.pi, np.pi, 200)])
    pr = candidate_pairs(p, 1.0, np.radians(30.0))
    d = np.hypot(*(p[pr[:, 0], :2] - p[pr[:, 1], :2]).T)
    dth = np.abs(se2.wrap(p[pr[:, 0], 2] - p[pr[:, 1], 2]))
    assert np.all(d <= 1.0) and np.all(dth <= np.radians(30.0)) and np.all(pr[:, 0] < pr[:, 1])
    # brute force: the same set
    i, j = np.triu_indices(len(p), 1)
    ok = (np.hypot(*(p[i, :2] - p[j, :2]).T) <= 1.0) & (np.abs(se2.wrap(p[i, 2] - p[j, 2])) <= np.radians(30.0))
    assert len(pr) == int(ok.sum())
