"""Calibration of the fixed-scanner network from a static sequence (journal paper, section 4.3).

Unknowns: the planar pose ``(x, y, theta)`` of every scanner in the world (height, roll and pitch are
kept from the rig file). Data: each scanner's background scan (:mod:`gtrig.laser.background`, the
per-beam median of the empty room, a few millimetres of noise over sqrt(scans)).

All poses are estimated jointly by Gauss-Newton on two kinds of point-to-line residuals, re-associated
at every iteration with a shrinking gate:

* **Overlap.** A point of scanner ``i`` against the local line through the nearest points of scanner
  ``j`` (walls and furniture both see), for every ordered pair; lines are taken only where ``j``'s scan
  is locally straight, and only when the surface faces both scanners (the two sides of a thin heater are
  different surfaces).
* **World object.** Points near the outline of the object whose edges define the world frame (the seed's
  box with the world origin on its edges; ``scene.boxes['calib_object']`` in the simulator), against its
  known sides in the world: this fixes the network's gauge.

A weak prior at the nominal poses keeps the first iterations well posed. Residual RMS per scanner and
kind are reported, and the formal standard deviations of each pose (from the final normal equations
and the residuals' variance).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from gtrig import geometry as geo
from gtrig.errors import ConvergenceError, InputError
from gtrig.laser.background import BackgroundModel
from gtrig.laser.hull_icp import HullModel
from gtrig.rig.models import LaserScanner, Pose, Rig

_J90 = np.array([[0.0, -1.0], [1.0, 0.0]])


@dataclass(frozen=True)
class ScannerCalibration:
    """One scanner's calibrated pose and residuals.

    Attributes
    ----------
    name : scanner name.
    xytheta : (3,) calibrated planar pose in the world (m, m, rad).
    std_xytheta : (3,) formal standard deviations.
    delta_xytheta : (3,) calibrated minus nominal.
    n_overlap, rms_overlap_m : overlap residuals of this scanner's points against other scanners.
    n_object, rms_object_m : residuals against the world object.
    """

    name: str
    xytheta: np.ndarray
    std_xytheta: np.ndarray
    delta_xytheta: np.ndarray
    n_overlap: int
    rms_overlap_m: float
    n_object: int
    rms_object_m: float


@dataclass(frozen=True)
class CalibrationReport:
    """What :func:`calibrate_scanners` found: per scanner, and the iterations it took.

    ``cov_xytheta`` (3 S, 3 S) is the joint covariance of the scanners' planar poses (scanner ``s`` owns
    rows ``3 s .. 3 s + 2``: x, y m, theta rad, world frame), for
    :func:`gtrig.laser.track.track_frames` to propagate into the robot poses.
    """

    scanners: tuple[ScannerCalibration, ...]
    iterations: int
    rms_overlap_m: float
    rms_object_m: float
    cov_xytheta: np.ndarray


def _scan_geometry(
    bg: BackgroundModel, scanner: LaserScanner, max_jump_m: float = 0.05, max_bend_m: float = 0.004
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Background points (n, 2) in the scanner's plane, their unit normals (n, 2) where the scan is locally
    straight (else nan: corners, edges and their mixed pixels), facing the scanner, and the mask (B,) of
    beams with a background range."""
    a = scanner.angles_rad
    r = bg.ranges_m
    p = np.column_stack([r * np.cos(a), r * np.sin(a)])
    ok = np.isfinite(r)
    prev = np.roll(p, 1, axis=0)
    nxt = np.roll(p, -1, axis=0)
    ok_n = ok & np.roll(ok, 1) & np.roll(ok, -1)
    ok_n[0] = ok_n[-1] = False
    with np.errstate(invalid="ignore"):
        jump = np.maximum(np.linalg.norm(p - prev, axis=1), np.linalg.norm(nxt - p, axis=1))
        tan = nxt - prev
        tan /= np.linalg.norm(tan, axis=1, keepdims=True)
        n = tan @ _J90.T
        bend = np.abs(np.einsum("ij,ij->i", p - prev, n))
        straight = ok_n & (jump < max_jump_m + 0.02 * r) & (bend < max_bend_m + 0.002 * r)
    n[~straight] = np.nan
    flip = np.einsum("ij,ij->i", n, -p) < 0
    n[flip] *= -1
    return p[ok], n[ok], ok


