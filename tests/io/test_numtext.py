"""The compiled whole-file number parser (gtrig.io._numtext): Python's float() bit for bit, or None (the
line loop decides) for anything unusual; the readers built on it keep their one-line errors."""

from __future__ import annotations

import random
from pathlib import Path

import numpy as np
import pytest

from gtrig.errors import FormatError
from gtrig.io._numtext import MAX_SLOW, parse_numeric
from gtrig.io.formats import read_trajectory
from gtrig.io.formats._common import numeric_rows
from gtrig.io.tum import read_tum


def _cell(rng: random.Random) -> str:
    k = rng.random()
    if k < 0.3:
        return f"{rng.uniform(-1e6, 1e6):.{rng.randint(0, 12)}f}"
    if k < 0.5:
        return f"{rng.uniform(-10, 10) * 10 ** rng.randint(-30, 30):.{rng.randint(0, 16)}e}"
    if k < 0.6:
        return repr(rng.uniform(-1, 1) * 10.0 ** rng.randint(-300, 300))
    if k < 0.7:
        return str(rng.randint(0, 2 ** 63 - 1))
    if k < 0.85:
        return rng.choice(["0", "-0", "-0.0", "+1.5", "1.", ".5", "1E5", "1e+05", "1e-22", "1e22", "1e23",
                           "9007199254740993", "9007199254740993.0", "123456789012345678901234567890",
                           "0.1234567890123456789", "1_000", "0e999", "4.9e-324", "1.7976931348623157e308"])
    return repr(rng.random())


def _bits(a: np.ndarray) -> np.ndarray:
    return np.ascontiguousarray(a).view(np.int64)


@pytest.mark.parametrize("comma", [False, True])
def test_every_number_equals_float_bit_for_bit(comma: bool) -> None:
    rng = random.Random(7)
    for _ in range(200):
        w = rng.choice([1, 4, 8, 12, 13])
        rows = [[_cell(rng) for _ in range(w)] for _ in range(rng.randint(1, 40))]
        sep = ", " if comma else rng.choice([" ", "\t", "  "])
        eol = rng.choice(["\n", "\r\n"])
        text = "# a comment\n\n" + eol.join("  " + sep.join(r) + " " for r in rows) + rng.choice(["", eol])
        got = parse_numeric(text.encode(), (w,), comma)
        assert got is not None, text[:200]
        values, lines = got.values, got.line_numbers
        assert np.array_equal(_bits(values), _bits(np.array([[float(c) for c in r] for r in rows])))
        assert lines.tolist() == list(range(3, 3 + len(rows)))


def test_the_slow_reader_decides_whatever_is_unusual() -> None:
    for text in (b"1 2\n3\n",              # widths differ
                 b"1 2\n3 x\n",            # not a number
                 b"1 2\r3 4\n",            # a lone CR: a line break to str.splitlines
                 b"1 2\n\x0c3 4\n",        # a form feed: another one
                 b"1 2\n3 4 # c\n",        # a comment after numbers
                 b"# \xc2\xb0\n1 2\n",     # non-ASCII
                 b"1,2\n",                 # commas in a blank-separated file
                 b"\n# only comments\n"):  # no rows
        assert parse_numeric(text, (2,), comma=False) is None, text
    for text in (b"1,2,\n", b"1,,2\n", b"1 2,3\n"):
        assert parse_numeric(text, (2, 3), comma=True) is None, text
    # a byte-order mark is skipped, as the utf-8-sig readers do
    assert parse_numeric(b"\xef\xbb\xbf1 2\n", (2,), comma=False).values.tolist() == [[1.0, 2.0]]  # type: ignore[union-attr]


def test_many_cells_past_the_exact_grammar() -> None:
    """17-digit reprs (covariances) by NumPy's conversion, more than one pass stores: float()'s bits."""
    rng = np.random.default_rng(5)
    v = rng.normal(size=(MAX_SLOW, 3)) * 10.0 ** rng.integers(-12, 3, (MAX_SLOW, 3))
    got = parse_numeric("".join(",".join(repr(float(x)) for x in row) + "\n" for row in v).encode(), (3,), comma=True)
    assert got is not None and np.array_equal(_bits(got.values), _bits(v))
    bad = "".join(",".join(repr(float(x)) for x in row) + "\n" for row in v[:5000]) + "1,2,1e-30x\n"
    assert parse_numeric(bad.encode(), (3,), comma=True) is None


def test_word_columns() -> None:
    got = parse_numeric(b"1.5,ok,,2\n2.5,flagged,too far,3\n3.5,ok,\n", (4,), comma=True, text_cols=(1, 2))
    assert got is None  # the last line lacks a cell
    got = parse_numeric(b"1.5,ok,,2\n2.5,flagged,far,3\n", (4,), comma=True, text_cols=(1, 2))
    assert got is not None
    words = [[got.buf[a:b].tobytes() for a, b in row] for row in got.spans]
    assert words == [[b"ok", b""], [b"flagged", b"far"]] and got.values[:, [0, 3]].tolist() == [[1.5, 2], [2.5, 3]]
    for text in (b'1,"ok",,2\n', b"1, ok,,2\n", b"1,ok,a b,2\n"):  # quotes and blanks: csv.reader decides
        assert parse_numeric(text, (4,), comma=True, text_cols=(1, 2)) is None, text


