"""Figures of the GPS report: the coverage map (path coloured by fix type, 1-sigma ellipses every N
kept fixes) and satellites / HDOP / fix type over time. matplotlib, Agg backend; on top of the core.

Both are drawn from the report's own data (:func:`gtrig.gps.report.gps_report`'s ``coverage`` and
```series_1hz``), so ``gtrig gps --plot`` and ``gtrig report`` draw the same figures, the latter
from the JSON alone.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from gtrig.gps.epochs import FIX_NAMES
from gtrig.gps.groundtruth import GpsResult
from gtrig.plotting import figure, save

FIX_COLOURS = {4: "tab:green", 5: "tab:orange", 2: "tab:blue", 1: "tab:red", 9: "tab:purple", 3: "tab:red"}
def _nice_scale(x: float) -> float:
    """The largest of 1, 2, 5, 10, 20, ... not above ``x`` (at least 1)."""
    if not np.isfinite(x) or x <= 1:
        return 1.0
    e = 10.0 ** np.floor(np.log10(x))
    return float(max(m * e for m in (1, 2, 5) if m * e <= x))


def coverage_figure(cov: dict[str, Any], title: str = "") -> Any:
    """The coverage map from the report's ``coverage`` dict: every epoch at its position, coloured by
    fix type, over a grey band where the fix was kept, and the 1-sigma horizontal ellipse of every
    ``ellipse_every``-th kept fix, magnified so that the median one spans about 1 % of the map (the
    factor is in the title, after ``title``)."""
    from matplotlib.patches import Ellipse

    x, y = np.asarray(cov["x_m"], float), np.asarray(cov["y_m"], float)
    q, kept = np.asarray(cov["quality"], int), np.asarray(cov["kept"], bool)
    fig, ax = figure(figsize=(7.5, 6.5))
    # the kept fixes as a band under the fix-type dots, so that both stay visible
    ax.scatter(x[kept], y[kept], s=30, color="0.7", lw=0, label="kept (ground truth)", zorder=1)
    for code in np.unique(q):
        m = q == code
        ax.scatter(x[m], y[m], s=3, color=FIX_COLOURS.get(int(code), "grey"), zorder=2,
                   label=f"{FIX_NAMES.get(int(code), code)} ({m.mean():.0%} of epochs)")
    ell = np.asarray(cov["ellipses"], float).reshape(-1, 5)
    extent = max(float(np.ptp(x)) if x.size else 0.0, float(np.ptp(y)) if y.size else 0.0, 1.0)
    scale = 1.0
    if len(ell):
        C = np.stack([np.stack([ell[:, 2], ell[:, 3]], -1), np.stack([ell[:, 3], ell[:, 4]], -1)], -2)
        w, V = np.linalg.eigh(C)
        scale = _nice_scale(0.01 * extent / max(float(np.median(np.sqrt(np.maximum(w[:, 1], 0)))), 1e-6))
        for (ex, ey), wk, Vk in zip(ell[:, :2], w, V, strict=True):
            ax.add_patch(Ellipse((ex, ey), 2 * scale * np.sqrt(max(wk[1], 0.0)), 2 * scale * np.sqrt(max(wk[0], 0.0)),
                                 angle=np.degrees(np.arctan2(Vk[1, 1], Vk[0, 1])), fill=False, color="k", lw=0.7,
                                 zorder=3))
    ax.set_aspect("equal")
    axes = ("east", "north") if cov.get("frame", "enu") == "enu" else ("UTM easting", "UTM northing")
    ax.set_xlabel(f"{axes[0]} (m)")
    ax.set_ylabel(f"{axes[1]} (m)")
    ax.set_title(f"{title or 'coverage'}: fix type per epoch; 1-sigma ellipses x{scale:g} every "
                 f"{cov['ellipse_every']} kept fixes", fontsize=9)
    ax.legend(loc="best", fontsize=7, markerscale=2)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    return fig


def _broken(t: np.ndarray, v: np.ndarray, max_gap_s: float) -> tuple[np.ndarray, np.ndarray]:
    """``t, v`` with a NaN after every step longer than ``max_gap_s``, so no line is drawn across a gap."""
    cut = np.flatnonzero(np.diff(t) > max_gap_s) + 1
    return np.insert(t, cut, np.nan), np.insert(v, cut, np.nan)


def time_series_figure(series: dict[str, Any], lost: list[tuple[float, float]] | None = None) -> Any:
    """Satellites, HDOP and fix type against time since the first epoch (the report's ``series_1hz``),
    the lost-fix intervals (seconds since the first epoch) shaded."""
    t = np.asarray(series["t_s"], float)
    n_sat = np.asarray(series["n_sat"], float)
    n_sat[n_sat < 0] = np.nan
    hdop = np.array([np.nan if v is None else v for v in series["hdop"]], float)
    q = np.asarray(series["quality"], int)
    fig, axs = figure(nrows=3, ncols=1, figsize=(8, 6), sharex=True)
    gap = 2.5 * float(np.median(np.diff(t))) if t.size > 1 else 1.0  # no epoch (no fix): no line
    axs[0].plot(*_broken(t, n_sat, gap), lw=0.8)
    axs[0].set_ylabel("satellites")
    axs[1].plot(*_broken(t, hdop, gap), lw=0.8)
    axs[1].set_ylabel("HDOP")
    codes = sorted(int(v) for v in np.unique(q))
    for code in codes:
        m = q == code
        axs[2].scatter(t[m], q[m], s=2, color=FIX_COLOURS.get(code, "grey"))
    axs[2].set_yticks(codes, [FIX_NAMES.get(c, str(c)) for c in codes])
    axs[2].set_xlabel("time since the first epoch (s)")
    for a in axs:
        for k, (t0, t1) in enumerate(lost or []):
            a.axvspan(t0, t1, color="r", alpha=0.12, lw=0, label="no kept fix" if k == 0 and a is axs[0] else None)
        a.grid(alpha=0.3)
    if lost:
        axs[0].legend(loc="upper right", fontsize=7)
    axs[0].set_title("satellites, HDOP and fix type over time", fontsize=9)
    fig.tight_layout()
    return fig


def lost_since_first(rep: dict[str, Any]) -> list[tuple[float, float]]:
    """The report's lost-fix intervals in seconds since the first epoch (the time series' axis)."""
    lost = rep["lost_fix_intervals"]
    return [(a - lost["t0_s"], b - lost["t0_s"]) for a, b in lost["intervals"]]


def coverage_map(res: GpsResult, path: str | Path, ellipse_every: int = 50, title: str = "") -> Path:
    """Write the coverage map of ``res`` (:func:`coverage_figure`) as a PNG; returns the path."""
    from gtrig.gps.report import coverage_data

    save(coverage_figure(coverage_data(res, ellipse_every), title), path)
    return Path(path)


def time_series(res: GpsResult, path: str | Path) -> Path:
    """Write satellites, HDOP and fix type over time (:func:`time_series_figure`) as a PNG; returns the path."""
    from gtrig.gps.report import gps_report

    rep = gps_report(res)
    save(time_series_figure(rep["series_1hz"], lost_since_first(rep)), path)
    return Path(path)
