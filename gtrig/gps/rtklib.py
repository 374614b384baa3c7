"""RTKLIB solution files (``.pos``, rtkpost / rnx2rtkp / rtknavi output) in latitude/longitude/height.

Header lines start with ``%``; the column line names the time system (``GPST``, ``UTC`` or ``JST``)
and whether time is ``yyyy/mm/dd hh:mm:ss.sss`` or ``week tow``. A row holds latitude and longitude
(degrees), ellipsoidal height (metres), the quality flag Q (1 fix, 2 float, 3 SBAS, 4 DGPS,
5 single, 6 PPP), the satellite count ns, and ``sdn sde sdu sdne sdeu sdun`` (metres): the standard
deviations, and the signed square roots of the covariances (``sign(c) sqrt(|c|)``, RTKLIB manual,
appendix B.5); then ``age`` and ``ratio``.

Q is mapped onto GGA's fix quality (1 -> 4, 2 -> 5, 3 -> 9, 4 -> 2, 5 -> 1, 6 -> 2) so one filter
serves both. GPS time is turned into UTC with the leap seconds of :data:`LEAP_SECONDS`.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from gtrig.errors import FormatError
from gtrig.gps.covariance import CovSource
from gtrig.gps.epochs import DAY_S, Epochs
from gtrig.gps.nmea import days_from_civil
from gtrig.io.text import read_text

Q_TO_GGA = {1: 4, 2: 5, 3: 9, 4: 2, 5: 1, 6: 2}
#: (UTC instant from which it holds, GPS - UTC seconds)
LEAP_SECONDS = ((362793600, 1), (394329600, 2), (425865600, 3), (489024000, 4), (567993600, 5),
                (631152000, 6), (662688000, 7), (709948800, 8), (741484800, 9), (773020800, 10),
                (820454400, 11), (867715200, 12), (915148800, 13), (1136073600, 14), (1230768000, 15),
                (1341100800, 16), (1435708800, 17), (1483228800, 18))
GPS_EPOCH_UNIX_S = 315964800.0


def gps_minus_utc_s(gps_unix_s: np.ndarray) -> np.ndarray:
    """GPS - UTC (seconds) at instants given as GPS seconds counted from the Unix epoch."""
    starts = np.array([s for s, _ in LEAP_SECONDS], float)
    leaps = np.array([0] + [v for _, v in LEAP_SECONDS], float)
    return leaps[np.searchsorted(starts, gps_unix_s - leaps[np.searchsorted(starts, gps_unix_s, "right")], "right")]


def read_rtklib_pos(path: str | os.PathLike[str]) -> Epochs:
    """Epochs from an RTKLIB ``.pos`` file (module docstring). One-line :class:`FormatError` on bad input."""
    p = Path(path)
    lines = read_text(p, "RTKLIB .pos text file", encoding="ascii").splitlines()
    header = [ln for ln in lines if ln.startswith("%")]
    cols_line = next((ln for ln in reversed(header) if "latitude" in ln or "x-ecef" in ln), None)
    if cols_line is None:
        raise FormatError(f"{p}: not an RTKLIB .pos file (no '%  ... latitude(deg) longitude(deg) ...' header)")
    if "x-ecef" in cols_line or "e-baseline" in cols_line:
        raise FormatError(f"{p}: ECEF/ENU .pos output; write the solution as lat/lon/height (deg)")
    if "latitude(d'\")" in cols_line:
        raise FormatError(f"{p}: .pos in deg-min-sec; write the solution in decimal degrees")
    system = "GPST" if "GPST" in cols_line else "UTC" if "UTC" in cols_line else "JST" if "JST" in cols_line else ""
    if not system:
        raise FormatError(f"{p}: the .pos header does not name its time system (GPST/UTC/JST)")
    rows: list[list[str]] = []
    line_no: list[int] = []
    for i, ln in enumerate(lines):
        if ln.startswith("%") or not ln.strip():
            continue
        rows.append(ln.split())
        line_no.append(i + 1)
    if not rows:
        raise FormatError(f"{p}: no solution rows")
    week_tow = "/" not in rows[0][0]
    tcols = 2
    need = tcols + 3 + 2 + 6
    for r, row_no in zip(rows, line_no, strict=True):
        if len(r) < need:
            raise FormatError(f"{p}:{row_no}: {len(r)} columns, a .pos row has at least {need}")
    try:
        num = np.array([[float(v) for v in r[tcols:need]] for r in rows])
        if week_tow:
            t_gps = GPS_EPOCH_UNIX_S + np.array([float(r[0]) * 7 * DAY_S + float(r[1]) for r in rows])
        else:
            ymd = np.array([[int(v) for v in r[0].split("/")] for r in rows])
            ok = (ymd.dtype != object and ymd.ndim == 2 and ymd.shape[1] == 3)
            bad_date = np.flatnonzero(~((ymd[:, 0] >= 1980) & (ymd[:, 0] <= 2200) & (ymd[:, 1] >= 1) & (ymd[:, 1] <= 12)
                                        & (ymd[:, 2] >= 1) & (ymd[:, 2] <= 31))) if ok else np.array([0])
            if bad_date.size:
                raise FormatError(f"{p}:{line_no[int(bad_date[0])]}: the date is not yyyy/mm/dd between 1980 and 2200")
            hms = np.array([[float(v) for v in r[1].split(":")] for r in rows])
            t_gps = days_from_civil(ymd[:, 0], ymd[:, 1], ymd[:, 2]) * DAY_S + hms @ np.array([3600.0, 60.0, 1.0])
    except ValueError as e:
        raise FormatError(f"{p}: a .pos value is not a number ({e})") from None
    if not np.all(np.isfinite(t_gps)):
        raise FormatError(f"{p}:{line_no[int(np.argmax(~np.isfinite(t_gps)))]}: the time is not a finite number")
    if system == "GPST" or week_tow:
        utc = t_gps - gps_minus_utc_s(t_gps)
    elif system == "JST":
        utc = t_gps - 9 * 3600.0
    else:
        utc = t_gps
    lat, lon, h, q, ns = num[:, 0], num[:, 1], num[:, 2], num[:, 3].astype(int), num[:, 4]
    bad = np.flatnonzero(~((np.abs(lat) <= 90) & (np.abs(lon) <= 180) & np.isin(q, list(Q_TO_GGA))))
    if bad.size:
        raise FormatError(f"{p}:{line_no[bad[0]]}: latitude, longitude or Q out of range")
    sdn, sde, sdu, sdne, sdeu, sdun = (num[:, 5 + k] for k in range(6))
    cov = np.zeros((len(rows), 3, 3))
    cov[:, 0, 0], cov[:, 1, 1], cov[:, 2, 2] = sde**2, sdn**2, sdu**2
    cen = np.sign(sdne) * sdne**2
    ceu = np.sign(sdeu) * sdeu**2
    cun = np.sign(sdun) * sdun**2
    cov[:, 0, 1] = cov[:, 1, 0] = cen
    cov[:, 0, 2] = cov[:, 2, 0] = ceu
    cov[:, 1, 2] = cov[:, 2, 1] = cun
    quality = np.array([Q_TO_GGA[v] for v in q], np.int8)
    order = np.argsort(utc, kind="stable")
    keep = order[np.concatenate([[True], np.diff(utc[order]) > 0])]
    n = keep.size
    return Epochs(line=np.array(line_no)[keep], utc_s=utc[keep], stamp_log_s=np.full(n, np.nan),
                  lat_deg=lat[keep], lon_deg=lon[keep], h_m=h[keep], quality=quality[keep], n_sat=ns[keep],
                  hdop=np.full(n, np.nan), sigma_lat_m=sdn[keep], sigma_lon_m=sde[keep], cov_enu=cov[keep],
                  cov_source=np.full(n, CovSource.RTKLIB, np.int8), date_known=True,
                  dropped={"repeated epoch (same time as the one before)": len(rows) - n} if n < len(rows) else {})
