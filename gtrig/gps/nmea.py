"""NMEA 0183 logs: GGA, GST, RMC, ZDA, GSA and GSV sentences, plain or as RAWSEEDS ``unixtime, sentence`` lines.

The compiled scanner (:mod:`gtrig.gps._scan`) cuts every line into numeric fields in one pass; this
module decodes the columns of each sentence type with NumPy and checks them (field counts, ranges,
hemisphere letters). Every line ends up in exactly one class of :class:`LineAccount`: a sentence
decoded, a sentence of another type (ignored), a blank line, or a malformed line with its reason.
Talkers GP (GPS), GN (multi-constellation), GL (GLONASS), GA (Galileo), GB and BD (BeiDou), GQ
(QZSS) and GI (NavIC) are read alike.

Field layouts follow NMEA 0183 v4.11 (the fields after the address field, 0-based):

- GGA: time, lat, N/S, lon, E/W, quality, satellites, HDOP, altitude (MSL), M, geoid separation, M,
  age of differential data, station id (14 fields);
- GST: time, RMS of the pseudorange residuals, semi-major, semi-minor (1-sigma, metres), orientation
  of the semi-major axis (degrees), sigma of latitude, longitude and altitude (metres) (8);
- RMC: time, status A/V, lat, N/S, lon, E/W, speed (knots), course (deg), date ddmmyy, magnetic
  variation, E/W [, mode [, navigational status]] (11 to 13);
- ZDA: time, day, month, year, local zone hours, minutes (6);
- GSA: mode, fix type, 12 satellite ids, PDOP, HDOP, VDOP [, system id] (17 or 18);
- GSV: messages, message number, satellites in view, 0 to 4 groups of (id, elevation, azimuth,
  SNR) [, signal id].
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from gtrig.errors import FormatError
from gtrig.gps import _scan as S  # noqa: N812  (the scanner's codes, S.K_GGA ...)

KNOT_MPS = 1852.0 / 3600.0

#: sentence types decoded here
SENTENCES = ("GGA", "GST", "RMC", "ZDA", "GSA", "GSV")


@dataclass(frozen=True)
class Sentences:
    """The decoded sentences of one type, in file order.

    Attributes
    ----------
    line : (M,) 1-based line numbers in the log.
    cols : name -> (M,) column (float64 unless said otherwise); see :func:`read_nmea` for the names.
    """

    line: np.ndarray
    cols: Mapping[str, np.ndarray]

    def __len__(self) -> int:
        return int(self.line.size)

    def __getitem__(self, name: str) -> np.ndarray:
        return self.cols[name]


@dataclass(frozen=True)
class LineAccount:
    """What became of every line of a log.

    Attributes
    ----------
    n_lines : lines in the file.
    decoded : sentence type -> lines decoded.
    ignored : lines holding a valid sentence of another type (VTG, proprietary, ...).
    blank : empty lines.
    malformed : reason -> count.
    malformed_lines : (line, reason) of the first malformed lines (at most ``MAX_LISTED``).
    checksums : "full", "truncated", "none", "bad" -> count over the lines with a sentence.
    """

    n_lines: int
    decoded: dict[str, int]
    ignored: int
    blank: int
    malformed: dict[str, int]
    malformed_lines: tuple[tuple[int, str], ...]
    checksums: dict[str, int]

    MAX_LISTED = 50

    @property
    def n_malformed(self) -> int:
        return int(sum(self.malformed.values()))

    @property
    def n_sentences(self) -> int:
        return int(sum(self.decoded.values())) + self.ignored + self.n_malformed


@dataclass(frozen=True)
class NmeaLog:
    """A decoded NMEA log: one :class:`Sentences` table per type and the account of its lines."""

    path: str
    sentences: dict[str, Sentences]
    account: LineAccount
    talkers: dict[str, int] = field(default_factory=dict)


# ------------------------------------------------------------------------------------------------
# field helpers (all vectorized over the lines of one type)


def _tod_s(hhmmss: np.ndarray) -> np.ndarray:
    """Seconds of the UTC day from ``hhmmss.ss`` values; ``nan`` where out of range."""
    hh = np.floor(hhmmss / 10000.0)
    mm = np.floor(hhmmss / 100.0) - 100.0 * hh
    ss = hhmmss - 10000.0 * hh - 100.0 * mm
    ok = (hh < 24) & (mm < 60) & (ss < 61) & (hhmmss >= 0)
    # round away the binary noise of hhmmss (the receivers give at most milliseconds)
    return np.where(ok, np.round(hh * 3600.0 + mm * 60.0 + ss, 6), np.nan)


def _ddmm_deg(v: np.ndarray) -> np.ndarray:
    """Degrees from NMEA's ``(d)ddmm.mmmm``; ``nan`` where the minutes are 60 or more."""
    deg = np.floor(v / 100.0)
    minutes = v - 100.0 * deg
    return np.where(minutes < 60.0, deg + minutes / 60.0, np.nan)


