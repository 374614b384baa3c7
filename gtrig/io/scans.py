"""Laser scan CSV files: ``timestamp,r_0,...,r_{n-1}`` (docs/formats.md, "Laser scans").

Ranges are metres, ``nan`` for no return; time stamps strictly increase. Reading parses the numbers
with NumPy's C parser and validates afterwards, so a 20k-scan file reads in well under a second;
every error is one line naming the file and line.
"""

from __future__ import annotations

import hashlib
import logging
import os
import zipfile
from dataclasses import dataclass, replace
from pathlib import Path
from typing import BinaryIO, Protocol

import numpy as np

from gtrig.errors import FormatError
from gtrig.io.atomic import atomic_group, atomic_open
from gtrig.io.text import read_text

log = logging.getLogger(__name__)


class _HasBeams(Protocol):
    @property
    def beams(self) -> int: ...


@dataclass(frozen=True)
class ScanLog:
    """The scans of one scanner.

    Attributes
    ----------
    stamps_s : (N,) strictly increasing seconds (the time of each scan's first beam, the scanner's
        clock).
    ranges_m : (N, B) metres along beam ``i`` (angles in the rig file); ``nan`` = no return.
    """

    stamps_s: np.ndarray
    ranges_m: np.ndarray

    def __post_init__(self) -> None:
        st = np.asarray(self.stamps_s, dtype=float)
        r = np.asarray(self.ranges_m, dtype=float)
        if st.ndim != 1 or r.ndim != 2 or r.shape[0] != st.shape[0]:
            raise ValueError(f"ScanLog: stamps_s (N,), ranges_m (N, B) expected, got {st.shape}, {r.shape}")
        object.__setattr__(self, "stamps_s", st)
        object.__setattr__(self, "ranges_m", r)
        st.setflags(write=False)
        r.setflags(write=False)

    def __len__(self) -> int:
        return int(self.stamps_s.size)

    @property
    def beams(self) -> int:
        return int(self.ranges_m.shape[1])


def data_lines(path: Path) -> tuple[str, list[str], list[int]]:
    """Split a CSV file into its header and data lines, skipping blank and ``#`` lines.

    Returns the header, the data lines and their 1-based line numbers in the file.
    """
    text = read_text(path, "UTF-8 text file")
    lines = text.splitlines()
    keep = [i for i, s in enumerate(lines) if s.strip() and not s.lstrip().startswith("#")]
    if not keep:
        raise FormatError(f"{path}: empty file, expected a header line")
    header = lines[keep[0]].strip()
    rows = keep[1:]
    return header, [lines[i] for i in rows], [i + 1 for i in rows]


def parse_numbers(path: Path, lines: list[str], line_no: list[int], n_cols: int) -> np.ndarray:
    """(N, n_cols) floats of comma-separated lines; one-line errors name the bad line."""
    if not lines:
        return np.zeros((0, n_cols))
    counts = np.fromiter((s.count(",") for s in lines), dtype=np.int64, count=len(lines))
    bad = np.flatnonzero(counts != n_cols - 1)
    if bad.size:
        i = int(bad[0])
        raise FormatError(f"{path}:{line_no[i]}: expected {n_cols} values, got {counts[i] + 1}")
    try:
        a = np.loadtxt(lines, delimiter=",", dtype=float, ndmin=2)
    except ValueError:
        for i, s in enumerate(lines):
            for tok in s.split(","):
                try:
                    float(tok)
                except ValueError:
                    raise FormatError(f"{path}:{line_no[i]}: not a number: {tok.strip()!r}") from None
        raise FormatError(f"{path}: could not parse the numbers") from None
    if a.shape != (len(lines), n_cols):
        # loadtxt cuts a row at a '#' (an inline comment): the row holds fewer numbers than its commas say
        i = next((k for k, s in enumerate(lines) if "#" in s), 0)
        raise FormatError(f"{path}:{line_no[i]}: expected {n_cols} values; a '#' cuts this row short")
    return a


def check_stamps(path: Path, stamps: np.ndarray, line_no: list[int]) -> None:
    """Time stamps must be finite and strictly increasing."""
    bad = np.flatnonzero(~np.isfinite(stamps))
    if bad.size:
        raise FormatError(f"{path}:{line_no[int(bad[0])]}: time stamp is not a finite number")
    bad = np.flatnonzero(np.diff(stamps) <= 0)
    if bad.size:
        i = int(bad[0]) + 1
        raise FormatError(f"{path}:{line_no[i]}: time stamp {stamps[i]:.9f} does not increase "
                          f"(previous {stamps[i - 1]:.9f})")


