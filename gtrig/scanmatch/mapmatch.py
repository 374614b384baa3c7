"""Validation against a building map: onboard scans aligned on an occupancy grid from rough poses,
with the map's own errors found and named rather than absorbed into the poses.

The journal paper (section 6) validated the Bicocca ground truth by ICP of the onboard scans on the
building's map from manual initial poses. Here:

1. the map's surface points are the occupied pixels bordering free space, moved half a pixel towards
   the free side (the pixel edge is where the surface is), with normals from a line fit over their
   neighbours (cKDTree), oriented towards free space;
2. the map's surfaces are the connected groups of those points whose normals agree (a wall, a box
   face): :func:`map_features`;
3. every scan is matched on the map points from its initial pose (point-to-line ICP, the genetic
   matcher when the acceptance test refuses, as for scan pairs);
4. per feature, the signed residuals of every scan's inliers are averaged per scan, and the feature's
   offset is their mean over the scans with its standard error (scans' means are independent); a
   feature off by more than ``min_offset_m`` at more than ``min_t`` standard errors is a map error,
   named by its end points;
5. the scans are matched again, from their rough poses, without the flagged features' points, so a
   moved wall does not pull the poses; steps 3-5 repeat until the flagged set no longer changes.

Residual sign: positive when the scanned surface lies on the free side of the map's (the map draws
the wall too far back).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from gtrig.io.rosmap import OccupancyMap
from gtrig.scanmatch import se2
from gtrig.scanmatch.accept import AcceptParams, Verdict
from gtrig.scanmatch.genetic import GeneticParams
from gtrig.scanmatch.icp import DEFAULT_ICP, IcpParams
from gtrig.scanmatch.scan import PlanarScan

FEATURE_MAX_TURN_RAD = np.radians(15.0)
# a map lacks clutter a scan sees, and a surface found wrong is left out of it: a lower share
MAP_ACCEPT = AcceptParams(min_explained=0.4)


@dataclass(frozen=True)
class MapPoints:
    """The map's surface points as a reference scan, and their feature labels (K,)."""

    scan: PlanarScan
    feature: np.ndarray


def map_points(m: OccupancyMap, neighbour_px: float = 3.0) -> MapPoints:
    """Surface points of an occupancy map (module docstring, steps 1 and 2)."""
    occ, free = m.occupied, m.free
    H, W = occ.shape
    pts, dirs = [], []
    for dr, dc in ((-1, 0), (1, 0), (0, -1), (0, 1)):
        nb = np.zeros_like(free)
        rs = slice(max(0, -dr), H - max(0, dr))
        cs = slice(max(0, -dc), W - max(0, dc))
        rd = slice(max(0, dr), H - max(0, -dr))
        cd = slice(max(0, dc), W - max(0, -dc))
        nb[rs, cs] = free[rd, cd]
        r, c = np.nonzero(occ & nb)
        pts.append(np.column_stack([r + 0.5 * dr, c + 0.5 * dc]))
        dirs.append(np.tile([dr, dc], (len(r), 1)))
    rc = np.vstack(pts)
    dv = np.vstack(dirs).astype(float)
    # collapse the half-pixel edge points of one pixel's sides to unique edge points
    rc, idx = np.unique(rc, axis=0, return_index=True)
    dv = dv[idx]
    xy = m.pixel_centres(rc[:, 0], rc[:, 1])
    free_dir = np.column_stack([dv[:, 1], -dv[:, 0]])  # row down = -y
    yaw = m.origin[2]
    c, s = np.cos(yaw), np.sin(yaw)
    free_dir = free_dir @ np.array([[c, -s], [s, c]]).T
    tree = cKDTree(xy)
    rad = neighbour_px * m.resolution_m
    nbrs = tree.query_ball_point(xy, rad)
    n = np.zeros_like(xy)
    ok = np.zeros(len(xy), bool)
    for i, nb in enumerate(nbrs):
        if len(nb) < 3:
            continue
        q = xy[nb] - xy[nb].mean(axis=0)
        w, v = np.linalg.eigh(q.T @ q)
        n[i] = v[:, 0]
        ok[i] = w[0] <= 0.05 * w[1]
    flip = np.sum(n * free_dir, axis=1) < 0
    n[flip] *= -1
    # features: neighbours with agreeing normals, connected
    pairs = tree.query_pairs(1.5 * m.resolution_m, output_type="ndarray")
    agree = ok[pairs[:, 0]] & ok[pairs[:, 1]] & (np.sum(n[pairs[:, 0]] * n[pairs[:, 1]], axis=1)
                                                 > np.cos(FEATURE_MAX_TURN_RAD))
    pairs = pairs[agree]
    g = coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(len(xy), len(xy)))
    _, lab = connected_components(g, directed=False)
    sigma = np.full(len(xy), m.resolution_m / np.sqrt(12.0))  # the pixel grid's quantisation
    return MapPoints(PlanarScan(xy, n, ok, sigma), lab)


@dataclass(frozen=True)
class MapFeatureError:
    """A map feature whose scans disagree with it: label, end points (2, 2), offset (m, positive: the
    real surface is in front of the map's), its standard error, the scans seeing it, points used."""

    feature: int
    ends_xy: np.ndarray
    offset_m: float
    se_m: float
    n_scans: int
    n_points: int
    flagged: bool

    def name(self) -> str:
        (x1, y1), (x2, y2) = self.ends_xy
        return f"map surface ({x1:.2f}, {y1:.2f}) - ({x2:.2f}, {y2:.2f}) m"


