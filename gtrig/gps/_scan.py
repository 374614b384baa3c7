"""The compiled NMEA 0183 line scanner (numba): one pass over a log's bytes.

Per line it finds the optional log-clock prefix (the RAWSEEDS ``unixtime, $SENTENCE`` layout), the
``$`` sentence, its talker and type, verifies the checksum (two hex digits, or the one left by the
RAWSEEDS logger's truncation, which must equal the high nibble) and cuts the fields at the commas,
parsing each as a decimal number. Nothing here knows what a field means: :mod:`gtrig.gps.nmea`
decodes the columns per sentence type with NumPy.

A decimal field is parsed as an exact integer mantissa divided by a power of ten (both exact in
binary64 for up to 18 significant digits), so the value equals Python's ``float()`` of the field.
Throughput: about 4 million sentences per second on one core (bench/gps.py).
"""

from __future__ import annotations

import numpy as np
from numba import njit

#: fields after the address field that are kept (GSV with four satellites and a signal id has 20)
MAX_FIELDS = 21

# sentence types (column ``kind``)
K_BLANK, K_GGA, K_GST, K_RMC, K_ZDA, K_GSA, K_GSV, K_OTHER, K_BAD = 0, 1, 2, 3, 4, 5, 6, 7, 8
KIND_NAMES = ("blank", "GGA", "GST", "RMC", "ZDA", "GSA", "GSV", "other", "bad")

# checksum states (column ``cs``)
CS_FULL, CS_TRUNCATED, CS_NONE, CS_BAD = 0, 1, 2, 3

# why a line is bad (column ``bad``), before any per-type check
B_NONE, B_NO_SENTENCE, B_PREFIX, B_CHECKSUM, B_ADDRESS, B_TOO_MANY, B_BINARY = 0, 1, 2, 3, 4, 5, 6
BAD_NAMES = ("", "no $ sentence on the line", "the log-clock prefix is not a number",
             "checksum mismatch", "the address field is not a known talker and type",
             "more fields than any known sentence", "non-ASCII bytes")

TALKERS = ("GP", "GN", "GL", "GA", "GB", "BD", "GQ", "GI")
_POW10 = np.array([10.0 ** k for k in range(23)])


@njit(cache=True, inline="always")
def _hex(c: int) -> int:
    if 48 <= c <= 57:
        return c - 48
    if 65 <= c <= 70:
        return c - 55
    if 97 <= c <= 102:
        return c - 87
    return -1


@njit(cache=True, inline="always")
def _number(buf: np.ndarray, a: int, b: int, pow10: np.ndarray) -> float:
    """The decimal in ``buf[a:b]`` (optional sign, digits, one dot), ``nan`` if it is not one."""
    if a >= b:
        return np.nan
    neg = False
    i = a
    if buf[i] == 45 or buf[i] == 43:
        neg = buf[i] == 45
        i += 1
    mant = 0
    nd = 0
    frac = -1
    while i < b:
        c = buf[i]
        if 48 <= c <= 57:
            if nd < 18:
                mant = mant * 10 + (c - 48)
                nd += 1
                if frac >= 0:
                    frac += 1
            elif frac < 0:
                return np.nan  # more integer digits than a field of this kind ever has
        elif c == 46 and frac < 0:
            frac = 0
        else:
            return np.nan
        i += 1
    if nd == 0:
        return np.nan
    v = float(mant)
    if frac > 0:
        v = v / pow10[frac]
    return -v if neg else v


@njit(cache=True, inline="always")
def _sentence_bounds(buf: np.ndarray, a: int, b: int) -> tuple[int, int, int, bool]:
    """One pass over ``buf[a:b]``: the ``$``, the ``*``, the XOR between them, and whether a byte is not
    printable ASCII (``d`` and ``star`` are -1 when absent)."""
    d = -1
    star = -1
    x = 0
    for i in range(a, b):
        c = buf[i]
        if c > 126 or (c < 32 and c != 9):
            return d, star, x, True
        if d < 0:
            if c == 36:
                d = i
        elif star < 0:
            if c == 42:
                star = i
            else:
                x ^= c
    return d, star, x, False


