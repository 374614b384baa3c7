"""Bulk paths of the scan import: the scan CSV text built for the whole array equals Python's %
formatting character for character, and LaserScan messages decoded in bulk equal rosbags' decoding."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from gtrig.io.rosbag._bag import header, serialize, typestore
from gtrig.io.rosbag.scan_decode import GEOMETRY, decode_scans
from gtrig.io.scans import ScanLog, fixed_decimal_text, write_scans


@pytest.mark.parametrize("decimals", [0, 1, 4, 6, 9])
def test_fixed_decimal_text_is_percent_formatting(decimals: int) -> None:
    rng = np.random.default_rng(decimals)
    a = np.concatenate([
        rng.uniform(-50, 50, 20000), rng.uniform(-1e6, 1e6, 5000), 1.7e9 + rng.uniform(0, 1e3, 5000),
        np.round(rng.uniform(0, 30, 5000) * 1e4) / 1e4 + 0.5e-4,  # ties of the 4th decimal
        [0.0, -0.0, np.nan, np.inf, -np.inf, 5e-5, 1.5e-4, -1e-5, 999999.99995, 1e16, -1e17, 0.5, 1.5, 2.5, -0.5,
         1e14 + 0.5, 10.0, 100.0, 1000.0, -1000.0, 10000.0, -10000.0, 12345678.0, -0.001, 100000001.5]])
    t = fixed_decimal_text(a[None, :], decimals)[0]
    got = [bytes(row).decode().strip() for row in t]
    want = [f"%.{decimals}f" % v for v in a]
    assert got == want
    small = rng.uniform(-2, 2, 1000)  # int32 arithmetic throughout
    assert [bytes(r).decode().strip() for r in fixed_decimal_text(small[None, :], decimals)[0]] == \
        [f"%.{decimals}f" % v for v in small]


def test_write_scans_text_unchanged(tmp_path: Path) -> None:
    rng = np.random.default_rng(2)
    st = 1.7e9 + np.cumsum(rng.uniform(0.01, 0.02, 300))
    r = np.round(rng.uniform(0.1, 30, (300, 181)) * 1e4) / 1e4
    r[rng.random(r.shape) < 0.05] = np.nan
    r[0, :3] = [29.99995, 0.0, 1e-9]
    write_scans(tmp_path / "s.csv", ScanLog(st, r))
    fmt = "%.9f" + ",%.4f" * 181
    want = "timestamp," + ",".join(f"r_{i}" for i in range(181)) + "\n" + \
        "".join(fmt % tuple(row) + "\n" for row in np.column_stack([st, r]).tolist())
    assert (tmp_path / "s.csv").read_text() == want


@pytest.mark.parametrize("ver", [1, 2])
def test_bulk_decode_equals_rosbags(ver: int) -> None:
    ts = typestore(ver)
    T = ts.types
    rng = np.random.default_rng(ver)
    msgs = []
    # two sizes, frame ids of two lengths, one message of another layout but the same byte count
    for i in range(40):
        n = 181 if i % 7 else 90
        fid = "laser0" if i != 13 else "laser0abcd"
        n = 180 if i == 13 else n  # 4 more bytes of frame id, one beam fewer: same size as its neighbours
        msgs.append(T["sensor_msgs/msg/LaserScan"](
            header=header(ts, ver, 1.7e9 + i * 0.0133 + 1e-9 * i, fid, i), angle_min=float(rng.uniform(-2, 0)),
            angle_max=1.0, angle_increment=0.0174, time_increment=1e-5, scan_time=0.0133, range_min=0.05,
            range_max=30.0, ranges=rng.uniform(0, 40, n).astype(np.float32),
            intensities=rng.uniform(0, 1, 3 if i % 2 else 0).astype(np.float32)))
    raws = [serialize(ts, ver, m) for m in msgs]

    def de(raw: bytes):  # type: ignore[no-untyped-def]
        return ts.deserialize_ros1(raw, "sensor_msgs/msg/LaserScan") if ver == 1 else \
            ts.deserialize_cdr(raw, "sensor_msgs/msg/LaserScan")

    b = decode_scans(raws, ver == 2, de)
    for i, m in enumerate(msgs):
        assert b.stamps_s[i] == m.header.stamp.sec + m.header.stamp.nanosec * 1e-9
        assert b.beams[i] == len(m.ranges)
        np.testing.assert_array_equal(b.ranges[i, :len(m.ranges)], m.ranges)
        np.testing.assert_array_equal(b.geometry[i], np.array([getattr(m, g) for g in GEOMETRY], np.float32))
