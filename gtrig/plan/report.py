"""The plan's table and its summary in words (what ``gtrig plan`` prints and puts on its page)."""

from __future__ import annotations

import numpy as np

from gtrig.io.plan import SOURCES, PlanTable
from gtrig.plan.maps import CellMaps, TargetSummary
from gtrig.plan.predict import PlanResult


def plan_table(plan: PlanResult) -> PlanTable:
    """The grid CSV's columns of a plan (one row per pose)."""
    return PlanTable(plan.poses_xytheta, {s: plan.sigma_xy_m(s) for s in SOURCES},
                     {s: plan.sigma_yaw_rad(s) for s in SOURCES}, (plan.views > 0).sum(axis=1),
                     plan.views.sum(axis=1), (plan.beams > 0).sum(axis=1), plan.beams.sum(axis=1))


def _pct(v: np.ndarray, q: float, scale: float) -> str:
    f = v[np.isfinite(v)]
    return f"{scale * np.percentile(f, q):.2f}" if f.size else "-"


def summary_lines(plan: PlanResult, maps: CellMaps, s: TargetSummary, elapsed_s: float) -> list[str]:
    """Lines: the grid, each source's coverage and median sigmas, the share meeting the target, and the
    largest regions where it fails."""
    g = plan.grid
    what = (f"{g.n_cells} cells of {g.step_m:g} m x {g.n_headings} headings" if g.kind == "area"
            else f"{g.n_cells} poses of the path")
    lines = [f"plan: {what} = {g.n_cells * g.n_headings} poses, {len(plan.camera_names)} cameras, "
             f"{len(plan.scanner_names)} scanners, {elapsed_s:.1f} s"]
    for src in SOURCES:
        sxy, syaw = plan.sigma_xy_m(src), plan.sigma_yaw_rad(src)
        cov = float(np.mean(np.isfinite(sxy)))
        lines.append(f"{src}: covers {100 * cov:.1f} % of the poses; position sigma median {_pct(sxy, 50, 1000)} mm "
                     f"(95th percentile {_pct(sxy, 95, 1000)} mm), yaw sigma median "
                     f"{_pct(syaw, 50, float(np.degrees(1)))} deg")
    unit = "of the area" if g.kind == "area" else "of the path's poses"
    lines.append(f"target {1000 * s.target_xy_m:g} mm / {np.degrees(s.target_yaw_rad):g} deg (fused, one sigma): "
                 f"met at every heading on {100 * s.share_worst:.1f} % {unit}, at the median heading on "
                 f"{100 * s.share_median:.1f} %, over all poses {100 * s.share_poses:.1f} %")
    for r in s.fails:
        x0, y0, x1, y1 = r.box_xy
        size = f"{r.size:.2f} m2" if g.kind == "area" else f"{r.size:.2f} m of path"
        why = "uncovered at some heading" if r.uncovered else (
            f"worst {1000 * r.worst_xy_m:.2f} mm / {np.degrees(r.worst_yaw_rad):.3f} deg")
        lines.append(f"fails: x {x0:.2f}..{x1:.2f} m, y {y0:.2f}..{y1:.2f} m ({size}): {why}")
    return lines
