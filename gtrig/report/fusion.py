"""The fusion section: ``fusion_report.json`` (what each source offered and what was used, rejected or
down-weighted; the segments with their odometry bridges; the outliers)."""

from __future__ import annotations

import html
import json
from pathlib import Path
from typing import Any

from gtrig.report.section import Section

#: outliers listed in the page at most (the JSON holds them all)
MAX_OUTLIERS = 50


def _n(v: Any) -> str:
    return f"{float(v):.0f}" if isinstance(v, int | float) else "-"


def fusion_section(path: Path | None) -> Section | None:
    """The section, or None without a fusion report."""
    if path is None:
        return None
    d = json.loads(path.read_text(encoding="utf-8"))
    if not isinstance(d, dict):
        raise ValueError(f"{path.name}: not a fusion report")
    s = Section("fusion", "Fusion")
    segs = [g for g in d.get("segments") or [] if isinstance(g, dict)]
    n_poses = sum(int(g.get("poses", 0)) for g in segs)
    n_bridged = sum(int(g.get("bridged", 0)) for g in segs)
    outliers = list(d.get("outliers") or [])
    s.add(f'<p class="note">{html.escape(path.name)}: estimator {html.escape(str(d.get("estimator", "?")))}, '
          f'process model {html.escape(str(d.get("process", "?")))}; {n_poses} poses in {len(segs)} segments, '
          f"{n_bridged} bridged by odometry alone, {len(outliers)} fixes gated out or down-weighted.</p>")
    rows = []
    for name, v in (d.get("sources") or {}).items():
        if isinstance(v, dict):
            rows.append([str(name), _n(v.get("offered")), _n(v.get("used")), _n(v.get("rejected")),
                         _n(v.get("downweighted")), f"{1000 * float(v.get('offset_s') or 0):+.3f}",
                         f"{1000 * float(v.get('offset_sigma_s') or 0):.3f}"])
    s.add("<h3>Fixes per source (gated: rejected or down-weighted)</h3>")
    s.table(["source", "offered", "used", "rejected", "down-weighted", "clock offset (ms)", "sigma (ms)"], rows)
    if segs:
        t0 = float(segs[0].get("t0_s", 0.0))
        s.add("<h3>Segments (bridged: poses from odometry alone, between fixes)</h3>")
        s.table(["segment", "start (s)", "end (s)", "poses", "bridged", "longest bridge (s)"],
                [[str(k + 1), f"{float(g.get('t0_s', t0)) - t0:.2f}", f"{float(g.get('t1_s', t0)) - t0:.2f}",
                  _n(g.get("poses")), _n(g.get("bridged")), f"{float(g.get('longest_bridge_s', 0.0)):.2f}"]
                 for k, g in enumerate(segs)])
    if outliers:
        s.add(f"<h3>Rejected or down-weighted fixes ({len(outliers)})</h3>")
        shown = [o for o in outliers[:MAX_OUTLIERS] if isinstance(o, dict)]
        t_first = float(segs[0].get("t0_s", 0.0)) if segs else 0.0
        s.table(["source", "time (s)", "chi2", "dof", "by"],
                [[str(o.get("source", "")), f"{float(o.get('stamp_s', t_first)) - t_first:.3f}",
                  f"{float(o.get('chi2', float('nan'))):.2f}", str(o.get("dof", "")), str(o.get("stage", ""))]
                 for o in shown])
        if len(outliers) > len(shown):
            s.add(f'<p class="note">{len(outliers) - len(shown)} more in {html.escape(path.name)}</p>')
    return s
