"""Laser scanners in the simulator: the fixed GTlaser network and the robot's onboard scanners.

Geometry is exact: each beam is a 3D ray in its scanner's plane, fired at its own instant (a scanner's
mirror sweeps the beams over part of its rotation, so the robot and the people move during a scan).
Walls and clutter are vertical prisms, so the beam is cast in 2D against their footprints and its 3D
range is the 2D distance divided by the cosine of the beam's elevation; a clutter face only counts if
the beam meets it below the box's top. The robot's gown is a box tilted with the robot on the uneven
floor: the scanner plane cuts it in a quadrilateral whose height and outline vary with the tilt
(:func:`gown_sections`). People are two leg circles each (:mod:`gtrig.sim.people`).

The sensor model (docs/simulator.md, "Laser scanners") adds, in this order: mixed pixels over the beam's
footprint, a reflectivity-dependent bias, Gaussian noise, random dropouts, the range limit and 1 mm
quantisation; scan time stamps carry a per-scanner clock offset and jitter.
"""

from __future__ import annotations

import dataclasses
import logging
import math
import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike

from gtrig import geometry as geo
from gtrig.errors import InputError
from gtrig.io.scans import ScanLog, write_scans
from gtrig.rig.models import BeamTiming, Hull, LaserScanner, StampAt
from gtrig.sim.config import SimConfig, noise_stream
from gtrig.sim.gtroom import Box, Scene
from gtrig.sim.motion import RobotMotion
from gtrig.sim.people import HIP_HALF_WIDTH_M, LEG_RADIUS_M, LEG_SWING_M, People, simulate_people
from gtrig.sim.raycast import cast_circles, cast_segments

log = logging.getLogger(__name__)

# Beam divergence (full angle) of SICK LMS2xx / Hokuyo URG class scanners: a few mrad, i.e. a spot of
# a few centimetres at several metres. The footprint is sampled by MIXED_SUBRAYS rays across it.
BEAM_DIVERGENCE_RAD = 0.004
MIXED_SUBRAYS = 5
# Two surfaces further apart than this inside one footprint give the stronger echo rather than an
# average (a pulsed time-of-flight receiver separates echoes longer apart than its pulse).
MIXED_MAX_SEPARATION_M = 1.0
# Reflectivities (0 black, 1 white) of what the scanners see besides the clutter boxes.
WALL_REFLECTIVITY = 0.8  # painted plaster
GOWN_REFLECTIVITY = 0.7  # light fabric over cardboard
LEG_REFLECTIVITY = 0.35  # trousers
# A surface draw (``cfg.laser.surface_draw`` > 0) gives every wall and every clutter box a reflectivity of
# its own, uniform over the span of the designed room's materials (heaters 0.9 to the darkest box 0.3):
# rooms that differ in what their surfaces' range biases are, for Monte Carlo over that error.
SURFACE_REFLECTIVITY_SPAN = (0.3, 0.9)
_SURFACE_DRAW_SALT = 0x5EF1EC7
# Range quantisation of the devices (SICK LMS2xx mm mode, Hokuyo URG: 1 mm).
RANGE_RESOLUTION_M = 0.001
# Scanner clocks: each scanner's stamps are late or early by a fixed offset (residual synchronisation
# of the logging PCs, serial transfer delay) plus a per-scan jitter (driver and bus latency).
CLOCK_OFFSET_SIGMA_S = 0.002
STAMP_JITTER_SIGMA_S = 0.0003
ONBOARD_RANGE_SIGMA_M = 0.01  # SICK LMS291: about 1 cm statistical error indoors
# Candidate beams for moving objects are found with bounding circles grown by this margin (metres).
CULL_MARGIN_M = 0.02
_CHUNK_RAYS = 400_000


@dataclass(frozen=True)
class ScanSimInfo:
    """What the simulator did that a recording does not tell: per scanner, its clock offset (seconds
    added to the true scan start time) and the number of scans."""

    clock_offsets_s: dict[str, float] = field(default_factory=dict)
    n_scans: dict[str, int] = field(default_factory=dict)


