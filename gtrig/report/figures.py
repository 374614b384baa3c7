"""The report's own figures (the evaluation's come from gtrig.evaluate.plots): status over time, camera
coverage and detections, the survey's points and ellipses, calibration residuals, sync correlation curves.

Each function takes already-read data and returns a matplotlib figure; the page embeds it as a PNG."""

from __future__ import annotations

from typing import Any

import numpy as np

from gtrig.plotting import ellipse_xy, figure
from gtrig.trajectory import PoseStatus, PoseTrack


def status_figure(track: PoseTrack, title: str) -> Any:
    """Status per pose over time, and the per-pose position sigma (mm) and gaps between poses."""
    fig, (a0, a1) = figure(nrows=2, sharex=True, figsize=(9, 3.6))
    t = track.stamps_s - track.stamps_s[0]
    colors = {PoseStatus.OK: "g", PoseStatus.FLAGGED: "orange", PoseStatus.BRIDGED: "purple",
              PoseStatus.REJECTED: "r"}
    for s, c in colors.items():
        m = track.status == s
        if np.any(m):
            a0.plot(t[m], np.full(int(m.sum()), int(s)), "|", color=c, ms=10, label=f"{s.name.lower()} {m.sum()}")
    a0.set_yticks([int(s) for s in PoseStatus], [s.name.lower() for s in PoseStatus])
    a0.set_ylim(-0.5, 3.5)
    a0.legend(loc="upper right", fontsize=9, ncol=4)
    a0.set_title(title)
    C = track.cov_xytheta() if track.cov is not None and track.cov_kind != "xyz" else track.cov
    if C is not None:
        a1.semilogy(t, 1000 * np.sqrt(np.maximum(C[:, 0, 0] + C[:, 1, 1], 1e-30)), "b.", ms=1.5,
                    label="position sigma (mm)")
    if len(t) > 1:
        a1.semilogy(t[1:], 1000 * np.diff(t), "k-", lw=0.5, alpha=0.5, label="gap to previous pose (ms)")
    a1.legend(loc="upper right", fontsize=9)
    a1.grid(True, alpha=0.3)
    a1.set_xlabel("time since first pose (s)")
    return fig


#: corners drawn per camera at most (every k-th beyond), images drawn one tick each at most
MAX_CORNERS_DRAWN = 100_000
MAX_IMAGE_TICKS = 600


