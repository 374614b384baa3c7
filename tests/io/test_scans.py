"""Scan CSV files: round trip, one-line errors naming file and line, read speed; the block-wise index that
reads them a few scans at a time (the same values and the same errors)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import gtrig.io.scans as scans
from gtrig.errors import FormatError
from gtrig.io.scans import ScanLog, index_scans, read_scans, write_scans
from gtrig.sim.gtroom import make_scene


def _cached_index(path, *args, **kwargs):  # type: ignore[no-untyped-def]
    """index_scans keeping the parsed ranges in a cache folder beside the file."""
    return index_scans(path, *args, cache=Path(path).parent / "cache", **kwargs)


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
@pytest.mark.parametrize("reader", [read_scans, index_scans, _cached_index])
def test_bad_lines_name_file_and_line(tmp_path, body, line, words, reader) -> None:  # type: ignore[no-untyped-def]
    p = tmp_path / "bad.csv"
    p.write_text(body)
    with pytest.raises(FormatError) as e:
        reader(p, beams=2)
    msg = str(e.value)
    assert "\n" not in msg and f"{p}:{line}:" in msg and words in msg
    assert not (tmp_path / "cache").exists() or not list((tmp_path / "cache").iterdir())  # nothing kept


@pytest.mark.parametrize(
    ("body", "words"),
    [
        ("timestamp,r_0,r_1,r_2\n1.0,2.0,3.0,4.0\n", "3 beams in the header, the rig's scanner has 2"),
        ("time,r_0,r_1\n1.0,2.0,3.0\n", "header must be"),
        ("", "empty file"),
    ],
)
@pytest.mark.parametrize("reader", [read_scans, index_scans, _cached_index])
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
    for reader in (read_scans, index_scans, _cached_index):
        if refused:
            with pytest.raises(FormatError, match="millimetres"):
                reader(p, sc)
        else:
            assert len(reader(p, sc)) == len(values) + 1


def _every_digit(log: ScanLog) -> list[str]:
    """The header and rows of a scan CSV with every digit of each number (Python's repr)."""
    return ["timestamp," + ",".join(f"r_{i}" for i in range(log.beams))] + [
        ",".join(repr(float(v)) for v in (t, *rr)) for t, rr in zip(log.stamps_s, log.ranges_m, strict=True)]


def _same_values(ix, whole: ScanLog) -> None:  # type: ignore[no-untyped-def]
    n = len(whole)
    assert ix.stamps_s.tobytes() == whole.stamps_s.tobytes() and len(ix) == n
    for lo, hi in ((0, n), (0, 1), (n // 3, n // 2), (n - 1, n), (5, 5)):
        assert ix.read(lo, hi).tobytes() == whole.ranges_m[lo:hi].tobytes(), (lo, hi)
    assert ix.part(n // 3, n // 2).read(1, 3).tobytes() == whole.ranges_m[n // 3 + 1:n // 3 + 3].tobytes()


def test_cached_ranges_are_the_texts_bit_for_bit_and_parsed_once(tmp_path, monkeypatch) -> None:  # type: ignore[no-untyped-def]
    """Blocks of 7 lines, comments, CRLF, numbers written with every digit (not the 0.1 mm grid): the binary
    copy holds what the text parses to, bit for bit; a second indexing and the reads parse no text at all."""
    monkeypatch.setattr(scans, "INDEX_BLOCK_LINES", 7)
    rng = np.random.default_rng(3)
    r = rng.uniform(0.1, 30, (40, 5))
    r[rng.random(r.shape) < 0.1] = np.nan
    lines = _every_digit(ScanLog(1.7e9 + 0.013 * np.arange(40), r))
    text = "# head\r\n" + "".join(x + ("\r\n# c\r\n\r\n" if k % 9 == 4 else "\r\n") for k, x in enumerate(lines))
    (tmp_path / "s.csv").write_bytes(text.encode())
    whole = read_scans(tmp_path / "s.csv", beams=5)
    ix = index_scans(tmp_path / "s.csv", beams=5, cache=tmp_path / "cache")
    assert ix.ranges_file is not None and ix.ranges_file.stat().st_size == 40 * 5 * 8
    _same_values(ix, whole)

    def no_parsing(*a, **k):  # type: ignore[no-untyped-def]
        raise AssertionError("the text was parsed again")

    monkeypatch.setattr(scans, "parse_numbers", no_parsing)
    again = index_scans(tmp_path / "s.csv", beams=5, cache=tmp_path / "cache")
    _same_values(again, whole)
    assert again.line_no.tobytes() == ix.line_no.tobytes() and again.starts.tobytes() == ix.starts.tobytes()
    assert again.end == ix.end == len(text.encode())
    assert not list((tmp_path / "cache").glob(".*.tmp"))


def test_cached_ranges_of_the_carmen_logs(tmp_path, shared_dir) -> None:  # type: ignore[no-untyped-def]
    """The real Radish logs' scans (../shared/data/carmen) as scan CSVs, written as write_scans does (the
    text GTlaser reads) and with every digit: the cached ranges are read_scans' bit for bit."""
    from gtrig.io.carmen import read_carmen

    for name in ("intel-corrected.log.gz", "freiburg-079-corrected.log.gz"):
        lg = read_carmen(shared_dir / "data" / "carmen" / name)
        n = min(len(lg.laser_stamps_s), 1500)
        # intel's stamps do not always increase: the scans are kept, restamped
        log = ScanLog(1000.0 + 0.1 * np.arange(n), lg.laser_ranges[:n])
        write_scans(tmp_path / "w.csv", log)
        (tmp_path / "r.csv").write_text("\n".join(_every_digit(log)) + "\n")
        for f in ("w.csv", "r.csv"):
            whole = read_scans(tmp_path / f, beams=log.beams)
            ix = index_scans(tmp_path / f, beams=log.beams, cache=tmp_path / "cache")
            assert ix.ranges_file is not None
            _same_values(ix, whole)
        assert np.array_equal(read_scans(tmp_path / "r.csv").ranges_m, log.ranges_m, equal_nan=True)


def test_a_changed_log_is_indexed_again_never_read_stale(tmp_path) -> None:  # type: ignore[no-untyped-def]
    """A log changed in place (same size, its modification time put back) gets new cache files: the
    values read are the new text's; cache files cut short are made again."""
    import os

    p = tmp_path / "s.csv"
    write_scans(p, _log(n=30, beams=4))
    st = p.stat()
    first = index_scans(p, beams=4, cache=tmp_path / "cache")
    b = p.read_bytes()
    i = b.index(b".", b.index(b"\n", b.index(b"\n") + 1) + 1 + 21)  # a range's decimal point, line 3
    p.write_bytes(b[:i + 1] + (b"1" if b[i + 1:i + 2] != b"1" else b"2") + b[i + 2:])
    os.utime(p, ns=(st.st_atime_ns, st.st_mtime_ns))
    second = index_scans(p, beams=4, cache=tmp_path / "cache")
    assert second.ranges_file != first.ranges_file
    _same_values(second, read_scans(p, beams=4))
    assert first.read(0, 30).tobytes() != second.read(0, 30).tobytes()
    with open(second.ranges_file, "r+b") as f:  # type: ignore[arg-type]
        f.truncate(100)
    third = index_scans(p, beams=4, cache=tmp_path / "cache")
    assert third.ranges_file == second.ranges_file and third.ranges_file.stat().st_size == 30 * 4 * 8  # type: ignore[union-attr]
    _same_values(third, read_scans(p, beams=4))
    rows_file = third.ranges_file.with_name(third.ranges_file.name.replace(".ranges.f8", ".rows.npz"))  # type: ignore[union-attr]
    for junk in (b"", b"not a zip", rows_file.read_bytes()[:50]):  # a rows file empty, foreign or cut short
        rows_file.write_bytes(junk)
        _same_values(index_scans(p, beams=4, cache=tmp_path / "cache"), read_scans(p, beams=4))
        assert len(rows_file.read_bytes()) > 50  # made again
    # the key holds the beams and the maximum range asked for: another check, other files
    assert index_scans(p, cache=tmp_path / "cache").ranges_file != second.ranges_file


def test_an_unwritable_cache_folder_reads_the_text(tmp_path) -> None:  # type: ignore[no-untyped-def]
    """A cache folder that cannot be made (a read-only disk; here a file in its way) is no error: the
    ranges are parsed from the text; and a reader that cannot open the ranges file parses the text."""
    p = tmp_path / "s.csv"
    write_scans(p, _log(n=20, beams=3))
    (tmp_path / "ro").write_text("a file, not a folder")
    ix = index_scans(p, beams=3, cache=tmp_path / "ro" / "cache")
    assert ix.ranges_file is None
    _same_values(ix, read_scans(p, beams=3))
    cached = index_scans(p, beams=3, cache=tmp_path / "cache")
    cached.ranges_file.unlink()  # type: ignore[union-attr]
    _same_values(cached, read_scans(p, beams=3))


def _index_in_process(args: tuple[str, str]) -> bytes:
    ix = index_scans(args[0], beams=180, cache=args[1])
    return ix.read(0, len(ix)).tobytes() + ix.stamps_s.tobytes()


def test_two_processes_building_one_cache_at_once(tmp_path) -> None:  # type: ignore[no-untyped-def]
    """Two processes indexing one log into one folder at the same time: both get its values, and the
    folder ends with one whole pair of files, no temporaries."""
    from concurrent.futures import ProcessPoolExecutor

    p = tmp_path / "s.csv"
    log = _log(n=3000)
    write_scans(p, log)
    with ProcessPoolExecutor(2) as ex:
        got = list(ex.map(_index_in_process, [(str(p), str(tmp_path / "cache"))] * 4))
    assert set(got) == {log.ranges_m.tobytes() + log.stamps_s.tobytes()}
    assert sorted(f.suffix for f in (tmp_path / "cache").iterdir()) == [".f8", ".npz"]
