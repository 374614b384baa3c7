"""The body of a scan CSV written by one compiled (numba) pass: ``stamp,r_0,...,r_{B-1}\\n`` per scan.

Each range is printed as Python's ``"%.{d}f" % r`` prints it (``d`` up to 4): the double's exact binary
value ``m 2^e`` times ``10^d = 5^d 2^d`` is the integer ``m 5^d`` (below 2^63 for ``d <= 4``) shifted by
``e + d`` bits, rounded half to even on that exact value, as Python's correctly rounded formatting does.
``nan``, ``inf`` and ``-inf`` print as Python prints them, a negative value rounding to zero keeps its
sign (``-0.0000``). The stamps (9 decimals of 10^9-second epochs: past this exact integer arithmetic) are
formatted by Python and copied in.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

#: the largest ``decimals`` the exact integer path takes (``2^53 5^d < 2^63``)
MAX_DECIMALS = 4
_LIMIT = 1.0e14  # |r| beyond this: the shifted integer may overflow; the caller formats such logs otherwise


@njit(cache=True, error_model="numpy")
def _body(stamps: np.ndarray, stamp_end: np.ndarray, ranges: np.ndarray, decimals: int, out: np.ndarray) -> int:
    """Write the rows into ``out`` (uint8); returns the bytes written, or -1 for a range past ``_LIMIT``."""
    n, nb = ranges.shape
    five = 5 ** decimals
    unit = 10 ** decimals
    digits = np.empty(24, np.uint8)
    pos = 0
    s0 = 0
    for i in range(n):
        for k in range(s0, stamp_end[i]):
            out[pos] = stamps[k]
            pos += 1
        s0 = stamp_end[i]
        for j in range(nb):
            out[pos] = 44  # ','
            pos += 1
            r = ranges[i, j]
            if math.isnan(r):
                out[pos] = 110
                out[pos + 1] = 97
                out[pos + 2] = 110
                pos += 3
                continue
            if math.isinf(r):
                if r < 0:
                    out[pos] = 45
                    pos += 1
                out[pos] = 105
                out[pos + 1] = 110
                out[pos + 2] = 102
                pos += 3
                continue
            a = abs(r)
            if a >= _LIMIT:
                return -1
            if r < 0 or (r == 0 and math.copysign(1.0, r) < 0):
                out[pos] = 45
                pos += 1
            # a = f 2^e with f in [0.5, 1): m = f 2^53 is an exact integer, a 10^d = m 5^d 2^(e - 53 + d)
            f, e = math.frexp(a)
            m = np.int64(f * 9007199254740992.0)
            big = m * five
            sh = e - 53 + decimals
            if sh >= 0:
                q = big << sh
            elif sh <= -63:
                q = 0
            else:
                s = -sh
                q = big >> s
                rem = big - (q << s)
                half = np.int64(1) << (s - 1)
                if rem > half or (rem == half and (q & 1) == 1):
                    q += 1
            ip = q // unit
            fp = q - ip * unit
            nd = 0
            while True:
                digits[nd] = 48 + ip % 10
                nd += 1
                ip //= 10
                if ip == 0:
                    break
            for k in range(nd - 1, -1, -1):
                out[pos] = digits[k]
                pos += 1
            if decimals > 0:
                out[pos] = 46  # '.'
                pos += 1
                for k in range(decimals - 1, -1, -1):
                    out[pos + k] = 48 + fp % 10
                    fp //= 10
                pos += decimals
        out[pos] = 10
        pos += 1
    return pos


def scan_body(stamps_s: np.ndarray, ranges_m: np.ndarray, decimals: int) -> bytes | None:
    """The rows of a scan CSV: each stamp as ``"%.9f"``, each range as ``"%.{decimals}f"`` (module docstring);
    ``None`` when ``decimals`` is over :data:`MAX_DECIMALS` or a range is too large for the exact path."""
    if not 0 <= decimals <= MAX_DECIMALS:
        return None
    r = np.ascontiguousarray(ranges_m, dtype=float)
    texts = [f"{t:.9f}".encode() for t in np.asarray(stamps_s, float).tolist()]
    stamp_bytes = np.frombuffer(b"".join(texts), np.uint8)
    stamp_end = np.cumsum([len(t) for t in texts], dtype=np.int64)
    # per range at most a sign, 15 integer digits, the point, the decimals and the comma
    out = np.empty(stamp_bytes.size + r.size * (18 + decimals) + len(texts), np.uint8)
    size = _body(stamp_bytes, stamp_end, r, int(decimals), out)
    return None if size < 0 else out[:size].tobytes()
