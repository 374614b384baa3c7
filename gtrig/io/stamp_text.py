"""The exact nanoseconds of a text file's stamp column, when its digits go past what a float keeps.

A float64 reads ``1700000300.019999981`` and ``1700000300.020000000`` as one number; a file written with
nanosecond digits (a ROS bag's stamps printed to 9 decimals) is therefore read once more for its first
column, as text, into integer nanoseconds (gtrig.stamps). Files with at most 6 decimals (TUM's usual
microseconds) need no second reading: :func:`gtrig.stamps.ns_from_seconds` gives their exact
nanoseconds from the float.
"""

from __future__ import annotations

import numpy as np

from gtrig.stamps import ns_from_decimals


def _first_token(line: str, sep: str | None) -> str:
    s = line.strip()
    if sep is None:
        return s.replace(",", " ").split(None, 1)[0]
    return s.split(sep, 1)[0].strip()


def needs_text_stamps(lines: list[str], sep: str | None = None) -> bool:
    """True when the first data line's stamp has more than 6 decimals (or an exponent)."""
    for line in lines:
        s = line.strip()
        if s and not s.startswith("#"):
            tok = _first_token(s, sep)
            frac = tok.partition(".")[2]
            return len(frac) > 6 or "e" in tok.lower()
    return False


def text_stamps_ns(lines: list[str], sep: str | None = None) -> np.ndarray:
    """(N,) int64 nanoseconds of the first column of every data line (not empty, not ``#``), in order."""
    return ns_from_decimals([_first_token(s, sep) for s in lines if s.strip() and not s.strip().startswith("#")])