def _check_unit(p: Path, ranges: np.ndarray, range_max_m: float | None) -> None:
    """Refuse ranges in another unit: most returns of a real scan lie within the scanner's maximum range;
    a median beyond twice that is millimetres (or centimetres) written for metres."""
    if range_max_m is None or not ranges.size:
        return
    finite = ranges[np.isfinite(ranges)]
    if finite.size and float(np.median(finite)) > 2.0 * float(range_max_m):
        raise FormatError(f"{p}: ranges are in metres; their median {float(np.median(finite)):.4g} m is beyond twice "
                          f"the scanner's maximum range {float(range_max_m):g} m (millimetres given for metres?)")


def read_scans(
    path: str | os.PathLike[str], scanner: _HasBeams | None = None, *, beams: int | None = None
) -> ScanLog:
    """Read a scan CSV.

    Parameters
    ----------
    path : the file.
    scanner : the rig's scanner (fixed or onboard); its ``beams`` is the expected beam count.
    beams : the expected beam count, if no scanner is given. Without either, the header decides.

    Raises
    ------
    FormatError
        One line naming the file and line: wrong header or beam count, not a number, time stamps not
        increasing, a negative or infinite range.
    """
    p = Path(path)
    expected = scanner.beams if scanner is not None else beams
    header, lines, line_no = data_lines(p)
    names = [h.strip() for h in header.split(",")]
    n_beams = len(names) - 1
    if names[0] != "timestamp" or n_beams < 1 or names[1:] != [f"r_{i}" for i in range(n_beams)]:
        raise FormatError(f"{p}: header must be 'timestamp,r_0,...,r_{{n-1}}', got {header[:60]!r}")
    if expected is not None and n_beams != expected:
        raise FormatError(f"{p}: {n_beams} beams in the header, the rig's scanner has {expected}")
    a = parse_numbers(p, lines, line_no, n_beams + 1)
    stamps = a[:, 0].copy()
    ranges = a[:, 1:]
    check_stamps(p, stamps, line_no)
    bad = np.flatnonzero(np.any(ranges < 0, axis=1))
    if bad.size:
        i = int(bad[0])
        j = int(np.argmax(ranges[i] < 0))
        raise FormatError(f"{p}:{line_no[i]}: negative range r_{j} = {ranges[i, j]:g}")
    bad = np.flatnonzero(np.any(np.isinf(ranges), axis=1))
    if bad.size:
        i = int(bad[0])
        raise FormatError(f"{p}:{line_no[i]}: infinite range (write nan for no return)")
    _check_unit(p, ranges, getattr(scanner, "range_max_m", None))
    return ScanLog(stamps, np.ascontiguousarray(ranges))


@dataclass(frozen=True)
class ScanRows:
    """Where each scan of a scan CSV is, to read the scans a few at a time (:func:`index_scans`): a
    recording's hours of scans are never in memory at once (20 bytes per scan).

    Attributes
    ----------
    path : the file.
    beams : ranges per scan.
    stamps_s : (N,) strictly increasing seconds (as :class:`ScanLog`).
    starts : (N,) byte offset of each scan's line.
    line_no : (N,) its 1-based line number (for messages).
    end : byte offset where the last scan's line ends.
    ranges_file : ``None``, or the binary copy of the log's ranges that :func:`index_scans` made in its
        ``cache`` folder: (N_file, beams) little-endian float64 metres, row-major, no header, the values
        the text parses to bit for bit. :meth:`read` reads its rows instead of parsing the text again; a
        process that cannot open it (a Dask worker that does not see the folder) parses the text.
    row0 : the row of ``ranges_file`` that holds this object's first scan (:meth:`part`).
    """

    path: Path
    beams: int
    stamps_s: np.ndarray
    starts: np.ndarray
    line_no: np.ndarray
    end: int
    ranges_file: Path | None = None
    row0: int = 0

    def __len__(self) -> int:
        return int(self.stamps_s.size)

    def shifted(self, offset_s: float) -> ScanRows:
        """The same scans with ``offset_s`` subtracted from their stamps (another clock)."""
        return replace(self, stamps_s=self.stamps_s - offset_s)

    def part(self, lo: int, hi: int) -> ScanRows:
        """Scans ``[lo, hi)`` (their indices from 0)."""
        end = int(self.starts[hi]) if hi < len(self) else self.end
        return replace(self, stamps_s=self.stamps_s[lo:hi], starts=self.starts[lo:hi], line_no=self.line_no[lo:hi],
                       end=end, row0=self.row0 + lo)

    def read(self, lo: int, hi: int) -> np.ndarray:
        """(hi - lo, beams) the ranges of scans ``[lo, hi)``, metres, the values :func:`read_scans` reads.

        Raises
        ------
        FormatError
            The file changed since it was indexed (when read from the text).
        """
        if hi <= lo:
            return np.zeros((0, self.beams))
        if self.ranges_file is not None:
            got = _read_binary_rows(self.ranges_file, self.row0 + lo, hi - lo, self.beams)
            if got is not None:
                return got
        return self._parse(lo, hi)

    def _parse(self, lo: int, hi: int) -> np.ndarray:
        """:meth:`read` from the text."""
        end = int(self.starts[hi]) if hi < len(self) else self.end
        try:
            with open(self.path, "rb") as f:
                f.seek(int(self.starts[lo]))
                data = f.read(end - int(self.starts[lo]))
            lines = [t for t in data.decode("utf-8").splitlines() if _is_data(t)]
        except (OSError, UnicodeDecodeError):
            lines = []
        if len(lines) != hi - lo:
            raise FormatError(f"{self.path}: changed while it was read (scans {lo + 1}-{hi} are not where they were)")
        a = parse_numbers(self.path, lines, [int(n) for n in self.line_no[lo:hi]], self.beams + 1)
        return np.ascontiguousarray(a[:, 1:])