def object_outlines(objects: np.ndarray | Sequence[np.ndarray]) -> list[np.ndarray]:
    """One outline (K, 2) or several as a list of counter-clockwise (K_j, 2) arrays (world, metres).

    Raises
    ------
    InputError
        An outline that is not (K >= 3, 2).
    """
    arr = objects if isinstance(objects, np.ndarray) else None
    outlines = [arr] if arr is not None and arr.ndim == 2 else list(objects)
    out = []
    for c in outlines:
        c = np.asarray(c, dtype=float)
        if c.ndim != 2 or c.shape[1] != 2 or c.shape[0] < 3:
            raise InputError(f"an object outline must be (K >= 3, 2), got shape {c.shape}")
        area = 0.5 * np.sum(c[:, 0] * np.roll(c[:, 1], -1) - np.roll(c[:, 0], -1) * c[:, 1])
        out.append(c if area > 0 else c[::-1].copy())
    if not out:
        raise InputError("no world object outline given")
    return out


def _to_world(xyt: np.ndarray, p: np.ndarray) -> np.ndarray:
    return _rot_rows(p, xyt[2]) + xyt[:2]


def calibrate_scanners(
    scanners: Sequence[LaserScanner],
    backgrounds: Sequence[BackgroundModel],
    object_corners_world_xy: np.ndarray | Sequence[np.ndarray],
    gates_m: Sequence[float] = (0.3, 0.2, 0.12, 0.08, 0.05, 0.03, 0.03, 0.03),
    iterations_per_gate: int = 3,
    prior_std_m: float = 0.1,
    prior_std_rad: float = np.radians(5.0),
    sigma_point_m: float = 0.002,
    range_bias_std_m: float = 0.0,
    surface_bias_std_m: float = 0.001,
) -> tuple[tuple[LaserScanner, ...], CalibrationReport]:
    """Estimate the scanners' planar poses in the world from their background scans.

    Parameters
    ----------
    scanners
        The scanners with their nominal ``T_world_scanner`` (the start and the prior).
    backgrounds
        Their background models, same order.
    object_corners_world_xy
        (K, 2) outline of the world-defining object, or a sequence of outlines (K_j, 2) of several
        objects whose poses in the world are known (surveyed), world frame, metres.
    gates_m
        Association gates of the successive rounds, metres.
    iterations_per_gate
        Gauss-Newton iterations per gate.
    prior_std_m, prior_std_rad
        Standard deviations of the prior at the nominal poses.
    sigma_point_m
        Noise of one background point along its normal, the least the formal covariance takes (it takes
        the overlap residuals' RMS where that is larger): it stands for what is neither white noise nor a
        surface's bias (the lines' fit, edges of stretches). At 3 mm the network's common shift and
        rotation were stated 1.6 times too wide in variance over 90 drawn rooms (NEES / dof 0.63, 0.90 at
        2 mm; docs/laser.md, "Why a 2 mm point noise").
    range_bias_std_m, surface_bias_std_m
        Standard deviations (m) of range biases that the fit cannot estimate and that do not average
        down over points: one per scanner (its ranging offset) and one per straight stretch of its
        background scan (a surface's reflectivity: dark surfaces range long, by the same amount for
        every scanner); "considered" in the covariance (:func:`_bias_covariance`), the poses unchanged.
        Without them the formal covariance shrinks as 1 / points and was 5-7 times too confident
        (NEES / dof of the four scanners' poses against truth 4.9-7.2 on gtrig's simulator).
        ``surface_bias_std_m`` defaults to the tracker's per-side bias (``TrackSettings.side_bias_std_m``);
        the ranging offset defaults to none because the tracker's common bias
        (``TrackSettings.surface_bias_std_m``) already carries it into each robot pose, and an offset
        that moves the scanner and the hull it measures alike would otherwise count twice.

    Returns
    -------
    scanners : the scanners with calibrated ``T_world_scanner``.
    report : residuals and formal standard deviations.

    Raises
    ------
    InputError
        A background of the wrong beam count, or fewer than two scanners.
    ConvergenceError
        No scanner sees the world object.
    """
    S = len(scanners)
    if S != len(backgrounds):
        raise InputError(f"{S} scanners but {len(backgrounds)} background models")
    for s, b in zip(scanners, backgrounds, strict=True):
        if b.beams != s.beams:
            raise InputError(f"scanner {s.name}: background has {b.beams} beams, the rig says {s.beams}")
    objs = [HullModel.from_corners(c) for c in object_outlines(object_corners_world_xy)]
    geoms = [_scan_geometry(b, s) for b, s in zip(backgrounds, scanners, strict=True)]
    bias_cols = _bias_columns(geoms)
    n_bias = int(max(c.max() for c in bias_cols) + 1) if S else 0
    # each world object: one material, so one bias on all of its sides for every scanner that sees it (a
    # bias of its own per side would let the gauge wander by the sides' independent biases, which the
    # object's sides, seen from all around, do not have)
    face_col = n_bias + np.arange(len(objs))
    n_bias += len(objs)
    nominal = np.array([geo.T_to_se2(s.T_world_scanner.matrix()) for s in scanners])
    x = nominal.copy()
    prior = np.tile([1 / prior_std_m**2, 1 / prior_std_m**2, 1 / prior_std_rad**2], S)
    ne = _Normal(np.diag(prior), np.zeros(3 * S), np.zeros((3 * S, S + n_bias)))
    it = 0
    stats: dict[str, list[tuple[int, float]]] = {}
    for gate in gates_m:
        for _ in range(iterations_per_gate):
            it += 1
            ne, stats = _normal_equations(x, nominal, prior, geoms, objs, bias_cols, face_col, n_bias, gate,
                                          sigma_point_m)
            delta = -np.linalg.solve(ne.H, ne.g)
            x = x + delta.reshape(S, 3)
    if not any(n for n, _ in stats["object"]):
        raise ConvergenceError(
            "no scanner sees the world object: check its outline and the nominal scanner poses"
        )
    all_r = [(n, r) for n, r in stats["overlap"] if n]
    rms_ov = (
        float(np.sqrt(sum(n * r * r for n, r in all_r) / sum(n for n, _ in all_r))) if all_r else float("nan")
    )
    all_o = [(n, r) for n, r in stats["object"] if n]
    rms_ob = float(np.sqrt(sum(n * r * r for n, r in all_o) / sum(n for n, _ in all_o)))
    scale = max(1.0, (rms_ov / sigma_point_m) ** 2) if np.isfinite(rms_ov) else 1.0
    Hinv = np.linalg.inv(ne.H)
    cov = Hinv * scale + _bias_covariance(Hinv, ne.G, S, range_bias_std_m, surface_bias_std_m)
    cov = 0.5 * (cov + cov.T)
    out_scanners, cal = _calibrated(scanners, x, nominal, cov, stats)
    return out_scanners, CalibrationReport(cal, it, rms_ov, rms_ob, cov)


