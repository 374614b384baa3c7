"""Files of ``gtrig plan``: the grid CSV (one row per pose) and the self-contained HTML page.

CSV columns: ``x_m, y_m, heading_deg``, then for each source (vision, laser, fused) the position's
largest standard deviation ``<source>_sxy_mm`` and the yaw's ``<source>_syaw_deg`` (empty: the source
does not cover the pose), then ``cameras`` (cameras seeing a marker whole), ``views`` (markers seen
whole, all cameras), ``scanners`` (scanners with beams on the hull), ``beams`` (beams on the hull).
"""

from __future__ import annotations

import base64
import html
import io
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from gtrig.errors import FormatError
from gtrig.io.atomic import atomic_write_text

SOURCES = ("vision", "laser", "fused")
COLUMNS = ("x_m", "y_m", "heading_deg") + tuple(
    f"{s}_{q}" for s in SOURCES for q in ("sxy_mm", "syaw_deg")) + ("cameras", "views", "scanners", "beams")


@dataclass(frozen=True)
class PlanTable:
    """The grid CSV's columns: ``xytheta`` (K, 3) (m, m, rad); ``sigma_xy_m`` and ``sigma_yaw_rad``
    {source: (K,)} (nan: uncovered); ``cameras``, ``views``, ``scanners``, ``beams`` (K,) counts."""

    xytheta: np.ndarray
    sigma_xy_m: dict[str, np.ndarray]
    sigma_yaw_rad: dict[str, np.ndarray]
    cameras: np.ndarray
    views: np.ndarray
    scanners: np.ndarray
    beams: np.ndarray


def plan_csv_text(t: PlanTable) -> str:
    """The CSV text of a table (positions to 0.1 mm, sigmas to 1 nm and 1e-7 deg)."""
    cols: list[np.ndarray] = [t.xytheta[:, 0], t.xytheta[:, 1], np.degrees(t.xytheta[:, 2])]
    for s in SOURCES:
        cols += [1000 * t.sigma_xy_m[s], np.degrees(t.sigma_yaw_rad[s])]
    data = np.column_stack(cols + [t.cameras, t.views, t.scanners, t.beams])
    buf = io.StringIO()
    fmt = ["%.4f", "%.4f", "%.4f"] + ["%.6f", "%.7f"] * 3 + ["%d"] * 4
    np.savetxt(buf, data, fmt=fmt, delimiter=",", header=",".join(COLUMNS), comments="")
    return buf.getvalue().replace("nan", "")


def write_plan_csv(path: str | os.PathLike[str], t: PlanTable) -> None:
    """Write the table atomically."""
    atomic_write_text(path, plan_csv_text(t))


def read_plan_csv(path: str | os.PathLike[str]) -> PlanTable:
    """Read a table written by :func:`write_plan_csv`; :class:`FormatError` names the file, line and
    field of a malformed value."""
    p = Path(path)
    lines = p.read_text(encoding="utf-8").splitlines()
    if not lines or tuple(lines[0].split(",")) != COLUMNS:
        raise FormatError(f"{p}:1: expected the header {','.join(COLUMNS)}")
    rows = np.full((len(lines) - 1, len(COLUMNS)), np.nan)
    for i, line in enumerate(lines[1:]):
        f = line.split(",")
        if len(f) != len(COLUMNS):
            raise FormatError(f"{p}:{i + 2}: {len(f)} fields, expected {len(COLUMNS)}")
        for j, v in enumerate(f):
            if v == "" and 3 <= j < 9:
                continue
            try:
                rows[i, j] = float(v)
            except ValueError:
                raise FormatError(f"{p}:{i + 2}: {COLUMNS[j]} {v!r} is not a number") from None
            if not np.isfinite(rows[i, j]):
                raise FormatError(f"{p}:{i + 2}: {COLUMNS[j]} {v!r} is not finite")
    sxy = {s: rows[:, 3 + 2 * k] / 1000 for k, s in enumerate(SOURCES)}
    syaw = {s: np.radians(rows[:, 4 + 2 * k]) for k, s in enumerate(SOURCES)}
    xyt = np.column_stack([rows[:, 0], rows[:, 1], np.radians(rows[:, 2])])
    c = rows[:, 9:].astype(int)
    return PlanTable(xyt, sxy, syaw, c[:, 0], c[:, 1], c[:, 2], c[:, 3])


def write_plan_html(path: str | os.PathLike[str], title: str, summary_lines: list[str],
                    figures: list[tuple[str, bytes]]) -> None:
    """A self-contained page: the title, the summary (one paragraph per line) and each PNG figure
    (caption, bytes) embedded as base64; written atomically."""
    parts = ["<!DOCTYPE html>", "<html><head><meta charset='utf-8'>", f"<title>{html.escape(title)}</title>",
             "<style>body{font-family:sans-serif;max-width:1100px;margin:auto}img{max-width:100%}"
             "figure{margin:1em 0}</style></head><body>", f"<h1>{html.escape(title)}</h1>"]
    parts += [f"<p>{html.escape(s)}</p>" for s in summary_lines]
    for caption, png in figures:
        b64 = base64.b64encode(png).decode("ascii")
        parts.append(f"<figure><img alt='{html.escape(caption)}' src='data:image/png;base64,{b64}'>"
                     f"<figcaption>{html.escape(caption)}</figcaption></figure>")
    parts.append("</body></html>")
    atomic_write_text(path, "\n".join(parts) + "\n")
