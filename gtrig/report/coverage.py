"""Per-camera and per-scanner coverage: what each sensor contributed to the run.

Cameras: GTvision's checkpoint of detections (``gt_vision_*.checkpoint``, NDJSON). Both layouts are read:
one line per camera and chunk of images (``{"camera", "frames": [[row, [[marker_id, corners (4, 2),
cov (4, 2, 2)], ...]], ...]}``, version 5) and whole instants (``{"chunk", "items"}``, before). Per camera:
images read, images with a marker, marker detections, and the share of the image the corners cover (cells of
a 16 x 12 grid holding a corner; the resolution from the folder's rig). Scanners: the observations and time
windows each one gave the sync stage (``sync.yaml``), the only per-scanner record a results folder keeps."""

from __future__ import annotations

import html
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from gtrig.io.checkpoint import checkpoint_records
from gtrig.report.section import Section

#: the grid the image-coverage share is counted on (columns, rows)
GRID = (16, 12)


@dataclass
class CameraCoverage:
    """One camera's detections in one checkpoint: ``rows`` (image row or stamp of each image read),
    ``marked`` (whether it shows a marker), ``corners_px`` (M, 2) every detected corner, ``n_markers``."""

    rows: list[float] = field(default_factory=list)
    marked: list[bool] = field(default_factory=list)
    corners_px: list[np.ndarray] = field(default_factory=list)
    n_markers: int = 0

    def uv(self) -> np.ndarray:
        return np.concatenate(self.corners_px) if self.corners_px else np.zeros((0, 2))

    def covered_share(self, size_px: tuple[int, int] | None) -> float:
        """Share of the image's grid cells holding a corner (nan without the image size)."""
        if size_px is None:
            return float("nan")
        uv = self.uv()
        if not len(uv):
            return 0.0
        i = np.clip((uv[:, 0] / size_px[0] * GRID[0]).astype(int), 0, GRID[0] - 1)
        j = np.clip((uv[:, 1] / size_px[1] * GRID[1]).astype(int), 0, GRID[1] - 1)
        return len(set(zip(i.tolist(), j.tolist(), strict=True))) / (GRID[0] * GRID[1])


def _add(cov: CameraCoverage, row: float, markers: list[Any]) -> None:
    cov.rows.append(row)
    cov.marked.append(bool(markers))
    for m in markers:
        cov.corners_px.append(np.asarray(m, float).reshape(-1, 2))
        cov.n_markers += 1


def read_checkpoint(path: Path) -> tuple[dict[str, CameraCoverage], str]:
    """Per camera its coverage, and what the row axis is (``image`` rows or ``time`` stamps in s)."""
    per: dict[str, CameraCoverage] = {}
    axis = "image"
    for d in checkpoint_records(path):
        if not isinstance(d, dict):
            continue
        if "camera" in d:
            cov = per.setdefault(str(d["camera"]), CameraCoverage())
            for row, dets in d.get("frames") or []:
                _add(cov, float(row), [m[1] for m in dets])
            continue
        axis = "time"
        for item in d.get("items") or []:
            obs = item.get("obs") if isinstance(item, dict) else None
            if isinstance(obs, dict):
                for v in obs.get("views", []):
                    _add(per.setdefault(str(v[0]), CameraCoverage()), float(obs.get("stamp_s", 0.0)), [v[2]])
    return per, axis


def camera_sizes(rig_yaml: Path | None) -> dict[str, tuple[int, int]]:
    """Each camera's resolution (width, height) px from the folder's rig, when it has one."""
    if rig_yaml is None:
        return {}
    from gtrig.io.text import read_text
    from gtrig.io.yamlfile import safe_load

    d = safe_load(read_text(rig_yaml, "YAML file")) or {}
    out = {}
    for c in d.get("cameras") or []:
        res = c.get("resolution") if isinstance(c, dict) else None
        if isinstance(res, list) and len(res) == 2:
            out[str(c.get("name"))] = (int(res[0]), int(res[1]))
    return out


def cameras_section(checkpoints: list[Path], rig_yaml: Path | None) -> Section | None:
    """Per checkpoint, a table per camera and a figure (corners in each image, marked images over the run)."""
    from gtrig.report.figures import camera_coverage_figure

    sizes = camera_sizes(rig_yaml)
    s = Section("cameras", "GTvision: per-camera coverage and detections")
    for cp in checkpoints:
        per, axis = read_checkpoint(cp)
        if not per:
            continue
        name = cp.stem
        s.add(f"<h3>{html.escape(name)}</h3>")
        rows = []
        for cam, c in sorted(per.items()):
            n, k = len(c.rows), int(np.sum(c.marked))
            share = c.covered_share(sizes.get(cam))
            rows.append([cam, str(n), str(k), f"{100 * k / n:.1f}" if n else "-", str(c.n_markers),
                         f"{100 * share:.0f}" if np.isfinite(share) else "-"])
        s.table(["camera", "images read", "with a marker", "share (%)", "marker detections",
                 f"image covered (% of a {GRID[0]} x {GRID[1]} grid)"], rows)
        silent = [cam for cam, c in sorted(per.items()) if not any(c.marked)]
        s.warnings([f"{name}: {cam} saw no marker" for cam in silent])
        s.figure(camera_coverage_figure(per, sizes, axis, name),
                 f"{name}: every detected marker corner in each camera's image (frame drawn at the image's size) "
                 f"and the images showing a marker along the {'recording' if axis == 'image' else 'run'}")
    return s if s.n_figures else None


def scanners_section(sync_yaml: Path | None) -> Section | None:
    """Per scanner, what it gave the time sync (``sync.yaml``'s ``laser/<name>`` entries)."""
    if sync_yaml is None:
        return None
    from gtrig.io.text import read_text
    from gtrig.io.yamlfile import safe_load

    d = safe_load(read_text(sync_yaml, "YAML file")) or {}
    rows = [[str(k).split("/", 1)[1], str(v.get("windows", "-")), str(v.get("verdict", "")), str(v.get("reason", ""))]
            for k, v in (d.get("sources") or {}).items() if str(k).startswith("laser/") and isinstance(v, dict)]
    if not rows:
        return None
    s = Section("scanners", "Fixed scanners: per-scanner coverage")
    s.add(f'<p class="note">What each scanner gave the time sync ({html.escape(sync_yaml.name)}): the robot\'s '
          "observations and the time windows they fall in.</p>")
    s.table(["scanner", "windows", "sync verdict", "observations"], rows)
    return s