# ----------------------------------------------------------------------------------------- geometry
def robot_poses(motion: RobotMotion, t: ArrayLike) -> np.ndarray:
    """``T_world_robot`` (..., 4, 4) at times ``t`` (...,): vectorised :meth:`Floor.robot_pose`."""
    t = np.asarray(t, dtype=float)
    shape = t.shape
    xyth = motion.planar(t.ravel())
    x, y, th = xyth[:, 0], xyth[:, 1], xyth[:, 2]
    gx, gy = motion.floor.gradient(x, y)
    n = np.column_stack([-np.asarray(gx), -np.asarray(gy), np.ones_like(x)])
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    h = np.column_stack([np.cos(th), np.sin(th), np.zeros_like(th)])
    xa = h - n * np.sum(h * n, axis=1, keepdims=True)
    xa /= np.linalg.norm(xa, axis=1, keepdims=True)
    ya = np.cross(n, xa)
    T = np.zeros((len(x), 4, 4))
    T[:, :3, 0], T[:, :3, 1], T[:, :3, 2] = xa, ya, n
    T[:, :3, 3] = np.column_stack([x, y, motion.floor.height(x, y)])
    T[:, 3, 3] = 1.0
    return T.reshape(*shape, 4, 4)


def plane_box_section(hull: Hull, T_plane_robot: ArrayLike) -> np.ndarray:
    """Section of the gown box by the plane z = 0 of a frame, for one pose, by brute force.

    Intersects all 12 box edges with the plane. Returns the convex polygon (V, 2) in the plane
    frame's x-y, counter-clockwise (V = 0 if the plane misses the box).
    """
    T = np.asarray(T_plane_robot, dtype=float)
    xy = hull.corners_xy()
    corners = np.array([[x, y, z] for z in (hull.z_min_m, hull.z_max_m) for x, y in xy])
    edges = [(i, (i + 1) % 4) for i in range(4)] + [(4 + i, 4 + (i + 1) % 4) for i in range(4)] + [
        (i, i + 4) for i in range(4)]
    p = geo.transform_points(T, corners)
    pts = []
    for a, b in edges:
        za, zb = p[a, 2], p[b, 2]
        if (za < 0) != (zb < 0) or za == 0:
            s = 0.0 if za == zb else za / (za - zb)
            pts.append(p[a, :2] + s * (p[b, :2] - p[a, :2]))
    if len(pts) < 3:
        return np.zeros((0, 2))
    q = np.array(pts)
    c = q.mean(axis=0)
    q = q[np.argsort(np.arctan2(q[:, 1] - c[1], q[:, 0] - c[0]))]
    keep = np.r_[True, np.linalg.norm(np.diff(q, axis=0), axis=1) > 1e-12]
    return q[keep]


