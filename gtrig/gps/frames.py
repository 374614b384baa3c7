"""WGS84 geodetic coordinates to a local metric frame: ENU at an origin, or UTM (pyproj / PROJ).

- ENU: PROJ's ``cart`` + ``topocentric`` pipeline, the exact geodetic -> ECEF -> east-north-up map at
  the origin (no flat-earth approximation), metres.
- UTM: the zone of the origin's longitude (one zone for the whole run, as RAWSEEDS did), northern or
  southern by its latitude; easting, northing and ellipsoidal height, minus the origin's.

A covariance given in the local ENU of each fix is carried into the frame: for ENU at a distant
origin the rotation between the fix's and the origin's ENU (the meridians converge); for UTM the grid
convergence angle and the point scale factor (pyproj ``get_factors``).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np

from gtrig.errors import InputError

Frame = Literal["enu", "utm"]


@dataclass(frozen=True)
class Origin:
    """The local frame's origin: WGS84 latitude, longitude (degrees) and ellipsoidal height (metres)."""

    lat_deg: float
    lon_deg: float
    h_m: float

    @staticmethod
    def parse(text: str) -> Origin:
        """From ``"LAT,LON,H"`` (degrees, degrees, metres)."""
        parts = text.split(",")
        try:
            lat, lon, h = (float(p) for p in parts)
        except ValueError:
            raise InputError(f"--origin {text!r}: expected 'first' or LAT,LON,H in degrees and metres") from None
        if not (abs(lat) <= 90 and abs(lon) <= 180 and np.isfinite(h)):
            raise InputError(f"--origin {text!r}: latitude or longitude out of range")
        return Origin(lat, lon, h)


def utm_epsg(lat_deg: float, lon_deg: float) -> int:
    """The EPSG code of the WGS84 UTM zone holding (lat, lon) (the standard 6-degree zones)."""
    zone = int(np.floor((lon_deg + 180.0) / 6.0)) % 60 + 1
    return (32600 if lat_deg >= 0 else 32700) + zone


def _rot_enu(lat_deg: np.ndarray, lon_deg: np.ndarray) -> np.ndarray:
    """(N, 3, 3) rows = east, north, up unit vectors in ECEF at (lat, lon)."""
    la, lo = np.radians(lat_deg), np.radians(lon_deg)
    sl, cl, so, co = np.sin(la), np.cos(la), np.sin(lo), np.cos(lo)
    z = np.zeros_like(la)
    return np.stack([np.stack([-so, co, z], -1), np.stack([-sl * co, -sl * so, cl], -1),
                     np.stack([cl * co, cl * so, sl], -1)], -2)


def to_local(lat_deg: np.ndarray, lon_deg: np.ndarray, h_m: np.ndarray, origin: Origin, frame: Frame = "enu",
             cov_enu: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray | None]:
    """Positions (N, 3) in the local frame, metres, and the covariances (N, 3, 3) carried into it.

    Parameters
    ----------
    lat_deg, lon_deg, h_m : (N,) WGS84 geodetic coordinates, ellipsoidal height.
    origin : the frame's origin (subtracted; for UTM its easting, northing and height).
    frame : ``"enu"`` (east, north, up at the origin) or ``"utm"`` (easting, northing, up, minus the origin's).
    cov_enu : (N, 3, 3) covariances in each fix's own ENU, or ``None``.
    """
    from pyproj import Proj, Transformer

    lat = np.asarray(lat_deg, float)
    lon = np.asarray(lon_deg, float)
    h = np.asarray(h_m, float)
    if frame == "enu":
        tr = Transformer.from_pipeline(
            f"+proj=pipeline +step +proj=cart +ellps=WGS84 +step +proj=topocentric +ellps=WGS84 "
            f"+lat_0={float(origin.lat_deg)!r} +lon_0={float(origin.lon_deg)!r} +h_0={float(origin.h_m)!r}")
        e, n, u = tr.transform(lon, lat, h)
        xyz = np.column_stack([e, n, u])
        if cov_enu is None:
            return xyz, None
        # R maps the fix's ENU into the origin's ENU: R = R_o R_f^T (both ECEF -> ENU)
        R_o = _rot_enu(np.array([origin.lat_deg]), np.array([origin.lon_deg]))[0]
        R = R_o[None] @ np.swapaxes(_rot_enu(lat, lon), 1, 2)
        return xyz, R @ cov_enu @ np.swapaxes(R, 1, 2)
    if frame == "utm":
        epsg = utm_epsg(origin.lat_deg, origin.lon_deg)
        tr = Transformer.from_crs(4326, epsg, always_xy=True)
        x, y = tr.transform(lon, lat)
        x0, y0 = tr.transform(origin.lon_deg, origin.lat_deg)
        xyz = np.column_stack([x - x0, y - y0, h - origin.h_m])
        if cov_enu is None:
            return xyz, None
        f = Proj(f"EPSG:{epsg}").get_factors(lon, lat)
        # grid north is true north turned by the meridian convergence gamma (clockwise positive in
        # PROJ's sign), and UTM distances are true ones times the point scale factor k
        g = np.radians(np.asarray(f.meridian_convergence, float))
        k = np.asarray(f.meridional_scale, float)
        c, s = np.cos(g), np.sin(g)
        R = np.zeros((lat.size, 3, 3))
        R[:, 0, 0], R[:, 0, 1], R[:, 1, 0], R[:, 1, 1], R[:, 2, 2] = k * c, -k * s, k * s, k * c, 1.0
        return xyz, R @ cov_enu @ np.swapaxes(R, 1, 2)
    raise InputError(f"frame {frame!r}: expected enu or utm")
