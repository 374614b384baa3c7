"""Real data: the two CARMEN logs (raw odometry against the scan-matching-corrected scan poses). Lags added
to the odometry stamps are recovered within one odometry period, with the sign convention of gtrig sync."""

from pathlib import Path

import numpy as np
import pytest

from gtrig.io.carmen import read_carmen
from gtrig.sync.offset import estimate_offset

CARMEN = Path(__file__).parents[2] / ".." / "shared" / "data" / "carmen"


@pytest.mark.parametrize("name", ["intel", "freiburg-079"])
def test_added_lags_recovered(name: str) -> None:
    path = CARMEN / f"{name}-corrected.log.gz"
    if not path.exists():
        pytest.skip(f"{path} not present")
    log = read_carmen(path)
    st, xyt = log.rebuilt_odometry()
    period = float(np.median(np.diff(st)))
    ls, ly = log.laser_stamps_s, log.laser_xytheta[:, 2]
    ok = np.r_[True, np.diff(ls) > 0]
    base = estimate_offset(st, xyt[:, 2], ls[ok], ly[ok], name)
    assert base.verdict == "ok" and base.ci95_s[0] <= base.offset_s <= base.ci95_s[1]
    for lag in (0.1, 0.5, 1.5):
        est = estimate_offset(st + lag, xyt[:, 2], ls[ok], ly[ok], name)
        assert est.verdict == "ok"
        # odometry stamped `lag` later: the scans' offset to it (scan stamp - odometry stamp) drops by `lag`
        assert abs((base.offset_s - est.offset_s) - lag) < period
