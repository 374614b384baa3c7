"""Real data: scan pairs of the CARMEN logs from raw odometry against the logs' corrected poses."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from gtrig.scanmatch import se2
from gtrig.scanmatch.icp import evaluate
from gtrig.scanmatch.pairs import Guess, candidate_pairs, match_pairs
from gtrig.scanmatch.scan import ranges_to_scan

DATA = Path(__file__).parents[2] / ".." / "shared" / "data" / "carmen"


@pytest.mark.parametrize("name", ["intel-corrected.log.gz", "freiburg-079-corrected.log.gz"])
def test_pairs_agree_with_corrected_poses(name):
    from gtrig.io.carmen import read_carmen

    path = DATA / name
    if not path.exists():
        pytest.skip(f"{path} not present")
    log = read_carmen(path)
    n = log.laser_ranges.shape[1]
    ang = -np.pi / 2 + np.arange(n) * np.pi / n  # 180 one-degree beams from the right
    idx = np.arange(0, min(len(log.laser_stamps_s), 1200), 1 if n <= 180 else 4)
    scans = [ranges_to_scan(np.where(log.laser_ranges[k] < 50.0, log.laser_ranges[k], np.nan), ang, np.zeros(3),
                            0.01, 50.0, float(log.laser_stamps_s[k])) for k in idx]
    t, p = log.rebuilt_odometry()  # raw ODOM (the FLASER odometry fields hold corrected poses here)
    odo, cor = Guess(t, p).at(log.laser_stamps_s[idx]), log.laser_xytheta[idx]
    # pairs within 1 m and 30 deg (by the corrected poses: raw odometry drifts metres over a loop),
    # each matched from the raw odometry's relative pose
    pairs = candidate_pairs(cor, 1.0, np.radians(30.0))
    pairs = pairs[np.linspace(0, len(pairs) - 1, min(120, len(pairs))).astype(int)]
    rels = match_pairs(scans, odo, pairs, surface_bias_m=0.0, genetic=None)
    ref = se2.relative(cor[pairs[:, 0]], cor[pairs[:, 1]])
    e = np.array([se2.relative(ref[k], r.pose) for k, r in enumerate(rels)])
    acc = np.array([r.verdict.accepted for r in rels])
    dxy, dth = np.hypot(e[:, 0], e[:, 1]), np.degrees(np.abs(e[:, 2]))
    print(name, acc.mean(), np.mean(((dxy < 0.02) & (dth < 1.0))[acc]), np.mean(((dxy < 0.05) & (dth < 1.0))[acc]))
    assert acc.mean() > 0.2
    # the logs' corrected poses are themselves off by centimetres (their scans fit worse there than at
    # our matches, below): agreement is checked at 5 cm and 1 deg, the 2 cm share is in docs/scanmatch.md
    assert np.mean(((dxy < 0.05) & (dth < 1.0))[acc]) >= 0.85
    better = [evaluate(scans[a], scans[b], rels[k].pose).s_m < evaluate(scans[a], scans[b], ref[k]).s_m
              for k, (a, b) in enumerate(pairs) if acc[k]]
    assert np.mean(better) >= 0.7
