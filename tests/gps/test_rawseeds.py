"""The three shared Bovisa logs against the RAWSEEDS toolkit's read_gps.m (re-implemented below from
its text) and against an independent pyproj conversion: the kept fixes and their UTM positions (first
fix subtracted) to 1 mm, and every line accounted for."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from gtrig.gps.filter import FilterOptions
from gtrig.gps.groundtruth import GpsOptions, gps_ground_truth
from gtrig.gps.report import gps_report


def _read_gps_m(path: Path) -> list[tuple[int, float, float, float, int]]:
    """read_gps.m (RAWSEEDS Metrics Computation Toolkit v1.0, Civera, Cadena, Grasa), line for line:
    a $GPGGA line sets lat/lon/height, a $GPGST line keeps the last GGA's position when its latitude
    and longitude sigmas are both under 0.2 m; ddmm.mmmm to degrees as it does; its Coticchia-Surace
    UTM formulas; the first kept record subtracted. Besides (line, x, y) it returns the fix quality of
    the GGA each record took its position from (read_gps.m never looks at it) and the GST line."""
    a, b = 6378137.0, 6356752.3142
    ep2 = ((a * a - b * b) ** 0.5 / b) ** 2
    c = a * a / b
    out = []
    lat = lon = None
    quality = -1
    for i, text in enumerate(path.read_text().splitlines()):
        if len(text) < 25:
            continue
        comma = [k for k, ch in enumerate(text) if ch == ","]

        def field(j: int, text: str = text, comma: list[int] = comma) -> str:
            return text[comma[j - 1] + 1:comma[j]]  # MATLAB's 1-based c(j)+1 : c(j+1)-1

        if text[24] == "A":
            lat, lon = float(field(3)), float(field(5))
            quality = int(field(7))
        elif text[24] == "T":
            s_lat, s_lon = float(field(7)), float(field(8))
            if s_lat < 0.2 and s_lon < 0.2 and lat is not None:
                la = math.floor(lat / 100) + math.fmod(lat / 100, math.floor(lat / 100)) * 100 / 60
                lo = math.floor(lon / 100) + math.fmod(lon / 100, math.floor(lon / 100)) * 100 / 60
                out.append((i + 1, la, lo, quality))
    res = []
    for line, la_d, lo_d, q in out:
        latr, lonr = la_d * math.pi / 180, lo_d * math.pi / 180
        tzone = math.floor(lo_d / 6 + 31)
        ang = lonr - (tzone * 6 - 183) * math.pi / 180
        A = math.cos(latr) * math.sin(ang)
        xi = 0.5 * math.log((1 + A) / (1 - A))
        eta = math.atan(math.tan(latr) / math.cos(ang)) - latr
        aux = math.cos(latr) ** 2
        ni = c * 0.9996 / math.sqrt(1 + ep2 * aux)
        zeta = 0.5 * ep2 * xi * xi * aux
        A1 = math.sin(2 * latr)
        A2 = A1 * aux
        J2 = latr + A1 / 2
        J4 = 0.75 * J2 + 0.25 * A2
        J6 = (5 * J4 + A2 * aux) / 3
        alpha = 0.75 * ep2
        beta = 5 * alpha * alpha / 3
        gamma = 35 * alpha**3 / 27
        B = 0.9996 * c * (latr - alpha * J2 + beta * J4 - gamma * J6)
        x = xi * ni * (1 + zeta / 3) + 500000.0
        y = eta * ni * (1 + zeta) + B
        res.append((line, x, y, q, line))
    x0, y0 = res[0][1], res[0][2]
    return [(line - 1, x - x0, y - y0, 0.0, q) for line, x, y, q, _ in res]


def _pyproj_utm(path: Path, gga_lines: np.ndarray) -> np.ndarray:
    """Independent: parse the GGA lines with str.split, convert with pyproj's EPSG:32632."""
    from pyproj import Transformer

    lines = path.read_text().splitlines()
    lat, lon = [], []
    for ln in gga_lines:
        f = lines[ln - 1].split(",")
        la, lo = float(f[3]), float(f[5])
        lat.append(int(la // 100) + (la - 100 * int(la // 100)) / 60)
        lon.append(int(lo // 100) + (lo - 100 * int(lo // 100)) / 60)
    x, y = Transformer.from_crs(4326, 32632, always_xy=True).transform(np.array(lon), np.array(lat))
    return np.column_stack([x - x[0], y - y[0]])


@pytest.fixture(scope="module")
def rawseeds_like(bovisa_log: Path):
    opts = GpsOptions(frame="utm", filter=FilterOptions(fix="any", max_sigma_m=0.2, outlier_gate=None))
    return bovisa_log, gps_ground_truth(bovisa_log, opts)


def test_kept_fixes_and_positions_match_read_gps_m(rawseeds_like) -> None:
    path, res = rawseeds_like
    ref = _read_gps_m(path)
    ours_lines = res.epochs.line[res.all_epochs.ok]
    ref_lines = np.array([r[0] for r in ref])
    ref_q = np.array([r[4] for r in ref])
    # read_gps.m keeps a GST after a GGA without a fix (quality 0: the receiver re-sends its last
    # solution with its old time); we do not. Everything else must be the same set of fixes.
    assert np.array_equal(ref_lines[ref_q > 0], ours_lines)
    assert np.all(np.isin(res.epochs.line, ref_lines[ref_q > 0]) == res.all_epochs.ok)
    sel = np.isin(ref_lines, ours_lines)
    ref_xy = np.array([[r[1], r[2]] for r in ref])[sel]
    # both subtract their first kept record; read_gps.m's may be a stale one, so re-reference to ours
    ref_xy = ref_xy - ref_xy[0]
    err = np.abs(res.track.xyz[:, :2] - ref_xy)
    assert err.max() < 1e-3, err.max()
    # and an independent pyproj conversion of the same GGA lines
    indep = _pyproj_utm(path, ours_lines)
    assert np.abs(res.track.xyz[:, :2] - indep).max() < 1e-3


def test_every_line_accounted_for(rawseeds_like) -> None:
    path, res = rawseeds_like
    rep = gps_report(res)
    ln = rep["lines"]
    n_lines = len(path.read_bytes().splitlines())
    assert ln["total"] == n_lines
    assert sum(ln["decoded"].values()) + ln["ignored"] + ln["blank"] + sum(ln["malformed"].values()) == n_lines
    # each GGA is an epoch (kept or refused with a reason) or not an epoch with its reason
    n_gga = ln["decoded"]["GGA"]
    assert rep["epochs"] + sum(rep["not_epochs"].values()) == n_gga
    assert rep["kept"] + sum(rep["refused"].values()) == rep["epochs"]
    assert all(r for r, k in zip(res.all_epochs.reasons, res.all_epochs.ok, strict=True) if not k)
    # the logger truncated every checksum to its first hex digit, and each one matched
    assert ln["checksums"]["truncated"] == sum(ln["decoded"].values()) and ln["checksums"]["bad"] == 0
    # GST lags GGA by about 10 ms in these logs: every epoch found its GST
    assert rep["covariance_source"]["hdop"] == 0
    # the Trimble's ellipses give back their sigmas with the semi-axes swapped (docs/gps.md)
    cs = rep["covariance_source"]
    assert cs["gst_ellipse_swapped"] + cs["gst_ellipse"] >= 0.95 * rep["epochs"]
    assert cs["gst_ellipse_swapped"] > cs["gst_ellipse"]
