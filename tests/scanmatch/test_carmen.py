"""Real data: scan pairs of the CARMEN logs from raw odometry against the logs' corrected poses."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from gtrig.scanmatch import se2
from gtrig.scanmatch.pairs import candidate_pairs, match_pairs
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
    idx = np.arange(0, min(len(log.laser_stamps_s), 1500), 5)
    scans = [ranges_to_scan(np.where(log.laser_ranges[k] < 50.0, log.laser_ranges[k], np.nan), ang, np.zeros(3),
                            0.01, 50.0, float(log.laser_stamps_s[k])) for k in idx]
    odo, cor = log.laser_odom_xytheta[idx], log.laser_xytheta[idx]
    pairs = candidate_pairs(odo, 1.0, np.radians(30.0))
    pairs = pairs[np.linspace(0, len(pairs) - 1, min(120, len(pairs))).astype(int)]
    rels = match_pairs(scans, odo, pairs, surface_bias_m=0.0, genetic=None)
    ref = se2.relative(cor[pairs[:, 0]], cor[pairs[:, 1]])
    e = np.array([se2.relative(ref[k], r.pose) for k, r in enumerate(rels)])
    acc = np.array([r.verdict.accepted for r in rels])
    agree = (np.hypot(e[:, 0], e[:, 1]) < 0.02) & (np.degrees(np.abs(e[:, 2])) < 1.0)
    assert acc.mean() > 0.3
    assert agree[acc].mean() >= 0.95
