"""Maps of a plan (matplotlib): sigma and coverage over the floor, worst and median over headings.

Each function returns PNG bytes, so that the CLI can write them as files and embed them in the page.
"""

from __future__ import annotations

import io
from typing import Any

import numpy as np

from gtrig.plan.maps import CellMaps, TargetSummary
from gtrig.plan.predict import PlanResult
from gtrig.plotting import figure


def _png(fig: Any) -> bytes:
    import matplotlib.pyplot as plt

    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=110, bbox_inches="tight")
    plt.close(fig)
    return buf.getvalue()


def _image(plan: PlanResult, values: np.ndarray) -> tuple[np.ndarray, tuple[float, float, float, float]]:
    """Cell values (C,) as an image (ny, nx) over the grid's bounding box (nan outside the area)."""
    g = plan.grid
    xy = g.cells_xy
    lo = xy.min(axis=0)
    ij = np.rint((xy - lo) / g.step_m).astype(int)
    img = np.full(ij.max(axis=0)[::-1] + 1, np.nan)
    img[ij[:, 1], ij[:, 0]] = values
    h = g.step_m / 2
    x1 = lo[0] + (img.shape[1] - 1) * g.step_m + h
    y1 = lo[1] + (img.shape[0] - 1) * g.step_m + h
    return img, (lo[0] - h, x1, lo[1] - h, y1)


def _panel(ax: Any, plan: PlanResult, values: np.ndarray, title: str, label: str, vmax: float,
           cmap: str = "viridis") -> None:
    import matplotlib as mpl

    # uncovered (infinite) and beyond the scale: dark grey; outside the area: white
    cm = mpl.colormaps[cmap].with_extremes(over="0.35", bad="white")
    v = np.where(np.isinf(values), vmax * 10, values)
    if plan.grid.kind == "area":
        img, ext = _image(plan, v)
        im = ax.imshow(img, origin="lower", extent=ext, cmap=cm, vmin=0, vmax=vmax, interpolation="nearest")
    else:
        xy = plan.grid.cells_xy
        im = ax.scatter(xy[:, 0], xy[:, 1], c=v, s=6, cmap=cm, vmin=0, vmax=vmax)
    P = plan.grid.polygon_xy
    ax.plot(np.r_[P[:, 0], P[0, 0]], np.r_[P[:, 1], P[0, 1]], "k-", lw=0.8)
    ax.set_aspect("equal")
    ax.set_title(title, fontsize=9)
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.figure.colorbar(im, ax=ax, label=label, extend="max", shrink=0.8)


def sigma_maps(plan: PlanResult, maps: CellMaps, source: str, target_xy_m: float, target_yaw_rad: float) -> bytes:
    """Position and yaw sigma of ``source``: worst and median over headings (2 x 2 panels)."""
    fig, axes = figure(nrows=2, ncols=2, figsize=(11, 9))
    for row, (what, vals, scale, unit, tgt) in enumerate((
            ("position sigma", maps.sigma_xy_m[source], 1000.0, "mm", target_xy_m * 1000),
            ("yaw sigma", maps.sigma_yaw_rad[source], float(np.degrees(1.0)), "deg",
             float(np.degrees(target_yaw_rad))))):
        for col, (agg, v) in enumerate(zip(("worst", "median"), vals, strict=True)):
            _panel(axes[row, col], plan, v * scale, f"{source}: {what}, {agg} heading", f"{what} ({unit})",
                   4 * tgt, "viridis")
    return _png(fig)


def coverage_maps(plan: PlanResult, maps: CellMaps) -> bytes:
    """Cameras seeing a marker whole and scanners with beams on the hull: worst and median heading."""
    fig, axes = figure(nrows=2, ncols=2, figsize=(11, 9))
    for row, (what, vals, n) in enumerate((("cameras seeing a marker", maps.cameras, len(plan.camera_names)),
                                           ("scanners on the hull", maps.scanners, len(plan.scanner_names)))):
        for col, (agg, v) in enumerate(zip(("worst", "median"), vals, strict=True)):
            _panel(axes[row, col], plan, v, f"{what}, {agg} heading", "count", max(n, 1), "magma")
    return _png(fig)


def target_map(plan: PlanResult, summary: TargetSummary) -> bytes:
    """Where the fused pose meets the target at every heading (green) and where not (red)."""
    fig, ax = figure(figsize=(7, 6))
    _panel(ax, plan, summary.meets.astype(float),
           f"meets {1000 * summary.target_xy_m:g} mm / {np.degrees(summary.target_yaw_rad):g} deg at every heading: "
           f"{100 * summary.share_worst:.1f} %", "1: meets", 1.0, "RdYlGn")
    for r in summary.fails:
        x0, y0, x1, y1 = r.box_xy
        ax.add_patch(__import__("matplotlib.patches", fromlist=["Rectangle"]).Rectangle(
            (x0, y0), max(x1 - x0, 1e-3), max(y1 - y0, 1e-3), fill=False, ec="k", lw=0.8, ls="--"))
    return _png(fig)
