"""Figures of the GPS report: the coverage map (path coloured by fix type, 1-sigma ellipses every N
kept fixes) and satellites / HDOP / fix type over time. matplotlib, Agg backend; on top of the core."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from gtrig.gps.epochs import FIX_NAMES
from gtrig.gps.groundtruth import GpsResult
from gtrig.io.atomic import atomic_open

FIX_COLOURS = {4: "tab:green", 5: "tab:orange", 2: "tab:blue", 1: "tab:red", 9: "tab:purple", 3: "tab:red"}


def _save(fig: object, path: Path) -> None:
    with atomic_open(path, "wb") as f:
        fig.savefig(f, format="png", dpi=110)  # type: ignore[attr-defined]


def coverage_map(res: GpsResult, path: str | Path, ellipse_every: int = 50, title: str = "") -> Path:
    """The path in the output frame, each epoch coloured by its fix type, the kept ones marked black,
    with the 1-sigma horizontal ellipse of every ``ellipse_every``-th kept fix (scaled x10 when
    smaller than the line width would show)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.patches import Ellipse

    tr = res.all_epochs
    q = res.epochs.quality
    fig, ax = plt.subplots(figsize=(7.5, 6.5))
    for code in np.unique(q):
        m = q == code
        ax.scatter(tr.xyz[m, 0], tr.xyz[m, 1], s=3, color=FIX_COLOURS.get(int(code), "grey"),
                   label=f"{FIX_NAMES.get(int(code), code)} ({m.mean():.0%})")
    kept = res.track
    ax.scatter(kept.xyz[:, 0], kept.xyz[:, 1], s=0.3, color="k", label="kept (ground truth)", zorder=3)
    scale = 10.0
    if kept.cov is not None:
        for i in range(0, len(kept), max(1, ellipse_every)):
            C = kept.cov[i, :2, :2]
            w, V = np.linalg.eigh(C)
            ang = np.degrees(np.arctan2(V[1, 1], V[0, 1]))
            ax.add_patch(Ellipse(tuple(kept.xyz[i, :2]), 2 * scale * np.sqrt(w[1]), 2 * scale * np.sqrt(w[0]),
                                 angle=ang, fill=False, color="k", lw=0.6))
    ax.set_aspect("equal")
    axes = ("east", "north") if res.frame == "enu" else ("UTM easting", "UTM northing")
    ax.set_xlabel(f"{axes[0]} (m)")
    ax.set_ylabel(f"{axes[1]} (m)")
    ax.set_title(title or f"coverage: fix types, 1-sigma ellipses x{scale:g} every {ellipse_every} kept fixes",
                 fontsize=9)
    ax.legend(loc="best", fontsize=7, markerscale=3)
    ax.grid(alpha=0.3)
    out = Path(path)
    fig.tight_layout()
    _save(fig, out)
    plt.close(fig)
    return out


def time_series(res: GpsResult, path: str | Path) -> Path:
    """Satellites, HDOP and fix type against time since the first epoch."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    ep = res.epochs
    t = ep.utc_s - ep.utc_s[0]
    fig, axs = plt.subplots(3, 1, figsize=(8, 6), sharex=True)
    axs[0].plot(t, ep.n_sat, lw=0.8)
    axs[0].set_ylabel("satellites")
    axs[1].plot(t, ep.hdop, lw=0.8)
    axs[1].set_ylabel("HDOP")
    for code in np.unique(ep.quality):
        m = ep.quality == code
        axs[2].scatter(t[m], ep.quality[m], s=2, color=FIX_COLOURS.get(int(code), "grey"))
    axs[2].set_yticks(sorted(set(int(v) for v in np.unique(ep.quality))))
    axs[2].set_yticklabels([FIX_NAMES.get(int(v), str(v)) for v in sorted(set(int(v) for v in np.unique(ep.quality)))])
    axs[2].set_xlabel("time since the first epoch (s)")
    for a in axs:
        a.grid(alpha=0.3)
    fig.tight_layout()
    out = Path(path)
    _save(fig, out)
    plt.close(fig)
    return out
