"""Files of onboard scan matching: relations (gtrig CSV and the RAWSEEDS ``.relations`` layout),
per-stop pose tables, and planar pose tables read as inputs (``pose,x,y,theta[,cov...]``).

relations.csv::

    t1,t2,dx,dy,dtheta,cov_x_x,cov_x_y,cov_x_yaw,cov_y_x,...,cov_yaw_yaw,guess_dx,guess_dy,guess_dtheta,
    matcher,explained,inlier_share,s_ratio,sd_max_m,sd_theta_rad,mahalanobis2,verdict,reason

``(dx, dy, dtheta)`` is the pose at ``t2`` in the robot frame at ``t1``; the covariance is over
``(x, y, yaw)`` of that pose (gtrig.trajectory's convention). The ``.relations`` file holds the
accepted rows as ``t1 t2 dx dy dz droll dpitch dyaw`` (RAWSEEDS Metrics Computation Toolkit).
Both are written together or not at all.
"""

from __future__ import annotations

import csv
import io
import os
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np

from gtrig.errors import FormatError
from gtrig.io.atomic import atomic_group
from gtrig.io.scans import data_lines, parse_numbers

RELATION_COLUMNS = (["t1", "t2", "dx", "dy", "dtheta"]
                    + [f"cov_{a}_{b}" for a in ("x", "y", "yaw") for b in ("x", "y", "yaw")]
                    + ["guess_dx", "guess_dy", "guess_dtheta", "matcher", "explained", "inlier_share", "s_ratio",
                       "sd_max_m", "sd_theta_rad", "mahalanobis2", "verdict", "reason"])


def write_relations(relations: list, csv_path: str | os.PathLike[str],
                    rawseeds_path: str | os.PathLike[str] | None = None) -> None:
    """Write :class:`gtrig.scanmatch.pairs.Relation` rows (all) and the accepted ones as RAWSEEDS."""
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(RELATION_COLUMNS)
    raw = []
    for r in relations:
        v = r.verdict
        w.writerow([f"{r.t1:.6f}", f"{r.t2:.6f}", f"{r.pose[0]:.6f}", f"{r.pose[1]:.6f}", f"{r.pose[2]:.8f}",
                    *[f"{c:.6e}" for c in np.asarray(r.cov).ravel()],
                    f"{r.guess[0]:.6f}", f"{r.guess[1]:.6f}", f"{r.guess[2]:.8f}", r.matcher,
                    f"{v.explained:.4f}", f"{v.inlier_share:.4f}", f"{v.s_ratio:.4f}", f"{v.sd_max_m:.6f}",
                    f"{v.sd_theta_rad:.8f}", f"{v.mahalanobis2:.3f}", "accepted" if v.accepted else "rejected",
                    v.reason])
        if v.accepted:
            raw.append(f"{r.t1:.6f} {r.t2:.6f} {r.pose[0]:.6f} {r.pose[1]:.6f} 0 0 0 {r.pose[2]:.8f}")
    paths = [csv_path] + ([rawseeds_path] if rawseeds_path is not None else [])
    texts = [buf.getvalue()] + (["\n".join(raw) + ("\n" if raw else "")] if rawseeds_path is not None else [])
    with atomic_group(*paths) as tmps:
        for t, text in zip(tmps, texts, strict=True):
            t.write_text(text, encoding="utf-8")


def read_planar_poses(path: str | os.PathLike[str]) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    """A ``pose,x,y,theta`` table (extra columns ``cov_xx,cov_xy,cov_xt,cov_yy,cov_yt,cov_tt`` read when
    present, as ``gtrig survey poses`` writes). Returns pose numbers (K,), poses (K, 3) and covariances
    (K, 3, 3) or None."""
    p = Path(path)
    header, lines, line_no = data_lines(p)
    names = [h.strip() for h in header.split(",")]
    if names[:4] != ["pose", "x", "y", "theta"]:
        raise FormatError(f"{p}: header must start with 'pose,x,y,theta', got {header[:60]!r}")
    a = parse_numbers(p, lines, line_no, len(names))
    if not len(a):
        raise FormatError(f"{p}: no poses")
    bad = np.flatnonzero(~np.all(np.isfinite(a[:, :4]), axis=1))
    if bad.size:
        raise FormatError(f"{p}:{line_no[int(bad[0])]}: pose values must be finite numbers")
    cov = None
    cov_names = ["cov_xx", "cov_xy", "cov_xt", "cov_yy", "cov_yt", "cov_tt"]
    if all(c in names for c in cov_names):
        c = a[:, [names.index(n) for n in cov_names]]
        cov = np.array([[[r[0], r[1], r[2]], [r[1], r[3], r[4]], [r[2], r[4], r[5]]] for r in c])
    return a[:, 0].astype(int), a[:, 1:4], cov


def stop_poses_text(rows: Sequence[Mapping[str, object]]) -> str:
    """The per-stop table of ``gtrig scanmatch validate`` / ``map`` as CSV text (columns of the rows)."""
    buf = io.StringIO()
    if not rows:
        return ""
    w = csv.DictWriter(buf, fieldnames=list(rows[0].keys()), lineterminator="\n")
    w.writeheader()
    for r in rows:
        w.writerow({k: (f"{v:.9g}" if isinstance(v, float) else v) for k, v in r.items()})
    return buf.getvalue()
