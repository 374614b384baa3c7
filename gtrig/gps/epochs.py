"""One record per receiver epoch: GGA's position joined with its GST, the date and the log's clock.

Time: GGA carries only the UTC time of day. The date comes from the nearest dated sentence before it
(RMC or ZDA; the first one after it for the epochs before any), else from the log's own clock when
that is a Unix time (the RAWSEEDS logs); the day is the one that puts the epoch nearest that
reference, which handles a midnight roll-over between the two. Without any date the day count starts
at 0 and steps at each roll-over of the time of day. The log's clock is kept beside UTC; their offset
(log minus UTC) is what a synchronisation needs.

An epoch is a GGA sentence with a position and a fix; GGAs without a fix (quality 0, or the
all-zero "no position yet" records a receiver prints before its first fix), repeated epochs (the
receiver re-sending its last solution with the same time) and epochs going back in time are dropped
and counted with their reason. GST joins its GGA by equal UTC time.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from gtrig.gps.covariance import CovSource, gst_cov_enu, hdop_cov_enu
from gtrig.gps.nmea import NmeaLog

DAY_S = 86400.0
#: a log-clock value above this is a Unix time (after 2001-09-09), so it can date the epochs
UNIX_MIN_S = 1.0e9

FIX_NAMES = {0: "invalid", 1: "single", 2: "dgps", 3: "pps", 4: "rtk_fixed", 5: "rtk_float", 6: "dead_reckoning",
             7: "manual", 8: "simulated", 9: "sbas"}


@dataclass(frozen=True)
class Epochs:
    """Receiver epochs with a fix, in time order.

    Attributes
    ----------
    line : (N,) line of the GGA (or .pos row) in the log, 1-based.
    utc_s : (N,) UTC seconds since 1970 (or since the first day's midnight when ``date_known`` is False).
    stamp_log_s : (N,) the log's own clock at the GGA line, ``nan`` without one.
    lat_deg, lon_deg : (N,) WGS84 degrees.
    h_m : (N,) ellipsoidal height (GGA's altitude plus its geoid separation), metres.
    quality : (N,) int8 GGA fix quality (RTKLIB's Q mapped onto it).
    n_sat, hdop : (N,) satellites used and HDOP (``nan`` when not given).
    sigma_lat_m, sigma_lon_m : (N,) the receiver's 1-sigma latitude/longitude errors (``nan`` without GST).
    cov_enu : (N, 3, 3) covariance in the fix's own east-north-up, metres^2.
    cov_source : (N,) int8 :class:`~gtrig.gps.covariance.CovSource`.
    date_known : whether ``utc_s`` carries the date.
    dropped : reason -> count of GGA records that are not epochs.
    """

    line: np.ndarray
    utc_s: np.ndarray
    stamp_log_s: np.ndarray
    lat_deg: np.ndarray
    lon_deg: np.ndarray
    h_m: np.ndarray
    quality: np.ndarray
    n_sat: np.ndarray
    hdop: np.ndarray
    sigma_lat_m: np.ndarray
    sigma_lon_m: np.ndarray
    cov_enu: np.ndarray
    cov_source: np.ndarray
    date_known: bool = True
    dropped: dict[str, int] = field(default_factory=dict)
    dropped_lines: tuple[tuple[int, str], ...] = ()

    def __len__(self) -> int:
        return int(self.line.size)

    def select(self, m: np.ndarray) -> Epochs:
        kw = {k: getattr(self, k)[m] for k in ("line", "utc_s", "stamp_log_s", "lat_deg", "lon_deg", "h_m",
                                                "quality", "n_sat", "hdop", "sigma_lat_m", "sigma_lon_m",
                                                "cov_enu", "cov_source")}
        return Epochs(**kw, date_known=self.date_known, dropped=dict(self.dropped), dropped_lines=self.dropped_lines)


def _day_reference(line: np.ndarray, ref_line: np.ndarray, ref_abs: np.ndarray) -> np.ndarray:
    """For each line, the absolute time of the nearest preceding reference (the first one for those before)."""
    j = np.searchsorted(ref_line, line, side="right") - 1
    return ref_abs[np.clip(j, 0, ref_abs.size - 1)]


def _absolute(tod: np.ndarray, ref: np.ndarray) -> np.ndarray:
    """The instant with time of day ``tod`` nearest the absolute ``ref`` (midnight roll-over)."""
    return tod + DAY_S * np.round((ref - tod) / DAY_S)


def absolute_utc(log: NmeaLog, line: np.ndarray, tod: np.ndarray, stamp: np.ndarray) -> tuple[np.ndarray, bool]:
    """UTC seconds since 1970 of sentences at ``line`` with time of day ``tod`` (module docstring)."""
    dated = [log.sentences[k] for k in ("RMC", "ZDA") if len(log.sentences.get(k, ())) > 0]
    if dated:
        ref_line = np.concatenate([d.line for d in dated])
        ref_abs = np.concatenate([d["day"] * DAY_S + d["tod_s"] for d in dated])
        o = np.argsort(ref_line, kind="stable")
        return _absolute(tod, _day_reference(line, ref_line[o], ref_abs[o])), True
    if stamp.size and np.all(np.isfinite(stamp)) and np.all(stamp > UNIX_MIN_S):
        return _absolute(tod, stamp), True
    # no date anywhere: count the roll-overs (the time of day dropping by more than half a day)
    day = np.concatenate([[0], np.cumsum(np.diff(tod) < -DAY_S / 2)])
    return tod + DAY_S * day, False


def epochs_from_nmea(log: NmeaLog) -> Epochs:
    """Join a decoded NMEA log into :class:`Epochs` (module docstring)."""
    gga, gst = log.sentences["GGA"], log.sentences["GST"]
    utc, date_known = absolute_utc(log, gga.line, gga["tod_s"], gga["stamp_log_s"])
    q = gga["quality"]
    dropped: dict[str, int] = {}
    reason = np.full(len(gga), "", dtype=object)

    def drop(m: np.ndarray, why: str) -> None:
        new = m & (reason == "")
        if np.any(new):
            dropped[why] = dropped.get(why, 0) + int(new.sum())
            reason[new] = why

    lat, lon = gga["lat_deg"], gga["lon_deg"]
    drop((q > 0) & (lat == 0) & (lon == 0), "no position yet (0 N 0 E before the first fix)")
    drop(q == 0, "no fix (quality 0)")
    drop(np.isnan(lat), "no position")
    # time order: an epoch must be later than every earlier epoch that was kept (running maximum)
    live = reason == ""
    prev_max = np.maximum.accumulate(np.where(live, utc, -np.inf))
    prev_max = np.concatenate([[-np.inf], prev_max[:-1]])
    drop(live & (utc == prev_max), "repeated epoch (same UTC time as the one before)")
    drop(live & (utc < prev_max), "epoch goes back in time")
    keep = np.flatnonzero(reason == "")
    bad_i = np.flatnonzero(reason != "")
    dropped_lines = tuple((int(gga.line[i]), str(reason[i])) for i in bad_i[:50])

    n = keep.size
    sig_lat = np.full(n, np.nan)
    sig_lon = np.full(n, np.nan)
    cov = hdop_cov_enu(gga["hdop"][keep], q[keep])
    src = np.full(n, CovSource.HDOP, np.int8)
    if len(gst):
        gst_utc, _ = absolute_utc(log, gst.line, gst["tod_s"], gst["stamp_log_s"])
        # the first GST of each UTC time (a receiver repeating an epoch repeats its GST too)
        key_g = np.round(gst_utc * 1000).astype(np.int64)
        uk, first = np.unique(key_g, return_index=True)
        key_e = np.round(utc[keep] * 1000).astype(np.int64)
        j = np.clip(np.searchsorted(uk, key_e), 0, uk.size - 1)
        has = uk[j] == key_e
        # a GST of all-zero sigmas (a receiver before its first solution) carries no covariance
        zero = (gst["sigma_lat_m"] == 0) & (gst["sigma_lon_m"] == 0)
        has &= ~zero[first[j]]
        g = first[j[has]]
        c, s = gst_cov_enu(gst["major_m"][g], gst["minor_m"][g], gst["orient_deg"][g], gst["sigma_lat_m"][g],
                           gst["sigma_lon_m"][g], gst["sigma_alt_m"][g])
        cov[has], src[has] = c, s
        sig_lat[has], sig_lon[has] = gst["sigma_lat_m"][g], gst["sigma_lon_m"][g]
    sep = np.nan_to_num(gga["geoid_sep_m"][keep])
    return Epochs(line=gga.line[keep], utc_s=utc[keep], stamp_log_s=gga["stamp_log_s"][keep], lat_deg=lat[keep],
                  lon_deg=lon[keep], h_m=gga["alt_msl_m"][keep] + sep, quality=q[keep], n_sat=gga["n_sat"][keep],
                  hdop=gga["hdop"][keep], sigma_lat_m=sig_lat, sigma_lon_m=sig_lon, cov_enu=cov, cov_source=src,
                  date_known=date_known, dropped=dropped, dropped_lines=dropped_lines)
