"""What a match's covariance owes to errors that do not average over the points.

:func:`gtrig.scanmatch.icp.evaluate` gives ``s^2 H^-1``, the covariance for independent point
errors. Two physical errors are shared by many points and add to it:

- a surface's range bias: a scanner's range error depends on the surface's reflectivity (darker:
  longer), so all points of one surface move together. With ``J_k`` the Jacobian rows of surface
  ``k``'s inliers, the sandwich ``H^-1 (sigma_b^2 sum_k (sum_i J_i)(sum_i J_i)^T) H^-1`` adds it, for
  each of the two scans (their surfaces are the same walls seen from two places, biased independently);
- the platform's tilt on an uneven floor: a scanner ``h`` metres above the floor moves sideways by
  ``h * tilt``; both scanners of a rigid robot move alike, so the whole scan translates. Each scan adds
  ``(h * sigma_tilt)^2`` per axis to the translation.

Surfaces are runs of scan-order neighbours whose normals agree within 20 degrees.
"""

from __future__ import annotations

import numpy as np

from gtrig.scanmatch.icp import IcpResult
from gtrig.scanmatch.scan import NORMAL_GAP_M, PlanarScan

SURFACE_MAX_TURN_RAD = np.radians(20.0)


def surface_labels(scan: PlanarScan) -> np.ndarray:
    """(N,) integer label of the surface (run of consistent neighbours) each point belongs to."""
    xy, n = scan.xy, scan.normals
    if len(xy) == 0:
        return np.zeros(0, np.int64)
    gap = np.linalg.norm(np.diff(xy, axis=0), axis=1)
    r = np.linalg.norm(xy[1:], axis=1)
    cosang = np.abs(np.sum(n[1:] * n[:-1], axis=1))
    brk = (gap > NORMAL_GAP_M + 0.07 * r) | (cosang < np.cos(SURFACE_MAX_TURN_RAD)) | ~scan.normal_ok[1:]
    return np.r_[0, np.cumsum(brk)]


def systematic_cov(res: IcpResult, cur: PlanarScan, surface_bias_sigma_m: float,
                   tilt_shift_sigma_m: float) -> np.ndarray:
    """(3, 3) covariance to add to ``res.cov`` for the surfaces' range bias and the platforms' tilt.

    Parameters
    ----------
    res : the match (its inliers and Hessian).
    cur : the current scan of the match.
    surface_bias_sigma_m : standard deviation of one surface's range bias, metres.
    tilt_shift_sigma_m : standard deviation of one scan's sideways shift by the tilt, per axis, metres
        (scanner height times the floor's tilt).
    """
    out = np.zeros((3, 3))
    if res.n_inliers > 3 and surface_bias_sigma_m > 0 and np.all(np.isfinite(res.cov)):
        lab = surface_labels(cur)[res.inlier]
        J = res.jacobian[res.inlier]
        sums = np.zeros((int(lab.max()) + 1 if lab.size else 1, 3))
        np.add.at(sums, lab, J)
        B = sums.T @ sums
        Hinv = np.linalg.inv(res.hessian)
        out += 2.0 * surface_bias_sigma_m**2 * (Hinv @ B @ Hinv)
    if tilt_shift_sigma_m > 0:
        out[:2, :2] += 2.0 * tilt_shift_sigma_m**2 * np.eye(2)
    return out

