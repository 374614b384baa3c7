"""The NMEA reader on hand-made sentences: checksums (full, truncated, bad), talkers, field counts,
ranges, dates and day roll-over, the ellipse convention check, RTKLIB .pos, and the frames."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from gtrig.errors import FormatError, InputError
from gtrig.gps.covariance import CovSource, gst_cov_enu
from gtrig.gps.epochs import epochs_from_nmea
from gtrig.gps.frames import Origin, to_local
from gtrig.gps.groundtruth import GpsOptions, gps_ground_truth
from gtrig.gps.nmea import days_from_civil, decode_nmea

from ._nmea_text import GGA, GST, cs


def test_checksum_full_truncated_and_bad() -> None:
    good = cs(GGA.format(t="120000.00", q=4))
    trunc = good[:-1]  # RAWSEEDS: only the first hex digit kept
    wrong_digit = "%X" % ((int(good[-2], 16) + 1) % 16)
    bad = good[:-2] + wrong_digit + good[-1]
    log = decode_nmea("\n".join([good, trunc, bad, ""]).encode())
    a = log.account
    assert a.checksums == {"full": 1, "truncated": 1, "none": 0, "bad": 1}
    assert a.decoded["GGA"] == 2 and a.malformed == {"checksum mismatch": 1}
    assert a.malformed_lines == ((3, "checksum mismatch"),)


def test_fields_equal_python_float_and_degrees() -> None:
    log = decode_nmea(cs(GGA.format(t="235959.80", q=4)).encode())
    g = log.sentences["GGA"]
    assert g["lat_deg"][0] == 45 + float("30.36844637") / 60
    assert g["lon_deg"][0] == 9 + float("09.97033083") / 60
    assert g["tod_s"][0] == pytest.approx(86399.8, abs=1e-9)
    assert g["alt_msl_m"][0] == 129.085 and g["quality"][0] == 4


@pytest.mark.parametrize("talker", ["GP", "GN", "GL", "GA", "GB", "BD"])
def test_talkers(talker: str) -> None:
    log = decode_nmea(cs(talker + GGA.format(t="120000.00", q=4)[2:]).encode())
    assert log.account.decoded["GGA"] == 1 and talker in log.talkers


def test_malformed_reasons_by_line() -> None:
    lines = [cs(GGA.format(t="120000.00", q=4)),
             cs("GPGGA,120000.20,4530.3,N,00909.9,E,4,8,0.9,129.0,M,48.0,M"),  # 12 fields
             cs("GPGGA,120000.40,9530.36844637,N,00909.97033083,E,4,8,0.9,129.0,M,48.0,M,1.0,0000"),  # lat 95
             cs("GPGGA,126100.00,4530.3,N,00909.9,E,4,8,0.9,129.0,M,48.0,M,1.0,0000"),  # minute 61
             cs("GPGGA,120000.60,4530.3,X,00909.9,E,4,8,0.9,129.0,M,48.0,M,1.0,0000"),
             "garbage without a sentence", "\x01\x02\x03", cs("GPVTG,,T,,M,0.0,N,0.0,K,A")]
    a = decode_nmea("\n".join(lines).encode()).account
    reasons = dict(a.malformed_lines)
    assert a.decoded["GGA"] == 1 and a.ignored == 1
    assert "12 fields" in reasons[2] and "latitude out of range" in reasons[3]
    assert "hhmmss" in reasons[4] and "N/S" in reasons[5]
    assert reasons[6] == "no $ sentence on the line" and reasons[7] == "non-ASCII bytes"
    assert a.n_lines == 8 == sum(a.decoded.values()) + a.ignored + a.blank + a.n_malformed


def test_date_from_rmc_and_midnight_rollover() -> None:
    rows = []
    for t in ("235959.60", "235959.80", "000000.00", "000000.20"):
        rows += [cs(GGA.format(t=t, q=4)), cs(GST.format(t=t))]
    # one RMC before midnight dates the lot; the epochs after midnight are the next day
    rmc = cs("GPRMC,235959.60,A,4530.36844637,N,00909.97033083,E,0.0,0.0,311208,,,R")
    ep = epochs_from_nmea(decode_nmea("\n".join([rmc] + rows).encode()))
    day = days_from_civil(np.array([2008]), np.array([12]), np.array([31]))[0]
    assert ep.date_known
    np.testing.assert_allclose(ep.utc_s - day * 86400.0, [86399.6, 86399.8, 86400.0, 86400.2], atol=1e-6)
    # without any date: the day count steps at the roll-over
    ep2 = epochs_from_nmea(decode_nmea("\n".join(rows).encode()))
    assert not ep2.date_known and np.all(np.diff(ep2.utc_s) > 0)


def test_zda_dates_and_log_clock_offset() -> None:
    zda = cs("GPZDA,120000.00,04,10,2008,00,00")
    rows = [f"{1223121600.0 + 0.2 * k + 3.5:.6f}, " + cs(GGA.format(t=f"1200{0.2 * k:05.2f}", q=4)) for k in range(5)]
    ep = epochs_from_nmea(decode_nmea("\n".join([zda] + rows).encode()))
    np.testing.assert_allclose(ep.utc_s, 1223121600.0 + 0.2 * np.arange(5), atol=1e-6)
    np.testing.assert_allclose(ep.stamp_log_s - ep.utc_s, 3.5, atol=1e-6)


def test_pre_fix_records_repeats_and_no_fix_are_not_epochs() -> None:
    rows = [cs("GPGGA,120000.00,0000.0000,N,00000.0000,E,1,0,0.0,0.0,M,0.0,M,,"),
            cs("GPGGA,120000.20,,,,,0,3,,,M,,M,,"),
            cs(GGA.format(t="120000.40", q=4)), cs(GGA.format(t="120000.40", q=4)), cs(GGA.format(t="120000.60", q=5))]
    ep = epochs_from_nmea(decode_nmea("\n".join(rows).encode()))
    assert len(ep) == 2
    assert sum(ep.dropped.values()) == 3 and any("0 N 0 E" in k for k in ep.dropped)
    assert ep.cov_source.tolist() == [CovSource.HDOP, CovSource.HDOP]  # no GST: HDOP model


def test_gst_ellipse_standard_and_trimble_convention() -> None:
    # standard: major axis 30 deg east of north, the sigmas follow from the ellipse
    a, b, th = 0.03, 0.01, math.radians(30)
    sE = math.sqrt(a * a * math.sin(th) ** 2 + b * b * math.cos(th) ** 2)
    sN = math.sqrt(a * a * math.cos(th) ** 2 + b * b * math.sin(th) ** 2)
    cov, src = gst_cov_enu(*(np.array([v]) for v in (a, b, 30.0, sN, sE, 0.05)))
    assert src[0] == CovSource.GST_ELLIPSE
    assert cov[0, 0, 1] == pytest.approx((a * a - b * b) * math.sin(th) * math.cos(th))
    # Trimble/RAWSEEDS: the latitude sigma is the ellipse's east one: the orientation is the
    # semi-minor axis', the swapped ellipse is used, correlation of the other sign
    cov2, src2 = gst_cov_enu(*(np.array([v]) for v in (a, b, 30.0, sE, sN, 0.05)))
    c = (a * a - b * b) * math.sin(th) * math.cos(th)
    assert src2[0] == CovSource.GST_ELLIPSE_SWAPPED
    assert cov2[0, 0, 0] == pytest.approx(sN**2) and cov2[0, 1, 1] == pytest.approx(sE**2)
    assert cov2[0, 0, 1] == pytest.approx(-c)
    # sigmas that neither reading gives: the sigmas, and a bound that contains either sign of c
    cov3, src3 = gst_cov_enu(*(np.array([v]) for v in (a, b, 30.0, 0.02, 0.02, 0.05)))
    assert src3[0] == CovSource.GST_SIGMAS and cov3[0, 0, 1] == 0.0
    for sign in (1, -1):
        C = np.array([[0.02**2, sign * abs(c)], [sign * abs(c), 0.02**2]])
        assert np.all(np.linalg.eigvalsh(cov3[0, :2, :2] - C) >= -1e-15)


def test_enu_against_ecef_formulas_and_utm_covariance() -> None:
    a, f = 6378137.0, 1 / 298.257223563
    e2 = f * (2 - f)

    def ecef(lat: float, lon: float, h: float) -> np.ndarray:
        la, lo = math.radians(lat), math.radians(lon)
        N = a / math.sqrt(1 - e2 * math.sin(la) ** 2)
        return np.array([(N + h) * math.cos(la) * math.cos(lo), (N + h) * math.cos(la) * math.sin(lo),
                         (N * (1 - e2) + h) * math.sin(la)])

    o = Origin(45.5, 9.2, 150.0)
    pts = [(45.501, 9.2013, 152.0), (45.49, 9.18, 140.0)]
    xyz, _ = to_local(np.array([p[0] for p in pts]), np.array([p[1] for p in pts]), np.array([p[2] for p in pts]), o)
    la, lo = math.radians(o.lat_deg), math.radians(o.lon_deg)
    R = np.array([[-math.sin(lo), math.cos(lo), 0],
                  [-math.sin(la) * math.cos(lo), -math.sin(la) * math.sin(lo), math.cos(la)],
                  [math.cos(la) * math.cos(lo), math.cos(la) * math.sin(lo), math.sin(la)]])
    for k, p in enumerate(pts):
        np.testing.assert_allclose(xyz[k], R @ (ecef(*p) - ecef(o.lat_deg, o.lon_deg, o.h_m)), atol=1e-6)
    # UTM: the covariance carried by the grid convergence and scale must equal J C J^T with J the
    # numerical Jacobian of pyproj's UTM over 1 m geodesic steps east and north (pyproj.Geod)
    from pyproj import Geod, Transformer

    lat0, lon0 = 45.5, 11.0
    utm = Transformer.from_crs(4326, 32632, always_xy=True)
    g = Geod(ellps="WGS84")
    x0, y0 = utm.transform(lon0, lat0)
    J = np.zeros((3, 3))
    J[2, 2] = 1.0
    for k, az in enumerate((90.0, 0.0)):
        lo, la, _ = g.fwd(lon0, lat0, az, 1.0)
        x, y = utm.transform(lo, la)
        J[:2, k] = [x - x0, y - y0]
    C = np.array([[[0.04, 0.01, 0.0], [0.01, 0.09, 0.0], [0.0, 0.0, 0.25]]])
    _, c_utm = to_local(np.array([lat0]), np.array([lon0]), np.array([0.0]), Origin(lat0, lon0, 0.0), "utm", C)
    np.testing.assert_allclose(c_utm[0], J @ C[0] @ J.T, rtol=1e-5, atol=1e-9)
    # east of the central meridian (9 E) true north points to the grid's west
    assert J[0, 1] < 0


_HEAD = ("%  GPST                  latitude(deg) longitude(deg)  height(m)   Q  ns   sdn(m)   sde(m)   sdu(m)"
         "  sdne(m)  sdeu(m)  sdun(m) age(s)  ratio")
_ROWS = (("52.600", "45.506174120", "9.166706630", "186.5270", "1", "0.0068", "0.0052", "0.0155", "-0.0021"),
         ("52.800", "45.506174140", "9.166706640", "186.5280", "2", "0.1068", "0.0852", "0.1555", "0.0321"),
         ("53.000", "45.506174160", "9.166706650", "186.5290", "1", "0.0068", "0.0052", "0.0155", "-0.0021"))
POS = "\n".join(["% program   : RTKPOST ver.2.4.3", "% pos mode  : kinematic", _HEAD]
                + [f"2008/10/04 13:55:{t}   {la}    {lo}   {h}   {q}   9   {n}   {e}   {u}   {ne}   0.0010  -0.0042"
                   "   0.60   12.3" for t, la, lo, h, q, n, e, u, ne in _ROWS]) + "\n"


def test_rtklib_pos(tmp_path: Path) -> None:
    p = tmp_path / "run.pos"
    p.write_text(POS)
    res = gps_ground_truth(p, GpsOptions())
    assert res.log_format == "rtklib" and len(res.track) == 2  # the float row is not asked for
    ep = res.epochs
    # GPST - UTC = 14 s in 2008
    day = days_from_civil(np.array([2008]), np.array([10]), np.array([4]))[0]
    assert ep.utc_s[0] == pytest.approx(day * 86400 + 13 * 3600 + 55 * 60 + 52.6 - 14, abs=1e-6)
    assert ep.quality.tolist() == [4, 5, 4]
    assert ep.cov_enu[0, 0, 1] == pytest.approx(-(0.0021**2))  # sdne is the signed root of the covariance
    assert ep.cov_enu[0, 1, 1] == pytest.approx(0.0068**2) and ep.cov_enu[0, 0, 0] == pytest.approx(0.0052**2)


def test_no_fix_of_the_kind_asked(tmp_path: Path) -> None:
    p = tmp_path / "float.nmea"
    p.write_text("\n".join(cs(GGA.format(t=f"1200{0.2 * k:05.2f}", q=5)) for k in range(10)) + "\n")
    with pytest.raises(InputError, match="no fix of the kind asked"):
        gps_ground_truth(p)


def test_too_many_malformed_refused(tmp_path: Path) -> None:
    p = tmp_path / "bad.nmea"
    rows = [cs(GGA.format(t=f"1200{0.2 * k:05.2f}", q=4)) for k in range(10)]
    rows[3] = cs("GPGGA,120000.60,9530.0,N,00909.9,E,4,8,0.9,129.0,M,48.0,M,1.0,0000")
    p.write_text("\n".join(rows) + "\n")
    with pytest.raises(FormatError, match=r"bad.nmea:4: GGA latitude out of range"):
        gps_ground_truth(p)
    # a few bad sentences in a long log are skipped and counted instead
    ok = gps_ground_truth(p, GpsOptions(max_malformed=0.2))
    assert len(ok.track) == 9 and ok.account.malformed_lines[0][0] == 4


def test_zero_sigma_gst_and_missing_hdop_are_no_covariance(tmp_path: Path) -> None:
    rows = []
    for k in range(6):
        t = f"1200{0.2 * k:05.2f}"
        rows.append(cs(GGA.format(t=t, q=4)))
        rows.append(cs(f"GPGST,{t},0.0,0.0,0.0,0.0,0.0,0.0,0.0") if k < 3 else cs(GST.format(t=t)))
    rows.append(cs("GPGGA,120001.20,4530.36844637,N,00909.97033083,E,4,8,,129.085,M,48.022,M,1.0,0000"))
    p = tmp_path / "z.nmea"
    p.write_text("\n".join(rows) + "\n")
    res = gps_ground_truth(p)
    # the zero-sigma GSTs fall back to HDOP (flagged); no GST and no HDOP: refused with its reason
    assert res.all_epochs.counts()["flagged"] == 3 and len(res.track) == 6
    assert res.all_epochs.reasons[-1] == "no covariance (no usable GST, no HDOP)"
    assert np.all(np.linalg.eigvalsh(res.track.cov) > 0)
