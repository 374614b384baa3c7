"""A compiled (numba) fast path for text tables of numbers: TUM, KITTI, EuRoC, RAWSEEDS files of 10^6 lines.

:func:`parse_numeric` reads the bytes of a whole file in one pass and gives the numbers, or ``None``
whenever anything is unusual (a line of another width, a byte that is not printable ASCII, a cell that
is not a number, too many cells outside the exact grammar below). The caller then runs its line-by-line
reader, which finds the same numbers or raises the one-line error naming the file and line: this path
never makes an error message of its own, so both paths fail alike.

Equal to Python's ``float()`` bit for bit. A cell ``[+-]digits[.digits][(e|E)[+-]digits]`` whose digits
form an integer below 2^53 and whose decimal exponent is within +-22 is that integer times or divided by
an exact power of ten: one correctly rounded IEEE operation (Clinger's fast path), hence ``float()``'s
value. Any other cell (17-digit ``repr``s, a larger exponent, ``nan``, ``inf``, ``1_000``) is converted
afterwards, all at once, by NumPy's bytes-to-float64 conversion, which gives ``float()``'s value (both are
correctly rounded; tests/io/test_numtext.py) and refuses what ``float()`` refuses.

Lines are split as ``str.splitlines`` splits these bytes (``\\n`` and ``\\r\\n``; a lone ``\\r`` or any other
line-break byte sends the file to the slow path); blank lines and lines whose first non-blank character
is ``#`` are skipped, as the slow readers skip them. Throughput: about 10^6 TUM lines (117 MB) in 0.3 s.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba import njit

OK, BAD_BYTE, BAD_WIDTH, TOO_MANY_SLOW, NO_ROWS = 0, 1, 2, 3, 4
#: cells outside the exact grammar stored in the first pass; a file with more is scanned twice
MAX_SLOW = 4096
_POW10 = np.array([10.0 ** k for k in range(23)])
_TWO53 = 2 ** 53
_INT64_MAX = np.frombuffer(b"9223372036854775807", np.uint8).copy()


@njit(cache=True, inline="always")
def _blank(c: int) -> bool:
    return c == 32 or c == 9 or c == 13


@njit(cache=True, inline="always")
def _fits_int64(buf: np.ndarray, a: int) -> bool:
    """The 19 digits at ``buf[a:]`` are at most 2^63 - 1 = 9223372036854775807."""
    lim = _INT64_MAX
    for k in range(19):
        if buf[a + k] != lim[k]:
            return buf[a + k] < lim[k]
    return True


@njit(cache=True, inline="always")
def _cell(buf: np.ndarray, i: int, n: int, pow10: np.ndarray) -> tuple[float, int, bool, int]:
    """``(value, exact_integer, ok, end)`` of the number starting at ``buf[i]``: ``end`` is the first byte
    the grammar (module docstring) did not take; ``ok`` is False when the digits read are not exactly
    convertible (the caller then hands the cell to ``float()``). ``exact_integer`` is the value of a plain
    integer cell (digits only), else -1."""
    neg = False
    if buf[i] == 45 or buf[i] == 43:
        neg = buf[i] == 45
        i += 1
    # the integer digits, then the fraction's: the hot loops of a 10^8-byte file, one test per byte
    mant = 0
    start = i
    while i < n and 48 <= buf[i] <= 57:
        mant = mant * 10 + (buf[i] - 48)
        i += 1
    nd = i - start
    frac = 0
    dot = i < n and buf[i] == 46
    if dot:
        i += 1
        start = i
        while i < n and 48 <= buf[i] <= 57:
            mant = mant * 10 + (buf[i] - 48)
            i += 1
        frac = i - start
        nd += frac
    # over 18 digits the int64 may have wrapped: exact only for a plain integer that provably did not
    big = nd > 18 and not (nd == 19 and not dot and _fits_int64(buf, i - 19))
    if nd == 0:
        return 0.0, -1, False, i
    exp = 0
    has_exp = False
    if i < n and (buf[i] == 101 or buf[i] == 69):
        has_exp = True
        i += 1
        eneg = False
        if i < n and (buf[i] == 45 or buf[i] == 43):
            eneg = buf[i] == 45
            i += 1
        ne = 0
        while i < n and 48 <= buf[i] <= 57:
            if exp < 100_000:
                exp = exp * 10 + (buf[i] - 48)
            ne += 1
            i += 1
        if ne == 0:
            return 0.0, -1, False, i
        if eneg:
            exp = -exp
    as_int = -1 if (dot or has_exp or neg or big) else mant
    if mant == 0 and not big:
        return (-0.0 if neg else 0.0), as_int, True, i
    e10 = exp - frac
    # an integer converts correctly rounded at any size; a scaled one only when both factors are exact
    if big or e10 > 22 or e10 < -22 or (mant >= _TWO53 and e10 != 0):
        return 0.0, as_int, False, i
    v = float(mant)
    if e10 > 0:
        v = v * pow10[e10]
    elif e10 < 0:
        v = v / pow10[-e10]
    return (-v if neg else v), as_int, True, i


@njit(cache=True)
def _width(buf: np.ndarray, comma: bool) -> int:
    """Cells on the first data line (0: none)."""
    n = buf.size
    i = 0
    while i < n:
        j = i
        while j < n and buf[j] != 10:
            j += 1
        a, b = i, j
        while a < b and _blank(buf[a]):
            a += 1
        while b > a and _blank(buf[b - 1]):
            b -= 1
        if a < b and buf[a] != 35:
            w = 1
            if comma:
                for k in range(a, b):
                    if buf[k] == 44:
                        w += 1
            else:
                for k in range(a + 1, b):
                    if _blank(buf[k]) and not _blank(buf[k - 1]):
                        w += 1
            return w
        i = j + 1
    return 0


@njit(cache=True, inline="always")
def _eol(buf: np.ndarray, i: int, n: int) -> int:
    """1 at ``\n``, 2 at ``\r\n``, -1 at any other control or non-ASCII byte, 0 otherwise."""
    c = buf[i]
    if c == 10:
        return 1
    if c == 13:
        return 2 if i + 1 < n and buf[i + 1] == 10 else -1
    if c > 126 or (c < 32 and c != 9):
        return -1
    return 0


@njit(cache=True)
def _scan(buf: np.ndarray, comma: bool, width: int, text: np.ndarray, out: np.ndarray, line_no: np.ndarray,
          first_int: np.ndarray, slow: np.ndarray, spans: np.ndarray) -> tuple[int, int, int, bool]:
    """Fill ``out`` (rows, width), ``line_no`` (rows,), ``first_int`` (rows,), ``slow`` (m, 3: start, end,
    flat index of the cells left to NumPy's parser) and ``spans`` (rows, text columns, 2: start, end of the
    cells of the columns ``text`` marks) in one pass. Returns ``(status, rows, slow cells, every first cell
    a plain integer)``; past ``slow``'s length the slow cells are only counted (status TOO_MANY_SLOW)."""
    pow10 = _POW10
    sep = 44 if comma else 32
    n = buf.size
    row = 0
    nslow = 0
    all_int = True
    line = 0
    i = 0
    while i < n:
        line += 1
        while i < n and (buf[i] == 32 or buf[i] == 9):
            i += 1
        if i >= n:
            break
        t = _eol(buf, i, n)
        if t > 0:
            i += t
            continue
        if buf[i] == 35:  # a comment line
            while i < n:
                t = _eol(buf, i, n)
                if t < 0:
                    return BAD_BYTE, row, nslow, all_int
                i += 1
                if t > 0:
                    i += t - 1
                    break
            continue
        if row >= out.shape[0]:
            return BAD_WIDTH, row, nslow, all_int
        col = 0
        tcol = 0
        while True:  # one cell per turn; i is at its first byte, a non-blank
            if col >= width:
                return BAD_WIDTH, row, nslow, all_int
            s0 = i
            if text[col]:
                # a word as csv.reader reads it unquoted: no blank, no quote, up to the comma or the line's end
                while i < n and buf[i] != 44:
                    c = buf[i]
                    if c == 10 or (c == 13 and i + 1 < n and buf[i + 1] == 10):
                        break
                    if c == 34 or c == 32 or c < 32 or c > 126:
                        return BAD_BYTE, row, nslow, all_int
                    i += 1
                spans[row, tcol, 0] = s0
                spans[row, tcol, 1] = i
                tcol += 1
                out[row, col] = np.nan
                ok = True
                as_int = -1
            else:
                if buf[i] == 44:
                    return BAD_WIDTH, row, nslow, all_int  # an empty cell
                v, as_int, ok, i = _cell(buf, i, n, pow10)
                t = 1 if i >= n else _eol(buf, i, n)
                if not (t > 0 or buf[i] == 32 or buf[i] == 9 or buf[i] == sep):
                    ok = False  # more bytes than the grammar took: a parser decides; up to the separator
                    while i < n and buf[i] != sep and not (not comma and buf[i] == 9):
                        t = _eol(buf, i, n)
                        if t != 0:
                            break
                        i += 1
                    if t < 0:
                        return BAD_BYTE, row, nslow, all_int
                s1 = i
                while s1 > s0 and (buf[s1 - 1] == 32 or buf[s1 - 1] == 9):
                    s1 -= 1
                if ok:
                    out[row, col] = v
                else:
                    if nslow < slow.shape[0]:
                        slow[nslow, 0] = s0
                        slow[nslow, 1] = s1
                        slow[nslow, 2] = row * width + col
                    nslow += 1
            if col == 0:
                first_int[row] = as_int
                if as_int < 0:
                    all_int = False
            col += 1
            while i < n and (buf[i] == 32 or buf[i] == 9):
                i += 1
            t = 1 if i >= n else _eol(buf, i, n)
            if t < 0:
                return BAD_BYTE, row, nslow, all_int
            if t > 0:
                i += t
                break
            if comma:
                if buf[i] != 44:
                    return BAD_WIDTH, row, nslow, all_int  # "1 2," : a cell with a blank inside
                i += 1
                while i < n and not text[col] and (buf[i] == 32 or buf[i] == 9):  # a word keeps its blanks
                    i += 1
                if i >= n or (_eol(buf, i, n) != 0 and not text[col]):
                    return BAD_WIDTH, row, nslow, all_int  # an empty number cell at the end of the line
            if col < width and text[col] and (i >= n or _eol(buf, i, n) > 0):
                # an empty word at the end of the line ("...,ok,"): its cell is empty, not missing
                spans[row, tcol, 0] = i
                spans[row, tcol, 1] = i
                tcol += 1
                out[row, col] = np.nan
                col += 1
                if i < n:
                    i += _eol(buf, i, n)
                break
        if col != width:
            return BAD_WIDTH, row, nslow, all_int
        line_no[row] = line
        row += 1
    if row == 0:
        return NO_ROWS, row, nslow, all_int
    if nslow > slow.shape[0]:
        return TOO_MANY_SLOW, row, nslow, all_int
    return OK, row, nslow, all_int