def days_from_civil(y: np.ndarray, m: np.ndarray, d: np.ndarray) -> np.ndarray:
    """Days since 1970-01-01 of the proleptic Gregorian dates ``y-m-d`` (integer arrays; H. Hinnant's
    algorithm, vectorized)."""
    y = np.asarray(y, np.int64) - (np.asarray(m) <= 2)
    era = np.floor_divide(y, 400)
    yoe = y - era * 400
    mp = (np.asarray(m, np.int64) + 9) % 12
    doy = (153 * mp + 2) // 5 + np.asarray(d, np.int64) - 1
    doe = yoe * 365 + yoe // 4 - yoe // 100 + doy
    return era * 146097 + doe - 719468


def _valid_date(y: np.ndarray, m: np.ndarray, d: np.ndarray) -> np.ndarray:
    ok = (m >= 1) & (m <= 12) & (d >= 1) & (d <= 31) & (y >= 1980) & (y < 2200)
    mi = np.where(ok, m, 1).astype(np.int64)
    nxt = days_from_civil(np.where(mi == 12, y + 1, y), np.where(mi == 12, 1, mi + 1), np.ones_like(mi))
    length = nxt - days_from_civil(y, mi, np.ones_like(mi))
    return ok & (d <= length)


class _Decoder:
    """Checks of one sentence type: collects a reason per failing line, first failure wins."""

    def __init__(self, kind: str, idx: np.ndarray, vals: np.ndarray, chars: np.ndarray, nf: np.ndarray):
        self.kind = kind
        self.idx = idx
        # columns are gathered one by one when a check asks for them (copying all 21 costs more)
        self._vals = vals
        self._chars = chars
        self.nf = nf[idx]
        self.reason = np.full(idx.size, -1, np.int64)
        self.messages: list[str] = []

    def v(self, j: int | slice) -> np.ndarray:
        """Field(s) ``j`` as numbers (``nan`` when empty or not a number)."""
        return self._vals[j, self.idx] if isinstance(j, int) else self._vals[j, self.idx].T

    def c(self, j: int) -> np.ndarray:
        """The first byte of field ``j`` (0 when empty)."""
        return self._chars[j, self.idx]

    def fail(self, mask: np.ndarray, message: str) -> None:
        new = mask & (self.reason < 0)
        if np.any(new):
            self.messages.append(message)
            self.reason[new] = len(self.messages) - 1

    def field_count(self, allowed: np.ndarray | tuple[int, ...]) -> None:
        ok = np.isin(self.nf, np.asarray(allowed))
        if not np.all(ok):
            bad_n = self.nf[~ok & (self.reason < 0)]
            for n in np.unique(bad_n):
                self.fail(~ok & (self.nf == n), f"{self.kind} has {int(n)} fields, expected "
                          + " or ".join(str(a) for a in allowed))

    def numeric(self, j: int, name: str, required: bool = False) -> np.ndarray:
        """Field ``j`` as numbers; a non-empty field that is not a number (or an empty required one) fails."""
        x = self.v(j)
        self.fail(np.isnan(x) & (self.c(j) != 0), f"{self.kind} {name} is not a number")
        if required:
            self.fail(np.isnan(x), f"{self.kind} {name} is empty")
        return x

    def letter(self, j: int, name: str, allowed: bytes, required: bool = False) -> np.ndarray:
        ch = self.c(j)
        ok = np.isin(ch, np.frombuffer(allowed, np.uint8)) | (ch == 0)
        if required:
            ok &= ch != 0
        self.fail(~ok, f"{self.kind} {name} is not one of {'/'.join(chr(b) for b in allowed)}")
        return ch

    def time(self, j: int = 0) -> np.ndarray:
        t = self.numeric(j, "time", required=True)
        tod = _tod_s(np.nan_to_num(t, nan=0.0))
        self.fail(np.isnan(tod), f"{self.kind} time is not hhmmss.ss")
        return tod

    def position(self, j: int, required: bool) -> tuple[np.ndarray, np.ndarray]:
        """Latitude and longitude (degrees, signed) from fields j..j+3; ``nan`` where empty."""
        lat_raw = self.numeric(j, "latitude", required)
        ns = self.letter(j + 1, "N/S", b"NS", required)
        lon_raw = self.numeric(j + 2, "longitude", required)
        ew = self.letter(j + 3, "E/W", b"EW", required)
        lat = _ddmm_deg(np.abs(lat_raw)) * np.where(ns == ord("S"), -1.0, 1.0)
        lon = _ddmm_deg(np.abs(lon_raw)) * np.where(ew == ord("W"), -1.0, 1.0)
        has = ~np.isnan(lat_raw) | ~np.isnan(lon_raw)
        self.fail(has & (np.isnan(lat_raw) | np.isnan(lon_raw)), f"{self.kind} has only one of latitude/longitude")
        self.fail(has & ((ns == 0) | (ew == 0)), f"{self.kind} position lacks its N/S or E/W letter")
        self.fail(has & ~(np.abs(lat) <= 90.0), f"{self.kind} latitude out of range (|lat| > 90 deg or minutes >= 60)")
        self.fail(has & ~(np.abs(lon) <= 180.0),
                  f"{self.kind} longitude out of range (|lon| > 180 deg or minutes >= 60)")
        self.fail(lat_raw < 0, f"{self.kind} latitude is negative (the sign belongs in N/S)")
        self.fail(lon_raw < 0, f"{self.kind} longitude is negative (the sign belongs in E/W)")
        return lat, lon

    def good(self) -> np.ndarray:
        return self.reason < 0


