"""The run's checks (``summary.csv``) and its accuracy against truth (``accuracy.csv``): one table each, in the
pipeline's layout ``stage, metric, value, unit, target, ok``, and the checks that missed their target or could
not be measured listed as warnings above the table."""

from __future__ import annotations

import html
import math
from pathlib import Path

from gtrig.report.section import Section, read_csv

_MARK = {"1": '<span class="ok">ok</span>', "True": '<span class="ok">ok</span>',
         "0": '<span class="miss">miss</span>', "False": '<span class="miss">miss</span>'}


def _value(r: dict[str, str]) -> tuple[str, bool]:
    """The value as shown, and whether it was measured (a number that is not nan)."""
    raw = (r.get("value") or "").strip()
    try:
        v = float(raw)
    except ValueError:
        return html.escape(raw), bool(raw)
    if math.isnan(v):
        return '<span class="note">not measured</span>', False
    return f"{v:.4g}", True


def _warning(r: dict[str, str], measured: bool) -> str | None:
    what = f"{r.get('stage', '')}: {r.get('metric', '')}"
    if not measured:
        return f"{what}: not measured" if r.get("ok") in ("0", "False") else None
    if r.get("ok") in ("0", "False"):
        target = r.get("target") or "its target"
        return f"{what} is {r.get('value', '')} {r.get('unit', '')} (target {target})".replace("  ", " ")
    return None


def checks_section(path: Path, key: str, title: str, intro: str) -> Section:
    """The table of one ``stage, metric, value, unit, target, ok`` CSV, its warnings first."""
    s = Section(key, title)
    rows, warns, n_unmeasured = [], [], 0
    for r in read_csv(path):
        val, measured = _value(r)
        n_unmeasured += not measured
        w = _warning(r, measured)
        if w is not None:
            warns.append(w)
        rows.append([html.escape(r.get("stage", "")), html.escape(r.get("metric", "")), val,
                     html.escape(r.get("unit", "")), html.escape(r.get("target", "")), _MARK.get(r.get("ok", ""), "")])
    n_miss = sum("miss" in r[-1] for r in rows)
    s.add(f'<p class="note">{html.escape(intro)} {len(rows)} figures, {n_miss} missing their target, '
          f"{n_unmeasured} not measured.</p>")
    s.warnings(warns)
    s.table(["stage", "metric", "value", "unit", "target", ""], rows, raw=True)
    return s
