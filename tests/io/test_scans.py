"""Scan CSV files: round trip, one-line errors naming file and line, read speed; the block-wise index that
reads them a few scans at a time (the same values and the same errors)."""

from __future__ import annotations

import numpy as np
import pytest

import gtrig.io.scans as scans
from gtrig.errors import FormatError
from gtrig.io.scans import ScanLog, index_scans, read_scans, write_scans
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
@pytest.mark.parametrize("reader", [read_scans, index_scans])
def test_bad_lines_name_file_and_line(tmp_path, body, line, words, reader) -> None:  # type: ignore[no-untyped-def]
    p = tmp_path / "bad.csv"
    p.write_text(body)
    with pytest.raises(FormatError) as e:
        reader(p, beams=2)
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
@pytest.mark.parametrize("reader", [read_scans, index_scans])
def test_bad_files(tmp_path, body, words, reader) -> None:  # type: ignore[no-untyped-def]
    p = tmp_path / "bad.csv"
    p.write_text(body)
    with pytest.raises(FormatError) as e:
        reader(p, beams=2)
    assert "\n" not in str(e.value) and str(p) in str(e.value) and words in str(e.value)
    with pytest.raises(FormatError, match="no such file"):
        reader(tmp_path / "missing.csv")


def test_reads_a_large_file_quickly(tmp_path) -> None:  # type: ignore[no-untyped-def]
    import time

    log = _log(n=3000)
    write_scans(tmp_path / "big.csv", log)
    t = time.perf_counter()
    back = read_scans(tmp_path / "big.csv", beams=180)
    # about 0.15 s on one idle core for 3000 x 180; generous for loaded CI machines
    assert time.perf_counter() - t < 3.0 and len(back) == 3000


def test_index_reads_the_values_read_scans_reads(tmp_path, monkeypatch) -> None:  # type: ignore[no-untyped-def]
    """Blocks of 7 lines, comments and blank lines between scans, CRLF line ends: every run of scans read
    through the index is bit for bit what the whole file's reading gives."""
    monkeypatch.setattr(scans, "INDEX_BLOCK_LINES", 7)
    log = _log(n=60, beams=5)
    write_scans(tmp_path / "s.csv", log)
    lines = (tmp_path / "s.csv").read_text().splitlines()
    body = lines[:1] + [x for i, x in enumerate(lines[1:]) for x in ((x, "# c", "") if i % 9 == 4 else (x,))]
    (tmp_path / "s.csv").write_bytes(("\r\n".join(["# head"] + body) + "\r\n").encode())
    whole = read_scans(tmp_path / "s.csv", beams=5)
    ix = index_scans(tmp_path / "s.csv", beams=5)
    assert ix.beams == 5 and len(ix) == 60
    assert ix.stamps_s.tobytes() == whole.stamps_s.tobytes()
    for lo, hi in ((0, 60), (0, 1), (13, 29), (59, 60), (30, 30)):
        assert ix.read(lo, hi).tobytes() == whole.ranges_m[lo:hi].tobytes(), (lo, hi)
    part = ix.part(13, 29)
    assert part.read(0, 16).tobytes() == whole.ranges_m[13:29].tobytes()
    assert part.read(15, 16).tobytes() == whole.ranges_m[28:29].tobytes()
    np.testing.assert_array_equal(ix.shifted(0.5).stamps_s, whole.stamps_s - 0.5)


@pytest.mark.parametrize(("values", "refused"), [
    ([1.0, 25.0, 25.0], True),  # median 25 m, beyond twice 10 m
    ([1.0, 1.0, 25.0], False),
    ([19.0, 22.0], True),  # the even case: exactly half beyond, the middle two's mean 20.5 m is beyond
    ([17.0, 22.0], False),  # ... and 19.5 m is not
])
def test_index_refuses_millimetres_as_read_scans_does(tmp_path, monkeypatch, values, refused) -> None:  # type: ignore[no-untyped-def]
    """The unit check (median of every finite range beyond twice the maximum range) decided block by block
    gives what the whole file's median does, also when exactly half the ranges are beyond the limit."""
    from types import SimpleNamespace

    monkeypatch.setattr(scans, "INDEX_BLOCK_LINES", 1)
    p = tmp_path / "u.csv"
    p.write_text("timestamp,r_0\n" + "".join(f"{k + 1}.0,{v}\n" for k, v in enumerate(values)) + "9.0,nan\n")
    sc = SimpleNamespace(beams=1, range_max_m=10.0)
    for reader in (read_scans, index_scans):
        if refused:
            with pytest.raises(FormatError, match="millimetres"):
                reader(p, sc)
        else:
            assert len(reader(p, sc)) == len(values) + 1
