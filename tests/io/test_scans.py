"""Scan CSV files: round trip, one-line errors naming file and line, read speed."""

from __future__ import annotations

import numpy as np
import pytest

from gtrig.errors import FormatError
from gtrig.io.scans import ScanLog, read_scans, write_scans
from gtrig.sim.gtroom import make_scene


def _log(n: int = 50, beams: int = 180, seed: int = 0) -> ScanLog:
    rng = np.random.default_rng(seed)
    stamps = 1.7e9 + np.cumsum(rng.uniform(0.01, 0.02, n))
    # values on the file's 0.1 mm grid round-trip exactly
    r = np.round(rng.uniform(0.1, 30, (n, beams)) * 1e4) / 1e4
    r[rng.random((n, beams)) < 0.05] = np.nan
    return ScanLog(stamps, r)


def test_round_trip(tmp_path) -> None:  # type: ignore[no-untyped-def]
    log = _log()
    write_scans(tmp_path / "s.csv", log)
    back = read_scans(tmp_path / "s.csv", make_scene(0).rig_true.laser_scanners[0])
    np.testing.assert_array_equal(back.stamps_s, log.stamps_s)
    np.testing.assert_array_equal(back.ranges_m, log.ranges_m)  # nan == nan here
    write_scans(tmp_path / "t.csv", back)
    assert (tmp_path / "s.csv").read_bytes() == (tmp_path / "t.csv").read_bytes()
    assert not list(tmp_path.glob(".*.tmp"))  # atomic write leaves no temporary behind


def test_comments_blank_lines_and_empty(tmp_path) -> None:  # type: ignore[no-untyped-def]
    p = tmp_path / "c.csv"
    p.write_text("# a comment\ntimestamp,r_0,r_1\n1.0,2.0,nan\n\n# late comment\n2.0,3.5,1\n")
    log = read_scans(p, beams=2)
    np.testing.assert_array_equal(log.stamps_s, [1.0, 2.0])
    assert np.isnan(log.ranges_m[0, 1]) and log.ranges_m[1, 1] == 1.0
    p.write_text("timestamp,r_0,r_1\n")
    assert len(read_scans(p)) == 0


@pytest.mark.parametrize(
    ("body", "line", "words"),
    [
        ("timestamp,r_0,r_1\n1.0,2.0,3.0\n2.0,2.0\n", 3, "expected 3 values"),
        ("timestamp,r_0,r_1\n1.0,2.0,3.0\n2.0,abc,3.0\n", 3, "not a number"),
        ("timestamp,r_0,r_1\n1.0,2.0,3.0\n# c\n1.0,2.0,3.0\n", 4, "does not increase"),
        ("timestamp,r_0,r_1\n1.0,2.0,3.0\n2.0,2.0,-0.5\n", 3, "negative range r_1"),
        ("timestamp,r_0,r_1\n1.0,inf,3.0\n", 2, "infinite range"),
        ("timestamp,r_0,r_1\nnan,1,3.0\n", 2, "time stamp"),
    ],
)
def test_bad_lines_name_file_and_line(tmp_path, body, line, words) -> None:  # type: ignore[no-untyped-def]
    p = tmp_path / "bad.csv"
    p.write_text(body)
    with pytest.raises(FormatError) as e:
        read_scans(p, beams=2)
    msg = str(e.value)
    assert "\n" not in msg and f"{p}:{line}:" in msg and words in msg


@pytest.mark.parametrize(
    ("body", "words"),
    [
        ("timestamp,r_0,r_1,r_2\n1.0,2.0,3.0,4.0\n", "3 beams in the header, the rig's scanner has 2"),
        ("time,r_0,r_1\n1.0,2.0,3.0\n", "header must be"),
        ("", "empty file"),
    ],
)
def test_bad_files(tmp_path, body, words) -> None:  # type: ignore[no-untyped-def]
    p = tmp_path / "bad.csv"
    p.write_text(body)
    with pytest.raises(FormatError) as e:
        read_scans(p, beams=2)
    assert "\n" not in str(e.value) and str(p) in str(e.value) and words in str(e.value)
    with pytest.raises(FormatError, match="no such file"):
        read_scans(tmp_path / "missing.csv")


def test_reads_a_large_file_quickly(tmp_path) -> None:  # type: ignore[no-untyped-def]
    import time

    log = _log(n=3000)
    write_scans(tmp_path / "big.csv", log)
    t = time.perf_counter()
    back = read_scans(tmp_path / "big.csv", beams=180)
    # about 0.15 s on one idle core for 3000 x 180; generous for loaded CI machines
    assert time.perf_counter() - t < 3.0 and len(back) == 3000