def _decode_gga(d: _Decoder) -> dict[str, np.ndarray]:
    d.field_count((14,))
    tod = d.time()
    lat, lon = d.position(1, required=False)
    q = d.numeric(5, "fix quality", required=True)
    d.fail(~np.isin(q, np.arange(10.0)), "GGA fix quality is not 0..9")
    nsat = d.numeric(6, "satellites")
    hdop = d.numeric(7, "HDOP")
    alt = d.numeric(8, "altitude")
    d.letter(9, "altitude unit", b"M")
    sep = d.numeric(10, "geoid separation")
    d.letter(11, "separation unit", b"M")
    age = d.numeric(12, "age of corrections")
    d.fail(d.good() & (q > 0) & np.isnan(lat), "GGA reports a fix without a position")
    d.fail(d.good() & (q > 0) & np.isnan(alt), "GGA reports a fix without an altitude")
    d.fail(d.good() & ((nsat < 0) | (nsat > 255) | (hdop < 0)), "GGA satellites or HDOP out of range")
    return {"tod_s": tod, "lat_deg": lat, "lon_deg": lon, "quality": np.nan_to_num(q).astype(np.int8),
            "n_sat": nsat, "hdop": hdop, "alt_msl_m": alt, "geoid_sep_m": sep, "age_s": age}


def _decode_gst(d: _Decoder) -> dict[str, np.ndarray]:
    d.field_count((8,))
    tod = d.time()
    names = ("rms_m", "major_m", "minor_m", "orient_deg", "sigma_lat_m", "sigma_lon_m", "sigma_alt_m")
    out = {"tod_s": tod}
    for j, n in enumerate(names, start=1):
        out[n] = d.numeric(j, n)
    sig = np.column_stack([out[n] for n in names if n != "orient_deg"])
    d.fail(np.any(sig < 0, axis=1), "GST has a negative sigma")
    d.fail(np.isnan(out["sigma_lat_m"]) | np.isnan(out["sigma_lon_m"]), "GST lacks its latitude/longitude sigmas")
    d.fail(np.abs(out["orient_deg"]) > 360, "GST orientation out of range")
    return out


def _decode_rmc(d: _Decoder) -> dict[str, np.ndarray]:
    d.field_count((11, 12, 13))
    tod = d.time()
    status = d.letter(1, "status", b"AV", required=True)
    lat, lon = d.position(2, required=False)
    speed = d.numeric(6, "speed")
    course = d.numeric(7, "course")
    date = d.numeric(8, "date", required=True)
    dd = np.floor(np.nan_to_num(date) / 10000.0)
    mm = np.floor(np.nan_to_num(date) / 100.0) - 100 * dd
    yy = np.nan_to_num(date) - 10000 * dd - 100 * mm
    year = np.where(yy < 80, 2000 + yy, 1900 + yy).astype(np.int64)
    ok = _valid_date(year, mm.astype(np.int64), dd.astype(np.int64))
    d.fail(~ok, "RMC date is not ddmmyy")
    day = np.where(ok, days_from_civil(year, np.where(ok, mm, 1), np.where(ok, dd, 1)), 0)
    return {"tod_s": tod, "valid": status == ord("A"), "lat_deg": lat, "lon_deg": lon,
            "speed_mps": speed * KNOT_MPS, "course_deg": course, "day": day.astype(np.int64)}


