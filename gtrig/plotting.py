"""Figure helpers shared by every stage's plots: a figure on the Agg backend, an atomic save, error ellipses.

Matplotlib is imported only inside these functions (and by the plot modules on top of them): the core
never imports it.
"""

from __future__ import annotations

import io
import os
from typing import Any

import numpy as np

from gtrig.io.atomic import atomic_write_bytes


def figure(**kw: Any) -> tuple[Any, Any]:
    """A new figure and axes (``plt.subplots(**kw)``) on the non-interactive Agg backend."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt.subplots(**kw)


def save(fig: Any, path: str | os.PathLike[str]) -> None:
    """Save a figure atomically (format from the suffix) and close it."""
    import matplotlib.pyplot as plt

    buf = io.BytesIO()
    fmt = os.path.splitext(str(path))[1].lstrip(".").lower() or "png"
    fig.savefig(buf, format=fmt, dpi=130, bbox_inches="tight")
    plt.close(fig)
    atomic_write_bytes(path, buf.getvalue())


def ellipse_xy(center: np.ndarray, cov: np.ndarray, n_sigma: float = 3.0, n: int = 72) -> np.ndarray:
    """Outline (n, 2) of the ``n_sigma`` ellipse of a 2 x 2 covariance around ``center``."""
    w, V = np.linalg.eigh(0.5 * (cov + cov.T))
    a = np.linspace(0, 2 * np.pi, n)
    circle = np.column_stack([np.cos(a), np.sin(a)])
    return center + n_sigma * (circle * np.sqrt(np.maximum(w, 0))) @ V.T
