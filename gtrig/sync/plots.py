"""Figures of fusion and sync (matplotlib; imported by the CLI only)."""

from __future__ import annotations

import os

from gtrig.sync.offset import OffsetEstimate


def correlation_figure(estimates: list[OffsetEstimate], path: str | os.PathLike[str]) -> None:
    """One panel per source (normalised heading-rate correlation against the lag) or per camera / scanner
    (the timing fit's min cost / cost against the trial offset), the estimate marked."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from gtrig.io.atomic import atomic_open

    fig, axes = plt.subplots(len(estimates), 1, figsize=(7, 2.4 * len(estimates)), squeeze=False)
    for ax, e in zip(axes[:, 0], estimates, strict=True):
        ax.plot(e.lags_s, e.corr, lw=1)
        if e.verdict == "ok":
            ax.axvline(e.offset_s, color="r", lw=0.8)
        ax.set_title(f"{e.source}: {e.verdict}" + (f", {e.offset_s * 1e3:+.2f} ms" if e.verdict == "ok" else ""))
        ax.set_xlabel("offset (s): source stamp - reference stamp")
        # heading-rate correlation (a source) or min cost / cost of the timing fit (a camera, a scanner)
        ax.set_ylabel("correlation" if "/" not in e.source else "min cost / cost")
    fig.tight_layout()
    with atomic_open(path, "wb") as f:
        fig.savefig(f, format="png", dpi=110)
    plt.close(fig)
