"""The time-sync section: ``sync.yaml`` (each source's clock offset to the reference, its 95 % interval,
the verdict and why) and, when the folder holds them, the correlation curves' CSVs."""

from __future__ import annotations

import html
from pathlib import Path
from typing import Any

import numpy as np

from gtrig.report.section import Section, read_csv


def _ms(v: Any) -> str:
    return f"{1000 * float(v):+.3f}" if isinstance(v, int | float) else "-"


def _interval_ms(v: Any) -> str:
    if isinstance(v, list | tuple) and len(v) == 2 and all(isinstance(x, int | float) for x in v):
        return f"{1000 * float(v[0]):+.3f} .. {1000 * float(v[1]):+.3f}"
    return "-"


_VERDICT = {"ok": '<span class="ok">ok</span>', "ambiguous": '<span class="miss">ambiguous</span>',
            "unobservable": '<span class="miss">unobservable</span>'}


def _sync_yaml(s: Section, path: Path) -> None:
    from gtrig.io.text import read_text
    from gtrig.io.yamlfile import safe_load

    d = safe_load(read_text(path, "YAML file")) or {}
    sources = d.get("sources") or {}
    s.add(f'<p class="note">{html.escape(path.name)}: clock offsets to {html.escape(str(d.get("reference", "?")))}'
          f' ({html.escape(str(d.get("convention", "")))}); per sensor, also to GTvision\'s clock.</p>')
    rows: list[list[str]] = []
    missed: dict[str, list[str]] = {}
    for name, v in sources.items():
        if not isinstance(v, dict):
            continue
        verdict = str(v.get("verdict", ""))
        rows.append([html.escape(str(name)), _VERDICT.get(verdict, html.escape(verdict)), _ms(v.get("offset_s")),
                     _interval_ms(v.get("ci95_s")), _ms(v.get("offset_to_vision_s")),
                     _interval_ms(v.get("ci95_to_vision_s")), html.escape(str(v.get("windows", "-"))),
                     html.escape(str(v.get("reason", "")))])
        if verdict != "ok":
            missed.setdefault(verdict, []).append(str(name))
    s.warnings([f"{verdict}, no offset measured: {', '.join(names)} (the table says why)"
                for verdict, names in missed.items()])
    s.table(["source", "verdict", "offset (ms)", "95 % interval (ms)", "offset to GTvision (ms)",
             "95 % interval (ms)", "windows", "why"], rows, raw=True)


def _curves(paths: list[Path]) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    curves: dict[str, tuple[np.ndarray, np.ndarray]] = {}
    for p in paths:
        rows = read_csv(p)
        if not rows:
            continue
        keys = list(rows[0])
        xk = next((k for k in keys if "lag" in k or "offset" in k), None)
        yks = [k for k in keys if k != xk and ("corr" in k or "score" in k or "cost" in k)]
        if xk is None or not yks:
            continue
        x = np.array([float(r[xk]) for r in rows])
        for yk in yks:
            curves[f"{p.stem} {yk}"] = (x, np.array([float(r[yk]) for r in rows]))
    return curves


def sync_section(sync_yaml: Path | None, curve_csvs: list[Path]) -> Section | None:
    """The section, or None when the folder holds neither ``sync.yaml`` nor a curve."""
    from gtrig.report.figures import curves_figure

    curves = _curves(curve_csvs)
    if sync_yaml is None and not curves:
        return None
    s = Section("sync", "Time synchronization")
    if sync_yaml is not None:
        _sync_yaml(s, sync_yaml)
    if curves:
        s.figure(curves_figure(curves, "lag (s)", "correlation", "sync correlation curves"),
                 "correlation against the clock offset (the maxima marked)")
    return s
