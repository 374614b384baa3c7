"""The RAWSEEDS Metrics Computation Toolkit's ATE and RPE (Cadena and Tardos, Univ. Zaragoza, v1.1 2009:
get_ATE.m, get_RPE.m), re-derived from their text, planar ``(x, y, theta)``.

ATE (get_ATE.m):

1. GT samples inside the estimate's span ``[t_est[0], t_est[-1]]`` only;
2. the estimate's heading unwrapped, then ``(x, y, theta)`` interpolated linearly at the GT stamps;
3. a 2-D alignment ``(x, y, theta)`` (or ``+ scale`` for monocular SLAM) by least squares on the position
   residuals ``p_gt - (R p_est + t)``, over all samples or an alignment interval; the toolkit runs
   Levenberg-Marquardt from zero, whose optimum is the closed form used here (Umeyama in 2-D);
4. errors ``estimate - GT`` per axis, the heading wrapped to (-pi, pi]; ``d_j = |e_xy|``;
   ATE = ``[mean d, std d, mean - 3 std, mean + 3 std]`` (std with ddof 1, MATLAB's), and the same for
   ``|e_theta|``.

With a scale, the toolkit fits ``p_gt = s (t + R p)`` but then applies ``t + R s p`` (the translation is
not scaled: a slip in get_ATE.m); here the fitted transform is applied. The fits are the same family and
give the same optimum, so both agree when ``s = 1``.

RPE (get_RPE.m): relations ``(t_i, t_j, dx, dy, dtheta)`` with both stamps inside the estimate's span;
the estimate interpolated (heading unwrapped) at ``t_i`` and ``t_j``; ``x_ij = x_i^-1 x_j``,
``e_ij = xGT_ij^-1 x_ij``; T-RPE = ``sqrt(mean(e_x^2 + e_y^2))`` (m), R-RPE = ``sqrt(mean(e_theta^2))``
in degrees.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from gtrig.errors import InputError
from gtrig.evaluate.align import umeyama


def normalize_angle(a: np.ndarray) -> np.ndarray:
    """Angles to (-pi, pi] (the toolkit's normalize_ang)."""
    a = np.asarray(a, float)
    return a + 2 * np.pi * np.floor((np.pi - a) / (2 * np.pi))


def interp_xytheta(stamps_s: np.ndarray, xytheta: np.ndarray, at_s: np.ndarray) -> np.ndarray:
    """(m, 3) linear interpolation of ``(x, y, unwrapped theta)`` at ``at_s`` (inside the span)."""
    th = np.unwrap(xytheta[:, 2])
    return np.column_stack([np.interp(at_s, stamps_s, xytheta[:, 0]), np.interp(at_s, stamps_s, xytheta[:, 1]),
                            np.interp(at_s, stamps_s, th)])


def compose(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``a (+) b`` for (3,) ``a`` and (n, 3) ``b`` (tcomp), heading normalized."""
    c, s = np.cos(a[2]), np.sin(a[2])
    return np.column_stack([a[0] + c * b[:, 0] - s * b[:, 1], a[1] + s * b[:, 0] + c * b[:, 1],
                            normalize_angle(a[2] + b[:, 2])])


def relative(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``a^-1 (+) b`` row by row for (n, 3) arrays (trel)."""
    c, s = np.cos(a[:, 2]), np.sin(a[:, 2])
    dx, dy = b[:, 0] - a[:, 0], b[:, 1] - a[:, 1]
    return np.column_stack([c * dx + s * dy, -s * dx + c * dy, normalize_angle(b[:, 2] - a[:, 2])])


@dataclass(frozen=True)
class RawseedsATE:
    """get_ATE.m's results.

    Attributes
    ----------
    stamps_s : (n,) the GT stamps used.
    gt_xytheta, est_xytheta : (n, 3) the GT and the aligned, interpolated estimate.
    errors : (n, 3) ``estimate - GT`` (m, m, rad wrapped to (-pi, pi]).
    dist_m : (n,) ``|errors[:, :2]|``.
    transform : ``(x, y, theta)`` of the alignment (the toolkit's ``RT``); ``scale`` 1 without scale.
    ate : ``(mean, std, mean - 3 std, mean + 3 std)`` of ``dist_m``, metres.
    heading : the same of ``|errors[:, 2]|``, radians.
    """

    stamps_s: np.ndarray
    gt_xytheta: np.ndarray
    est_xytheta: np.ndarray
    errors: np.ndarray
    dist_m: np.ndarray
    transform: tuple[float, float, float]
    scale: float
    ate: tuple[float, float, float, float]
    heading: tuple[float, float, float, float]

    @property
    def rmse_m(self) -> float:
        return float(np.sqrt(np.mean(self.dist_m**2)))


def _four(v: np.ndarray) -> tuple[float, float, float, float]:
    m = float(np.mean(v))
    s = float(np.std(v, ddof=1)) if v.size > 1 else float("nan")
    return (m, s, m - 3 * s, m + 3 * s)


def ate(gt_stamps_s: np.ndarray, gt_xytheta: np.ndarray, est_stamps_s: np.ndarray, est_xytheta: np.ndarray,
        unknown_scale: bool = False, align_interval_s: tuple[float, float] | None = None,
        align: bool = True) -> RawseedsATE:
    """The RAWSEEDS ATE (module docstring).

    Parameters
    ----------
    gt_stamps_s, gt_xytheta : (m,), (m, 3) the ground truth (world frame, metres, radians).
    est_stamps_s, est_xytheta : (n,), (n, 3) the estimate (its own frame), increasing stamps.
    unknown_scale : fit a scale too (monocular SLAM).
    align_interval_s : fit the alignment on the GT samples stamped in ``[t0, t1]`` only (the toolkit's
        ``alignment_path``, here a time interval).
    align : False to skip the alignment (both already in one frame).
    """
    t0, t1 = float(est_stamps_s[0]), float(est_stamps_s[-1])
    good = (gt_stamps_s >= t0) & (gt_stamps_s <= t1)
    if not np.any(good):
        raise InputError(f"no GT sample inside the estimate's span {t0:.3f}..{t1:.3f} s")
    t = np.asarray(gt_stamps_s, float)[good]
    G = np.asarray(gt_xytheta, float)[good]
    Xe = interp_xytheta(est_stamps_s, est_xytheta, t)
    rt, s = np.zeros(3), 1.0
    if align:
        m = np.ones(t.size, bool) if align_interval_s is None else (t >= align_interval_s[0]) & (
            t <= align_interval_s[1])
        if np.sum(m) < 2:
            raise InputError(f"{int(np.sum(m))} GT samples in the alignment interval {align_interval_s}: "
                             "at least 2 are needed")
        R, tr, s = umeyama(Xe[m, :2], G[m, :2], unknown_scale)
        rt = np.array([tr[0], tr[1], np.arctan2(R[1, 0], R[0, 0])])
    Xa = compose(rt, np.column_stack([s * Xe[:, :2], Xe[:, 2]]))
    err = Xa - G
    err[:, 2] = normalize_angle(err[:, 2])
    d = np.hypot(err[:, 0], err[:, 1])
    return RawseedsATE(t, G, Xa, err, d, (float(rt[0]), float(rt[1]), float(rt[2])), float(s), _four(d),
                       _four(np.abs(err[:, 2])))


@dataclass(frozen=True)
class RawseedsRPE:
    """get_RPE.m's results.

    Attributes
    ----------
    t_i, t_j : (n,) stamps of the relations used.
    errors : (n, 3) ``xGT_ij^-1 x_ij``.
    n_relations : relations in the file; ``len(t_i)`` of them inside the estimate's span.
    t_rpe_m : ``sqrt(mean(e_x^2 + e_y^2))``.
    r_rpe_deg : ``sqrt(mean(e_theta^2))`` in degrees.
    """

    t_i: np.ndarray
    t_j: np.ndarray
    errors: np.ndarray
    n_relations: int
    t_rpe_m: float
    r_rpe_deg: float


def rpe(est_stamps_s: np.ndarray, est_xytheta: np.ndarray, relations: np.ndarray) -> RawseedsRPE:
    """The RAWSEEDS RPE (module docstring); ``relations`` is (m, 5) ``t_i, t_j, dx, dy, dtheta``."""
    rel = np.asarray(relations, float).reshape(-1, 5)
    t0, t1 = float(est_stamps_s[0]), float(est_stamps_s[-1])
    ti, tj = rel[:, 0], rel[:, 1]
    good = (ti >= t0) & (ti <= t1) & (tj >= t0) & (tj <= t1)
    if not np.any(good):
        raise InputError(f"no relation with both stamps inside the estimate's span {t0:.3f}..{t1:.3f} s "
                         f"(relations span {np.min(ti):.3f}..{np.max(tj):.3f} s)")
    ti, tj, gij = ti[good], tj[good], rel[good, 2:5]
    xi = interp_xytheta(est_stamps_s, est_xytheta, ti)
    xj = interp_xytheta(est_stamps_s, est_xytheta, tj)
    e = relative(gij, relative(xi, xj))
    return RawseedsRPE(ti, tj, e, len(rel), float(np.sqrt(np.mean(np.sum(e[:, :2] ** 2, axis=1)))),
                       float(np.degrees(np.sqrt(np.mean(e[:, 2] ** 2)))))
