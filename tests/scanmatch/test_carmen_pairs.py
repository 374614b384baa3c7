"""Real data: scan pairs of the CARMEN logs matched from the raw odometry, against the logs' corrected
poses and against what the scans themselves say (their fit, loop closure).

The logs' corrected poses are a few centimetres off scan to scan (docs/scanmatch.md: at them the
same scans fit with a residual spread of 16-17 mm against 9-10 mm at our matches, and our matches
close around triplets within 2-4 mm while differing from the logs' by 20-25 mm): they check our
matches at 5 cm, and the scans' own match near the logs' pose checks them at 2 cm.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from gtrig.scanmatch import se2
from gtrig.scanmatch.icp import evaluate
from gtrig.scanmatch.pairs import candidate_pairs, match_pairs

DATA = Path(__file__).parents[2] / ".." / "shared" / "data" / "carmen"


def _within(a: np.ndarray, b: np.ndarray, m: float, deg: float) -> np.ndarray:
    e = se2.relative(a, b)
    return (np.hypot(e[:, 0], e[:, 1]) < m) & (np.degrees(np.abs(e[:, 2])) < deg)


# (log, scan rows): a stretch with revisits, about 425 pairs each (seconds)
CASES = [("intel-corrected.log.gz", slice(0, 300, 1)), ("freiburg-079-corrected.log.gz", slice(0, 2400, 8))]


@pytest.mark.parametrize(("name", "rows"), CASES)
def test_pairs_from_raw_odometry(name, rows):
    from gtrig.io.carmen import read_carmen
    from gtrig.scanmatch.carmen import log_scans, odometry_at_scans, scans_own_match, triplet_closures

    path = DATA / name
    if not path.exists():
        pytest.fail(f"{path} is missing (the shared real data)")
    log = read_carmen(path)
    idx = np.arange(len(log.laser_stamps_s))[rows]
    scans, odo, cor = log_scans(log, idx), odometry_at_scans(log, idx), log.laser_xytheta[idx]
    pairs = candidate_pairs(cor, 1.0, np.radians(30.0))
    rels = match_pairs(scans, odo, pairs, genetic=None)
    ours, acc = np.array([r.pose for r in rels]), np.array([r.verdict.accepted for r in rels])
    log_rel = se2.relative(cor[pairs[:, 0]], cor[pairs[:, 1]])
    own = scans_own_match(scans, cor, pairs)
    reach = _within(own, np.array([r.guess for r in rels]), 0.3, 10.0)
    # most pairs whose odometry guess is within the local matcher's reach are accepted; the others
    # (metres of odometry drift around a loop) rarely
    assert acc[reach].mean() >= 0.5, acc[reach].mean()
    # every accepted match is the scans' own alignment (2 cm, 0.5 deg), and near the logs' poses at 5 cm
    assert _within(own, ours, 0.02, 0.5)[acc].mean() >= 0.95
    assert _within(log_rel, ours, 0.05, 1.0)[acc].mean() >= 0.65
    # of the pairs whose odometry guess is within 0.3 m and 10 deg of the logs' relative pose, most accepted
    near = _within(log_rel, np.array([r.guess for r in rels]), 0.3, 10.0)
    assert acc[near].mean() >= 0.5, acc[near].mean()
    # the accepted covariances are honest against the logs once the logs' own noise is counted: 2 cm per
    # axis, and in heading what the accepted pairs' heading differences show (ours are ~0.05 deg)
    cov = np.array([r.cov for r in rels])[acc]
    e = np.array([se2.compose(o, se2.inverse(g)) for o, g in zip(ours[acc], log_rel[acc], strict=True)])
    sd_th = 1.4826 * np.median(np.abs(e[:, 2] - np.median(e[:, 2])))
    ref = np.diag([0.02**2, 0.02**2, sd_th**2])
    nees_dof = float(np.mean(np.einsum("ni,nij,nj->n", e, np.linalg.inv(cov + ref), e))) / 3
    assert 0.5 <= nees_dof <= 2.0, nees_dof
    # the scans fit better at our relative poses than at the logs'
    better = [evaluate(scans[a], scans[b], ours[k]).s_m < evaluate(scans[a], scans[b], log_rel[k]).s_m
              for k, (a, b) in enumerate(pairs) if acc[k]]
    assert np.mean(better) >= 0.95
    # our matches close around triplets far better than they agree with the logs': the disagreement is
    # the logs' (relative poses of one set of absolute poses close exactly, whatever their errors)
    cl = triplet_closures(pairs[acc], ours[acc])
    e = se2.relative(log_rel[acc], ours[acc])
    if len(cl) >= 5:
        assert np.median(np.hypot(cl[:, 0], cl[:, 1])) < 0.5 * np.median(np.hypot(e[:, 0], e[:, 1]))
    print(f"{name}: accepted {acc.mean():.2f} ({acc[reach].mean():.2f} within reach, {acc[near].mean():.2f} of the "
          f"odometry within 0.3 m, 10 deg), within 2 cm and 1 deg of the logs' "
          f"{_within(log_rel, ours, 0.02, 1.0)[acc].mean():.2f}, {len(cl)} triplets, NEES/dof {nees_dof:.2f} "
          f"(logs' heading sd {np.degrees(sd_th):.2f} deg)")
