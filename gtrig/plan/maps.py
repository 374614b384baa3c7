"""Per-cell maps of a plan: each cell's worst and median over headings, and whether it meets a target.

A pose that a source does not cover counts as infinitely uncertain, so a cell's worst heading is
uncovered when any heading is.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from gtrig.plan.predict import PlanResult


@dataclass(frozen=True)
class CellMaps:
    """Per cell (C,) of the grid (path: per pose): ``worst`` and ``median`` over headings of each
    quantity. Sigmas in m and rad (inf: uncovered); counts of cameras seeing at least one marker whole
    and of scanners with beams on the hull."""

    sigma_xy_m: dict[str, tuple[np.ndarray, np.ndarray]]
    sigma_yaw_rad: dict[str, tuple[np.ndarray, np.ndarray]]
    cameras: tuple[np.ndarray, np.ndarray]
    scanners: tuple[np.ndarray, np.ndarray]


def _per_cell(values: np.ndarray, n_cells: int, worst: str) -> tuple[np.ndarray, np.ndarray]:
    v = values.reshape(n_cells, -1)
    w = v.max(axis=1) if worst == "max" else v.min(axis=1)
    return w, np.median(v, axis=1)


def cell_maps(plan: PlanResult) -> CellMaps:
    """Each cell's worst and median over its headings."""
    C = plan.grid.n_cells
    sxy, syaw = {}, {}
    for src in plan.cov:
        sxy[src] = _per_cell(np.nan_to_num(plan.sigma_xy_m(src), nan=np.inf), C, "max")
        syaw[src] = _per_cell(np.nan_to_num(plan.sigma_yaw_rad(src), nan=np.inf), C, "max")
    cams = _per_cell((plan.views > 0).sum(axis=1).astype(float), C, "min")
    scans = _per_cell((plan.beams > 0).sum(axis=1).astype(float), C, "min")
    return CellMaps(sxy, syaw, cams, scans)


@dataclass(frozen=True)
class FailRegion:
    """A connected group of cells (or a run of path poses) that misses the target: its bounding box
    (x0, y0, x1, y1) in m, area in m^2 (path: length in m), and why (the worst fused sigmas there)."""

    box_xy: tuple[float, float, float, float]
    size: float
    worst_xy_m: float
    worst_yaw_rad: float
    uncovered: bool


@dataclass(frozen=True)
class TargetSummary:
    """How much of the area (or path) meets the target with the fused pose.

    Attributes
    ----------
    target_xy_m, target_yaw_rad : the target.
    meets : (C,) every heading of the cell meets it (path: the pose does).
    share_worst : share of the cells (path: poses) meeting it at every heading.
    share_median : share of the cells whose median heading meets it.
    share_poses : share of all (cell, heading) poses meeting it.
    fails : the largest failing regions, largest first.
    """

    target_xy_m: float
    target_yaw_rad: float
    meets: np.ndarray
    share_worst: float
    share_median: float
    share_poses: float
    fails: tuple[FailRegion, ...]


def _regions(plan: PlanResult, bad: np.ndarray, sxy: np.ndarray, syaw: np.ndarray, n_max: int
             ) -> tuple[FailRegion, ...]:
    """Connected failing cells on the grid (4-neighbours), or runs of failing poses on a path."""
    g = plan.grid
    xy = g.cells_xy
    if g.kind == "area":
        from scipy import ndimage

        ij = np.rint((xy - xy.min(axis=0)) / g.step_m).astype(int)
        img = np.zeros(ij.max(axis=0)[::-1] + 1, dtype=bool)
        img[ij[:, 1], ij[:, 0]] = bad
        lab, n = ndimage.label(img)
        cell_lab = lab[ij[:, 1], ij[:, 0]]
        unit = g.step_m**2
    else:
        edges = np.diff(np.r_[0, bad.astype(int), 0])
        starts, ends = np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)
        cell_lab = np.zeros(bad.size, dtype=int)
        for i, (a, b) in enumerate(zip(starts, ends, strict=True)):
            cell_lab[a:b] = i + 1
        n = starts.size
        unit = 0.0
    out = []
    for lbl in range(1, n + 1):
        m = cell_lab == lbl
        p = xy[m]
        size = m.sum() * unit if unit else float(np.sum(np.linalg.norm(np.diff(p, axis=0), axis=1)))
        out.append(FailRegion((float(p[:, 0].min()), float(p[:, 1].min()), float(p[:, 0].max()), float(p[:, 1].max())),
                              float(size), float(sxy[m].max()), float(syaw[m].max()),
                              bool(np.any(~np.isfinite(sxy[m])))))
    out.sort(key=lambda r: -r.size)
    return tuple(out[:n_max])


def summarize_target(plan: PlanResult, target_xy_m: float, target_yaw_rad: float, n_regions: int = 5
                     ) -> TargetSummary:
    """The share of the area (or path) whose fused pose meets ``target_xy_m`` and ``target_yaw_rad``
    (one-sigma), and where it does not."""
    maps = cell_maps(plan)
    wxy, mxy = maps.sigma_xy_m["fused"]
    wyaw, myaw = maps.sigma_yaw_rad["fused"]
    meets = (wxy <= target_xy_m) & (wyaw <= target_yaw_rad)
    med = (mxy <= target_xy_m) & (myaw <= target_yaw_rad)
    pose_ok = (np.nan_to_num(plan.sigma_xy_m("fused"), nan=np.inf) <= target_xy_m) & (
        np.nan_to_num(plan.sigma_yaw_rad("fused"), nan=np.inf) <= target_yaw_rad)
    return TargetSummary(float(target_xy_m), float(target_yaw_rad), meets, float(meets.mean()), float(med.mean()),
                         float(pose_ok.mean()), _regions(plan, ~meets, wxy, wyaw, n_regions))
