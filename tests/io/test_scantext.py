"""The compiled scan CSV writer (gtrig.io._scantext): Python's ``%`` characters exactly, ties included."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from gtrig.io._scantext import scan_body
from gtrig.io.scans import ScanLog, read_scans, write_scans


def _ranges(n: int, b: int) -> np.ndarray:
    rng = np.random.default_rng(1)
    r = rng.uniform(0, 30, (n, b)).astype(np.float32).astype(float)  # as a LaserScan holds them
    r[::7, 3] = np.nan
    r[::11, 5] = np.inf
    r[::13, 6] = -np.inf
    r[::3, 10] = rng.integers(0, 1000, len(r[::3])) / 32.0  # exact ties at 4 decimals: half to even
    r[::5, 11] = -rng.integers(0, 1000, len(r[::5])) / 64.0
    r[:8, 12] = [-0.0, -0.00001, 5e-324, 123456789.123456, 0.99995, 9.99995, 0.5, 2.5]
    return r


@pytest.mark.parametrize("decimals", [0, 1, 2, 3, 4])
def test_the_characters_of_python_percent_formatting(decimals: int) -> None:
    r = _ranges(300, 20)
    st = 1.7e9 + np.arange(len(r)) / 75.0
    want = "".join(f"{t:.9f}" + "".join(f",{v:.{decimals}f}" for v in row) + "\n" for t, row in zip(st, r, strict=True))
    got = scan_body(st, r, decimals)
    assert got is not None and got.decode() == want


def test_other_decimals_and_huge_ranges_take_the_numpy_path(tmp_path: Path) -> None:
    st = np.array([1.0, 2.0])
    r = np.array([[1.234567, 2.0], [1e15, 3.0]])
    assert scan_body(st, r, 5) is None and scan_body(st, r, 4) is None
    write_scans(tmp_path / "a.csv", ScanLog(st, r), range_decimals=5)
    lines = (tmp_path / "a.csv").read_text().splitlines()
    assert lines[1:] == [f"{t:.9f}," + ",".join(f"{v:.5f}" for v in row) for t, row in zip(st, r, strict=True)]


def test_written_scans_read_back(tmp_path: Path) -> None:
    r = np.abs(_ranges(50, 181))
    r[~np.isfinite(r)] = np.nan
    log = ScanLog(1.7e9 + np.arange(50) / 75.0, r)
    write_scans(tmp_path / "s.csv", log)
    back = read_scans(tmp_path / "s.csv", beams=181)
    assert back.stamps_s.tolist() == [float(f"{t:.9f}") for t in log.stamps_s]
    assert np.allclose(back.ranges_m, r, atol=5.1e-5, equal_nan=True)
