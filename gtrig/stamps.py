"""One stamp, one number: time stamps as integer nanoseconds beside the float seconds.

A float64 holds an epoch stamp (1.7e9 s) to about 0.24 us, so the same stamp printed from the float by
different writers comes out differently (``1700000300.020000`` at 6 decimals, ``1700000300.019999981`` at
9, ``1700000300019999981`` ns). gtrig keeps, where a source has them, the integer nanoseconds it read
(:attr:`gtrig.trajectory.PoseTrack.stamps_ns`), and every writer prints from them.

Conventions
-----------
- :func:`ns_from_seconds`: the integer nanoseconds of float seconds: the whole microsecond whose decimal
  reads back as the same float when there is one (the shortest decimal, as ``repr`` gives it: a stamp
  read from ``1700000300.020000`` is ``1700000300020000000`` ns); for a Unix-time stamp (from
  :data:`EPOCH_SCALE_S` up, where a float's last digit is 30 ns or more) computed in floats, the nearest
  microsecond (``1700000100.1 + 1.2`` is ``1700000101.300000``, not the float's ``...300000191``); else
  (a stamp counted from the start of a run) the nearest nanosecond.
- :func:`ns_from_decimal`: the exact nanoseconds of a decimal text (``"1700000300.019999981"``).
- :func:`seconds_from_ns`: float seconds from nanoseconds (whole seconds and the rest apart: the float
  nearest the stamp, to one rounding).
- :func:`format_seconds`: decimal seconds from nanoseconds, 6 decimals when every stamp is a whole
  microsecond, else 9: the same digits in every text format.
"""

from __future__ import annotations

import numpy as np

from gtrig.errors import InputError

NS_PER_S = 1_000_000_000
#: the largest stamp (s) integer nanoseconds hold in int64 (year 2262 as a Unix time)
MAX_NS_STAMP_S = 9.2e9
#: from here up (4.25 years as seconds) a float stamp's last digit is 30 ns or more: its digits past the
#: microsecond are rounding, and float stamps are taken to the nearest microsecond
EPOCH_SCALE_S = 2.0**27


def ns_from_seconds(stamps_s: np.ndarray) -> np.ndarray:
    """(N,) int64 nanoseconds of (N,) float seconds (module docstring); InputError past
    :data:`MAX_NS_STAMP_S` (nanoseconds read as seconds)."""
    t = np.asarray(stamps_s, dtype=float).reshape(-1)
    if t.size and not bool(np.all(np.abs(t) < MAX_NS_STAMP_S)):
        raise InputError(f"a stamp of {float(np.max(np.abs(t))):.4g} s is past what int64 nanoseconds hold "
                         f"({MAX_NS_STAMP_S:g} s): nanoseconds read as seconds?")
    whole = np.floor(t)
    frac = t - whole  # exact (Sterbenz)
    us = np.rint(frac * 1e6)
    # a whole microsecond count below 2^53 is exact in float64, and IEEE division rounds correctly: the
    # quotient is the float nearest the decimal; equal to t means the decimal reads back as t
    us_total = whole * 1e6 + us
    exact_us = ((np.abs(us_total) < 2.0**53) & (us_total / 1e6 == t)) | (np.abs(t) >= EPOCH_SCALE_S)
    sub_ns = np.rint(frac * 1e9).astype(np.int64)
    out = whole.astype(np.int64) * NS_PER_S + np.where(exact_us, us.astype(np.int64) * 1000, sub_ns)
    return out


def ns_from_decimal(text: str) -> int:
    """The exact nanoseconds of one decimal number of seconds (``"12.5"``, ``"-0.25"``, ``"1e3"``); digits
    past the ninth decimal are rounded half to even. ValueError when ``text`` is not a number."""
    from decimal import ROUND_HALF_EVEN, Decimal, InvalidOperation

    try:
        d = Decimal(text.strip())
    except InvalidOperation:
        raise ValueError(f"not a number: {text!r}") from None
    if not d.is_finite():
        raise ValueError(f"not a finite number: {text!r}")
    return int((d * NS_PER_S).quantize(Decimal(1), rounding=ROUND_HALF_EVEN))


def ns_from_decimals(texts: list[str]) -> np.ndarray:
    """(N,) int64 :func:`ns_from_decimal` of each text; a plain ``SECONDS.FRACTION`` by integer arithmetic
    (a million stamps in about a second), anything else by :mod:`decimal`."""
    out = np.empty(len(texts), np.int64)
    for i, s in enumerate(texts):
        s = s.strip()
        whole, dot, frac = s.partition(".")
        body = whole.lstrip("-")
        if body.isdigit() and (not frac or frac.isdigit()) and len(frac) <= 9:
            ns = int(body) * NS_PER_S + (int(frac.ljust(9, "0")) if frac else 0)
            out[i] = -ns if whole.startswith("-") else ns
        else:
            out[i] = ns_from_decimal(s)
    return out


def seconds_from_ns(stamps_ns: np.ndarray) -> np.ndarray:
    """(N,) float seconds of (N,) int64 nanoseconds."""
    ns = np.asarray(stamps_ns, dtype=np.int64).reshape(-1)
    return (ns // NS_PER_S).astype(float) + (ns % NS_PER_S).astype(float) * 1e-9


def decimals_needed(stamps_ns: np.ndarray) -> int:
    """6 when every stamp is a whole microsecond, else 9."""
    ns = np.asarray(stamps_ns, dtype=np.int64)
    return 6 if not ns.size or bool(np.all(ns % 1000 == 0)) else 9


def format_seconds(stamps_ns: np.ndarray, decimals: int | None = None) -> list[str]:
    """Decimal seconds of (N,) int64 nanoseconds with ``decimals`` (0-9) fraction digits, rounded half
    up; ``None``: :func:`decimals_needed`."""
    ns = np.asarray(stamps_ns, dtype=np.int64).reshape(-1)
    d = decimals_needed(ns) if decimals is None else int(decimals)
    if not 0 <= d <= 9:
        raise ValueError(f"decimals must be 0..9, got {d}")
    unit = 10 ** (9 - d)
    q = (np.abs(ns) + unit // 2) // unit if d < 9 else np.abs(ns)
    neg = ns < 0
    scale = 10**d
    whole, frac = q // scale, q % scale
    if d == 0:
        return [("-" if n else "") + str(w) for w, n in zip(whole.tolist(), neg.tolist(), strict=True)]
    return [f"{'-' if n else ''}{w}.{f:0{d}d}" for w, f, n in zip(whole.tolist(), frac.tolist(), neg.tolist(),
                                                                  strict=True)]
