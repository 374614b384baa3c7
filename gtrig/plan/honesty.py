"""Is a plan honest? Its predicted sigmas against the errors of a run, and its predicted coverage against
the share of images in which each camera found a marker, region by region of the floor.

A region is any labelling of the poses (the camera that sees the robot best, a stretch of a path). Per
region the ratio is the RMS error over the RMS predicted sigma (position: both axes pooled; yaw): about 1
when the prediction is honest, below when it is pessimistic, above when it is optimistic.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from gtrig.geometry import wrap_angle


@dataclass(frozen=True)
class RegionRatio:
    """One region's RMS error over RMS predicted sigma.

    Attributes
    ----------
    region : the region's label.
    poses : poses in it (with a finite prediction).
    position, yaw : the ratios (position: x and y pooled).
    rms_error_m, rms_sigma_m : position's RMS error and RMS predicted sigma per axis, metres.
    rms_error_rad, rms_sigma_rad : yaw's, radians.
    """

    region: int
    poses: int
    position: float
    yaw: float
    rms_error_m: float
    rms_sigma_m: float
    rms_error_rad: float
    rms_sigma_rad: float


def pose_errors(estimate_xytheta: np.ndarray, truth_xytheta: np.ndarray) -> np.ndarray:
    """(K, 3) estimate minus truth: x, y (m), yaw wrapped to (-pi, pi] (rad); both (K, 3), world frame."""
    err = np.asarray(estimate_xytheta, dtype=float) - np.asarray(truth_xytheta, dtype=float)
    err[:, 2] = wrap_angle(err[:, 2])
    return err


def region_ratios(err_xytheta: np.ndarray, cov_xytheta: np.ndarray, region: np.ndarray, min_poses: int = 10,
                  keep: np.ndarray | None = None) -> tuple[RegionRatio, ...]:
    """Per region (label ``region`` (K,)), the RMS error of ``err_xytheta`` (K, 3) over the RMS sigma of the
    predicted ``cov_xytheta`` (K, 3, 3); poses whose prediction is not finite, or not in ``keep`` (K,) bool
    when given, are left out, regions with fewer than ``min_poses`` poses are not reported. Sorted by
    label."""
    var = np.diagonal(np.asarray(cov_xytheta, dtype=float), axis1=1, axis2=2)
    ok = np.all(np.isfinite(var), axis=1) & np.all(np.isfinite(err_xytheta), axis=1)
    if keep is not None:
        ok &= np.asarray(keep, dtype=bool)
    out = []
    for r in np.unique(region[ok]):
        m = ok & (region == r)
        n = int(m.sum())
        if n < min_poses:
            continue
        e_pos = float(np.sqrt(np.mean(err_xytheta[m, :2] ** 2)))
        s_pos = float(np.sqrt(np.mean(var[m, :2])))
        e_yaw = float(np.sqrt(np.mean(err_xytheta[m, 2] ** 2)))
        s_yaw = float(np.sqrt(np.mean(var[m, 2])))
        out.append(RegionRatio(int(r), n, e_pos / s_pos, e_yaw / s_yaw, e_pos, s_pos, e_yaw, s_yaw))
    return tuple(out)


def nees(err_xytheta: np.ndarray, cov_xytheta: np.ndarray) -> np.ndarray:
    """(K,) normalized estimation error squared ``e^T C^-1 e`` of errors ``err_xytheta`` (K, 3) (x, y in m,
    yaw in rad) under covariances ``cov_xytheta`` (K, 3, 3) in the same units; nan where either is not
    finite or the covariance is singular. Chi-square with 3 degrees of freedom when ``C`` is honest."""
    e = np.asarray(err_xytheta, dtype=float)
    c = np.asarray(cov_xytheta, dtype=float)
    out = np.full(e.shape[0], np.nan)
    ok = np.all(np.isfinite(e), axis=1) & np.all(np.isfinite(c.reshape(c.shape[0], -1)), axis=1)
    ok[ok] &= np.linalg.det(c[ok]) > 0
    if ok.any():
        out[ok] = np.einsum("ki,ki->k", e[ok], np.linalg.solve(c[ok], e[ok][:, :, None])[:, :, 0])
    return out


def extreme_poses(err_xytheta: np.ndarray, cov_xytheta: np.ndarray, alpha: float = 1e-3) -> np.ndarray:
    """(K,) bool: the poses whose NEES (:func:`nees`) under ``cov_xytheta`` (K, 3, 3), e.g. the run's own
    per-pose covariance, exceeds the chi-square (3 degrees of freedom) quantile ``1 - alpha``: errors that
    covariance does not explain. Poses without a finite NEES are not extreme."""
    from scipy.stats import chi2

    n = nees(err_xytheta, cov_xytheta)
    return np.isfinite(n) & (n > chi2.ppf(1.0 - alpha, 3))


def best_camera_region(views: np.ndarray) -> np.ndarray:
    """(K,) the camera seeing most markers whole at each pose (``views`` (K, n_cameras)), -1 where none."""
    region = np.argmax(views, axis=1)
    return np.where(views.sum(axis=1) > 0, region, -1)


@dataclass(frozen=True)
class CoverageCheck:
    """One camera's predicted coverage against the run's: share (%) of its images in which the plan
    predicts a marker seen whole, and in which the run found a marker; ``agree`` the share (%) of images
    where both say the same."""

    camera: str
    images: int
    predicted_pct: float
    localized_pct: float
    agree_pct: float

    @property
    def difference_points(self) -> float:
        return self.predicted_pct - self.localized_pct


def coverage_check(camera: str, predicted_seen: np.ndarray, localized: np.ndarray) -> CoverageCheck:
    """Compare per image (both (N,) bool, the camera's images in order) the plan's ``predicted_seen`` and
    the run's ``localized`` (a marker found in the image)."""
    p, d = np.asarray(predicted_seen, dtype=bool), np.asarray(localized, dtype=bool)
    n = int(p.size)
    if n == 0:
        return CoverageCheck(camera, 0, float("nan"), float("nan"), float("nan"))
    return CoverageCheck(camera, n, 100.0 * float(p.mean()), 100.0 * float(d.mean()), 100.0 * float(np.mean(p == d)))