@dataclass
class _Normal:
    """The Gauss-Newton normal equations ``H dx = -g`` over the S scanners' (x, y, theta), and ``G``, the
    right-hand side's derivative by the range biases (their pull on the poses)."""

    H: np.ndarray
    g: np.ndarray
    G: np.ndarray


def _normal_equations(x: np.ndarray, nominal: np.ndarray, prior: np.ndarray, geoms: list, objs: list,
                      bias_cols: list, face_col: np.ndarray, n_bias: int, gate: float, sigma_point_m: float
                      ) -> tuple[_Normal, dict[str, list[tuple[int, float]]]]:
    """One Gauss-Newton iteration's normal equations at the poses ``x`` (S, 3): the prior, every pair of
    scanners' overlapping background points and every scanner's points on the world objects; with each
    scanner's point count and RMS residual (``overlap``, ``object``)."""
    S = len(x)
    ne = _Normal(np.diag(prior), prior * (x - nominal).ravel(), np.zeros((3 * S, S + n_bias)))
    stats: dict[str, list[tuple[int, float]]] = {"overlap": [(0, 0.0)] * S, "object": [(0, 0.0)] * S}
    pw = [_to_world(x[i], geoms[i][0]) for i in range(S)]
    nw = [_rot_rows(geoms[i][1], x[i, 2]) for i in range(S)]
    trees = [cKDTree(p) for p in pw]
    ray = [_rot_rows(geoms[i][0] / np.linalg.norm(geoms[i][0], axis=1, keepdims=True), x[i, 2])
           for i in range(S)]  # (n, 2) unit beam directions in the world
    for i in range(S):
        pi_s = geoms[i][0]
        dpi = (
            pi_s @ np.array([[np.cos(x[i, 2]), np.sin(x[i, 2])], [-np.sin(x[i, 2]), np.cos(x[i, 2])]])
        ) @ _J90.T  # d p_w / d theta_i
        ssq, cnt = 0.0, 0
        for j in range(S):
            if j == i:
                continue
            s_ij, c_ij = _overlap_pair(ne, i, j, x, pw, nw, trees, ray, dpi, bias_cols, gate, sigma_point_m)
            ssq += s_ij
            cnt += c_ij
        stats["overlap"][i] = (cnt, np.sqrt(ssq / cnt) if cnt else float("nan"))
        n_ob, ssq_ob = _object_terms(ne, i, x, pw, dpi, ray, objs, face_col, gate, sigma_point_m)
        if n_ob:
            stats["object"][i] = (n_ob, float(np.sqrt(ssq_ob / n_ob)))
    return ne, stats