def _read_binary_rows(path: Path, first: int, n: int, beams: int) -> np.ndarray | None:
    """(n, beams) rows ``first...`` of a binary ranges file (:class:`ScanRows`), or None when it cannot
    be read whole. A plain read, not a memory map: the client's resident memory stays a window's."""
    out = np.empty((n, beams), dtype="<f8")
    try:
        with open(path, "rb") as f:
            f.seek(first * beams * 8)
            got = f.readinto(memoryview(out.data).cast("B"))
    except OSError:
        return None
    return out.astype(float, copy=False) if got == out.nbytes else None


def _is_data(line: str) -> bool:
    """A data line of a CSV (:func:`data_lines` skips blank and ``#`` lines)."""
    return bool(line.strip()) and not line.lstrip().startswith("#")


#: data lines parsed at a time by :func:`index_scans` (bounds its memory: ~2 MB of text at 180 beams)
INDEX_BLOCK_LINES = 2048

#: the layout of a cache folder's files (:func:`index_scans`); a change of it makes new names
SCAN_CACHE_VERSION = 1


class _Indexer:
    """One pass of :func:`index_scans` over a scan CSV: validate it a block of lines at a time, keep each
    scan's stamp and place, and write the parsed ranges to ``sink`` (a binary file) when given."""

    def __init__(self, p: Path, scanner: _HasBeams | None, beams: int | None, sink: BinaryIO | None) -> None:
        self.p, self.scanner, self.beams_arg, self.sink = p, scanner, beams, sink
        self.expected = scanner.beams if scanner is not None else beams
        self.range_max = getattr(scanner, "range_max_m", None)
        self.stamps: list[np.ndarray] = []
        self.starts: list[int] = []
        self.line_no: list[int] = []
        self.block: list[str] = []
        self.n_beams = -1
        # the unit check of read_scans (median of the finite ranges beyond twice the maximum range),
        # decided exactly from counts and the two values either side of the limit
        self.n_fin = self.n_over = 0
        self.below, self.above = -np.inf, np.inf

    def refuse(self) -> FormatError:
        read_scans(self.p, self.scanner, beams=self.beams_arg)  # raises the same one-line error as the whole file's
        return FormatError(f"{self.p}: line ends other than '\\n' or '\\r\\n' (a scan CSV is read by lines)")

    def flush(self) -> bool:
        """Parse and check the block of lines; False when it is wrong."""
        try:
            a = parse_numbers(self.p, self.block, self.line_no[-len(self.block):], self.n_beams + 1)
        except FormatError:
            return False
        r = a[:, 1:]
        if np.any(r < 0) or np.any(np.isinf(r)):
            return False
        self.stamps.append(a[:, 0].copy())
        if self.range_max is not None:
            lim = 2.0 * float(self.range_max)
            fin = r[np.isfinite(r)]
            self.n_fin += fin.size
            over = fin > lim
            self.n_over += int(over.sum())
            if over.any():
                self.above = min(self.above, float(fin[over].min()))
            if not over.all():
                self.below = max(self.below, float(fin[~over].max()))
        if self.sink is not None:
            self.sink.write(np.ascontiguousarray(r, dtype="<f8").data)
        self.block.clear()
        return True

    def header(self, line: str) -> None:
        """Check the header line (its beam count against the expected one)."""
        names = [h.strip() for h in line.strip().split(",")]
        self.n_beams = len(names) - 1
        if (names[0] != "timestamp" or self.n_beams < 1 or names[1:] != [f"r_{i}" for i in range(self.n_beams)]
                or (self.expected is not None and self.n_beams != self.expected)):
            raise self.refuse()

    def lines(self) -> int:
        """Read the file's lines into blocks; returns the bytes read."""
        try:
            f = open(self.p, "rb")
        except OSError:
            raise self.refuse() from None
        with f:
            pos = 0
            for no, raw in enumerate(f, 1):
                at, pos = pos, pos + len(raw)
                try:
                    text = raw.decode("utf-8")
                except UnicodeDecodeError:
                    raise self.refuse() from None
                t = text.splitlines()
                if len(t) > 1:
                    raise self.refuse()
                line = t[0] if t else ""
                if not _is_data(line):
                    continue
                if self.n_beams < 0:
                    self.header(line)
                    continue
                self.starts.append(at)
                self.line_no.append(no)
                self.block.append(line)
                if len(self.block) >= INDEX_BLOCK_LINES and not self.flush():
                    raise self.refuse()
        return pos

    def run(self) -> ScanRows:
        """The pass: the file's lines, the last block, then the checks of the whole file."""
        end = self.lines()
        if self.n_beams < 0 or (self.block and not self.flush()):
            raise self.refuse()
        st = np.concatenate(self.stamps) if self.stamps else np.zeros(0)
        if not np.all(np.isfinite(st)) or np.any(np.diff(st) <= 0):
            raise self.refuse()
        # the median of n values is beyond the limit when more than half are; with exactly half, when the
        # mean of the two middle ones (the largest below, the smallest beyond) is
        n_fin, n_over = self.n_fin, self.n_over
        limit = 2.0 * float(self.range_max or 0.0)  # (no values are over without a maximum range)
        if n_fin and (2 * n_over > n_fin or (2 * n_over == n_fin and 0.5 * (self.below + self.above) > limit)):
            raise self.refuse()
        return ScanRows(self.p, self.n_beams, st, np.array(self.starts, dtype=np.int64),
                        np.array(self.line_no, dtype=np.int64), end)


