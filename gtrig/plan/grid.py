"""The poses a plan is evaluated at: a grid of floor cells times headings, or the poses of a path."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np

from gtrig.errors import InputError
from gtrig.rig.models import Rig

#: the largest number of poses (cells times headings) a plan evaluates
MAX_POSES = 20_000_000


@dataclass(frozen=True)
class PlanGrid:
    """Where the robot is put.

    Attributes
    ----------
    kind : ``"area"`` (cells of a polygon, each at every heading) or ``"path"`` (the poses of a path).
    cells_xy : (C, 2) cell centres (area) or path positions, world frame, metres.
    headings_rad : (H,) headings tried at every cell (area); for a path, (1,) zero and ``path_theta_rad``
        holds each pose's own heading.
    step_m : cell size (area), metres; nan for a path.
    polygon_xy : (V, 2) the area's outline, world frame, metres (a path: its bounding box).
    path_theta_rad : (C,) heading of each path pose, or None for an area.
    path_velocity : (C, 3) velocity of each path pose, x, y (m/s) and heading (rad/s), world frame, when
        the path has time stamps; None otherwise (a standing robot).
    """

    kind: Literal["area", "path"]
    cells_xy: np.ndarray
    headings_rad: np.ndarray
    step_m: float
    polygon_xy: np.ndarray
    path_theta_rad: np.ndarray | None = None
    path_velocity: np.ndarray | None = None

    @property
    def n_cells(self) -> int:
        return int(self.cells_xy.shape[0])

    @property
    def n_headings(self) -> int:
        return int(self.headings_rad.shape[0])

    def poses_xytheta(self) -> np.ndarray:
        """Every pose (C * H, 3): x, y (m), heading (rad); cell-major (pose ``c * H + h``)."""
        if self.path_theta_rad is not None:
            return np.column_stack([self.cells_xy, self.path_theta_rad])
        C, H = self.n_cells, self.n_headings
        xy = np.repeat(self.cells_xy, H, axis=0)
        return np.column_stack([xy, np.tile(self.headings_rad, C)])


def points_in_polygon(xy: np.ndarray, polygon_xy: np.ndarray) -> np.ndarray:
    """(N,) bool: which points (N, 2) lie inside the polygon (V, 2) (even-odd rule, any orientation)."""
    x, y = xy[:, 0], xy[:, 1]
    inside = np.zeros(xy.shape[0], dtype=bool)
    P = np.asarray(polygon_xy, dtype=float)
    for (x0, y0), (x1, y1) in zip(P, np.roll(P, -1, axis=0), strict=True):
        if y0 == y1:
            continue
        crosses = (y0 > y) != (y1 > y)
        xc = x0 + (y - y0) * (x1 - x0) / (y1 - y0)
        inside ^= crosses & (x < xc)
    return inside


def check_polygon(polygon_xy: np.ndarray, what: str = "--area") -> np.ndarray:
    """The polygon (V, 2) as floats, refused with a one-line :class:`InputError` when it has fewer than
    3 vertices, non-finite ones or no area."""
    P = np.asarray(polygon_xy, dtype=float)
    if P.ndim != 2 or P.shape[1] != 2 or P.shape[0] < 3:
        raise InputError(f"{what}: a polygon needs at least 3 vertices x,y (got {P.shape[0] if P.ndim == 2 else 0})")
    if not np.all(np.isfinite(P)):
        raise InputError(f"{what}: a vertex is not a finite number")
    area = 0.5 * abs(float(np.sum(P[:, 0] * np.roll(P[:, 1], -1) - np.roll(P[:, 0], -1) * P[:, 1])))
    if area <= 0.0:
        raise InputError(f"{what}: the polygon has no area")
    return P


def area_grid(polygon_xy: np.ndarray, step_m: float = 0.05, n_headings: int = 16) -> PlanGrid:
    """Cell centres on a square grid of ``step_m`` inside the polygon, each at ``n_headings`` headings
    evenly spread over the full turn (0 first)."""
    P = check_polygon(polygon_xy)
    if not (np.isfinite(step_m) and step_m > 0):
        raise InputError(f"--grid-m must be a positive number of metres, got {step_m:g}")
    if n_headings < 1:
        raise InputError(f"--headings must be at least 1, got {n_headings}")
    lo, hi = P.min(axis=0), P.max(axis=0)
    n = np.floor((hi - lo) / step_m).astype(int) + 1
    if float(n[0]) * float(n[1]) * n_headings > MAX_POSES:
        raise InputError(f"--grid-m {step_m:g} with {n_headings} headings makes more than {MAX_POSES:.0e} poses: "
                         "use a coarser grid or fewer headings")
    # cells centred in the bounding box so that the margins are even
    off = 0.5 * ((hi - lo) - (n - 1) * step_m)
    xs = lo[0] + off[0] + step_m * np.arange(n[0])
    ys = lo[1] + off[1] + step_m * np.arange(n[1])
    gx, gy = np.meshgrid(xs, ys)
    cells = np.column_stack([gx.ravel(), gy.ravel()])
    cells = cells[points_in_polygon(cells, P)]
    if cells.shape[0] == 0:
        raise InputError(f"--area: no cell of {step_m:g} m falls inside the polygon")
    headings = 2 * np.pi * np.arange(n_headings) / n_headings
    return PlanGrid("area", cells, headings, float(step_m), P)


def path_grid(xy: np.ndarray, theta_rad: np.ndarray, stamps_s: np.ndarray | None = None) -> PlanGrid:
    """The poses of a path: positions (N, 2) and headings (N,), world frame; with increasing time stamps
    (N,) in seconds, also each pose's velocity (central differences over the unwrapped heading)."""
    xy = np.asarray(xy, dtype=float).reshape(-1, 2)
    th = np.asarray(theta_rad, dtype=float).ravel()
    if xy.shape[0] == 0 or th.shape[0] != xy.shape[0]:
        raise InputError("--path: the path has no poses")
    lo, hi = xy.min(axis=0), xy.max(axis=0)
    box = np.array([[lo[0], lo[1]], [hi[0], lo[1]], [hi[0], hi[1]], [lo[0], hi[1]]])
    vel = None
    if stamps_s is not None and xy.shape[0] >= 2:
        t = np.asarray(stamps_s, dtype=float).ravel()
        if t.shape[0] != xy.shape[0] or np.any(np.diff(t) <= 0):
            raise InputError("--path: the stamps must increase")
        vel = np.gradient(np.column_stack([xy, np.unwrap(th)]), t, axis=0)
    return PlanGrid("path", xy, np.zeros(1), float("nan"), box, th, vel)