def _overlap_pair(ne: _Normal, i: int, j: int, x: np.ndarray, pw: list, nw: list, trees: list, ray: list,
                  dpi: np.ndarray, bias_cols: list, gate: float, sigma_point_m: float) -> tuple[float, int]:
    """Scanner ``i``'s background points on scanner ``j``'s background surfaces (facing both), point to
    line, added to ``ne``; their sum of squares and count."""
    S = len(x)
    d, idx = trees[j].query(pw[i], distance_upper_bound=gate + 0.15)
    m = np.isfinite(d)
    idx = idx[m]
    n = nw[j][idx]
    m2 = np.isfinite(n[:, 0])
    q = pw[j][idx[m2]]
    n = n[m2]
    sel = np.flatnonzero(m)[m2]
    # the surface must face scanner i as well as scanner j
    face = np.einsum("ij,ij->i", n, x[i, :2] - q) > 0
    sel, q, n = sel[face], q[face], n[face]
    r = np.einsum("ij,ij->i", n, pw[i][sel] - q)
    ok = np.abs(r) < gate
    sel, q, n, r = sel[ok], q[ok], n[ok], r[ok]
    if r.size == 0:
        return 0.0, 0
    dq = (q - x[j, :2]) @ _J90.T
    Ji = np.column_stack([n, np.einsum("ij,ij->i", n, dpi[sel])])
    Jj = -np.column_stack([n, np.einsum("ij,ij->i", n, dq)])
    wgt = 1.0 / (sigma_point_m**2 + (r / 3.0) ** 2 * (np.abs(r) > 3 * sigma_point_m))
    bi, bj = slice(3 * i, 3 * i + 3), slice(3 * j, 3 * j + 3)
    ne.H[bi, bi] += (Ji * wgt[:, None]).T @ Ji
    ne.H[bj, bj] += (Jj * wgt[:, None]).T @ Jj
    ne.H[bi, bj] += (Ji * wgt[:, None]).T @ Jj
    ne.H[bj, bi] += (Jj * wgt[:, None]).T @ Ji
    ne.g[bi] += Ji.T @ (wgt * r)
    ne.g[bj] += Jj.T @ (wgt * r)
    # a range bias moves point k along its beam: r changes by n . ray (i), -n . ray (j)
    di = np.einsum("ij,ij->i", n, ray[i][sel])
    dj = -np.einsum("ij,ij->i", n, ray[j][idx[m2][face][ok]])
    for own, cols, dr in ((i, bias_cols[i][sel], di), (j, bias_cols[j][idx[m2][face][ok]], dj)):
        for Jx, bx in ((Ji, bi), (Jj, bj)):
            _add_bias_pull(ne.G, bx, Jx, wgt * dr, cols, own, S)
    return float(r @ r), r.size


def _object_terms(ne: _Normal, i: int, x: np.ndarray, pw: list, dpi: np.ndarray, ray: list, objs: list,
                  face_col: np.ndarray, gate: float, sigma_point_m: float) -> tuple[int, float]:
    """Scanner ``i``'s points on the world objects' known sides (faces visible from it), point to line,
    added to ``ne``; their count and sum of squares. All sides of object ``o`` share its bias column
    ``face_col[o]``."""
    S = len(x)
    n_ob, ssq_ob = 0, 0.0
    for o, obj in enumerate(objs):
        vis = (obj.normals @ x[i, :2] - obj.offsets) > 0
        sd = pw[i] @ obj.normals.T - obj.offsets
        a = pw[i] @ obj.tangents.T - np.einsum("ij,ij->i", obj.tangents, obj.corners_xy)
        over = np.maximum(0.0, np.maximum(-a, a - obj.lengths))
        d2 = np.where(vis, sd * sd + over * over, np.inf)
        k = np.argmin(d2, axis=1)
        rows = np.arange(len(k))
        m = (d2[rows, k] < gate * gate) & (over[rows, k] < 0.01)
        if not np.any(m):
            continue
        n = obj.normals[k[m]]
        r = sd[rows, k][m]
        Ji = np.column_stack([n, np.einsum("ij,ij->i", n, dpi[m])])
        wgt = 1.0 / sigma_point_m**2
        bi = slice(3 * i, 3 * i + 3)
        ne.H[bi, bi] += wgt * Ji.T @ Ji
        ne.g[bi] += wgt * Ji.T @ r
        dr = np.einsum("ij,ij->i", n, ray[i][m])
        _add_bias_pull(ne.G, bi, Ji, wgt * dr, np.full(int(m.sum()), face_col[o]), i, S)
        n_ob += int(m.sum())
        ssq_ob += float(r @ r)
    return n_ob, ssq_ob


