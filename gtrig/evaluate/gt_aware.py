"""Scores that know the ground truth is not the truth: every gtrig pose has a covariance, so use it.

"The uncertainty of every pose is rarely computed for trajectory evaluation" (Vaidis et al., 2023). With
``g_i ~ N(0, C_i)`` the GT's own error (gtrig.trajectory's convention: world-frame perturbation) and
``e_i = est_i - gt_i`` the observed error (world frame, after any alignment), ``e_i = e*_i - g_i`` where
``e*_i = est_i - truth_i`` is what a user wants. Then:

- per pose, ``d2_i = e_i^T C_i^-1 e_i``: for an estimate as good as the truth, ``d2_i ~ chi2(k)``, so the
  *share resolved* (``d2_i <= chi2_k(0.95)``) is 95 % and ``mean(d2) / k`` (the NEES per degree of freedom)
  is 1: how often the GT cannot tell the estimate from the truth;
- the bias ``mu = E[e*]``: ``mean(e)`` estimates it without bias (the GT's errors have zero mean);
- the mean squared error against the truth: ``E|e_i|^2 = E|e*_i|^2 + tr C_i``, so
  ``MSE* = mean(|e_i|^2 - tr C_i)``: the RMSE with the GT's own uncertainty taken out (evo's RMSE is
  ``sqrt(mean |e_i|^2)``, the GT's noise included).

Their 95 % intervals are batch means (Flegal and Jones, Ann. Stat. 2010): the paired poses cut into
``B = 20`` consecutive batches, the interval from the batch means' spread with Student's t (B - 1 dof), so
the time correlation of SLAM drift and of the GT's errors is accounted for, and the interval covers the
estimate's error process (its bias, its RMSE against the truth), the GT's noise included. When the MSE*
interval reaches 0 and no bias interval excludes 0, the estimate is as good as the GT can tell.

The verdict *indistinguishable* needs three things: the errors consistent with the GT's covariance (NEES
per dof at most 2, the upper end of gtrig's consistency band 0.5-2 used by every accuracy table); the MSE*
intervals reaching 0; and no *resolved* bias, a bias being resolved when its interval excludes 0 and it
exceeds what one GT pose resolves, ``1.96 sigma`` of the GT on that axis (a GT's systematic error, e.g.
its calibration's, is shared by all its poses and bounded only by the per-pose covariance, so a smaller
mean offset cannot be told from the GT's own).

A lever arm (the estimate's body frame offset from the GT's robot frame by ``L`` in the body) shows as an
error ``R(theta_i) L + c`` turning with the heading: :func:`lever_arm` fits it and says when it is resolved.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from gtrig.evaluate import _kernels, quat
from gtrig.trajectory import PoseTrack

#: scipy.stats.norm.ppf(0.975), written out: importing scipy.stats costs a CLI call half a second
Z95 = 1.959963984540054
#: the upper end of gtrig's NEES-per-dof consistency band (docs/vision.md, the accuracy tables' 0.5-2)
NEES_MAX = 2.0


def world_errors(gt: PoseTrack, est: PoseTrack) -> np.ndarray:
    """(n, k) ``est - gt`` in the axes of ``gt.cov_kind``: ``(x, y, z, rx, ry, rz)`` with the rotation error
    ``log(R_est R_gt^T)`` (world frame), ``(x, y, yaw)`` with the yaw difference wrapped, or ``(x, y, z)``."""
    dt = est.xyz - gt.xyz
    if gt.cov_kind == "xyz":
        return dt
    if gt.cov_kind == "xyyaw":
        dyaw = (est.yaw_rad() - gt.yaw_rad() + np.pi) % (2 * np.pi) - np.pi
        return np.column_stack([dt[:, :2], dyaw])
    dphi = quat.rotvec(quat.mul(est.quat_xyzw, quat.conj(gt.quat_xyzw)))
    return np.column_stack([dt, dphi])


def _blocks(kind: str) -> tuple[tuple[int, ...], tuple[int, ...]]:
    """(translation axes, rotation axes) of a covariance kind."""
    return {"se3": ((0, 1, 2), (3, 4, 5)), "xyyaw": ((0, 1), (2,)), "xyz": ((0, 1, 2), ())}[kind]


@dataclass(frozen=True)
class Interval:
    """A point estimate and its 95 % interval."""

    value: float
    low: float
    high: float

    def contains(self, x: float) -> bool:
        return self.low <= x <= self.high


@dataclass(frozen=True)
class GTAwareScores:
    """The GT-aware scores of one estimate (module docstring).

    Attributes
    ----------
    axes : names of the error components (``x, y, yaw`` or ``x, y, z, rx, ry, rz`` or ``x, y, z``).
    n : poses scored (those with a finite, positive-definite GT covariance).
    d2 : (n,) Mahalanobis distances squared of the errors under the GT covariance.
    share_resolved : share of poses with ``d2 <= chi2_k(0.95)`` (95 % for a perfect estimate).
    mean_d2_per_dof : ``mean(d2) / k`` (1 for a perfect estimate).
    bias : per axis, the mean error and its interval.
    rmse_trans_m, rmse_rot_rad : the RMSE against the truth (GT's uncertainty removed) and its interval
        (``rmse_rot_rad`` None for a position-only GT).
    gt_sigma_trans_m : ``sqrt(mean tr C_trans)``: the GT's own RMS position uncertainty.
    indistinguishable : NEES per dof <= 2, the RMSE intervals reach 0 and no bias resolved (module docstring).
    bias_resolved : the axes whose bias is resolved.
    """

    axes: tuple[str, ...]
    n: int
    d2: np.ndarray
    share_resolved: float
    mean_d2_per_dof: float
    bias: dict[str, Interval]
    rmse_trans_m: Interval
    rmse_rot_rad: Interval | None
    gt_sigma_trans_m: float
    indistinguishable: bool
    bias_resolved: tuple[str, ...] = ()


N_BATCHES = 20


def batch_interval(x: np.ndarray, n_batches: int = N_BATCHES) -> Interval:
    """The mean of the series ``x`` (n,) and its 95 % batch-means interval (module docstring); under 40 values,
    the independent-sample interval."""
    x = np.asarray(x, float)
    n = x.size
    m = float(np.mean(x))
    if n < 2:
        return Interval(m, float("-inf"), float("inf"))
    from scipy import stats

    if n < 2 * n_batches:
        h = float(stats.t.ppf(0.975, n - 1) * np.std(x, ddof=1) / np.sqrt(n))
        return Interval(m, m - h, m + h)
    edges = np.linspace(0, n, n_batches + 1).astype(int)
    means = np.add.reduceat(x, edges[:-1]) / np.diff(edges)
    h = float(stats.t.ppf(0.975, n_batches - 1) * np.std(means, ddof=1) / np.sqrt(n_batches))
    return Interval(m, m - h, m + h)


def _rmse_interval(e: np.ndarray, C: np.ndarray) -> tuple[Interval, float]:
    trC = np.trace(C, axis1=1, axis2=2)
    iv = batch_interval(np.sum(e * e, axis=1) - trC)
    root = lambda v: float(np.sqrt(max(v, 0.0)))  # noqa: E731
    return Interval(root(iv.value), root(iv.low), root(iv.high)), float(np.sqrt(np.mean(trC)))


def score(gt: PoseTrack, est: PoseTrack) -> GTAwareScores | None:
    """GT-aware scores of ``est`` against ``gt`` (paired pose for pose, same world frame); None when the GT
    carries no covariance."""
    if gt.cov is None or gt.cov_kind not in ("se3", "xyyaw", "xyz"):
        return None
    from scipy import stats

    from gtrig.trajectory import COV_AXES

    e_all = world_errors(gt, est)
    C_all = np.asarray(gt.cov, float)
    finite = np.all(np.isfinite(C_all), axis=(1, 2)) & np.all(np.isfinite(e_all), axis=1)
    if np.any(finite):
        ev = np.linalg.eigvalsh(C_all[finite])
        pd = np.zeros(len(C_all), bool)
        pd[np.nonzero(finite)[0]] = ev[:, 0] > 0
    else:
        pd = finite
    if not np.any(pd):
        return None
    e, C = e_all[pd], C_all[pd]
    k = e.shape[1]
    d2 = np.einsum("ni,ni->n", e, np.linalg.solve(C, e[:, :, None])[:, :, 0])
    axes = COV_AXES[gt.cov_kind]
    bias = {name: batch_interval(e[:, a]) for a, name in enumerate(axes)}
    it, ir = _blocks(gt.cov_kind)
    it_, ir_ = np.array(it), np.array(ir)
    rmse_t, sig_t = _rmse_interval(e[:, it_], C[:, it_[:, None], it_[None, :]])
    rmse_r = _rmse_interval(e[:, ir_], C[:, ir_[:, None], ir_[None, :]])[0] if ir else None
    nees = float(np.mean(d2) / k)
    sig_axes = np.sqrt(np.mean(np.diagonal(C, axis1=1, axis2=2), axis=0))
    resolved = tuple(name for a, name in enumerate(axes)
                     if not bias[name].contains(0.0) and abs(bias[name].value) > Z95 * sig_axes[a])
    indist = nees <= NEES_MAX and rmse_t.low == 0.0 and (rmse_r is None or rmse_r.low == 0.0) and not resolved
    return GTAwareScores(axes, len(e), d2, float(np.mean(d2 <= stats.chi2.ppf(0.95, k))), nees,
                         bias, rmse_t, rmse_r, sig_t, bool(indist), resolved)


@dataclass(frozen=True)
class LeverArm:
    """A heading-correlated error fitted as a lever arm.

    Attributes
    ----------
    xy_m : (2,) the offset of the estimate's body frame from the GT's robot frame, in the robot frame.
    sigma_m : (2,) its standard deviations (residual autocorrelation accounted for).
    explained : share of the error variance the lever arm explains.
    resolved : True when ``|L|`` is over 5 of its sigmas and explains over 10 % of the variance, i.e. the
        error turns with the heading: a missing lever arm (a warning for the user).
    """

    xy_m: np.ndarray
    sigma_m: np.ndarray
    explained: float
    resolved: bool


def lever_arm(gt: PoseTrack, est: PoseTrack) -> LeverArm | None:
    """Fit ``e_xy,i = R(yaw_gt,i) L + c`` (least squares) to the planar position errors; None when the heading
    does not vary enough (under 90 degrees of spread) to separate ``L`` from ``c``."""
    n = len(gt)
    if n < 10:
        return None
    c, s = _kernels.heading_cos_sin(np.ascontiguousarray(gt.quat_xyzw))
    # the spread of headings: the resultant length of unit heading vectors is 1 for a constant heading
    if np.hypot(np.mean(c), np.mean(s)) > 0.9:
        return None
    e = (est.xyz - gt.xyz)[:, :2]
    # e_x = c Lx - s Ly + cx, e_y = s Lx + c Ly + cy: the 4 x 4 normal equations, built without the 2n x 4 matrix
    sc, ss = float(np.sum(c)), float(np.sum(s))
    AtA = np.array([[n, 0.0, sc, ss], [0.0, n, -ss, sc], [sc, -ss, n, 0.0], [ss, sc, 0.0, n]])
    Atb = np.array([np.sum(c * e[:, 0] + s * e[:, 1]), np.sum(-s * e[:, 0] + c * e[:, 1]), np.sum(e[:, 0]),
                    np.sum(e[:, 1])])
    sol = np.linalg.solve(AtA, Atb)
    pred = np.column_stack([c * sol[0] - s * sol[1] + sol[2], s * sol[0] + c * sol[1] + sol[3]])
    res = e - pred
    ss_res = float(np.sum(res * res))
    ss0 = float(np.sum((e - e.mean(axis=0)) ** 2))
    explained = 0.0 if ss0 == 0 else 1.0 - ss_res / ss0
    rx = res[:, 0]
    rho = float(np.corrcoef(rx[:-1], rx[1:])[0, 1]) if n > 3 and np.std(rx) > 0 else 0.0
    rho = min(max(rho, 0.0), 0.99)
    inflate = (1 + rho) / (1 - rho)  # AR(1) effective-sample-size correction
    s2 = ss_res / max(2 * n - 4, 1)
    cov = s2 * inflate * np.linalg.inv(AtA)
    L = sol[:2]
    sig = np.sqrt(np.diag(cov)[:2])
    snr = float(np.linalg.norm(L)) / max(float(np.linalg.norm(sig)), 1e-300)
    return LeverArm(L, sig, float(explained), bool(snr > 5 and explained > 0.1))