@njit(cache=True, inline="always")
def _prefix_stamp(buf: np.ndarray, a: int, d: int, pow10: np.ndarray) -> float:
    """The log's own clock before the sentence, ``"seconds,"`` with optional spaces (``nan`` if not a number)."""
    e = d
    while e > a and (buf[e - 1] == 32 or buf[e - 1] == 9):
        e -= 1
    if e > a and buf[e - 1] == 44:
        e -= 1
    while e > a and (buf[e - 1] == 32 or buf[e - 1] == 9):
        e -= 1
    return _number(buf, a, e, pow10)


@njit(cache=True, inline="always")
def _checksum(buf: np.ndarray, star: int, b: int, x: int) -> int:
    """The checksum's state: two hex digits equal to the XOR (full), one equal to its high nibble (the
    RAWSEEDS logger's truncation), or bad."""
    nd = b - star - 1
    if nd == 2:
        h1 = _hex(buf[star + 1])
        h2 = _hex(buf[star + 2])
        return CS_FULL if h1 >= 0 and h2 >= 0 and h1 * 16 + h2 == x else CS_BAD
    if nd == 1:
        h1 = _hex(buf[star + 1])
        return CS_TRUNCATED if h1 >= 0 and h1 == (x >> 4) else CS_BAD
    return CS_BAD


@njit(cache=True, inline="always")
def _talker(t0: int, t1: int) -> int:
    """Index of the two-letter talker in :data:`TALKERS`, -1 for another."""
    if t0 == 71:  # G
        if t1 == 80:
            return 0
        if t1 == 78:
            return 1
        if t1 == 76:
            return 2
        if t1 == 65:
            return 3
        if t1 == 66:
            return 4
        if t1 == 81:
            return 6
        if t1 == 73:
            return 7
    elif t0 == 66 and t1 == 68:
        return 5
    return -1


@njit(cache=True, inline="always")
def _sentence_type(s0: int, s1: int, s2: int) -> int:
    """The sentence type's kind code from its three letters."""
    if s0 == 71 and s1 == 71 and s2 == 65:
        return K_GGA
    if s0 == 71 and s1 == 83 and s2 == 84:
        return K_GST
    if s0 == 82 and s1 == 77 and s2 == 67:
        return K_RMC
    if s0 == 90 and s1 == 68 and s2 == 65:
        return K_ZDA
    if s0 == 71 and s1 == 83 and s2 == 65:
        return K_GSA
    if s0 == 71 and s1 == 83 and s2 == 86:
        return K_GSV
    return K_OTHER


@njit(cache=True, inline="always")
def _address(buf: np.ndarray, d: int, addr_end: int) -> tuple[int, int]:
    """(kind, talker) of the address field ``$ttSSS`` in ``buf[d:addr_end]``: a known talker and type, a
    proprietary ``$P...`` or another well-formed address (other), else bad."""
    if addr_end - d - 1 == 5:
        t0 = buf[d + 1]
        t1 = buf[d + 2]
        tk = _talker(t0, t1)
        k = _sentence_type(buf[d + 3], buf[d + 4], buf[d + 5])
        if tk < 0:
            k = K_OTHER if (t0 == 80 or (65 <= t0 <= 90 and 65 <= t1 <= 90)) else K_BAD
        return k, tk
    if addr_end - d - 1 >= 2 and buf[d + 1] == 80:  # proprietary $P...
        return K_OTHER, -1
    return K_BAD, -1


