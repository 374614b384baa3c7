"""Figures of the survey: world points and validation poses with error ellipses, uncertainty maps.

The figure, save and ellipse helpers are gtrig.plotting's; files are written atomically.
"""

from __future__ import annotations

import os
from collections.abc import Sequence

import numpy as np

from gtrig.plotting import ellipse_xy, figure, save


def plot_world_points(
    names: Sequence[str],
    xy: np.ndarray,
    cov_xy: np.ndarray,
    path: str | os.PathLike[str],
    reference_names: Sequence[str] = (),
    reference_xy: np.ndarray | None = None,
    n_sigma: float = 3.0,
    scale: float = 10.0,
) -> None:
    """World points with their ``n_sigma`` ellipses magnified ``scale`` times (seeds: 3 sigma, x10)."""
    fig, ax = figure(figsize=(7, 7))
    for n, p, c in zip(names, xy, cov_xy, strict=True):
        e = ellipse_xy(p, c * scale**2, n_sigma)
        ax.plot(e[:, 0], e[:, 1], "b-", lw=1)
        ax.plot(*p, "b.", ms=4)
        ax.annotate(n, p, textcoords="offset points", xytext=(4, 4), fontsize=8)
    if reference_xy is not None:
        ax.plot(reference_xy[:, 0], reference_xy[:, 1], "r^", ms=7, label="reference points")
        for n, p in zip(reference_names, reference_xy, strict=True):
            ax.annotate(n, p, textcoords="offset points", xytext=(4, -10), fontsize=8, color="r")
    ax.set_aspect("equal")
    ax.grid(True, alpha=0.3)
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.set_title(f"World points, {n_sigma:g}-sigma ellipses magnified x{scale:g}")
    if reference_xy is not None:
        ax.legend(loc="best", fontsize=8)
    save(fig, path)


def plot_poses(
    names: Sequence[str],
    xytheta: np.ndarray,
    cov_xytheta: np.ndarray,
    path: str | os.PathLike[str],
    world_xy: np.ndarray | None = None,
    n_sigma: float = 3.0,
    scale: float = 10.0,
) -> None:
    """Validation poses (arrows along the robot x axis) with position ellipses magnified ``scale`` times
    and the heading's ``n_sigma`` wedge in the label."""
    fig, ax = figure(figsize=(7, 7))
    if world_xy is not None:
        ax.plot(world_xy[:, 0], world_xy[:, 1], "ks", ms=4, label="world points")
    for n, p, c in zip(names, xytheta, cov_xytheta, strict=True):
        ax.arrow(p[0], p[1], 0.25 * np.cos(p[2]), 0.25 * np.sin(p[2]), head_width=0.06, color="g", lw=1)
        e = ellipse_xy(p[:2], c[:2, :2] * scale**2, n_sigma)
        ax.plot(e[:, 0], e[:, 1], "b-", lw=1)
        ax.annotate(
            f"{n} ({np.degrees(n_sigma * np.sqrt(c[2, 2])):.2f} deg)",
            p[:2],
            textcoords="offset points",
            xytext=(4, 4),
            fontsize=7,
        )
    ax.set_aspect("equal")
    ax.grid(True, alpha=0.3)
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.set_title(
        f"Validation poses, {n_sigma:g}-sigma position ellipses x{scale:g} (heading {n_sigma:g} sigma)"
    )
    save(fig, path)


def plot_uncertainty_map(
    x_m: np.ndarray,
    y_m: np.ndarray,
    sigma_pos_m: np.ndarray,
    sigma_theta_rad: np.ndarray,
    world_xy: np.ndarray,
    path: str | os.PathLike[str],
) -> None:
    """Two panels: expected position sigma (mm) and heading sigma (deg), worst heading, world points."""
    fig, axes = figure(ncols=2, figsize=(12, 5.5))
    for ax, z, title in (
        (axes[0], sigma_pos_m * 1000, "position sigma, worst axis (mm)"),
        (axes[1], np.degrees(sigma_theta_rad), "heading sigma (deg)"),
    ):
        im = ax.pcolormesh(x_m, y_m, z, shading="nearest", cmap="viridis")
        fig.colorbar(im, ax=ax)
        ax.plot(world_xy[:, 0], world_xy[:, 1], "rs", ms=4)
        ax.set_aspect("equal")
        ax.set_title(title)
        ax.set_xlabel("x (m)")
        ax.set_ylabel("y (m)")
    save(fig, path)
