"""Figure of a pose comparison: both trajectories, error vectors and covariance ellipses."""

from __future__ import annotations

import os
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from gtrig.evaluate.poses import PoseComparison
from gtrig.plotting import ellipse_xy, figure, save
from gtrig.trajectory import PoseTrack

if TYPE_CHECKING:
    from gtrig.evaluate.slam import SlamEvaluation


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


# --- trajectories (gtrig evaluate slam --plot, gtrig report) -------------------------------------------------

_STATUS_STYLE = {1: ("FLAGGED", "orange", "^"), 2: ("BRIDGED", "purple", "s"), 3: ("REJECTED", "red", "x")}


def track_figure(track: PoseTrack, other: PoseTrack | None = None, label: str = "GT", other_label: str = "estimate",
                 n_sigma: float = 3.0, max_ellipses: int = 150) -> Any:
    """The x-y path of ``track`` with ``n_sigma`` position ellipses (every k-th pose, at most ``max_ellipses``)
    and its flagged / bridged / rejected poses marked; ``other`` (an estimate, the truth) drawn over it."""
    fig, ax = figure(figsize=(7.5, 6.5))
    ax.plot(track.xyz[:, 0], track.xyz[:, 1], "b-", lw=0.8, label=label)
    C = track.cov_xytheta() if track.cov is not None else (track.cov if track.cov_kind == "xyz" else None)
    if C is not None and len(track):
        # millimetre ellipses on a room-sized path: magnified by a power of ten to about 1 % of the extent
        extent = float(np.ptp(track.xyz[:, :2], axis=0).max()) or 1.0
        sig = float(np.nanmedian(np.sqrt(np.maximum(C[:, 0, 0] + C[:, 1, 1], 0)))) or 1e-12
        mag = float(10 ** max(0, np.floor(np.log10(0.01 * extent / (n_sigma * sig)))))
        for i in np.arange(0, len(track), max(1, len(track) // max_ellipses)):
            if np.all(np.isfinite(C[i][:2, :2])):
                e = ellipse_xy(track.xyz[i, :2], C[i][:2, :2] * mag**2, n_sigma)
                ax.plot(e[:, 0], e[:, 1], "c-", lw=0.5)
        ax.plot([], [], "c-", lw=0.5, label=f"{n_sigma:g} sigma" + (f" x{mag:g}" if mag > 1 else ""))
    for code, (name, col, mk) in _STATUS_STYLE.items():
        m = track.status == code
        if np.any(m):
            ax.plot(track.xyz[m, 0], track.xyz[m, 1], mk, color=col, ms=4, ls="none", label=f"{name} ({m.sum()})")
    if other is not None:
        ax.plot(other.xyz[:, 0], other.xyz[:, 1], "r-", lw=0.7, alpha=0.8, label=other_label)
    ax.set_aspect("equal")
    ax.grid(True, alpha=0.3)
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.legend(loc="best", fontsize=8)
    return fig


def error_bounds_figure(gt: PoseTrack, est: PoseTrack, title: str = "", n_sigma: float = 3.0) -> Any:
    """Per-axis errors ``est - gt`` over time with the GT's ``+- n_sigma`` bounds (from its covariance)."""
    from gtrig.evaluate.gt_aware import world_errors
    from gtrig.trajectory import COV_AXES

    kind = gt.cov_kind if gt.cov is not None else "xyyaw"
    g = gt if gt.cov is not None else gt.with_cov(None, "xyyaw")
    e = world_errors(g, est)
    axes = COV_AXES[kind]
    show = [i for i, a in enumerate(axes) if a in ("x", "y", "z", "yaw", "rz")]
    fig, axs = figure(nrows=len(show), sharex=True, figsize=(9, 1.9 * len(show) + 0.6))
    axs = np.atleast_1d(axs)
    t = gt.stamps_s - gt.stamps_s[0]
    for ax, i in zip(axs, show, strict=True):
        rot = axes[i] in ("yaw", "rz")
        k = 1000.0 if not rot else float(np.degrees(1.0))
        ax.plot(t, k * e[:, i], "k.", ms=1.5, label="error")
        if gt.cov is not None:
            s = n_sigma * np.sqrt(np.maximum(gt.cov[:, i, i], 0))
            ax.fill_between(t, -k * s, k * s, color="c", alpha=0.3, lw=0, label=f"GT +-{n_sigma:g} sigma")
        ax.set_ylabel(f"{axes[i]} ({'deg' if rot else 'mm'})")
        ax.grid(True, alpha=0.3)
    axs[0].legend(loc="upper right", fontsize=8)
    axs[0].set_title(title)
    axs[-1].set_xlabel("time since first pose (s)")
    return fig


def series_figure(series: list[Any], title: str = "") -> Any:
    """Error series (evo's APE / RPE) over time, one panel each."""
    fig, axs = figure(nrows=len(series), sharex=True, figsize=(9, 1.9 * len(series) + 0.6))
    axs = np.atleast_1d(axs)
    t0 = min(float(s.stamps_s[0]) for s in series)
    for ax, s in zip(axs, series, strict=True):
        ax.plot(s.stamps_s - t0, s.values, "-", lw=0.7)
        st = s.stats()
        ax.axhline(st["rmse"], color="r", lw=0.8, label=f"rmse {st['rmse']:.4g} {s.unit}")
        ax.set_ylabel(f"{s.name} ({s.unit or '-'})")
        ax.grid(True, alpha=0.3)
        ax.legend(loc="upper right", fontsize=8)
    axs[0].set_title(title)
    axs[-1].set_xlabel("time (s)")
    return fig


def d2_figure(d2: np.ndarray, k: int, title: str = "") -> Any:
    """Histogram of Mahalanobis distances squared against the chi2(k) density (an honest covariance)."""
    from scipy import stats

    fig, ax = figure(figsize=(6.5, 4))
    hi = float(max(np.quantile(d2, 0.99), stats.chi2.ppf(0.999, k)))
    bins = np.linspace(0, hi, 60)
    ax.hist(np.clip(d2, 0, hi), bins=bins, density=True, color="0.6", label=f"d2 ({len(d2)} poses)")
    x = np.linspace(1e-3, hi, 300)
    ax.plot(x, stats.chi2.pdf(x, k), "r-", label=f"chi2({k})")
    ax.axvline(stats.chi2.ppf(0.95, k), color="r", ls="--", lw=0.8, label="95 %")
    ax.set_xlabel("d2 = e^T C^-1 e")
    ax.set_title(title)
    ax.legend(fontsize=8)
    return fig


def slam_figures(ev: SlamEvaluation, gt_label: str = "GT", est_label: str = "estimate") -> dict[str, Any]:
    """The figures of one evaluation, by file stem."""
    figs: dict[str, Any] = {"trajectory": track_figure(ev.association.gt, ev.est_aligned, gt_label,
                                                       f"{est_label} ({ev.alignment.kind})")}
    figs["errors"] = error_bounds_figure(ev.association.gt, ev.est_aligned, f"{est_label} - {gt_label}")
    series = [s for d in (ev.ape, ev.rpe) if d for k, s in d.items() if k != "full"]
    if series:
        figs["evo"] = series_figure(series, f"{est_label} against {gt_label}")
    if ev.rawseeds_ate is not None:
        a = ev.rawseeds_ate
        fig, ax = figure(figsize=(6.5, 4))
        ax.hist(a.dist_m, bins=80, color="c")
        for v, c in zip(a.ate, ("b", "k", "r", "r"), strict=True):
            ax.axvline(v, color=c, lw=0.8)
        ax.set_xlabel("position error (m)")
        ax.set_title(f"RAWSEEDS ATE: mean {a.ate[0]:.4f} m, std {a.ate[1]:.4f} m (mean +- 3 std in red)")
        figs["rawseeds_ate"] = fig
    if ev.gt_aware is not None:
        figs["d2"] = d2_figure(ev.gt_aware.d2, len(ev.gt_aware.axes), "errors under the GT covariance")
    return figs


def plot_slam(ev: SlamEvaluation, folder: str | os.PathLike[str], gt_label: str = "GT",
              est_label: str = "estimate") -> list[Path]:
    """Write :func:`slam_figures` as PNGs in ``folder``; returns the paths."""
    out = []
    for name, fig in slam_figures(ev, gt_label, est_label).items():
        p = Path(folder) / f"{name}.png"
        save(fig, p)
        out.append(p)
    return out