def test_first_column_exact_integers() -> None:
    got = parse_numeric(b"1403636579758555392,1\n1403636579758555393,2\n", (2,), comma=True)
    assert got is not None and got.first_int is not None
    assert got.first_int.tolist() == [1403636579758555392, 1403636579758555393]
    assert parse_numeric(b"1.5,1\n2,2\n", (2,), comma=True).first_int is None  # type: ignore[union-attr]


def _tum_lines(n: int) -> list[str]:
    rng = np.random.default_rng(3)
    q = rng.normal(size=(n, 4))
    q /= np.linalg.norm(q, axis=1)[:, None]
    return [f"{100 + 0.01 * i:.6f} {rng.normal():.9f} {rng.normal():.9f} {rng.normal():.9f} "
            + " ".join(f"{v:.12f}" for v in q[i]) for i in range(n)]


def test_tum_fast_path_equals_the_line_loop(tmp_path: Path) -> None:
    lines = ["# timestamp tx ty tz qx qy qz qw"] + _tum_lines(2000)
    p = tmp_path / "a.tum"
    p.write_text("\n".join(lines) + "\n")
    fast = read_tum(p)
    a, _ = numeric_rows(p, lines, (8,), None, "8 values")
    assert np.array_equal(fast.stamps_s, a[:, 0]) and np.array_equal(fast.xyz, a[:, 1:4])
    assert np.array_equal(fast.quat_xyzw, a[:, 4:8] / np.linalg.norm(a[:, 4:8], axis=1)[:, None])


@pytest.mark.parametrize(("name", "bad", "fragment"), [
    ("a.tum", "100.5 0 0 0 0 0 0", ":1502: expected 8 values"),
    ("a.tum", "100.5 0 0 0 0 0 0 x", ":1502: not a number"),
    ("a.kitti", "1 0 0 0 0 1 0 0 0 0 1", ":1502: expected 12 values"),
    ("a-GROUNDTRUTH.csv", "1,2,x,4", ":1502: not a number"),
    ("a-GROUNDTRUTH.csv", "1,2,nan,4", ":1502: a value is not finite"),
])
def test_a_bad_line_deep_in_a_big_file_is_named(tmp_path: Path, name: str, bad: str, fragment: str) -> None:
    if name.endswith(".tum"):
        good = _tum_lines(3000)
    elif name.endswith(".kitti"):
        good = [" ".join(["1", "0", "0", str(i), "0", "1", "0", "0", "0", "0", "1", "0"]) for i in range(3000)]
    else:
        good = [f"{i},{i},0,0" for i in range(3000)]
    good[1501] = bad
    p = tmp_path / name
    p.write_text("\n".join(good) + "\n")
    with pytest.raises(FormatError, match=fragment) as e:
        read_trajectory(p)
    assert str(e.value).startswith(str(p))


def test_euroc_nanosecond_stamps_as_the_line_loop_reads_them(tmp_path: Path) -> None:
    ns = [1403636579758555392 + 4_999_999 * i for i in range(50)]
    d = tmp_path / "state_groundtruth_estimate0"
    d.mkdir()
    p = d / "data.csv"
    p.write_text("#timestamp, x, y, z, qw, qx, qy, qz\n" + "".join(f"{t},0,0,0,1,0,0,0\n" for t in ns))
    track = read_trajectory(p)
    expect = [t // 1_000_000_000 + (t % 1_000_000_000) * 1e-9 for t in ns]
    assert track.stamps_s.tolist() == expect


def test_covariance_csv_fast_path_equals_the_line_loop(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    from gtrig.io import posetrack
    from gtrig.trajectory import PoseStatus, PoseTrack

    n = 3000
    rng = np.random.default_rng(2)
    A = rng.normal(size=(n, 6, 6)) * 1e-3
    status = rng.choice([int(s) for s in PoseStatus], n).astype(np.uint8)
    reasons = tuple("gap of 0.4 s" if s == PoseStatus.BRIDGED else "" for s in status)
    track = PoseTrack(100 + 0.01 * np.arange(n), rng.normal(size=(n, 3)), np.tile([0, 0, 0, 1.0], (n, 1)),
                      A @ np.swapaxes(A, 1, 2), "se3", status, reasons, "GTfused")
    posetrack.write_pose_track(track, tmp_path / "a.tum", tmp_path / "a_cov.csv")
    fast = posetrack.read_covariance_csv(tmp_path / "a_cov.csv")
    monkeypatch.setattr(posetrack, "_fast_covariances", lambda p, d: None)
    slow = posetrack.read_covariance_csv(tmp_path / "a_cov.csv")
    for a, b in zip(fast, slow, strict=True):
        assert np.array_equal(a, b) if isinstance(a, np.ndarray) else a == b
    assert np.array_equal(fast[1], track.cov) and fast[4] == reasons
    monkeypatch.undo()
    text = (tmp_path / "a_cov.csv").read_text().splitlines()
    text[1502] = text[1502].replace(",ok,", ",fine,").replace(",flagged,", ",fine,").replace(
        ",bridged,", ",fine,").replace(",rejected,", ",fine,")
    (tmp_path / "a_cov.csv").write_text("\n".join(text) + "\n")
    with pytest.raises(FormatError, match=r"a_cov.csv:1503: status 'fine' is none of"):
        posetrack.read_covariance_csv(tmp_path / "a_cov.csv")
