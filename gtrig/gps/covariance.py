"""The 3 x 3 ENU covariance of a fix: from the receiver's GST error ellipse, or from HDOP.

GST (NMEA 0183) gives the 1-sigma horizontal error ellipse (semi-major ``a``, semi-minor ``b``,
orientation ``theta`` of the semi-major axis, degrees clockwise from true north) and the 1-sigma
errors of latitude, longitude and altitude. With the semi-major axis along ``u = (sin theta, cos theta)``
in (east, north) the horizontal covariance is ``a^2 u u^T + b^2 v v^T`` (``v`` perpendicular to ``u``),
whose diagonal must give back the latitude (north) and longitude (east) sigmas.

The RAWSEEDS Trimble 5700 logs break that rule: their latitude sigma equals the ellipse's *east*
standard deviation and vice versa. Their numbers fit exactly when the orientation is that of the
semi-*minor* axis (the two semi-axes swapped), and the positions' own jitter agrees: its shape is
more likely under that reading than under the standard one or under the other reading that also
gives back the sigmas (axes from east, counter-clockwise), in each of the three shared logs
(docs/gps.md, bench/gps_accuracy.py). So each record is checked: where the standard ellipse
reproduces the latitude/longitude sigmas (to 5 %, or 5 mm), it is used; else where the swapped one
does, that one; where neither does, the diagonal comes from the latitude and longitude sigmas and
the unknown correlation ``c`` (from the ellipse's ``a^2 - b^2``) is bounded by adding ``|c|`` to both
variances, a covariance that contains either sign.

Without GST, the horizontal covariance comes from HDOP with a user-equivalent range error per fix
type (:data:`UERE_M`): ``sigma_E = sigma_N = HDOP * UERE / sqrt(2)`` (the DRMS split over two axes),
``sigma_U = VDOP_PER_HDOP * HDOP * UERE``; such fixes are flagged.
"""

from __future__ import annotations

import enum

import numpy as np

#: 1-sigma user-equivalent range error by GGA fix quality (metres), for the HDOP model: typical
#: figures of single-point L1 (1, 3), SBAS (9), code DGPS (2), RTK float (5) and RTK fixed (4)
UERE_M = {1: 4.0, 2: 0.7, 3: 4.0, 4: 0.015, 5: 0.25, 6: 10.0, 9: 1.5}
#: VDOP over HDOP when no GSA gives VDOP (open sky, mid latitudes: about 1.6)
VDOP_PER_HDOP = 1.6


class CovSource(enum.IntEnum):
    """Where a fix's covariance comes from."""

    GST_ELLIPSE = 0
    GST_SIGMAS = 1  # the ellipse agrees with the sigmas in neither reading: sigmas + bounded correlation
    HDOP = 2
    RTKLIB = 3
    GST_ELLIPSE_SWAPPED = 4  # the orientation is the semi-minor axis' (the RAWSEEDS Trimble logs)


#: names of the :class:`CovSource` codes, in code order
COV_SOURCE_NAMES = tuple(s.name.lower() for s in CovSource)


def gst_cov_enu(major_m: np.ndarray, minor_m: np.ndarray, orient_deg: np.ndarray, sigma_lat_m: np.ndarray,
                sigma_lon_m: np.ndarray, sigma_alt_m: np.ndarray, tol: float = 0.05) -> tuple[np.ndarray, np.ndarray]:
    """ENU covariances (N, 3, 3) from GST fields (N,), and the :class:`CovSource` per record.

    A record's ellipse is used when its diagonal matches the latitude/longitude sigmas to ``tol``
    (relative, or 5 mm), read by the standard or with its axes swapped; else the sigmas with the
    correlation bound (module docstring).
    """
    a2, b2 = np.square(major_m), np.square(minor_m)
    th = np.radians(orient_deg)
    uE, uN = np.sin(th), np.cos(th)
    cEE = a2 * uE**2 + b2 * uN**2
    cNN = a2 * uN**2 + b2 * uE**2
    cEN = (a2 - b2) * uE * uN
    sE, sN = sigma_lon_m, sigma_lat_m

    def close(var: np.ndarray, s: np.ndarray) -> np.ndarray:
        return np.abs(np.sqrt(var) - s) <= np.maximum(tol * s, 0.005)

    # the same ellipse with its semi-axes swapped (orientation of the semi-minor axis)
    sEE = b2 * uE**2 + a2 * uN**2
    sNN = b2 * uN**2 + a2 * uE**2
    std = close(cEE, sE) & close(cNN, sN) & np.isfinite(cEN)
    swp = ~std & close(sEE, sE) & close(sNN, sN) & np.isfinite(cEN)
    c_bound = np.where(np.isfinite(cEN), np.abs(cEN), 0.0)
    cov = np.zeros((major_m.size, 3, 3))
    cov[:, 0, 0] = np.where(std, cEE, np.where(swp, sEE, sE**2 + c_bound))
    cov[:, 1, 1] = np.where(std, cNN, np.where(swp, sNN, sN**2 + c_bound))
    cov[:, 0, 1] = cov[:, 1, 0] = np.where(std, cEN, np.where(swp, -cEN, 0.0))
    cov[:, 2, 2] = np.square(sigma_alt_m)
    src = np.where(std, CovSource.GST_ELLIPSE, np.where(swp, CovSource.GST_ELLIPSE_SWAPPED, CovSource.GST_SIGMAS))
    return cov, src.astype(np.int8)


def hdop_cov_enu(hdop: np.ndarray, quality: np.ndarray, vdop: np.ndarray | None = None) -> np.ndarray:
    """ENU covariances (N, 3, 3) from HDOP (and VDOP when known) with :data:`UERE_M` by fix quality."""
    uere = np.array([UERE_M.get(int(q), np.nan) for q in range(10)])[np.clip(quality, 0, 9)]
    s_h = hdop * uere / np.sqrt(2.0)
    s_v = (vdop if vdop is not None else VDOP_PER_HDOP * hdop) * uere
    cov = np.zeros((hdop.size, 3, 3))
    cov[:, 0, 0] = cov[:, 1, 1] = s_h**2
    cov[:, 2, 2] = s_v**2
    return cov


def sigma_horizontal(cov_enu: np.ndarray) -> np.ndarray:
    """(N,) the larger of the east and north standard deviations (RAWSEEDS's cut uses both sigmas)."""
    return np.sqrt(np.maximum(cov_enu[:, 0, 0], cov_enu[:, 1, 1]))