def index_scans(
    path: str | os.PathLike[str], scanner: _HasBeams | None = None, *, beams: int | None = None,
    cache: str | os.PathLike[str] | None = None,
) -> ScanRows:
    """Index a scan CSV: validate it as :func:`read_scans` does, a block of :data:`INDEX_BLOCK_LINES`
    lines at a time, and keep only each scan's stamp and place (:class:`ScanRows`).

    Parameters
    ----------
    path, scanner, beams
        As :func:`read_scans`.
    cache
        A folder where the parsed ranges are kept (``ScanRows.ranges_file``), so that the text is parsed
        once: by the first indexing of a file's content; a later one (another stage, a resumed run,
        another process) finds its files and parses nothing. Files are named by a SHA-256 of the log's
        bytes and of ``scanner``'s beams and maximum range (a changed log gets new files, never the old
        values), written atomically (two processes building the same one at once each rename a whole
        file into place). A folder that cannot be written (a read-only disk) is not an error: the ranges
        are then parsed from the text when read. On disk: 8 bytes per range (1.44 kB a scan at 180
        beams, about the text's size) and 24 bytes per scan.

    Raises
    ------
    FormatError
        The error :func:`read_scans` gives for the same file (a file found wrong here is read again
        whole by it, for the same one line); also lines that end other than in ``\\n`` or
        ``\\r\\n``, which a block-wise reading cannot place.
    """
    p = Path(path)
    if cache is not None:
        rows = _index_cached(p, scanner, beams, Path(cache))
        if rows is not None:
            return rows
    return _Indexer(p, scanner, beams, None).run()


class _LogChangedError(Exception):
    """The log changed while it was indexed: its cache files are not written."""


