"""The GT room's map in the ROS map_server format, as built and as a blueprint with errors.

What a lab has for map validation (journal paper, section 6: onboard scans aligned on the building
map) is a floor plan, and a floor plan is wrong by centimetres here and there. The simulator writes:

- ``map/gtroom.yaml`` + ``.pgm``: the room as built (walls with their true faces, the clutter that
  reaches above the onboard scanners' plane), 1 cm pixels;
- ``map/blueprint.yaml`` + ``.pgm``: the same with one wall (drawn from the seed) moved by
  ``BLUEPRINT_WALL_SHIFT_M`` along its normal;
- ``truth/map_errors.yaml``: which wall moved, by how much, and its end points.

Walls are drawn 10 cm thick behind their faces; a pixel is occupied when its centre is inside a
wall's or a box's outline (exact convex-polygon test).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import yaml

from gtrig.io.atomic import atomic_write_text
from gtrig.io.rosmap import write_map
from gtrig.sim.gtroom import Scene

MAP_RESOLUTION_M = 0.01
WALL_THICKNESS_M = 0.10
MAP_MARGIN_M = 0.5
BLUEPRINT_WALL_SHIFT_M = 0.03


def wall_polygons(walls: np.ndarray, shifts_m: np.ndarray | None = None) -> list[np.ndarray]:
    """Each wall (4, 2, 2) as a (4, 2) polygon from its face outwards; ``shifts_m`` (4,) move faces
    along their outward normals (positive: the room grows)."""
    centre = walls.reshape(-1, 2).mean(axis=0)
    out = []
    for k, (a, b) in enumerate(walls):
        d = (b - a) / np.linalg.norm(b - a)
        n = np.array([d[1], -d[0]])
        if n @ (0.5 * (a + b) - centre) < 0:
            n = -n
        s = 0.0 if shifts_m is None else float(shifts_m[k])
        a2, b2 = a + s * n - 0.3 * d, b + s * n + 0.3 * d  # overlap the corners
        out.append(np.array([a2, b2, b2 + WALL_THICKNESS_M * n, a2 + WALL_THICKNESS_M * n]))
    return out


def _fill_convex(mask: np.ndarray, poly_xy: np.ndarray, lo: np.ndarray, res: float) -> None:
    """Set the pixels of ``mask`` whose centres lie inside the convex polygon (exact half-plane test:
    OpenCV's fillPoly also takes the boundary pixels on one side, half a pixel of bias)."""
    H, W = mask.shape
    p = np.asarray(poly_xy, dtype=float)
    c0, c1 = np.floor((p[:, 0].min() - lo[0]) / res), np.ceil((p[:, 0].max() - lo[0]) / res)
    r0, r1 = np.floor((p[:, 1].min() - lo[1]) / res), np.ceil((p[:, 1].max() - lo[1]) / res)
    cols = np.arange(max(0, int(c0)), min(W, int(c1) + 1))
    ys = np.arange(max(0, int(r0)), min(H, int(r1) + 1))  # rows counted from the bottom
    X, Y = np.meshgrid(lo[0] + (cols + 0.5) * res, lo[1] + (ys + 0.5) * res)
    area = np.sum(p[:, 0] * np.roll(p[:, 1], -1) - np.roll(p[:, 0], -1) * p[:, 1])
    inside = np.ones(X.shape, bool)
    for a, b in zip(p, np.roll(p, -1, axis=0), strict=True):
        cross = (b[0] - a[0]) * (Y - a[1]) - (b[1] - a[1]) * (X - a[0])
        inside &= cross * np.sign(area) >= 0
    rr, cc = np.nonzero(inside)
    mask[H - 1 - ys[rr], cols[cc]] = True


def rasterize(scene: Scene, shifts_m: np.ndarray | None = None, scanner_z_m: float = 0.35,
              resolution_m: float = MAP_RESOLUTION_M) -> tuple[np.ndarray, np.ndarray, tuple[float, float, float]]:
    """Occupied and free masks (H, W) and the origin of the room's map."""
    polys = wall_polygons(scene.walls, shifts_m)
    pts = np.vstack(polys)
    lo = np.floor((pts.min(axis=0) - MAP_MARGIN_M) / resolution_m) * resolution_m
    hi = pts.max(axis=0) + MAP_MARGIN_M
    W, H = (np.ceil((hi - lo) / resolution_m)).astype(int)
    occupied = np.zeros((H, W), bool)
    inside = np.zeros((H, W), bool)
    # the room's inside: the faces (shifted as drawn) as a quadrilateral
    faces = [poly[:2] for poly in polys]
    corners = []
    for i in range(len(faces)):
        (a1, b1), (a2, b2) = faces[i - 1], faces[i]
        d1, d2 = b1 - a1, b2 - a2
        t = np.linalg.solve(np.column_stack([d1, -d2]), a2 - a1)
        corners.append(a1 + t[0] * d1)
    _fill_convex(inside, np.array(corners), lo, resolution_m)
    for poly in polys:
        _fill_convex(occupied, poly, lo, resolution_m)
    for box in scene.boxes:
        if box.size[2] > scanner_z_m:
            _fill_convex(occupied, box.corners_xy(), lo, resolution_m)
    free = inside & ~occupied
    return occupied, free, (float(lo[0]), float(lo[1]), 0.0)


def write_maps(scene: Scene, out: Path) -> None:
    """Write ``map/gtroom.*``, ``map/blueprint.*`` and ``truth/map_errors.yaml`` (module docstring)."""
    occ, free, origin = rasterize(scene)
    write_map(out / "map" / "gtroom.yaml", occ, free, MAP_RESOLUTION_M, origin)
    rng = np.random.default_rng([scene.seed, 0x3A9])
    k = int(rng.integers(0, len(scene.walls)))
    shifts = np.zeros(len(scene.walls))
    shifts[k] = BLUEPRINT_WALL_SHIFT_M
    occ_b, free_b, origin_b = rasterize(scene, shifts)
    write_map(out / "map" / "blueprint.yaml", occ_b, free_b, MAP_RESOLUTION_M, origin_b)
    a, b = scene.walls[k]
    doc = {"blueprint": {"moved_wall": k, "shift_m": BLUEPRINT_WALL_SHIFT_M, "direction": "outwards",
                         "wall_from_xy": [float(a[0]), float(a[1])], "wall_to_xy": [float(b[0]), float(b[1])]}}
    atomic_write_text(out / "truth" / "map_errors.yaml", yaml.safe_dump(doc, sort_keys=False))