@njit(cache=True, inline="always")
def _fields(buf: np.ndarray, comma: int, body_end: int, li: int, vals: np.ndarray, chars: np.ndarray,
            pow10: np.ndarray) -> int:
    """Cut ``buf[comma + 1:body_end]`` at the commas into line ``li`` of ``vals`` and ``chars``; the number of
    fields (more than :data:`MAX_FIELDS` when the line has too many)."""
    nf = 0
    f0 = comma + 1
    i = f0
    while True:
        if i == body_end or buf[i] == 44:
            if nf >= MAX_FIELDS:
                return nf + 1
            if i > f0:
                chars[nf, li] = buf[f0]
                vals[nf, li] = _number(buf, f0, i, pow10)
            nf += 1
            if i == body_end:
                return nf
            f0 = i + 1
        i += 1


@njit(cache=True)
def scan(buf: np.ndarray, starts: np.ndarray, ends: np.ndarray, vals: np.ndarray, chars: np.ndarray,
         nfields: np.ndarray, kind: np.ndarray, talker: np.ndarray, cs: np.ndarray, bad: np.ndarray,
         stamp: np.ndarray) -> None:
    """Fill the per-line outputs for the lines ``buf[starts[i]:ends[i]]`` (newline excluded).

    Outputs (length = number of lines L): ``vals`` (MAX_FIELDS, L) float64 field values (``nan`` when
    empty or not a number; field-major, so that one field of many lines is contiguous), ``chars``
    (MAX_FIELDS, L) uint8 first byte of each field (0 when empty),
    ``nfields``, ``kind``, ``talker`` (index in TALKERS, -1 for none), ``cs``, ``bad`` codes and
    ``stamp`` (the log-clock prefix in seconds, ``nan`` without one).
    """
    pow10 = _POW10
    for li in range(starts.size):
        a = starts[li]
        b = ends[li]
        vals[:, li] = np.nan
        chars[:, li] = 0
        nfields[li] = 0
        talker[li] = -1
        cs[li] = CS_NONE
        bad[li] = B_NONE
        stamp[li] = np.nan
        while b > a and (buf[b - 1] == 13 or buf[b - 1] == 32 or buf[b - 1] == 9):
            b -= 1
        while a < b and (buf[a] == 32 or buf[a] == 9):
            a += 1
        if a == b:
            kind[li] = K_BLANK
            continue
        kind[li] = K_BAD
        d, star, x, binary = _sentence_bounds(buf, a, b)
        if binary:
            bad[li] = B_BINARY
            continue
        if d < 0:
            bad[li] = B_NO_SENTENCE
            continue
        if d > a:
            t = _prefix_stamp(buf, a, d, pow10)
            if np.isnan(t):
                bad[li] = B_PREFIX
                continue
            stamp[li] = t
        body_end = b if star < 0 else star
        if star >= 0:
            cs[li] = _checksum(buf, star, b, x)
            if cs[li] == CS_BAD:
                bad[li] = B_CHECKSUM
                continue
        comma = -1
        for i in range(d + 1, body_end):
            if buf[i] == 44:
                comma = i
                break
        k, tk = _address(buf, d, body_end if comma < 0 else comma)
        talker[li] = tk
        if k == K_BAD:
            bad[li] = B_ADDRESS
            continue
        kind[li] = k
        if k == K_OTHER or comma < 0:
            continue
        nf = _fields(buf, comma, body_end, li, vals, chars, pow10)
        if nf > MAX_FIELDS:
            kind[li] = K_BAD
            bad[li] = B_TOO_MANY
            continue
        nfields[li] = nf


@njit(cache=True)
def line_bounds(buf: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(starts, ends) of the lines of ``buf`` (``\\n`` separated; a last line without one counts)."""
    n = 0
    for i in range(buf.size):
        if buf[i] == 10:
            n += 1
    last = buf.size > 0 and buf[buf.size - 1] != 10
    m = n + (1 if last else 0)
    starts = np.empty(m, np.int64)
    ends = np.empty(m, np.int64)
    j = 0
    s = 0
    for i in range(buf.size):
        if buf[i] == 10:
            starts[j] = s
            ends[j] = i
            j += 1
            s = i + 1
    if last:
        starts[j] = s
        ends[j] = buf.size
    return starts, ends
