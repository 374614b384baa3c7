"""The CARMEN reader on the real Radish logs in ../shared/data/carmen."""

from __future__ import annotations

import gzip

import numpy as np
import pytest

from gtrig.errors import FormatError
from gtrig.io.carmen import read_carmen


def _wrap(a: np.ndarray) -> np.ndarray:
    return np.angle(np.exp(1j * a))


def _rel(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Pose b in the frame of pose a, (N, 3)."""
    c, s = np.cos(a[:, 2]), np.sin(a[:, 2])
    d = b[:, :2] - a[:, :2]
    return np.column_stack([c * d[:, 0] + s * d[:, 1], -s * d[:, 0] + c * d[:, 1], _wrap(b[:, 2] - a[:, 2])])


@pytest.mark.parametrize(("name", "n_scans", "beams"), [("freiburg-079-corrected.log.gz", 4791, 360),
                                                        ("intel-corrected.log.gz", 910, 180)])
def test_real_logs(shared_dir, name, n_scans, beams):
    log = read_carmen(shared_dir / "data" / "carmen" / name)
    assert log.laser_ranges.shape == (n_scans, beams)
    assert log.counts["flaser"] == n_scans
    # one re-anchoring after (nearly) every scan
    assert log.counts["reanchor"] >= 0.9 * n_scans
    t, odo = log.rebuilt_odometry()
    assert np.all(np.diff(t) > 0)
    # intel's stamps are out of order for a quarter of its records: most are still emitted
    assert len(t) >= 0.75 * log.counts["odom"]
    # rebuilt odometry is continuous: no jump of the corrections left in it (intel's largest steps are
    # over stretches of out-of-order stamps, under 1 m)
    step = np.hypot(*np.diff(odo[:, :2], axis=0).T)
    assert step.max() < 1.0
    # between consecutive scans, odometry and the corrected poses agree to what scan matching corrects
    # (freiburg: 2.7 cm per 10 cm step in the median; intel 3 deg)
    io = np.clip(np.searchsorted(t, log.laser_stamps_s), 0, len(t) - 1)
    close = np.abs(t[io] - log.laser_stamps_s) < 0.02
    a, b = np.flatnonzero(close)[:-1], np.flatnonzero(close)[1:]
    d_odo = _rel(odo[io[a]], odo[io[b]])
    d_gt = _rel(log.laser_xytheta[a], log.laser_xytheta[b])
    err = np.abs(d_odo - d_gt)
    travel = np.hypot(d_gt[:, 0], d_gt[:, 1])
    assert np.median(np.hypot(err[:, 0], err[:, 1])) < 0.5 * np.median(travel)
    assert np.median(err[:, 2]) < np.radians(4)
    # the rebuilt odometry drifts away from the corrected poses (it is not the re-anchored chain)
    drift = np.hypot(*(odo[io[close], :2] - log.laser_xytheta[close, :2] - (odo[io[0], :2]
                                                                              - log.laser_xytheta[0, :2])).T)
    assert drift.max() > 0.5


def test_malformed_lines_named(tmp_path):
    p = tmp_path / "bad.log"
    p.write_text("ODOM 0 0 0 0 0 0 1.0 host 1.0\nFLASER 3 1 2 0 0 0 0 0 0 2.0 host 2.0\n")
    with pytest.raises(FormatError, match=r"bad.log:2: FLASER with 3 beams"):
        read_carmen(p)
    p.write_text("ODOM 0 0 x 0 0 0 1.0 host 1.0\n")
    with pytest.raises(FormatError, match=r"bad.log:1: not a number"):
        read_carmen(p)
    g = tmp_path / "bad.log.gz"
    g.write_bytes(b"not gzip")
    with pytest.raises(FormatError, match="gzip"):
        read_carmen(g)
    g.write_bytes(gzip.compress(b"PARAM a b\n"))
    with pytest.raises(FormatError, match="no ODOM or FLASER"):
        read_carmen(g)
