"""The figures of an evaluation as CSV, Markdown or JSON text (the table form is the CLI's, with Rich)."""

from __future__ import annotations

import csv
import io
import json

import numpy as np

from gtrig.evaluate.metrics_evo import STATS
from gtrig.evaluate.slam import Row, SlamEvaluation


def rows_csv(rows: list[Row]) -> str:
    """``family,metric,statistic,value,unit`` (values with 9 significant digits)."""
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(["family", "metric", "statistic", "value", "unit"])
    for r in rows:
        w.writerow([r.family, r.metric, r.statistic, f"{r.value:.9g}", r.unit])
    return buf.getvalue()


def rows_json(ev: SlamEvaluation) -> str:
    """Nested ``{family: {metric: {statistic: value}}}`` plus the warnings."""
    out: dict[str, object] = {}
    for r in ev.rows():
        fam = out.setdefault(r.family, {})
        assert isinstance(fam, dict)
        fam.setdefault(r.metric, {})[r.statistic] = None if not np.isfinite(r.value) else r.value
    out["association"] = ev.association.summary()
    out["warnings"] = list(ev.warnings)
    return json.dumps(out, indent=2) + "\n"


def evo_matrix(ev: SlamEvaluation) -> list[list[str]]:
    """evo's series as rows ``[name (unit), rmse, mean, median, std, min, max]``."""
    out = []
    for series in (ev.ape, ev.rpe):
        for s in (series or {}).values():
            st = s.stats()
            out.append([f"{s.name} ({s.unit or '-'})", *(f"{st[k]:.6f}" for k in STATS if k != "sse")])
    return out


def rows_markdown(ev: SlamEvaluation) -> str:
    """Markdown: the pairing line, evo's table, the RAWSEEDS and GT-aware figures, the warnings."""
    a = ev.association
    lines = [f"{a.describe()}; {len(a.gaps_s)} gaps; alignment {ev.alignment.kind} (scale "
             f"{ev.alignment.scale:.6f})", ""]
    if ev.time_offset is not None:
        to = ev.time_offset
        lines += [f"time offset estimated: {to.offset_s:+.5f} s (95 % {to.low_s:+.5f} .. {to.high_s:+.5f})", ""]
    m = evo_matrix(ev)
    if m:
        lines += ["| evo | rmse | mean | median | std | min | max |", "|---|---|---|---|---|---|---|"]
        lines += ["| " + " | ".join(r) + " |" for r in m]
        lines.append("")
    other = [r for r in ev.rows() if r.family in ("rawseeds", "gt-aware")]
    if other:
        lines += ["| family | metric | statistic | value | unit |", "|---|---|---|---|---|"]
        lines += [f"| {r.family} | {r.metric} | {r.statistic} | {r.value:.6g} | {r.unit} |" for r in other]
    lines += [f"\nwarning: {w}" for w in ev.warnings]
    return "\n".join(lines) + "\n"