@dataclass(frozen=True)
class MapMatchResult:
    """Poses (K, 3) of the scans in the map frame, covariances (K, 3, 3), verdicts, the features'
    offsets (all features seen by at least 3 scans) and the flagged ones."""

    poses: np.ndarray
    covs: np.ndarray
    verdicts: tuple[Verdict, ...]
    features: tuple[MapFeatureError, ...]

    @property
    def flagged(self) -> tuple[MapFeatureError, ...]:
        return tuple(f for f in self.features if f.flagged)


def _feature_ends(xy: np.ndarray) -> np.ndarray:
    c = xy.mean(axis=0)
    _, _, vt = np.linalg.svd(xy - c)
    t = (xy - c) @ vt[0]
    return np.array([c + t.min() * vt[0], c + t.max() * vt[0]])


def feature_offsets(mp: MapPoints, scans: list[PlanarScan], poses: np.ndarray, icp: IcpParams,
                    min_offset_m: float, min_t: float, min_scans: int = 3) -> list[MapFeatureError]:
    """Step 4 of the module docstring at the given poses."""
    from gtrig.scanmatch._kernels import residuals_at

    per: dict[int, list[tuple[float, int]]] = {}
    ref = mp.scan
    for s, p in zip(scans, poses, strict=True):
        d, e, _J, idx = residuals_at(ref.xy, ref.normals, ref.normal_ok, s.xy, p, icp.cell_m, icp.r_min_m)
        good = (idx >= 0) & np.isfinite(e)
        sig = np.hypot(s.sigma_m, ref.sigma_m[np.maximum(idx, 0)])
        # the residual at the map's truth can be a few centimetres: gate wider than for scan pairs
        good &= np.abs(e) < np.maximum(0.06, 4 * sig)
        lab = mp.feature[idx[good]]
        ee = e[good]  # e = n.(p - q) with n towards free space: positive = surface in front of the map's
        for f in np.unique(lab):
            sel = lab == f
            if sel.sum() >= 5:
                per.setdefault(int(f), []).append((float(np.mean(ee[sel])), int(sel.sum())))
    out = []
    for f, vals in per.items():
        if len(vals) < min_scans:
            continue
        means = np.array([v[0] for v in vals])
        npts = int(sum(v[1] for v in vals))
        off = float(means.mean())
        se = float(means.std(ddof=1) / np.sqrt(len(means))) if len(means) > 1 else np.inf
        flagged = abs(off) > min_offset_m and abs(off) > min_t * se
        out.append(MapFeatureError(f, _feature_ends(mp.scan.xy[mp.feature == f]), off, se, len(vals), npts, flagged))
    out.sort(key=lambda e: -abs(e.offset_m))
    return out


def match_to_map(mp: MapPoints, scans: list[PlanarScan], initial: np.ndarray, min_offset_m: float = 0.01,
                 min_t: float = 5.0, icp: IcpParams = DEFAULT_ICP, accept: AcceptParams = MAP_ACCEPT,
                 tilt_shift_m: float = 0.0, seed: int = 0, max_rounds: int = 4) -> MapMatchResult:
    """Align every scan (in its robot frame) on the map from ``initial`` (K, 3) map-frame poses."""
    from gtrig.scanmatch.validate import ErrorModel, match_pair

    model = ErrorModel()
    init = np.asarray(initial, dtype=float).reshape(-1, 3)
    gc = np.diag([0.3**2, 0.3**2, np.radians(15.0) ** 2])
    ga = GeneticParams(half_width=(0.45, 0.45, np.radians(22.0)), seed=seed)
    excluded = np.zeros(len(mp.scan), bool)
    flagged_ids: set[int] = set()
    poses = init.copy()
    covs = np.zeros((len(init), 3, 3))
    verdicts: list[Verdict] = []
    feats: list[MapFeatureError] = []
    for _round in range(max_rounds):
        keep = ~excluded
        ref = PlanarScan(mp.scan.xy[keep], mp.scan.normals[keep], mp.scan.normal_ok[keep], mp.scan.sigma_m[keep])
        verdicts = []
        for k, s in enumerate(scans):
            gp = GeneticParams(**{**ga.__dict__, "seed": seed + k})
            # every round starts from the rough pose: the acceptance test judges agreement with it
            pose, cov, _res, v, _name = match_pair(ref, s, init[k], gc, model, tilt_shift_m, icp, accept, gp)
            poses[k], covs[k] = pose, cov
            verdicts.append(v)
        ok = np.array([v.accepted for v in verdicts])
        feats = feature_offsets(mp, [s for s, o in zip(scans, ok, strict=True) if o], poses[ok], icp,
                                min_offset_m, min_t)
        now = {f.feature for f in feats if f.flagged}
        if now == flagged_ids:
            break
        # the flagged set is re-decided each round: a surface flagged while a moved wall still pulled
        # the poses comes back once the wall is out
        flagged_ids = now
        excluded = np.isin(mp.feature, list(flagged_ids))
    return MapMatchResult(poses, covs, tuple(verdicts), tuple(feats))


def initial_error(initial: np.ndarray, poses: np.ndarray) -> np.ndarray:
    """(K, 3) how far the initial poses were from the result (for a report)."""
    return se2.relative(poses, initial)