def _decode_zda(d: _Decoder) -> dict[str, np.ndarray]:
    d.field_count((6,))
    tod = d.time()
    day = d.numeric(1, "day", True)
    month = d.numeric(2, "month", True)
    year = d.numeric(3, "year", True)
    y, m, dd = (np.nan_to_num(a).astype(np.int64) for a in (year, month, day))
    ok = _valid_date(y, m, dd)
    d.fail(~ok, "ZDA date is not a date")
    days = np.where(ok, days_from_civil(y, np.where(ok, m, 1), np.where(ok, dd, 1)), 0)
    return {"tod_s": tod, "day": days.astype(np.int64)}


def _decode_gsa(d: _Decoder) -> dict[str, np.ndarray]:
    d.field_count((17, 18))
    d.letter(0, "mode", b"AM")
    fix = d.numeric(1, "fix type", True)
    d.fail(~np.isin(fix, (1.0, 2.0, 3.0)), "GSA fix type is not 1..3")
    used = np.sum(~np.isnan(d.v(slice(2, 14))), axis=1)
    pdop, hdop, vdop = (d.numeric(j, n) for j, n in ((14, "PDOP"), (15, "HDOP"), (16, "VDOP")))
    return {"fix_type": np.nan_to_num(fix).astype(np.int8), "n_used": used, "pdop": pdop, "hdop": hdop, "vdop": vdop}