def gown_sections(hull: Hull, T_plane_robot: ArrayLike) -> np.ndarray:
    """Outline of the gown where the plane z = 0 of a frame (a scanner's) cuts it.

    Parameters
    ----------
    hull : the gown, a box in the robot frame.
    T_plane_robot : (N, 4, 4) robot poses in the plane's frame.

    Returns
    -------
    (N, V, 2) closed polygon vertices in the plane frame's x-y, metres, counter-clockwise. Usually
    V = 4: the plane crosses the four vertical edges at heights that depend on the tilt. If any pose is
    cut through a top or bottom face, V = 6 and shorter polygons repeat their last vertex (degenerate
    segments never hit); poses whose plane misses the gown are all ``nan``.
    """
    T = np.asarray(T_plane_robot, dtype=float).reshape(-1, 4, 4)
    xy = hull.corners_xy()  # (4, 2)
    # the plane's z along a vertical edge (x_c, y_c, z): a + b z = 0
    a = T[:, 2, None, 0] * xy[None, :, 0] + T[:, 2, None, 1] * xy[None, :, 1] + T[:, 2, None, 3]
    b = T[:, 2, None, 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        z = -a / b
    p_robot = np.concatenate([np.broadcast_to(xy, (len(T), 4, 2)), z[..., None]], axis=-1)
    quad = np.einsum("nij,nkj->nki", T[:, :2, :3], p_robot) + T[:, None, :2, 3]
    ok = (z >= hull.z_min_m) & (z <= hull.z_max_m)
    ok = ok.all(axis=1) & np.isfinite(z).all(axis=1)
    # corners_xy is counter-clockwise in the robot frame; keep it so in the plane frame
    flip = np.linalg.det(T[:, :2, :2]) < 0
    quad[flip] = quad[flip, ::-1]
    if ok.all():
        return quad
    out = np.full((len(T), 6, 2), np.nan)
    out[ok, :4] = quad[ok]
    out[ok, 4:] = quad[ok, 3:4]
    for i in np.flatnonzero(~ok):
        poly = plane_box_section(hull, T[i])
        if len(poly):
            out[i, : len(poly)] = poly
            out[i, len(poly):] = poly[-1]
    return out


def _polygon_segments(poly: np.ndarray) -> np.ndarray:
    """(..., V, 2) closed polygons as (..., V, 2, 2) segments."""
    return np.stack([poly, np.roll(poly, -1, axis=-2)], axis=-2)


def _box_contains(bx: Box, xy: np.ndarray) -> bool:
    c, s = np.cos(bx.yaw_rad), np.sin(bx.yaw_rad)
    d = np.asarray(xy, dtype=float) - bx.centre_xy
    return abs(c * d[0] + s * d[1]) <= bx.size[0] / 2 and abs(-s * d[0] + c * d[1]) <= bx.size[1] / 2


def surface_reflectivities(scene: Scene, draw: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """Reflectivities (0 black, 1 white) of the walls (W,) and of the clutter boxes (scene order, (K,)).

    Parameters
    ----------
    scene : the room.
    draw : 0: the designed materials (walls ``WALL_REFLECTIVITY``, each box its own); k > 0: the k-th
        seeded draw (scene seed and ``k``), each wall and each box uniform over
        ``SURFACE_REFLECTIVITY_SPAN``, one material over all of a box's faces.
    """
    if draw == 0:
        return np.full(len(scene.walls), WALL_REFLECTIVITY), np.array([b.reflectivity for b in scene.boxes])
    rng = np.random.default_rng([scene.seed, _SURFACE_DRAW_SALT, int(draw)])
    rho = rng.uniform(*SURFACE_REFLECTIVITY_SPAN, len(scene.walls) + len(scene.boxes))
    return rho[: len(scene.walls)], rho[len(scene.walls):]


def static_segments(
    scene: Scene, mount_xy: ArrayLike | None = None, surface_draw: int = 0
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Walls and clutter faces as world x-y segments.

    A box whose footprint holds ``mount_xy`` (a fixed scanner's position) is taken as that scanner's
    mount and left out: a scanner does not see the inside of the stand it sits in. ``surface_draw``
    chooses the surfaces' reflectivities (:func:`surface_reflectivities`).

    Returns
    -------
    segments : (S, 2, 2) metres.
    z_top_m : (S,) height of each face's top (``inf`` for walls).
    reflectivity : (S,)
    """
    wall_refl, box_refl = surface_reflectivities(scene, surface_draw)
    segs = [np.asarray(scene.walls, dtype=float)]
    z_top = [np.full(len(scene.walls), np.inf)]
    refl = [wall_refl]
    for bx, rho in zip(scene.boxes, box_refl, strict=True):
        if mount_xy is not None and _box_contains(bx, np.asarray(mount_xy)):
            log.debug("box %s holds a scanner at %s: taken as its mount", bx.name, mount_xy)
            continue
        segs.append(_polygon_segments(bx.corners_xy()))
        z_top.append(np.full(4, bx.size[2]))
        refl.append(np.full(4, rho))
    return np.concatenate(segs), np.concatenate(z_top), np.concatenate(refl)


# ----------------------------------------------------------------------------- scene from settings
# The clutter that blocks part of a scanner's view: a screen this far in front of the scanner, this
# thick and this tall (above the scanning plane, so that it hides the robot's gown behind it).
BLOCK_DISTANCE_M = 0.45
BLOCK_DEPTH_M = 0.1
BLOCK_HEIGHT_M = 1.0


def blocking_box(scanner: LaserScanner, fraction: float) -> Box:
    """An upright screen next to ``scanner`` hiding the left ``fraction`` of its field of view (the
    beams from the last one backwards), as a cabinet or a pile of boxes left by a scanner does."""
    T = scanner.T_world_scanner.matrix()
    a = scanner.angles_rad
    a_hi = float(a[-1]) if scanner.angle_increment_rad > 0 else float(a[0])
    span = float(abs(a[-1] - a[0]))
    half = 0.5 * fraction * span  # half-angle of the hidden sector
    bis = a_hi - half + float(np.arctan2(T[1, 0], T[0, 0]))  # the sector's bisector, world
    d = BLOCK_DISTANCE_M + BLOCK_DEPTH_M / 2
    width = 2 * BLOCK_DISTANCE_M * np.tan(min(half, np.radians(75.0))) + 0.04
    c = T[:2, 3] + d * np.array([np.cos(bis), np.sin(bis)])
    return Box(f"block_{scanner.name}", (float(c[0]), float(c[1])), (BLOCK_DEPTH_M, float(width), BLOCK_HEIGHT_M),
               float(bis), 0.5)


def with_scanner_stamp_sigma(rig):  # noqa: ANN001, ANN201
    """``rig`` with its fixed scanners' ``stamp_sigma_s`` set to the simulator's clock model (a fixed
    offset per scanner plus per-scan jitter): the lab knows how well its logging PCs are synchronised."""
    sig = float(np.hypot(CLOCK_OFFSET_SIGMA_S, STAMP_JITTER_SIGMA_S))
    return rig.model_copy(update={"laser_scanners": tuple(
        s.model_copy(update={"stamp_sigma_s": sig}) for s in rig.laser_scanners)})


def configure_scene(scene: Scene, cfg: SimConfig) -> Scene:
    """The scene as ``cfg.laser`` sets it up: the fixed scanners' beam timing and stamp reference
    (true and nominal rig: the lab knows its driver), and the clutter blocking a scanner. The default
    settings return the scene unchanged."""
    lc = cfg.laser
    upd = {"beam_timing": BeamTiming(lc.beam_timing), "stamp_at": StampAt(lc.stamp_at)}
    if all(getattr(s, k) == v for s in scene.rig_true.laser_scanners for k, v in upd.items()) and (
        lc.blocked_scanner is None
    ):
        return scene

    def timed(rig):  # noqa: ANN001, ANN202
        return rig.model_copy(update={"laser_scanners": tuple(s.model_copy(update=upd) for s in rig.laser_scanners)})

    boxes = scene.boxes
    if lc.blocked_scanner is not None:
        scs = scene.rig_true.laser_scanners
        if lc.blocked_scanner >= len(scs):
            raise InputError(f"laser.blocked_scanner: {lc.blocked_scanner} but the rig has {len(scs)} scanners")
        boxes = boxes + (blocking_box(scs[lc.blocked_scanner], lc.blocked_fraction),)
    return dataclasses.replace(scene, rig_true=timed(scene.rig_true), rig_nominal=timed(scene.rig_nominal),
                               boxes=boxes)


# ------------------------------------------------------------------------------------ sensor model
def _subray_offsets(mixed: bool) -> np.ndarray:
    if not mixed:
        return np.zeros(1)
    return BEAM_DIVERGENCE_RAD * (np.arange(MIXED_SUBRAYS) / (MIXED_SUBRAYS - 1) - 0.5)


def _rays_world(T_world_scanner: np.ndarray, angles: np.ndarray) -> tuple[np.ndarray, ...]:
    """3D beams of scanner poses (..., 4, 4) at in-plane angles (...,) as 2D rays.

    Returns origin xy (..., 2), unit 2D direction (..., 2), origin height (...,), height gained per
    metre of 2D distance (...,), and the 3D range per 2D metre (...,).
    """
    d = np.stack([np.cos(angles), np.sin(angles)], axis=-1)
    R = T_world_scanner[..., :3, :3]
    d3 = R[..., :, 0] * d[..., 0, None] + R[..., :, 1] * d[..., 1, None]
    h = np.hypot(d3[..., 0], d3[..., 1])
    u = d3[..., :2] / h[..., None]
    return T_world_scanner[..., :2, 3], u, T_world_scanner[..., 2, 3], d3[..., 2] / h, 1.0 / h


def _sensor_model(
    ranges_m: np.ndarray, refl: np.ndarray, sigma_m: float, range_max_m: float, cfg: SimConfig,
    rng: np.random.Generator, ideal: bool,
) -> np.ndarray:
    """Measured ranges (N,) from exact sub-ray ranges (N, J) and reflectivities (N, J)."""
    J = ranges_m.shape[-1]
    if ideal or J == 1:
        r = ranges_m[..., J // 2].copy()
        rho = refl[..., J // 2]
    else:
        fin = np.isfinite(ranges_m)
        rmin = np.min(np.where(fin, ranges_m, np.inf), axis=-1, keepdims=True)
        rmax = np.max(np.where(fin, ranges_m, -np.inf), axis=-1, keepdims=True)
        fg = fin & (ranges_m <= 0.5 * (rmin + rmax))
        bg = fin & ~fg
        far_apart = (rmax - rmin) > MIXED_MAX_SEPARATION_M
        pick_fg = fg.sum(-1, keepdims=True) >= bg.sum(-1, keepdims=True)
        sel = np.where(far_apart, np.where(pick_fg, fg, bg), fin)
        n = sel.sum(-1)
        with np.errstate(invalid="ignore", divide="ignore"):
            r = np.where(sel, ranges_m, 0).sum(-1) / n
            rho = np.where(sel, refl, 0).sum(-1) / n
        # most of the footprint's energy lost (beyond range or off an edge into nothing): no echo
        r[2 * fin.sum(-1) < J] = np.inf
    if not ideal:
        # dark surfaces return weaker pulses that cross the detection threshold later: longer ranges
        r += cfg.laser.reflectivity_bias_m * (0.5 - rho)
        r += rng.normal(0.0, sigma_m, r.shape)
        r[rng.random(r.shape) < cfg.laser.dropout_prob] = np.nan
        r = np.maximum(r, 0.0)
        r = np.round(r / RANGE_RESOLUTION_M) * RANGE_RESOLUTION_M
    r[~(r <= range_max_m)] = np.nan
    return r


def _scan_starts(intervals_s: np.ndarray, rate_hz: float, scan_s: float, phase_s: float) -> np.ndarray:
    """True start times of a free-running scanner's scans lying wholly inside the intervals (K, 2)."""
    out = []
    for t0, t1 in np.asarray(intervals_s, dtype=float).reshape(-1, 2):
        first = math.ceil((t0 - phase_s) * rate_hz - 1e-9) / rate_hz + phase_s
        k = np.arange(0, max(0, int(math.floor((t1 - scan_s - first) * rate_hz + 1e-9)) + 1))
        out.append(first + k / rate_hz)
    starts = np.concatenate(out) if out else np.zeros(0)
    return np.unique(starts)


def _beam_delays(angles: np.ndarray, rate_hz: float, timing: BeamTiming = BeamTiming.SWEEP) -> np.ndarray:
    # the mirror turns once per scan period; beam i fires when it points at angle i
    if timing == BeamTiming.SIMULTANEOUS:
        return np.zeros(len(angles))
    return np.abs(angles - angles[0]) / (2 * math.pi) / rate_hz


def _stamp_offset(delays: np.ndarray, stamp_at: StampAt) -> float:
    """Time from the first beam to the instant the scan's stamp refers to."""
    return {StampAt.START: 0.0, StampAt.MIDDLE: 0.5 * float(delays[-1]), StampAt.END: float(delays[-1])}[
        StampAt(stamp_at)]


def sequence_people(
    scene: Scene, motion: RobotMotion | None, intervals_s: np.ndarray, cfg: SimConfig
) -> People:
    """The people walking during a sequence (intervals (K, 2)); the same for every scanner."""
    iv = np.asarray(intervals_s, dtype=float).reshape(-1, 2)
    t0, t1 = float(iv.min()), float(iv.max())
    # the same sequence gets the same people for every scanner, fixed or onboard
    seed = [scene.seed, 0x9E0B1E, int(round(t0 * 1000.0)) % (2**32)]
    rng_seed = int(np.random.default_rng(seed).integers(2**63))
    return simulate_people(scene, motion, t0 - 1.0, t1 + 1.0, cfg.laser.people, rng_seed)


def _check_intervals(intervals_s: np.ndarray) -> np.ndarray:
    iv = np.asarray(intervals_s, dtype=float)
    if iv.ndim != 2 or iv.shape[1] != 2 or len(iv) == 0 or np.any(iv[:, 1] <= iv[:, 0]):
        raise InputError(f"intervals_s must be (K, 2) with end > start, got shape {iv.shape}")
    return iv


# ----------------------------------------------------------------------------------- fixed scanners
def simulate_fixed_scans(
    scene: Scene, motion: RobotMotion | None, intervals_s: np.ndarray, cfg: SimConfig, seed: int,
    ideal: bool = False,
) -> tuple[dict[str, ScanLog], ScanSimInfo]:
    """Scans of every fixed scanner of ``scene.rig_true`` inside the time intervals.

    Parameters
    ----------
    scene : the room and the true rig.
    motion : the robot's true motion; ``None`` for the empty room (people still walk).
    intervals_s : (K, 2) start and end of the recorded intervals, recording clock, seconds.
    cfg : simulator settings (``cfg.laser``).
    seed : noise seed; the same arguments give identical scans.
    ideal : exact geometry only: no mixed pixels, bias, noise, dropouts, quantisation, clock offset or
        jitter (for tests). Beams are still fired at their own instants.

    Returns
    -------
    scans : scanner name -> :class:`ScanLog` (stamps in the scanner's clock, ranges in metres).
    info : clock offsets and scan counts.
    """
    iv = _check_intervals(intervals_s)
    people = sequence_people(scene, motion, iv, cfg)
    hull = scene.rig_true.robot.hull
    assert hull is not None, "the simulated room's robot always has a hull"
    hull_r = float(np.max(np.linalg.norm(hull.corners_xy(), axis=1)))
    person_r = HIP_HALF_WIDTH_M + LEG_SWING_M + LEG_RADIUS_M
    offsets = _subray_offsets(cfg.laser.mixed_pixels and not ideal)
    J = len(offsets)
    out: dict[str, ScanLog] = {}
    info = ScanSimInfo()
    side_refl = cfg.laser.gown_reflectivity

    def gown_refl(side: np.ndarray, n_vertices: int) -> np.ndarray | float:
        # the scanning plane usually cuts the four vertical faces, in the hull's side order; a cut
        # through the top or bottom (V = 6) takes the fabrics' mean
        if side_refl is None:
            return GOWN_REFLECTIVITY
        if n_vertices != 4:
            return float(np.mean(side_refl))
        return np.asarray(side_refl)[np.clip(side, 0, 3)]

    for si, sc in enumerate(scene.rig_true.laser_scanners):
        rng = np.random.default_rng([seed, si])
        # the clock offset and phase are the scanner's own; the range noise, dropouts and jitter are redrawn
        noise = noise_stream(rng, [seed, si], cfg.noise_draw_of("sensors"))
        T_ws = sc.T_world_scanner.matrix()
        T_sw = geo.inv_T(T_ws)
        segs, z_top, seg_refl = static_segments(scene, T_ws[:2, 3], cfg.laser.surface_draw)
        ang = sc.angles_rad
        B = len(ang)
        delays = _beam_delays(ang, sc.rate_hz, sc.beam_timing)
        offset = 0.0 if ideal else float(rng.normal(0.0, cfg.laser.clock_offset_sigma_s))
        starts = _scan_starts(iv, sc.rate_hz, delays[-1], float(rng.uniform(0, 1 / sc.rate_hz)))
        K = len(starts)
        sub_ang = ang[:, None] + offsets[None, :]  # (B, J)
        o, u, z0, dz, k3 = _rays_world(T_ws, sub_ang)
        d_st, i_st = cast_segments(o, u, segs, z0, dz, z_top[None, None, :])
        R = np.broadcast_to(d_st * k3, (K, B, J)).copy()
        rho = np.broadcast_to(np.where(i_st >= 0, seg_refl[i_st], 0.0), (K, B, J)).copy()

        # moving objects: bounding circles over each scan, then exact casts on candidate beams only
        t_a, t_b = starts, starts + delays[-1]
        centres, radii = [], []
        if motion is not None:
            pa, pb = motion.planar(t_a)[:, :2], motion.planar(t_b)[:, :2]
            centres.append(0.5 * (pa + pb))
            radii.append(hull_r + 0.5 * np.linalg.norm(pb - pa, axis=1) + CULL_MARGIN_M)
        for p in range(people.count):
            cp = people.centres_xy[:, p]
            xa = np.column_stack([np.interp(t_a, people.stamps_s, cp[:, k]) for k in range(2)])
            xb = np.column_stack([np.interp(t_b, people.stamps_s, cp[:, k]) for k in range(2)])
            centres.append(0.5 * (xa + xb))
            radii.append(person_r + 0.5 * np.linalg.norm(xb - xa, axis=1) + CULL_MARGIN_M)
        if centres and K:
            beam_world = np.arctan2(u[:, J // 2, 1], u[:, J // 2, 0])  # (B,)
            mask = np.zeros((K, B), dtype=bool)
            for c, rad in zip(centres, radii, strict=True):
                v = c - o
                dist = np.linalg.norm(v, axis=1)
                phi = np.arctan2(v[:, 1], v[:, 0])
                half = np.arcsin(np.minimum(1.0, rad / np.maximum(dist, 1e-9))) + BEAM_DIVERGENCE_RAD
                half[dist <= rad] = np.pi
                mask |= np.abs(geo.wrap_angle(beam_world[None, :] - phi[:, None])) <= half[:, None]
            kk, bb = np.nonzero(mask)
            for c0 in range(0, len(kk), max(1, _CHUNK_RAYS // J)):
                k_c, b_c = kk[c0:c0 + _CHUNK_RAYS // J], bb[c0:c0 + _CHUNK_RAYS // J]
                t_beam = starts[k_c] + delays[b_c]
                d_dyn = np.full((len(k_c), J), np.inf)
                r_dyn = np.zeros((len(k_c), J))
                if motion is not None:
                    T_sr = T_sw @ robot_poses(motion, t_beam)
                    poly = gown_sections(hull, T_sr)  # scanner frame
                    poly_w = np.einsum("ij,nvj->nvi", T_ws[:2, :2], poly) + T_ws[:2, 3]
                    dg, ig = cast_segments(o, u[b_c], _polygon_segments(poly_w)[:, None])
                    dg = dg * k3[b_c]
                    d_dyn, r_dyn = dg, np.where(np.isfinite(dg), gown_refl(ig, poly.shape[1]), 0.0)
                if people.count:
                    legs = people.legs_xy(t_beam)  # (n, 2P, 2)
                    dl, _ = cast_circles(o, u[b_c], legs[:, None], LEG_RADIUS_M)
                    dl = dl * k3[b_c]
                    closer = dl < d_dyn
                    d_dyn = np.where(closer, dl, d_dyn)
                    r_dyn = np.where(closer, LEG_REFLECTIVITY, r_dyn)
                cur = R[k_c, b_c]
                closer = d_dyn < cur
                R[k_c, b_c] = np.where(closer, d_dyn, cur)
                rho[k_c, b_c] = np.where(closer, r_dyn, rho[k_c, b_c])
        ranges = _sensor_model(R, rho, sc.range_sigma_m, sc.range_max_m, cfg, noise, ideal)
        # the driver stamps the scan at the start, middle or end of its sweep
        stamps = starts + offset + _stamp_offset(delays, sc.stamp_at)
        if not ideal:
            stamps = stamps + noise.normal(0.0, STAMP_JITTER_SIGMA_S, K)
        out[sc.name] = ScanLog(stamps, ranges.reshape(K, B))
        info.clock_offsets_s[sc.name] = offset
        info.n_scans[sc.name] = K
    return out, info


def write_fixed_scans(
    scene: Scene, motion: RobotMotion | None, intervals_s: np.ndarray, out_dir: str | os.PathLike[str],
    cfg: SimConfig, seed: int,
) -> ScanSimInfo:
    """Write ``out_dir/<scanner>.csv`` for every fixed scanner (see :func:`simulate_fixed_scans`)."""
    scans, info = simulate_fixed_scans(scene, motion, intervals_s, cfg, seed)
    for name, s in scans.items():
        write_scans(Path(out_dir) / f"{name}.csv", s)
    log.info("fixed scans: %s", info.n_scans)
    return info


# --------------------------------------------------------------------------------- onboard scanners
def simulate_onboard_scans(
    scene: Scene, motion: RobotMotion, intervals_s: np.ndarray, cfg: SimConfig, seed: int,
    ideal: bool = False,
) -> tuple[dict[str, ScanLog], ScanSimInfo]:
    """Scans of the robot's onboard scanners (``rig.robot.onboard_scanners``) inside the intervals.

    Each beam leaves from the scanner's pose at its own firing instant (``T_world_robot(t) @
    T_robot_scanner``, the robot tilted by the floor) and sees walls, clutter (below its top) and
    people. The gown does not block the onboard scanners (the seeds cut it to leave their view free).
    Parameters and returns as :func:`simulate_fixed_scans`; the range noise is
    ``ONBOARD_RANGE_SIGMA_M``.
    """
    iv = _check_intervals(intervals_s)
    people = sequence_people(scene, motion, iv, cfg)
    segs, z_top, seg_refl = static_segments(scene, surface_draw=cfg.laser.surface_draw)
    offsets = _subray_offsets(cfg.laser.mixed_pixels and not ideal)
    J = len(offsets)
    out: dict[str, ScanLog] = {}
    info = ScanSimInfo()
    for si, sc in enumerate(scene.rig_true.robot.onboard_scanners):
        rng = np.random.default_rng([seed, 100 + si])
        noise = noise_stream(rng, [seed, 100 + si], cfg.noise_draw_of("sensors"))
        T_rs = sc.T_robot_scanner.matrix()
        ang = sc.angles_rad
        B = len(ang)
        delays = _beam_delays(ang, sc.rate_hz)
        offset = 0.0 if ideal else float(rng.normal(0.0, cfg.laser.clock_offset_sigma_s))
        starts = _scan_starts(iv, sc.rate_hz, delays[-1], float(rng.uniform(0, 1 / sc.rate_hz)))
        K = len(starts)
        t_beam = (starts[:, None] + delays[None, :]).ravel()  # (K B,)
        b_all = np.tile(np.arange(B), K)

        def rays(idx: np.ndarray, offs: np.ndarray, t_beam: np.ndarray = t_beam, T_rs: np.ndarray = T_rs,
                 ang: np.ndarray = ang, b_all: np.ndarray = b_all) -> tuple[np.ndarray, ...]:
            T_ws = robot_poses(motion, t_beam[idx]) @ T_rs  # (n, 4, 4)
            return _rays_world(T_ws[:, None], ang[b_all[idx]][:, None] + offs[None, :])

        # static scene: centre rays first; the footprint's sub-rays only where the hit surface changes
        # between neighbouring beams (an edge can only lie in a footprint there)
        d_c = np.empty(K * B)
        i_c = np.empty(K * B, dtype=np.intp)
        step = max(1, _CHUNK_RAYS // max(1, len(segs)) * 4)
        for c0 in range(0, K * B, step):
            idx = np.arange(c0, min(K * B, c0 + step))
            o, u, z0, dz, k3 = rays(idx, np.zeros(1))
            d, i = cast_segments(o, u, segs, z0, dz, z_top)
            d_c[idx], i_c[idx] = (d * k3)[:, 0], i[:, 0]
        R = np.repeat(d_c[:, None], J, axis=1)
        rho = np.repeat(np.where(i_c >= 0, seg_refl[i_c], 0.0)[:, None], J, axis=1)
        if J > 1:
            ic = i_c.reshape(K, B)
            edge = np.zeros((K, B), dtype=bool)
            edge[:, 1:] |= ic[:, 1:] != ic[:, :-1]
            edge[:, :-1] |= ic[:, 1:] != ic[:, :-1]
            cand = np.flatnonzero(edge.ravel())
            step_c = max(1, step // J)
            for c0 in range(0, len(cand), step_c):
                idx = cand[c0:c0 + step_c]
                o, u, z0, dz, k3 = rays(idx, offsets)
                d, i = cast_segments(o, u, segs, z0, dz, z_top)
                R[idx] = d * k3
                rho[idx] = np.where(i >= 0, seg_refl[i], 0.0)
        if people.count:
            step_p = max(1, _CHUNK_RAYS // (J * 2 * people.count))
            for c0 in range(0, K * B, step_p):
                idx = np.arange(c0, min(K * B, c0 + step_p))
                o, u, _, _, k3 = rays(idx, offsets)
                dl, _ = cast_circles(o, u, people.legs_xy(t_beam[idx])[:, None], LEG_RADIUS_M)
                dl = dl * k3
                closer = dl < R[idx]
                R[idx] = np.where(closer, dl, R[idx])
                rho[idx] = np.where(closer, LEG_REFLECTIVITY, rho[idx])
        ranges = _sensor_model(R, rho, ONBOARD_RANGE_SIGMA_M, sc.range_max_m, cfg, noise, ideal)
        stamps = starts + offset
        if not ideal:
            stamps = stamps + noise.normal(0.0, STAMP_JITTER_SIGMA_S, K)
        out[sc.name] = ScanLog(stamps, ranges.reshape(K, B))
        info.clock_offsets_s[sc.name] = offset
        info.n_scans[sc.name] = K
    return out, info


def write_onboard_scans(
    scene: Scene, motion: RobotMotion, intervals_s: np.ndarray, out_dir: str | os.PathLike[str],
    cfg: SimConfig, seed: int,
) -> ScanSimInfo:
    """Write ``out_dir/<scanner>.csv`` for every onboard scanner (see :func:`simulate_onboard_scans`)."""
    scans, info = simulate_onboard_scans(scene, motion, intervals_s, cfg, seed)
    for name, s in scans.items():
        if cfg.odometry_clock_offset_s:  # onboard scanners share the robot's clock
            s = ScanLog(s.stamps_s + cfg.odometry_clock_offset_s, s.ranges_m)
        write_scans(Path(out_dir) / f"{name}.csv", s)
    log.info("onboard scans: %s", info.n_scans)
    return info