class NumericTable(NamedTuple):
    """What :func:`parse_numeric` read: ``values`` (n, w) (``nan`` in text columns), ``line_numbers`` (n,)
    1-based, ``first_int`` (n,) int64 exact integers of the first column when each is a plain non-negative
    integer below 2^63 (EuRoC's nanosecond stamps, past float64's 2^53) else ``None``, ``spans`` (n, k, 2)
    the start and end in ``buf`` of the text columns' cells, and ``buf`` the bytes parsed (uint8)."""

    values: np.ndarray
    line_numbers: np.ndarray
    first_int: np.ndarray | None
    spans: np.ndarray
    buf: np.ndarray


def _slow_cells(buf: np.ndarray, slow: np.ndarray, flat: np.ndarray) -> bool:
    """The cells outside the exact grammar by NumPy's bytes-to-float64 conversion (Python float()'s value,
    correctly rounded, 0.3 us a cell); False when one is not a number (or longer than 64 bytes)."""
    if not len(slow):
        return True
    length = slow[:, 1] - slow[:, 0]
    width = int(length.max())
    if width > 64 or int(length.min()) == 0:
        return False
    k = np.arange(width)
    idx = np.minimum(slow[:, :1] + k, buf.size - 1)
    cells = np.where(k < length[:, None], buf[idx], 0).astype(np.uint8)
    try:
        flat[slow[:, 2]] = np.ascontiguousarray(cells).view(f"S{width}").reshape(-1).astype(np.float64)
    except ValueError:
        return False
    return True