def _cache_files(p: Path, cache: Path, scanner: _HasBeams | None, beams: int | None) -> tuple[Path, Path]:
    """The ranges file and the rows file of ``p``'s content in ``cache`` (raises OSError)."""
    expected = scanner.beams if scanner is not None else beams
    h = hashlib.sha256(f"gtrig scan cache {SCAN_CACHE_VERSION}; beams {expected}; range max "
                       f"{getattr(scanner, 'range_max_m', None)!r}\n".encode())
    with open(p, "rb") as f:
        h = hashlib.file_digest(f, lambda: h)
    key = h.hexdigest()[:40]
    return cache / f"{key}.ranges.f8", cache / f"{key}.rows.npz"


def _index_cached(p: Path, scanner: _HasBeams | None, beams: int | None, cache: Path) -> ScanRows | None:
    """:func:`index_scans` through ``cache``: its files when they are there, else one pass that writes
    them; None when the log cannot be hashed (the plain pass then says why) or the folder written."""
    try:
        before = os.stat(p)
        ranges_file, rows_file = _cache_files(p, cache, scanner, beams)
    except OSError:
        return None
    found = _cached_rows(p, ranges_file, rows_file)
    if found is not None:
        return found
    try:
        with atomic_group(ranges_file, rows_file) as (tmp_ranges, tmp_rows):
            with open(tmp_ranges, "wb") as sink:
                rows = _Indexer(p, scanner, beams, sink).run()
            after = os.stat(p)
            if (after.st_size, after.st_mtime_ns) != (before.st_size, before.st_mtime_ns):
                raise _LogChangedError
            with open(tmp_rows, "wb") as f:
                np.savez(f, stamps_s=rows.stamps_s, starts=rows.starts, line_no=rows.line_no, beams=rows.beams,
                         end=rows.end)
    except _LogChangedError:
        return rows
    except OSError as e:
        log.info("%s: its parsed ranges are not kept in %s (%s); they are parsed from the text when read",
                 p, cache, e)
        return None
    return replace(rows, ranges_file=ranges_file)


def _cached_rows(p: Path, ranges_file: Path, rows_file: Path) -> ScanRows | None:
    """The :class:`ScanRows` of a cache folder's files, or None when they are not there whole."""
    try:
        with np.load(rows_file) as z:
            stamps, starts, line_no = z["stamps_s"], z["starts"], z["line_no"]
            n_beams, end = int(z["beams"]), int(z["end"])
        size = os.stat(ranges_file).st_size
    except (OSError, EOFError, KeyError, ValueError, zipfile.BadZipFile):  # missing, cut short, not ours
        return None
    n = stamps.size
    if starts.shape != (n,) or line_no.shape != (n,) or size != n * n_beams * 8:
        return None
    return ScanRows(p, n_beams, stamps, starts, line_no, end, ranges_file)


_ZERO4 = np.frombuffer("".join(f"{i:04d}" for i in range(10000)).encode(), np.uint8).reshape(10000, 4)
_SPACE4 = np.frombuffer("".join(f"{i:4d}" for i in range(10000)).encode(), np.uint8).reshape(10000, 4)


