"""Two ground-truth sources of one run side by side on their common span (GTvision against GTlaser, the
external GT against an onboard scan-matching GT, ...).

``b`` is interpolated at ``a``'s stamps (gaps in ``b`` longer than ``max_gap_s`` skipped and counted),
optionally aligned (two sources in one world frame need none; the RAWSEEDS GT-extended lives in its own
frame: ``se2``), and the difference is scored: per-axis mean and std, evo's APE, and the *consistency* of
the two covariances: ``d2_i = e_i^T (C_a,i + C_b,i)^-1 e_i`` should follow chi2(k) when both covariances
are honest and the errors independent, so the share of ``d2`` under chi2_k(0.95) should be 95 %.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from scipy import stats

from gtrig.evaluate import metrics_evo
from gtrig.evaluate.align import AlignKind, Alignment, apply_alignment, fit_alignment
from gtrig.evaluate.associate import Association, associate_interpolate
from gtrig.evaluate.gt_aware import world_errors
from gtrig.trajectory import PoseTrack


@dataclass(frozen=True)
class SourceComparison:
    """Result of :func:`compare_sources`.

    Attributes
    ----------
    association : b interpolated at a's stamps.
    alignment : b -> a.
    axes : ``x, y, yaw`` (planar) or ``x, y, z, rx, ry, rz``.
    errors : (n, k) ``b - a`` per axis (world frame of ``a``).
    ape : evo's APE series of ``b`` against ``a``.
    d2 : (n,) or None: Mahalanobis distances squared under ``C_a + C_b`` (when both have covariances).
    share_consistent : share of ``d2 <= chi2_k(0.95)`` (95 % if both covariances are honest), or None.
    """

    association: Association
    alignment: Alignment
    axes: tuple[str, ...]
    errors: np.ndarray
    ape: dict[str, metrics_evo.ErrorSeries]
    d2: np.ndarray | None
    share_consistent: float | None

    def rows(self) -> list[tuple[str, str, float, str]]:
        """(metric, statistic, value, unit) rows."""
        out: list[tuple[str, str, float, str]] = []
        counts = self.association.summary()
        for k, name in (("matched", "matched"), ("gt_poses", "a_poses"), ("est_poses", "b_poses"),
                        ("anchor_outside", "a_skipped_outside"),
                        ("anchor_in_gaps", "a_skipped_in_gaps"), ("gaps", "gaps")):
            out.append(("pairing", name, float(counts[k]), ""))
        for i, ax in enumerate(self.axes):
            unit = "m" if ax in ("x", "y", "z") else "rad"
            out += [(f"b - a {ax}", "mean", float(np.mean(self.errors[:, i])), unit),
                    (f"b - a {ax}", "std", float(np.std(self.errors[:, i], ddof=1)), unit)]
        for s in self.ape.values():
            st = s.stats()
            for k in ("rmse", "mean", "median", "max"):
                out.append((s.name, k, st[k], s.unit))
        if self.share_consistent is not None and self.d2 is not None:
            out += [("consistency", "share d2 <= chi2(0.95)", self.share_consistent, ""),
                    ("consistency", "mean d2 per dof", float(np.mean(self.d2)) / len(self.axes), "")]
        return out


def _planar(t: PoseTrack) -> PoseTrack:
    c = t.cov_xytheta()
    return replace(t, cov=c, cov_kind="xyyaw") if c is not None else replace(t, cov=None, cov_kind="xyyaw")


def compare_sources(a: PoseTrack, b: PoseTrack, align: AlignKind = "none", max_gap_s: float = 0.2,
                    t_offset_s: float = 0.0) -> SourceComparison:
    """``b`` against ``a`` (module docstring); only the usable poses of each are compared."""
    a, b = a.usable(), b.usable()
    assoc = associate_interpolate(a, b, max_gap_s, t_offset_s)
    al = fit_alignment(assoc.gt.xyz, assoc.est.xyz, align)
    bb = apply_alignment(assoc.est, al)
    ga = assoc.gt
    planar = ga.cov_kind != "se3" or bb.cov_kind != "se3" or ga.cov is None or bb.cov is None
    if planar:
        ga, bb = _planar(ga), _planar(bb)
    e = world_errors(replace(ga, cov_kind=ga.cov_kind), bb)
    axes = ("x", "y", "yaw") if planar else ("x", "y", "z", "rx", "ry", "rz")
    d2 = share = None
    if ga.cov is not None and bb.cov is not None:
        C = ga.cov + bb.cov
        ok = np.all(np.isfinite(C), axis=(1, 2)) & np.all(np.isfinite(e), axis=1)
        if np.any(ok):
            d2 = np.einsum("ni,ni->n", e[ok], np.linalg.solve(C[ok], e[ok][:, :, None])[:, :, 0])
            share = float(np.mean(d2 <= stats.chi2.ppf(0.95, len(axes))))
    Ra, Rb = assoc.gt.quat_xyzw, bb.quat_xyzw
    ape = metrics_evo.ape(assoc.gt.stamps_s, Ra, assoc.gt.xyz, Rb, bb.xyz)
    return SourceComparison(assoc, al, axes, e, ape, d2, share)


def mean_nees_interval(n: int, dof: int, level: float = 0.95) -> tuple[float, float]:
    """Range of the mean NEES / dof that an honest covariance gives ``level`` of the time.

    Parameters
    ----------
    n : number of independent errors averaged.
    dof : dimension of each error (its NEES follows chi2(dof) when the covariance is honest).
    level : two-sided coverage.

    Returns
    -------
    (low, high) : chi-square quantiles of chi2(n * dof) at (1 - level) / 2 and (1 + level) / 2, over n * dof.
    """
    k = n * dof
    a = (1.0 - level) / 2
    return float(stats.chi2.ppf(a, k)) / k, float(stats.chi2.ppf(1.0 - a, k)) / k
