"""Compare two sets of planar poses matched by name: per-pose differences and per-axis statistics.

Convention (the seeds', AD2.3 "Validation results"): the error is **reference minus estimate**, e.g.
validation (hand-laser survey) minus the GT system; angles wrapped to [-pi, pi). Statistics per axis:
mean, sample standard deviation (ddof = 1), maximum absolute value, 95 % confidence interval of the mean
(Student t with n - 1 dof), and the same for the Euclidean position error. "Poses localized" is the
number of reference poses that the estimate has, out of the reference poses.
"""

from __future__ import annotations

import csv
import io
from dataclasses import dataclass

import numpy as np
from scipy import stats

from gtrig.errors import InputError
from gtrig.io.survey_csv import PoseTable

AXES = ("x", "y", "theta", "pos")


@dataclass(frozen=True)
class AxisStats:
    """Statistics of one error component (metres, or radians for theta)."""

    mean: float
    std: float
    max_abs: float
    ci95_low: float
    ci95_high: float


@dataclass(frozen=True)
class PoseComparison:
    """Result of :func:`compare_poses`.

    Attributes
    ----------
    names : the matched poses (in the reference's order).
    reference_xytheta, estimate_xytheta : (n, 3) matched poses.
    err_xytheta : (n, 3) reference minus estimate, theta wrapped to [-pi, pi).
    err_pos_m : (n,) Euclidean position error.
    n_reference : poses in the reference; ``len(names)`` of them are localized.
    missing : reference poses without estimate.
    stats : per axis ``x``, ``y``, ``theta``, ``pos``.
    reference_cov, estimate_cov : (n, 3, 3) or None.
    """

    names: tuple[str, ...]
    reference_xytheta: np.ndarray
    estimate_xytheta: np.ndarray
    err_xytheta: np.ndarray
    err_pos_m: np.ndarray
    n_reference: int
    missing: tuple[str, ...]
    stats: dict[str, AxisStats]
    reference_cov: np.ndarray | None
    estimate_cov: np.ndarray | None


def _axis_stats(e: np.ndarray) -> AxisStats:
    n = e.size
    mean = float(np.mean(e))
    std = float(np.std(e, ddof=1)) if n > 1 else float("nan")
    half = float(stats.t.ppf(0.975, n - 1) * std / np.sqrt(n)) if n > 1 else float("nan")
    return AxisStats(mean, std, float(np.max(np.abs(e))), mean - half, mean + half)


def compare_poses(reference: PoseTable, estimate: PoseTable) -> PoseComparison:
    """Match poses by name and compute errors ``reference - estimate`` and their statistics."""
    est = {n: i for i, n in enumerate(estimate.names)}
    names = tuple(n for n in reference.names if n in est)
    missing = tuple(n for n in reference.names if n not in est)
    if not names:
        raise InputError(
            f"no pose in common between the reference ({', '.join(reference.names[:5])}...) and the "
            f"estimate ({', '.join(estimate.names[:5])}...)"
        )
    ir = [reference.names.index(n) for n in names]
    ie = [est[n] for n in names]
    R, E = reference.xytheta[ir], estimate.xytheta[ie]
    err = R - E
    err[:, 2] = (err[:, 2] + np.pi) % (2 * np.pi) - np.pi
    pos = np.linalg.norm(err[:, :2], axis=1)
    st = {a: _axis_stats(v) for a, v in zip(AXES, (err[:, 0], err[:, 1], err[:, 2], pos), strict=True)}
    return PoseComparison(
        names,
        R,
        E,
        err,
        pos,
        len(reference.names),
        missing,
        st,
        None if reference.cov_xytheta is None else reference.cov_xytheta[ir],
        None if estimate.cov_xytheta is None else estimate.cov_xytheta[ie],
    )


_DIGITS = 5


def _rows(c: PoseComparison) -> list[list[str]]:
    f = f"{{:.{_DIGITS}f}}"
    out = []
    for key, label in (
        ("mean", "mean"),
        ("std", "std (ddof=1)"),
        ("max_abs", "max abs"),
        ("ci95_low", "95% CI low"),
        ("ci95_high", "95% CI high"),
    ):
        out.append([label, *(f.format(getattr(c.stats[a], key)) for a in AXES)])
    return out


def per_pose_csv(c: PoseComparison) -> str:
    """``pose,err_x,err_y,err_theta,err_pos`` (metres, radians)."""
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(["pose", "err_x", "err_y", "err_theta", "err_pos"])
    for n, e, p in zip(c.names, c.err_xytheta, c.err_pos_m, strict=True):
        w.writerow([n, f"{e[0]:.6f}", f"{e[1]:.6f}", f"{e[2]:.6f}", f"{p:.6f}"])
    return buf.getvalue()


def summary_csv(c: PoseComparison) -> str:
    """``statistic,x,y,theta,pos`` rows plus ``localized``; 6 decimals."""
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(["statistic", *AXES])
    for key in ("mean", "std", "max_abs", "ci95_low", "ci95_high"):
        w.writerow([key, *(f"{getattr(c.stats[a], key):.6f}" for a in AXES)])
    w.writerow(["localized", f"{len(c.names)}/{c.n_reference}", "", "", ""])
    return buf.getvalue()


def summary_markdown(c: PoseComparison) -> str:
    """A Markdown table of the statistics (errors = reference - estimate)."""
    lines = [
        f"poses localized: {len(c.names)}/{c.n_reference}"
        + (f" (missing: {', '.join(c.missing)})" if c.missing else ""),
        "",
        "| statistic | x (m) | y (m) | theta (rad) | position (m) |",
        "|---|---|---|---|---|",
    ]
    lines += ["| " + " | ".join(r) + " |" for r in _rows(c)]
    return "\n".join(lines) + "\n"


def summary_rows(c: PoseComparison) -> list[list[str]]:
    """Rows for a table: statistic, x, y, theta, pos (5 decimals)."""
    return _rows(c)
