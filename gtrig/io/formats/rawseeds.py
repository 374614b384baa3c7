"""RAWSEEDS trajectories: ``t,x,y,theta`` per line, comma separated, no header; the ground-truth
files (``*-GROUNDTRUTH.csv``) add the 3 x 3 covariance of ``(x, y, theta)`` row by row (13 columns).

This is the layout of the published RAWSEEDS ground truth and SLAM solutions (RAWSEEDS Metrics
Computation Toolkit, 2009). The covariance is read as gtrig's ``"xyyaw"`` block: the published files
do not define its frame; x, y along the world axes and theta about the vertical is the only reading
a planar covariance allows, and it is the world-frame perturbation gtrig uses.

A pose track holds a quaternion, so a heading comes back wrapped to (-pi, pi]; the published files
let theta run a little past +-pi (Bicocca_2009-02-25a down to -3.157760). :func:`read_rawseeds_rows`
gives the printed numbers as they are and ``theta=`` writes them back on the file's own branch.

Precision kept: the writer prints ``t``, ``x``, ``y`` and ``theta`` with ``decimals`` (6, as the
published files: 1 us, 1 um, 1 urad) and the covariance with Python's shortest round-trip ``repr``
(exact: gtrig's covariances go down to 1e-10 m^2, which 6 fixed decimals would print as 0). A
published file read and written back gives the same numbers to its printed digits.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from gtrig.io.atomic import atomic_write_text
from gtrig.io.formats._common import read_numeric
from gtrig.io.stamp_order import stamp_order
from gtrig.trajectory import PoseTrack


def read_rawseeds_rows(path: str | os.PathLike[str]) -> np.ndarray:
    """(N, 4) or (N, 13) the numbers of a RAWSEEDS file as printed (theta on the file's own branch), in time
    order (a repeated stamp dropped, one a little back sorted: gtrig.io.stamp_order)."""
    p, a, numbers, _ = read_numeric(path, (4, 13), ",", "4 ('t,x,y,theta') or 13 (plus a 3x3 covariance) "
                                    "comma-separated values")
    keep = stamp_order(p, a[:, 0], numbers)  # as evo reads them (gtrig.io.stamp_order)
    return a if keep is None else a[keep]


def read_rawseeds(path: str | os.PathLike[str]) -> PoseTrack:
    """A RAWSEEDS ``t,x,y,theta[,cov 3x3]`` file as a planar pose track."""
    a = read_rawseeds_rows(path)
    cov = a[:, 4:].reshape(-1, 3, 3) if a.shape[1] == 13 else None
    return PoseTrack.from_xytheta(a[:, 0], a[:, 1:4], cov=cov, source=Path(path).stem)


def _fixed(v: float, decimals: int) -> str:
    return f"{v:.{decimals}f}"


def rawseeds_text(track: PoseTrack, decimals: int = 6, theta: np.ndarray | None = None) -> str:
    """The text of ``track`` in the RAWSEEDS layout (13 columns when it carries a planar or se3
    covariance, else 4). ``theta`` overrides the heading (default: :meth:`PoseTrack.yaw_rad`)."""
    th = track.yaw_rad() if theta is None else np.asarray(theta, float)
    cov = track.cov_xytheta()
    from gtrig.io.tum import stamp_texts

    stamps = stamp_texts(track, min(decimals, 9))
    out = []
    for i in range(len(track)):
        cells = [stamps[i], _fixed(track.xyz[i, 0], decimals),
                 _fixed(track.xyz[i, 1], decimals), _fixed(th[i], decimals)]
        if cov is not None:
            cells += [repr(float(v)) for v in cov[i].ravel()]
        out.append(",".join(cells))
    return "\n".join(out) + "\n"


def write_rawseeds(track: PoseTrack, path: str | os.PathLike[str], decimals: int = 6,
                   theta: np.ndarray | None = None) -> list[Path]:
    """Write the RAWSEEDS layout to ``path`` atomically (``theta``: see :func:`rawseeds_text`)."""
    atomic_write_text(path, rawseeds_text(track, decimals, theta))
    return [Path(path)]
