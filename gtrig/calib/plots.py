"""Figures of the camera calibration (matplotlib, Agg backend; imported only when a figure is asked for)."""

from __future__ import annotations

import os
from collections.abc import Mapping, Sequence

import numpy as np

from gtrig.io.atomic import atomic_open


def _figure():  # noqa: ANN202
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def plot_coverage(
    views: Sequence[np.ndarray],
    image_size: tuple[int, int],
    path: str | os.PathLike[str],
    per_image_rms_px: Mapping[str, float] | None = None,
    names: Sequence[str] = (),
    rejected: Sequence[np.ndarray] = (),
    title: str = "",
) -> None:
    """Where the corners fell in the image (one colour per view, rejected views as red crosses), and the
    per-image reprojection RMS; written atomically as PNG."""
    plt = _figure()
    w, h = image_size
    ncols = 2 if per_image_rms_px else 1
    fig, axes = plt.subplots(1, ncols, figsize=(6.5 * ncols, 5.0), squeeze=False)
    ax = axes[0, 0]
    cmap = plt.get_cmap("viridis")
    for i, c in enumerate(views):
        c = np.asarray(c)
        ax.plot(c[:, 0], c[:, 1], ".", ms=3, color=cmap(i / max(1, len(views) - 1)))
    for c in rejected:
        c = np.asarray(c)
        ax.plot(c[:, 0], c[:, 1], "x", ms=3, color="red")
    ax.set_xlim(0, w)
    ax.set_ylim(h, 0)
    ax.set_aspect("equal")
    ax.set_xlabel("u (px)")
    ax.set_ylabel("v (px)")
    ax.set_title(title or f"corner coverage, {len(views)} views")
    ax.grid(alpha=0.3)
    if per_image_rms_px:
        ax2 = axes[0, 1]
        keys = list(names) or list(per_image_rms_px)
        vals = [per_image_rms_px[k] for k in keys]
        ax2.bar(range(len(vals)), vals, color="tab:blue")
        ax2.set_xticks(range(len(vals)), keys, rotation=90, fontsize=7)
        ax2.set_ylabel("reprojection RMS (px)")
        ax2.set_title("per-image error")
    fig.tight_layout()
    with atomic_open(path, "wb") as f:
        fig.savefig(f, format="png", dpi=100)
    plt.close(fig)


def plot_overlay(
    before: np.ndarray, after: np.ndarray, path: str | os.PathLike[str], title: str = ""
) -> None:
    """The seeds' direct image comparison: before in red, after in green (yellow where they agree)."""
    plt = _figure()
    rgb = np.zeros(before.shape[:2] + (3,))
    rgb[..., 0] = before / 255.0
    rgb[..., 1] = after / 255.0
    fig, ax = plt.subplots(figsize=(8, 6))
    ax.imshow(rgb)
    ax.set_title(title or "before (red) / after (green)")
    ax.axis("off")
    fig.tight_layout()
    with atomic_open(path, "wb") as f:
        fig.savefig(f, format="png", dpi=100)
    plt.close(fig)
