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
    a0.legend(loc="upper right", fontsize=7, ncol=4)
    a0.set_title(title)
    C = track.cov_xytheta() if track.cov is not None and track.cov_kind != "xyz" else track.cov
    if C is not None:
        a1.semilogy(t, 1000 * np.sqrt(np.maximum(C[:, 0, 0] + C[:, 1, 1], 1e-30)), "b.", ms=1.5,
                    label="position sigma (mm)")
    if len(t) > 1:
        a1.semilogy(t[1:], 1000 * np.diff(t), "k-", lw=0.5, alpha=0.5, label="gap to previous pose (ms)")
    a1.legend(loc="upper right", fontsize=7)
    a1.grid(True, alpha=0.3)
    a1.set_xlabel("time since first pose (s)")
    return fig


def camera_figure(per_camera: dict[str, dict[str, list[float]]], title: str) -> Any:
    """Per camera: where in the image markers were detected (corner scatter) and detections over time."""
    cams = sorted(per_camera)
    fig, axs = figure(nrows=2, ncols=max(len(cams), 1), figsize=(3.2 * max(len(cams), 1), 5.6), squeeze=False)
    t0 = min((min(v["t"]) for v in per_camera.values() if v["t"]), default=0.0)
    for j, cam in enumerate(cams):
        d = per_camera[cam]
        ax = axs[0, j]
        ax.plot(d["u"], d["v"], ".", ms=1, alpha=0.4)
        ax.invert_yaxis()
        ax.set_aspect("equal")
        ax.set_title(f"{cam}: {len(d['t'])} detections", fontsize=9)
        ax.set_xlabel("u (px)", fontsize=8)
        ax = axs[1, j]
        if d["t"]:
            ax.hist(np.asarray(d["t"]) - t0, bins=60, color="c")
        ax.set_xlabel("time (s)", fontsize=8)
        ax.set_ylabel("markers per bin", fontsize=8)
    fig.suptitle(title)
    return fig


def survey_figure(points: dict[str, np.ndarray], cov: np.ndarray | None, truth: dict[str, np.ndarray] | None,
                  poses: np.ndarray | None, pose_cov: np.ndarray | None, scale: float) -> Any:
    """Surveyed world points and validation poses with their 3-sigma ellipses magnified ``scale`` times;
    with truth, the error of each point magnified alike."""
    fig, ax = figure(figsize=(7.5, 6.5))
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
    ax.legend(loc="best", fontsize=8)
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
    ax.legend(fontsize=8)
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
    ax.legend(fontsize=7)
    return fig
