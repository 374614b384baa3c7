"""Figure of a pose comparison: both trajectories, error vectors and covariance ellipses."""

from __future__ import annotations

import os

import numpy as np

from gtrig.evaluate.poses import PoseComparison
from gtrig.plotting import ellipse_xy, figure, save


def plot_comparison(
    c: PoseComparison,
    path: str | os.PathLike[str],
    reference_label: str = "reference",
    estimate_label: str = "estimate",
    n_sigma: float = 3.0,
) -> None:
    """Reference and estimate poses (lines in pose order, arrows for headings), an error vector from each
    estimate to its reference, and ``n_sigma`` position ellipses where covariances are given."""
    fig, ax = figure(figsize=(8, 8))
    R, E = c.reference_xytheta, c.estimate_xytheta
    ax.plot(R[:, 0], R[:, 1], "b.-", lw=0.8, label=reference_label)
    ax.plot(E[:, 0], E[:, 1], "r.-", lw=0.8, label=estimate_label)
    for P, col in ((R, "b"), (E, "r")):
        ax.quiver(
            P[:, 0], P[:, 1], np.cos(P[:, 2]), np.sin(P[:, 2]), color=col, scale=25, width=0.003, alpha=0.6
        )
    ax.quiver(
        E[:, 0],
        E[:, 1],
        R[:, 0] - E[:, 0],
        R[:, 1] - E[:, 1],
        angles="xy",
        scale_units="xy",
        scale=1,
        color="k",
        width=0.004,
        label="error (reference - estimate)",
    )
    for cov, P, col in ((c.reference_cov, R, "b"), (c.estimate_cov, E, "r")):
        if cov is not None:
            for p, s in zip(P, cov, strict=True):
                e = ellipse_xy(p[:2], s[:2, :2], n_sigma)
                ax.plot(e[:, 0], e[:, 1], col + "-", lw=0.7)
    for n, p in zip(c.names, R, strict=True):
        ax.annotate(n, p[:2], textcoords="offset points", xytext=(4, 4), fontsize=7)
    st = c.stats
    ax.set_title(
        f"{len(c.names)}/{c.n_reference} poses; mean |error| {st['pos'].mean * 1000:.1f} mm, "
        f"theta mean {np.degrees(st['theta'].mean):.2f} deg, std {np.degrees(st['theta'].std):.2f} deg"
    )
    ax.set_aspect("equal")
    ax.grid(True, alpha=0.3)
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.legend(loc="best", fontsize=8)
    save(fig, path)