def fixed_decimal_text(a: np.ndarray, decimals: int) -> np.ndarray:
    """(N, M) numbers as a (N, M, W) byte array: each right-aligned ``%.{decimals}f`` text, padded
    with spaces on the left; the characters Python's ``%`` formatting gives, built by integer
    arithmetic and 4-digit table look-ups over the whole array. Numbers that way cannot do exactly
    (ties of the rounding, beyond 1e15) are formatted by Python; ``nan`` and ``inf`` are filled in."""
    a = np.asarray(a, dtype=float)
    mag = np.abs(a) * (10.0 ** decimals)
    finite = mag < 1e15  # False for nan and inf too
    mag[~finite] = 0.0
    # round half up (the halves themselves are done by Python below); int32 arithmetic where it fits is
    # about twice as fast as int64's
    k = (mag + 0.5).astype(np.int32 if (mag.max() if mag.size else 0.0) < 2.0e9 else np.int64)
    # the scaled float rounds differently from % (the exact binary value) only next to a tie
    special = (np.isfinite(a) & ~finite) | (np.abs(mag - k) > 0.5 - 1e-6)
    unit = 10 ** decimals
    if k.dtype == np.int32 and decimals > 8:  # the decimals' 4-digit groups would overflow int32
        k = k.astype(np.int64)
    ip = k // unit
    fp = k - ip * unit
    top = int(ip.max()) if ip.size else 0
    n_int = 4 * max(1, -(-len(str(top)) // 4))  # integer digits in whole groups of 4
    n_dec = 4 * (-(-decimals // 4))
    extra = [f"%.{decimals}f" % float(v) for v in a[special]]
    body = 1 + n_int + (1 + decimals if decimals > 0 else 0)  # sign, integer, point, decimals
    width = max([body, 4] + [len(e) for e in extra])
    out = np.full(a.shape + (width,), ord(" "), dtype=np.uint8)
    c0 = width - body + 1  # first integer column
    # decimals: groups of 4 from the point (the last group padded with zeros to the right, then cut)
    if decimals:
        f = fp * 10 ** (n_dec - decimals)
        dec = np.empty(a.shape + (n_dec,), np.uint8)
        for g in range(n_dec // 4):
            div = 10 ** (n_dec - 4 * (g + 1))
            q = f // div
            dec[..., 4 * g:4 * g + 4] = np.take(_ZERO4, q, axis=0)  # take: 10x faster than [q] here
            f = f - q * div
        out[..., c0 + n_int] = ord(".")
        out[..., c0 + n_int + 1:] = dec[..., :decimals]
    # integer part: the leading group space-padded, the others zero-padded where a leading one is
    groups = []
    rest = ip
    for _ in range(n_int // 4):
        q = rest // 10000
        groups.append(rest - q * 10000)
        rest = q
    groups.reverse()  # most significant first
    if len(groups) == 1:  # the usual case (below 10000): one look-up
        out[..., c0:c0 + 4] = np.take(_SPACE4, groups[0], axis=0)
        groups = []
    higher = np.zeros(a.shape, bool)
    for g, v in enumerate(groups):
        last = g == len(groups) - 1
        cols = slice(c0 + 4 * g, c0 + 4 * g + 4)
        txt = np.where(higher[..., None], np.take(_ZERO4, v, axis=0), np.take(_SPACE4, v, axis=0))
        if not last:  # a group of zeros with nothing before it is blank
            txt[~higher & (v == 0)] = ord(" ")
        out[..., cols] = txt
        higher |= v > 0
    neg = np.signbit(a) & finite
    if np.any(neg):
        # the sign goes left of the first digit: count the leading spaces of the integer columns
        r, c = np.nonzero(neg)
        blanks = np.sum(np.cumprod(out[r, c, c0:c0 + n_int] == ord(" "), axis=1), axis=1)
        out[r, c, c0 - 1 + blanks] = ord("-")
    for word, mask in ((b"nan", np.isnan(a)), (b"inf", np.isposinf(a)), (b"-inf", np.isneginf(a))):
        if np.any(mask):
            out[mask] = np.frombuffer(word.rjust(width), np.uint8)
    if extra:
        texts = np.frombuffer("".join(e.rjust(width) for e in extra).encode(), np.uint8).reshape(-1, width)
        out[special] = texts  # row-major order, as a[special] listed them
    return out


def write_scans(path: str | os.PathLike[str], log: ScanLog, range_decimals: int = 4) -> None:
    """Write a scan CSV atomically: stamps with 9 decimals, ranges with ``range_decimals``
    (default 0.1 mm, below the devices' 1 mm resolution), ``nan`` for no return.

    The text is that of ``"%.9f" + ",%.4f" * B`` per row, built for the whole log at once: by one
    compiled pass (gtrig.io._scantext, about 20 M ranges/s), or for more than 4 decimals or ranges
    past 1e14 m by :func:`fixed_decimal_text` (about 1 M ranges/s). Both give Python's characters.
    """
    from gtrig.io._scantext import scan_body

    B = log.beams
    header = "timestamp," + ",".join(f"r_{i}" for i in range(B))
    n = len(log)
    body = scan_body(log.stamps_s, log.ranges_m, int(range_decimals)) if n else None
    if n and body is None:
        parts = [fixed_decimal_text(log.stamps_s[:, None], 9), fixed_decimal_text(log.ranges_m, int(range_decimals))]
        w = max(p.shape[2] for p in parts)
        grid = np.full((n, B + 1, w + 1), ord(" "), np.uint8)
        grid[:, :1, w - parts[0].shape[2]:w] = parts[0]
        grid[:, 1:, w - parts[1].shape[2]:w] = parts[1]
        # fixed-width cells, each followed by a comma (a newline after the last), then the padding dropped
        grid[:, :, w] = ord(",")
        grid[:, -1, w] = ord("\n")
        body = grid.tobytes().translate(None, b" ")
    with atomic_open(path, "wb") as f:
        f.write((header + "\n").encode())
        if n:
            f.write(body)
