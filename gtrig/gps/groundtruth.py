"""RTK-GPS ground truth: a log in, a position-only :class:`~gtrig.trajectory.PoseTrack` out.

``read -> epochs -> filter -> local frame``: the log is decoded (NMEA 0183, RAWSEEDS or RTKLIB),
joined into receiver epochs (:mod:`gtrig.gps.epochs`), filtered by fix type, sigma and outliers
(:mod:`gtrig.gps.filter`) and carried into ENU or UTM at the origin (:mod:`gtrig.gps.frames`; the
first kept fix by default, as RAWSEEDS did, so the base station's absolute offset cancels). The track
has ``cov_kind="xyz"``: the antenna's position with its 3 x 3 covariance in the output frame.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Literal

import numpy as np

from gtrig.errors import FormatError, InputError
from gtrig.gps.covariance import CovSource
from gtrig.gps.epochs import Epochs, epochs_from_nmea
from gtrig.gps.filter import FilterOptions
from gtrig.gps.filter import filter_epochs as _filter
from gtrig.gps.frames import Frame, Origin, to_local
from gtrig.gps.nmea import LineAccount, NmeaLog, read_nmea
from gtrig.trajectory import PoseStatus, PoseTrack

LogFormat = Literal["auto", "rawseeds", "nmea", "rtklib"]
Clock = Literal["auto", "log", "utc"]


@dataclass(frozen=True)
class GpsOptions:
    """What :func:`gps_ground_truth` does.

    Attributes
    ----------
    format : the log's layout; ``auto`` looks at its first lines.
    filter : fix type, sigma cut, outlier test.
    frame : ``enu`` or ``utm``.
    origin : ``None`` for the first kept fix, else a WGS84 origin.
    clock : the track's stamps: the log's own clock (``log``; what the other sensors of a recording
        share), UTC seconds (``utc``), or ``auto`` (the log's clock when every epoch has one).
    max_malformed : the share of malformed sentences above which the log is refused.
    """

    format: LogFormat = "auto"
    filter: FilterOptions = field(default_factory=FilterOptions)
    frame: Frame = "enu"
    origin: Origin | None = None
    clock: Clock = "auto"
    max_malformed: float = 0.01


@dataclass(frozen=True)
class GpsResult:
    """The ground truth and everything the report needs.

    Attributes
    ----------
    track : the kept fixes (OK, or FLAGGED when their covariance comes from HDOP).
    all_epochs : every epoch, the refused ones REJECTED with their reason (same frame and clock).
    epochs : the receiver epochs (geodetic), aligned with ``all_epochs``.
    origin : the frame's origin.
    account : what became of every line (NMEA logs; ``None`` for RTKLIB).
    clock : "log" or "utc": what ``stamps_s`` are.
    clock_offset_s : statistics of (log clock - UTC) over the epochs: median, min, max, drift (s/s).
    """

    track: PoseTrack
    all_epochs: PoseTrack
    epochs: Epochs
    origin: Origin
    frame: Frame
    account: LineAccount | None
    clock: str
    clock_offset_s: dict[str, float]
    log_format: str


def sniff_format(path: Path) -> str:
    """``rawseeds``, ``nmea`` or ``rtklib`` from the first lines of ``path``."""
    try:
        with open(path, "rb") as f:
            head = f.read(4096)
    except FileNotFoundError:
        raise FormatError(f"{path}: no such file") from None
    except IsADirectoryError:
        raise FormatError(f"{path}: is a folder, not a log") from None
    text = head.decode("ascii", errors="replace")
    if text.lstrip().startswith("%") and ("latitude" in text or "RTKLIB" in text or "program" in text):
        return "rtklib"
    for ln in text.splitlines():
        s = ln.strip()
        if not s:
            continue
        d = s.find("$")
        return "rawseeds" if d > 0 else "nmea"
    return "nmea"


def _clock_offset(ep: Epochs) -> dict[str, float]:
    ok = np.isfinite(ep.stamp_log_s)
    if not np.any(ok) or not ep.date_known:
        return {}
    off = ep.stamp_log_s[ok] - ep.utc_s[ok]
    t = ep.utc_s[ok]
    drift = float(np.polyfit(t - t[0], off, 1)[0]) if ok.sum() > 2 and np.ptp(t) > 0 else 0.0
    return {"median": float(np.median(off)), "min": float(off.min()), "max": float(off.max()), "drift": drift}


def read_epochs(path: str | os.PathLike[str], fmt: LogFormat = "auto", max_malformed: float = 0.01,
                ) -> tuple[Epochs, LineAccount | None, str]:
    """The receiver epochs of a log and the account of its lines; refuses a log with more than
    ``max_malformed`` of its sentences malformed, naming the first bad line."""
    from gtrig.gps.rtklib import read_rtklib_pos

    p = Path(path)
    kind = sniff_format(p) if fmt == "auto" else fmt
    if kind == "rtklib":
        return read_rtklib_pos(p), None, kind
    log: NmeaLog = read_nmea(p)
    acc = log.account
    if kind == "rawseeds" and acc.n_sentences and np.isnan(log.sentences["GGA"]["stamp_log_s"]).all():
        raise FormatError(f"{p}: --format rawseeds, but no line has the 'unixtime, ' prefix")
    if acc.n_malformed > max_malformed * max(acc.n_sentences, 1):
        line, why = acc.malformed_lines[0]
        raise FormatError(f"{p}:{line}: {why} ({acc.n_malformed} of {acc.n_sentences} sentences malformed, "
                          f"more than {max_malformed:.0%})")
    return epochs_from_nmea(log), acc, kind


def gps_ground_truth(path: str | os.PathLike[str], opts: GpsOptions | None = None) -> GpsResult:
    """The RTK-GPS ground truth of one log (module docstring).

    Raises
    ------
    FormatError
        The log is empty, binary, or too corrupt (one line naming the file and line).
    InputError
        No fix of the kind asked survives the filter.
    """
    opts = opts or GpsOptions()
    p = Path(path)
    ep, acc, kind = read_epochs(p, opts.format, opts.max_malformed)
    if len(ep) == 0:
        raise InputError(f"{p}: no fix with a position in the log ({_dropped_text(ep)})")
    # filter in a provisional ENU at the first epoch (the outlier test needs metres)
    o0 = Origin(float(ep.lat_deg[0]), float(ep.lon_deg[0]), float(ep.h_m[0]))
    xyz0, cov0 = to_local(ep.lat_deg, ep.lon_deg, ep.h_m, o0, "enu", ep.cov_enu)
    assert cov0 is not None
    keep, reasons = _filter(ep, xyz0, cov0, opts.filter)
    if not np.any(keep):
        counts: dict[str, int] = {}
        for r in reasons:
            counts[r] = counts.get(r, 0) + 1
        worst = max(counts, key=lambda k: counts[k])
        raise InputError(f"{p}: no fix of the kind asked (--fix {opts.filter.fix}, --max-sigma "
                         f"{opts.filter.max_sigma_m}); {len(ep)} epochs, most refused for: {worst}")
    i0 = int(np.flatnonzero(keep)[0])
    origin = opts.origin or Origin(float(ep.lat_deg[i0]), float(ep.lon_deg[i0]), float(ep.h_m[i0]))
    xyz, cov = to_local(ep.lat_deg, ep.lon_deg, ep.h_m, origin, opts.frame, ep.cov_enu)
    has_log = bool(np.all(np.isfinite(ep.stamp_log_s)))
    if opts.clock == "log" and not has_log:
        raise InputError(f"{p}: --clock log, but the log has no clock of its own; use --clock utc")
    clock = "log" if (opts.clock == "log" or (opts.clock == "auto" and has_log)) else "utc"
    stamps = ep.stamp_log_s if clock == "log" else ep.utc_s
    if np.any(np.diff(stamps) <= 0):
        if clock == "log" and opts.clock == "log":
            raise InputError(f"{p}: the log's clock does not increase with the epochs; use --clock utc")
        clock, stamps = "utc", ep.utc_s
    status = np.where(keep, np.where(ep.cov_source == CovSource.HDOP, PoseStatus.FLAGGED, PoseStatus.OK),
                      PoseStatus.REJECTED).astype(np.uint8)
    why = np.where(keep & (ep.cov_source == CovSource.HDOP), "covariance from HDOP (no GST)", reasons)
    quat = np.tile([0.0, 0.0, 0.0, 1.0], (len(ep), 1))
    all_t = PoseTrack(stamps, xyz, quat, cov, "xyz", status, tuple(str(w) for w in why), "gps",
                      frame_id=opts.frame, child_frame_id="gps_antenna")
    return GpsResult(all_t.select(keep), all_t, ep, origin, opts.frame, acc, clock, _clock_offset(ep), kind)


def _dropped_text(ep: Epochs) -> str:
    if not ep.dropped:
        return "no GGA sentence"
    return "; ".join(f"{v} {k}" for k, v in ep.dropped.items())