def camera_coverage_figure(per_camera: dict[str, Any], sizes_px: dict[str, tuple[int, int]], axis: str,
                           title: str) -> Any:
    """Per camera (columns): every detected corner in its image, the image's frame drawn at its size (top);
    the images showing a marker along the recording (bottom). ``per_camera[cam]`` is a
    gtrig.report.coverage.CameraCoverage; ``axis`` says whether its rows are ``image`` rows or ``time`` (s)."""
    cams = sorted(per_camera)
    n = max(len(cams), 1)
    image_h = 0.75 * 0.85 * 13 / n  # a 4:3 image in its column
    fig, axs = figure(nrows=2, ncols=n, figsize=(13, min(1.4 * image_h + 1.6, 9.0)), squeeze=False,
                      gridspec_kw={"height_ratios": [3, 1]})
    for j, cam in enumerate(cams):
        c = per_camera[cam]
        ax = axs[0, j]
        uv = c.uv()
        uv = uv[:: max(1, len(uv) // MAX_CORNERS_DRAWN)]
        ax.plot(uv[:, 0], uv[:, 1], ".", ms=2, alpha=0.5)
        if cam in sizes_px:
            w, h = sizes_px[cam]
            ax.plot([0, w, w, 0, 0], [0, 0, h, h, 0], "k-", lw=0.8)
            ax.set_xlim(-0.02 * w, 1.02 * w)
            ax.set_ylim(1.02 * h, -0.02 * h)
        else:
            ax.invert_yaxis()
        ax.set_aspect("equal")
        ax.set_title(f"{cam}: {c.n_markers} markers in {int(np.sum(c.marked))} images", fontsize=10)
        ax.set_xlabel("u (px)")
        if j == 0:
            ax.set_ylabel("v (px)")
        ax = axs[1, j]
        rows = np.asarray(c.rows, float)
        marked = np.asarray(c.marked, bool)
        r0 = (rows.min() if axis == "image" else min(min(p.rows) for p in per_camera.values() if p.rows)
              ) if rows.size else 0.0
        if rows.size <= MAX_IMAGE_TICKS:  # one tick per image
            ax.plot(rows[marked] - r0, np.ones(int(marked.sum())), "|", color="g", ms=12)
            ax.plot(rows[~marked] - r0, np.zeros(int((~marked).sum())), "|", color="0.6", ms=12)
            ax.set_yticks([0, 1], ["none", "marker"])
            ax.set_ylim(-0.6, 1.6)
        else:  # the share of images showing a marker, per bin
            n_all, edges = np.histogram(rows - r0, bins=60)
            n_marked, _ = np.histogram(rows[marked] - r0, bins=edges)
            ax.stairs(100 * n_marked / np.maximum(n_all, 1), edges, color="g", fill=True, alpha=0.6)
            ax.set_ylim(0, 105)
            ax.set_ylabel("% with a marker" if j == 0 else "")
        ax.set_xlabel("image number" if axis == "image" else "time (s)")
    fig.suptitle(title)
    fig.tight_layout()
    return fig


def _nice(v: float) -> float:
    """The largest of 1, 2, 5 x 10^k not above ``v`` (1 at least)."""
    if v <= 1:
        return 1.0
    k = 10 ** np.floor(np.log10(v))
    return float(max(m * k for m in (1, 2, 5) if m * k <= v))


def _zoom_window(xy: np.ndarray, C: np.ndarray | None, n_sigma: float) -> tuple[int, float]:
    """The pose the true-scale zoom centres on (the middle one of those with a finite position and
    covariance) and the zoom's half width (m): four of its ellipses across, 2 mm at least (2 cm without a
    covariance)."""
    ok = np.all(np.isfinite(xy), axis=1)
    if C is not None:
        ok &= np.all(np.isfinite(C[:, :2, :2].reshape(len(C), -1)), axis=1)
    cand = np.flatnonzero(ok)
    mid = int(cand[cand.size // 2]) if cand.size else 0
    if C is None or not cand.size:
        return mid, 0.02
    return mid, max(4 * n_sigma * float(np.sqrt(max(C[mid, 0, 0], C[mid, 1, 1], 1e-12))), 2e-3)


def _ellipses(ax: Any, xy: np.ndarray, C: np.ndarray, idx: np.ndarray, k: float, n_sigma: float) -> None:
    """The ``n_sigma`` position ellipses of the poses ``idx``, magnified ``k`` times."""
    for i in idx:
        if np.all(np.isfinite(C[i][:2, :2])) and np.all(np.isfinite(xy[i])):
            e = ellipse_xy(xy[i], C[i][:2, :2] * k**2, n_sigma)
            ax.plot(e[:, 0], e[:, 1], "c-", lw=0.7)
    ax.plot([], [], "c-", lw=0.7, label=f"{n_sigma:g}-sigma ellipse" + (f" x{k:g}" if k > 1 else ", true size"))


def track_figure(track: PoseTrack, truth: PoseTrack | None, name: str, n_sigma: float = 3.0,
                 max_ellipses: int = 120) -> tuple[Any, str]:
    """The x-y path of ``track`` with its ``n_sigma`` position ellipses magnified to be seen (left), and a
    zoom at true scale on the poses around the middle of the run (right); flagged / bridged / rejected poses
    marked, the truth in red. Returns the figure and a caption saying how the ellipses are drawn."""
    fig, (a0, a1) = figure(ncols=2, figsize=(13, 6.0), gridspec_kw={"width_ratios": [1.5, 1]})
    xy = track.xyz[:, :2]
    C = track.cov_xytheta() if track.cov is not None and track.cov_kind != "xyz" else track.cov
    mag, every = 1.0, max(1, len(track) // max_ellipses)
    if C is not None and len(track):
        extent = float(np.nanmax(np.ptp(xy, axis=0))) or 1.0
        sig = float(np.nanmedian(np.sqrt(np.maximum(C[:, 0, 0] + C[:, 1, 1], 0))))
        if np.isfinite(sig) and sig > 0:
            mag = _nice(0.02 * extent / (n_sigma * sig))  # the median ellipse about 2 % of the path
    mid, half = _zoom_window(xy, C, n_sigma)
    colors = {PoseStatus.FLAGGED: "orange", PoseStatus.BRIDGED: "purple", PoseStatus.REJECTED: "r"}
    for ax in (a0, a1):
        ax.plot(xy[:, 0], xy[:, 1], "b.-", lw=0.8, ms=2 if ax is a1 else 0, label=name)
        if truth is not None:
            ax.plot(truth.xyz[:, 0], truth.xyz[:, 1], "r-", lw=0.8, alpha=0.8, label="truth")
        for s, col in colors.items():
            m = track.status == s
            if np.any(m):
                ax.plot(xy[m, 0], xy[m, 1], "x", color=col, ms=5, ls="none", label=f"{s.name.lower()} ({m.sum()})")
    if C is not None and len(track):
        _ellipses(a0, xy, C, np.arange(0, len(track), every), mag, n_sigma)
        near = np.flatnonzero(np.all(np.abs(xy - xy[mid]) < half, axis=1))
        _ellipses(a1, xy, C, near[:: max(1, near.size // 40)], 1.0, n_sigma)
    if len(track):
        a0.add_patch(_box(xy[mid], half))
        a1.set_xlim(xy[mid, 0] - half, xy[mid, 0] + half)
        a1.set_ylim(xy[mid, 1] - half, xy[mid, 1] + half)
        a1.set_title(f"zoom at true scale: {2000 * half:.0f} mm wide (the box on the left)", fontsize=10)
    a0.set_title(f"{name}: path", fontsize=10)
    for ax in (a0, a1):
        ax.set_aspect("equal")
        ax.grid(True, alpha=0.3)
        ax.set_xlabel("x (m)")
        ax.legend(loc="best", fontsize=9)
    a0.set_ylabel("y (m)")
    fig.tight_layout()
    which = "every pose" if every == 1 else f"one pose in {every}"
    caption = (f"{name}: path (blue) "
               + (f"with its {n_sigma:g}-sigma position ellipses (cyan) magnified {mag:g}x on the left ({which}) "
                  "and at true size in the zoom on the right" if C is not None
                  else "without ellipses (no covariance in the folder), zoomed on the right")
               + ", flagged / bridged / rejected poses as crosses" + (", truth in red" if truth is not None else ""))
    return fig, caption


def _box(center: np.ndarray, half: float) -> Any:
    from matplotlib.patches import Rectangle

    return Rectangle((center[0] - half, center[1] - half), 2 * half, 2 * half, fill=False, ec="k", lw=1.0)


def survey_figure(points: dict[str, np.ndarray], cov: np.ndarray | None, truth: dict[str, np.ndarray] | None,
                  poses: np.ndarray | None, pose_cov: np.ndarray | None, scale: float) -> Any:
    """Surveyed world points and validation poses with their 3-sigma ellipses magnified ``scale`` times;
    with truth, the error of each point magnified alike."""
    fig, ax = figure(figsize=(13, 7.5))
    names = list(points)
    P = np.array([points[n] for n in names])
    ax.plot(P[:, 0], P[:, 1], "b+", label="world points")
    if cov is not None:
        for p, c in zip(P, cov, strict=True):
            e = ellipse_xy(p, c * scale**2, 3.0)
            ax.plot(e[:, 0], e[:, 1], "b-", lw=0.6)
    if truth:
        for n, p in zip(names, P, strict=True):
            if n in truth:
                d = (p - truth[n]) * scale
                ax.annotate("", p + d, p, arrowprops={"arrowstyle": "->", "color": "r", "lw": 0.8})
        ax.plot([], [], "r-", label=f"error (x{scale:g})")
    if poses is not None:
        ax.quiver(poses[:, 0], poses[:, 1], np.cos(poses[:, 2]), np.sin(poses[:, 2]), color="g", scale=30,
                  width=0.003, label="validation poses")
        if pose_cov is not None:
            for p, c in zip(poses, pose_cov, strict=True):
                e = ellipse_xy(p[:2], c[:2, :2] * scale**2, 3.0)
                ax.plot(e[:, 0], e[:, 1], "g-", lw=0.6)
    ax.set_title(f"survey: 3-sigma ellipses x{scale:g}")
    ax.set_aspect("equal")
    ax.grid(True, alpha=0.3)
    ax.legend(loc="best", fontsize=9)
    return fig


def bars_figure(groups: dict[str, dict[str, float]], ylabel: str, title: str) -> Any:
    """Grouped bars: ``groups[series][camera] = value``."""
    series = list(groups)
    cams = sorted({c for g in groups.values() for c in g})
    fig, ax = figure(figsize=(8, 3.5))
    w = 0.8 / max(len(series), 1)
    for k, s in enumerate(series):
        ax.bar(np.arange(len(cams)) + k * w, [groups[s].get(c, np.nan) for c in cams], w, label=s)
    ax.set_xticks(np.arange(len(cams)) + 0.4 - w / 2, cams)
    ax.set_ylabel(ylabel)
    ax.set_title(title)
    ax.legend(fontsize=9)
    ax.grid(True, axis="y", alpha=0.3)
    return fig


def curves_figure(curves: dict[str, tuple[np.ndarray, np.ndarray]], xlabel: str, ylabel: str, title: str) -> Any:
    """One line per curve, its maximum marked (the sync correlation curves)."""
    fig, ax = figure(figsize=(8, 3.5))
    for name, (x, y) in curves.items():
        ax.plot(x, y, "-", lw=0.8, label=name)
        i = int(np.nanargmax(y))
        ax.plot(x[i], y[i], "kx")
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    ax.set_title(title)
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=9)
    return fig
