"""The 3 x 3 ENU covariance of a fix: from the receiver's GST error ellipse, or from HDOP.

GST (NMEA 0183) gives the 1-sigma horizontal error ellipse (semi-major ``a``, semi-minor ``b``,
orientation ``theta`` of the semi-major axis, degrees clockwise from true north) and the 1-sigma
errors of latitude, longitude and altitude. With the semi-major axis along ``u = (sin theta, cos theta)``
in (east, north) the horizontal covariance is ``a^2 u u^T + b^2 v v^T`` (``v`` perpendicular to ``u``),
whose diagonal must give back the latitude (north) and longitude (east) sigmas.

The RAWSEEDS Trimble 5700 logs break that rule: their latitude sigma equals the ellipse's *east*
standard deviation and vice versa (the ellipse is read from east, not north), while the jitter of
the positions themselves follows the latitude/longitude sigmas (docs/gps.md measures both). So each
record is checked: where the ellipse, read by the standard, reproduces the latitude/longitude sigmas
(to 5 %), the full ellipse is used; where it does not, the diagonal comes from the latitude and
longitude sigmas and the unknown-sign correlation ``c`` (from the ellipse's ``(a^2 - b^2)``) is
bounded by adding ``|c|`` to both variances, a covariance that contains either sign.

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
    GST_SIGMAS = 1  # the ellipse disagrees with the sigmas (the Trimble convention): sigmas + bounded correlation
    HDOP = 2
    RTKLIB = 3


def gst_cov_enu(major_m: np.ndarray, minor_m: np.ndarray, orient_deg: np.ndarray, sigma_lat_m: np.ndarray,
                sigma_lon_m: np.ndarray, sigma_alt_m: np.ndarray, tol: float = 0.05) -> tuple[np.ndarray, np.ndarray]:
    """ENU covariances (N, 3, 3) from GST fields (N,), and the :class:`CovSource` per record.

    A record's ellipse is used when its diagonal matches the latitude/longitude sigmas to ``tol``
    (relative, or 5 mm), else the sigmas with the correlation bound (module docstring).
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

    use_ellipse = close(cEE, sE) & close(cNN, sN) & np.isfinite(cEN)
    c_bound = np.where(np.isfinite(cEN), np.abs(cEN), 0.0)
    cov = np.zeros((major_m.size, 3, 3))
    cov[:, 0, 0] = np.where(use_ellipse, cEE, sE**2 + c_bound)
    cov[:, 1, 1] = np.where(use_ellipse, cNN, sN**2 + c_bound)
    cov[:, 0, 1] = cov[:, 1, 0] = np.where(use_ellipse, cEN, 0.0)
    cov[:, 2, 2] = np.square(sigma_alt_m)
    src = np.where(use_ellipse, CovSource.GST_ELLIPSE, CovSource.GST_SIGMAS).astype(np.int8)
    return cov, src


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