def _decode_gsv(d: _Decoder) -> dict[str, np.ndarray]:
    nf = d.nf
    ok = (nf >= 3) & (((nf - 3) % 4 == 0) | ((nf - 4) % 4 == 0)) & (nf <= 20)
    d.fail(~ok, "GSV has a field count that is not 3 + 4 k (+ 1)")
    n_msg = d.numeric(0, "message count", True)
    i_msg = d.numeric(1, "message number", True)
    in_view = d.numeric(2, "satellites in view", True)
    d.fail(i_msg > n_msg, "GSV message number exceeds the message count")
    groups = np.clip((nf - 3) // 4, 0, 4)
    snr = d.v(slice(6, 19, 4))
    present = np.arange(4)[None, :] < groups[:, None]
    snr_sum = np.where(present & ~np.isnan(snr), snr, 0.0).sum(axis=1)
    snr_n = (present & ~np.isnan(snr)).sum(axis=1)
    return {"n_msg": n_msg, "i_msg": i_msg, "in_view": in_view, "snr_sum": snr_sum, "snr_n": snr_n.astype(float)}


_DECODERS = {"GGA": (S.K_GGA, _decode_gga), "GST": (S.K_GST, _decode_gst), "RMC": (S.K_RMC, _decode_rmc),
             "ZDA": (S.K_ZDA, _decode_zda), "GSA": (S.K_GSA, _decode_gsa), "GSV": (S.K_GSV, _decode_gsv)}


def decode_nmea(data: bytes, path: str = "<bytes>") -> NmeaLog:
    """Decode the NMEA sentences in ``data`` (a whole log, any of the layouts the module describes)."""
    buf = np.frombuffer(data, np.uint8)
    starts, ends = S.line_bounds(buf)
    n = int(starts.size)
    vals = np.empty((S.MAX_FIELDS, n), np.float64)
    chars = np.empty((S.MAX_FIELDS, n), np.uint8)
    nf = np.empty(n, np.int64)
    kind = np.empty(n, np.int8)
    talker = np.empty(n, np.int8)
    cs = np.empty(n, np.int8)
    bad = np.empty(n, np.int8)
    stamp = np.empty(n, np.float64)
    if n:
        S.scan(buf, starts, ends, vals, chars, nf, kind, talker, cs, bad, stamp)

    reasons = np.full(n, "", dtype=object)
    malformed: dict[str, int] = {}
    for code in range(1, len(S.BAD_NAMES)):
        m = bad == code
        if np.any(m):
            malformed[S.BAD_NAMES[code]] = int(m.sum())
            reasons[m] = S.BAD_NAMES[code]
    sentences: dict[str, Sentences] = {}
    decoded: dict[str, int] = {}
    for name, (k, fn) in _DECODERS.items():
        idx = np.flatnonzero(kind == k)
        dec = _Decoder(name, idx, vals, chars, nf)
        cols = fn(dec) if idx.size else {}
        good = dec.good()
        for r, msg in enumerate(dec.messages):
            m = dec.reason == r
            malformed[msg] = malformed.get(msg, 0) + int(m.sum())
            reasons[idx[m]] = msg
        keep = idx[good]
        cols = {c: a[good] for c, a in cols.items()}
        cols["stamp_log_s"] = stamp[keep]
        cols["talker"] = talker[keep]
        sentences[name] = Sentences(keep + 1, cols)
        decoded[name] = int(keep.size)
    bad_lines = np.flatnonzero(reasons != "")
    listed = tuple((int(i) + 1, str(reasons[i])) for i in bad_lines[:LineAccount.MAX_LISTED])
    has_sentence = (kind != S.K_BLANK) & (bad != S.B_NO_SENTENCE) & (bad != S.B_BINARY) & (bad != S.B_PREFIX)
    checks = {nm: int(np.sum(has_sentence & (cs == c))) for nm, c in
              (("full", S.CS_FULL), ("truncated", S.CS_TRUNCATED), ("none", S.CS_NONE), ("bad", S.CS_BAD))}
    ok_talk = talker[(talker >= 0) & (reasons == "")]
    talkers = {S.TALKERS[t]: int(c) for t, c in zip(*np.unique(ok_talk, return_counts=True), strict=True)}
    account = LineAccount(
        n_lines=n, decoded=decoded, ignored=int(np.sum((kind == S.K_OTHER) & (bad == S.B_NONE))),
        blank=int(np.sum(kind == S.K_BLANK)), malformed=malformed, malformed_lines=listed, checksums=checks)
    return NmeaLog(path, sentences, account, talkers)


def read_nmea(path: str | os.PathLike[str]) -> NmeaLog:
    """Read an NMEA log (plain sentences or RAWSEEDS ``unixtime, sentence`` lines).

    The columns of each table (:class:`Sentences`): every table has ``stamp_log_s`` (the log-clock
    prefix, ``nan`` without one) and ``talker`` (index into ``TALKERS``). GGA: ``tod_s`` (UTC seconds
    of the day), ``lat_deg``, ``lon_deg`` (WGS84, ``nan`` when the receiver has no position),
    ``quality`` (0 invalid, 1 single, 2 DGPS, 4 RTK fixed, 5 RTK float, ...), ``n_sat``, ``hdop``,
    ``alt_msl_m``, ``geoid_sep_m``, ``age_s``. GST: ``tod_s``, ``rms_m``, ``major_m``, ``minor_m``,
    ``orient_deg``, ``sigma_lat_m``, ``sigma_lon_m``, ``sigma_alt_m``. RMC: ``tod_s``, ``valid``,
    ``lat_deg``, ``lon_deg``, ``speed_mps``, ``course_deg``, ``day`` (days since 1970-01-01). ZDA:
    ``tod_s``, ``day``. GSA: ``fix_type``, ``n_used``, ``pdop``, ``hdop``, ``vdop``. GSV: ``n_msg``,
    ``i_msg``, ``in_view``, ``snr_sum``, ``snr_n``.

    Raises
    ------
    FormatError
        The file is missing, empty, binary, or holds no NMEA sentence at all.
    """
    p = Path(path)
    try:
        data = p.read_bytes()
    except FileNotFoundError:
        raise FormatError(f"{p}: no such file") from None
    except IsADirectoryError:
        raise FormatError(f"{p}: is a folder, not a log") from None
    if not data[:4096].strip() and not data.strip():
        raise FormatError(f"{p}: empty log")
    head = np.frombuffer(data[:65536], np.uint8)
    odd = (head > 126) | ((head < 32) & (head != 9) & (head != 10) & (head != 13))
    if np.any(head == 0) or odd.sum() > 0.05 * head.size:
        raise FormatError(f"{p}: a binary file, not an NMEA text log")
    log = decode_nmea(data, str(p))
    if sum(log.account.decoded.values()) + log.account.ignored == 0:
        first = log.account.malformed_lines[0] if log.account.malformed_lines else (1, "no sentence")
        n = log.account.n_lines
        raise FormatError(f"{p}: no valid NMEA sentence in {n} line{'s' if n != 1 else ''} "
                          f"(line {first[0]}: {first[1]})")
    return log