def parse_numeric(data: bytes, widths: tuple[int, ...], comma: bool, text_cols: tuple[int, ...] = ()
                  ) -> NumericTable | None:
    """The numbers of the text ``data`` (a leading UTF-8 byte-order mark skipped), or ``None`` when the
    slow reader must decide (module docstring).

    Parameters
    ----------
    data : the file's bytes.
    widths : the accepted numbers of cells per line; every line must have the same.
    comma : cells separated by commas (each trimmed of blanks) instead of runs of blanks.
    text_cols : columns holding words, not numbers (comma-separated files only): unquoted, without blanks,
        possibly empty (gtrig's pose covariance CSV's status and reason).
    """
    buf = np.frombuffer(data, np.uint8)
    if data[:3] == b"\xef\xbb\xbf":
        buf = buf[3:]
    width = int(_width(buf, comma))
    if width not in widths or (text_cols and not comma) or any(not 0 <= c < width for c in text_cols):
        return None
    text = np.zeros(width, np.bool_)
    text[list(text_cols)] = True
    # a row takes at least 2 * width - 1 bytes (a digit or an empty word, and a separator, per cell): a bound
    # on the rows without a pass over the bytes; np.empty's untouched pages cost nothing
    rows = (buf.size + 1) // max(2 * width - len(text_cols), 1) + 1
    out = np.empty((rows, width))
    line_no = np.empty(rows, np.int64)
    first = np.empty(rows, np.int64)
    spans = np.empty((rows if text_cols else 0, len(text_cols), 2), np.int64)
    slow = np.empty((MAX_SLOW, 3), np.int64)
    status, n, nslow, all_int = _scan(buf, comma, width, text, out, line_no, first, slow, spans)
    if status == TOO_MANY_SLOW:  # many cells past the exact grammar (17-digit reprs): once more, storing all
        slow = np.empty((nslow, 3), np.int64)
        status, n, nslow, all_int = _scan(buf, comma, width, text, out, line_no, first, slow, spans)
    if status != OK or not _slow_cells(buf, slow[:nslow], out.reshape(-1)):
        return None
    return NumericTable(out[:n], line_no[:n], first[:n] if all_int else None, spans[:n], buf)