def default_area(rig: Rig) -> np.ndarray:
    """The area a rig instruments when none is given: the room's outline when the rig gives one
    (``world.outline_xy``), else the convex hull (V, 2) of its laser scanners' positions and survey
    reference points (world xy, metres).

    Raises
    ------
    InputError
        When they are fewer than 3 or collinear (then ``--area`` or ``--path`` must say where).
    """
    if rig.world.outline_xy is not None:
        return check_polygon(np.asarray(rig.world.outline_xy, dtype=float), "world.outline_xy")
    pts = [s.T_world_scanner.xyz[:2] for s in rig.laser_scanners]
    pts += [p.xy for p in rig.survey.reference_points]
    P = np.unique(np.asarray(pts, dtype=float).reshape(-1, 2), axis=0)
    hull = _convex_hull(P) if P.shape[0] >= 3 else P
    if hull.shape[0] < 3:
        raise InputError("the rig has fewer than 3 laser scanners and reference points to outline its area: "
                         "give --area X,Y;X,Y;... or --path")
    return hull


def _convex_hull(P: np.ndarray) -> np.ndarray:
    """Counter-clockwise convex hull of points (N, 2) (monotone chain)."""
    pts = sorted(map(tuple, P))

    def half(seq: list[tuple[float, float]]) -> list[tuple[float, float]]:
        out: list[tuple[float, float]] = []
        for p in seq:
            while len(out) >= 2 and ((out[-1][0] - out[-2][0]) * (p[1] - out[-2][1])
                                     - (out[-1][1] - out[-2][1]) * (p[0] - out[-2][0])) <= 0:
                out.pop()
            out.append(p)
        return out

    lower, upper = half(pts), half(pts[::-1])
    return np.array(lower[:-1] + upper[:-1], dtype=float)