def _calibrated(scanners: Sequence[LaserScanner], x: np.ndarray, nominal: np.ndarray, cov: np.ndarray,
                stats: dict[str, list[tuple[int, float]]]
                ) -> tuple[tuple[LaserScanner, ...], tuple[ScannerCalibration, ...]]:
    """The scanners at their calibrated planar poses (nominal height, roll and pitch kept) and each one's
    calibration record."""
    std = np.sqrt(np.diag(cov)).reshape(len(scanners), 3)
    out_scanners = []
    cal = []
    for i, s in enumerate(scanners):
        T = s.T_world_scanner.matrix()
        T_new = geo.se2_to_T(x[i, 0], x[i, 1], x[i, 2], T[2, 3])
        # keep the nominal roll and pitch: rotate the nominal about the vertical by the yaw change
        T_new[:3, :3] = geo.se2_to_T(0, 0, x[i, 2] - nominal[i, 2])[:3, :3] @ T[:3, :3]
        out_scanners.append(s.model_copy(update={"T_world_scanner": Pose.from_matrix(T_new)}))
        cal.append(
            ScannerCalibration(
                s.name,
                x[i].copy(),
                std[i],
                x[i] - nominal[i],
                stats["overlap"][i][0],
                stats["overlap"][i][1],
                stats["object"][i][0],
                stats["object"][i][1],
            )
        )
    return tuple(out_scanners), tuple(cal)


def _rot_rows(p: np.ndarray, theta: float) -> np.ndarray:
    """Row vectors (n, 2) in the scanner's frame rotated by ``theta`` into the world's axes."""
    c, s = np.cos(theta), np.sin(theta)
    return p @ np.array([[c, s], [-s, c]])


def _bias_columns(geoms: Sequence[tuple[np.ndarray, np.ndarray, np.ndarray]]) -> list[np.ndarray]:
    """Per scanner, the column (n,) of each background point's surface bias among all scanners' straight
    stretches: a new stretch starts at every point without a normal (a corner, an edge, a jump)."""
    cols, off = [], 0
    for _, n, _ in geoms:
        run = np.cumsum(~np.isfinite(n[:, 0])) if len(n) else np.zeros(0, int)
        cols.append(off + run)
        off += int(run.max()) + 1 if len(n) else 0
    return cols


def _add_bias_pull(G: np.ndarray, rows: slice, J: np.ndarray, wdr: np.ndarray, cols: np.ndarray, owner: int,
                   S: int) -> None:
    """Add ``J^T wdr`` (3,) of every point into ``G[rows]``: at its stretch's column (``S + cols``) and at
    the ranging offset of the scanner ``owner`` that measured the points."""
    contrib = J * wdr[:, None]  # (n, 3)
    np.add.at(G[rows].T, S + cols, contrib)
    G[rows, owner] += contrib.sum(axis=0)


def _bias_covariance(Hinv: np.ndarray, G: np.ndarray, S: int, range_std_m: float, surface_std_m: float) -> np.ndarray:
    """Covariance (3 S, 3 S) of the poses that the range biases leave: the solution moves by
    ``-H^-1 G b`` for biases ``b``, which do not average out over a surface's points, so their share
    is ``H^-1 G Sigma_b G^T H^-1`` (a "consider" covariance, Bierman 1977, ch. VI) with ``Sigma_b``
    diagonal: ``range_std_m^2`` for the S scanners' offsets, ``surface_std_m^2`` for the stretches and
    the world objects."""
    var = np.r_[np.full(S, range_std_m**2), np.full(G.shape[1] - S, surface_std_m**2)]
    A = Hinv @ G
    return (A * var) @ A.T


def calibrated_rig(rig: Rig, scanners: Sequence[LaserScanner]) -> Rig:
    """``rig`` with its laser scanners replaced by ``scanners``."""
    return rig.model_copy(update={"laser_scanners": tuple(scanners)})
