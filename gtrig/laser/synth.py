"""Synthetic 2D scans for tests and the benchmark: rays cast against line segments.

This is a deliberately small ray caster (no mixed pixels, no reflectivity): the full laser simulator
lives in :mod:`gtrig.sim.lasers`. It exists so that the GTlaser steps can be tested on scenes whose
truth is exact and cheap to build.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from numpy.typing import ArrayLike

from gtrig import geometry as geo
from gtrig.rig.models import Hull, LaserScanner

Array = geo.Array


def rectangle_segments(corners_xy: ArrayLike) -> Array:
    """Closed polygon ``corners_xy`` (K, 2) as segments (K, 2, 2)."""
    c = np.asarray(corners_xy, dtype=float)
    return np.stack([c, np.roll(c, -1, axis=0)], axis=1)


def hull_segments_world(hull: Hull, xytheta: ArrayLike) -> Array:
    """The hull outline (4, 2, 2) in the world for the planar robot pose ``xytheta`` (x m, y m, theta rad)."""
    x, y, th = np.asarray(xytheta, dtype=float)
    c, s = np.cos(th), np.sin(th)
    corners = hull.corners_xy() @ np.array([[c, s], [-s, c]]) + [x, y]
    return rectangle_segments(corners)


def cast_rays(origin_xy: ArrayLike, dirs_xy: ArrayLike, segments: ArrayLike, range_max_m: float) -> Array:
    """Range (B,) along unit directions ``dirs_xy`` (B, 2) from ``origin_xy`` (2,) to the first of
    ``segments`` (S, 2, 2); ``nan`` where nothing is hit within ``range_max_m``."""
    o = np.asarray(origin_xy, dtype=float)
    d = np.asarray(dirs_xy, dtype=float)
    seg = np.asarray(segments, dtype=float)
    a = seg[:, 0]
    e = seg[:, 1] - seg[:, 0]  # (S, 2)
    # o + t d = a + u e  ->  [d, -e] [t, u]^T = a - o
    den = d[:, None, 0] * (-e[None, :, 1]) - d[:, None, 1] * (-e[None, :, 0])  # (B, S)
    ao = a - o  # (S, 2)
    with np.errstate(divide="ignore", invalid="ignore"):
        t = (ao[None, :, 0] * (-e[None, :, 1]) - ao[None, :, 1] * (-e[None, :, 0])) / den
        u = (d[:, None, 0] * ao[None, :, 1] - d[:, None, 1] * ao[None, :, 0]) / den
    ok = (np.abs(den) > 1e-12) & (t > 1e-9) & (u >= 0) & (u <= 1)
    t = np.where(ok, t, np.inf)
    r = t.min(axis=1)
    r[r > range_max_m] = np.nan
    return r


def scan(
    scanner: LaserScanner,
    segments: ArrayLike,
    rng: np.random.Generator | None = None,
    sigma_m: float | None = None,
    T_world_scanner: ArrayLike | None = None,
) -> Array:
    """One scan (B,) of ``scanner`` (its true pose ``T_world_scanner``, default the rig's) against
    world segments (S, 2, 2), with Gaussian range noise ``sigma_m`` (default the scanner's)."""
    T = (
        scanner.T_world_scanner.matrix()
        if T_world_scanner is None
        else np.asarray(T_world_scanner, dtype=float)
    )
    a = scanner.angles_rad
    dirs = np.column_stack([np.cos(a), np.sin(a), np.zeros_like(a)]) @ T[:3, :3].T
    dirs = dirs[:, :2] / np.linalg.norm(dirs[:, :2], axis=1, keepdims=True)
    r = cast_rays(T[:2, 3], dirs, segments, scanner.range_max_m)
    if rng is not None:
        s = scanner.range_sigma_m if sigma_m is None else sigma_m
        r = r + rng.normal(0.0, s, r.shape)
    return r


def person_segments(centre_xy: ArrayLike, radius_m: float = 0.12, n: int = 8) -> Array:
    """A person's legs at scanner height, as a small polygon (n, 2, 2) around ``centre_xy``."""
    ang = np.linspace(0, 2 * np.pi, n, endpoint=False)
    pts = np.asarray(centre_xy, dtype=float) + radius_m * np.column_stack([np.cos(ang), np.sin(ang)])
    return rectangle_segments(pts)


def room_segments(walls: ArrayLike, boxes: tuple = ()) -> Array:
    """Static segments (S, 2, 2): walls (4, 2, 2) and the outlines of ``boxes`` (objects with
    ``corners_xy()``)."""
    segs = [np.asarray(walls, dtype=float)]
    segs += [rectangle_segments(b.corners_xy()) for b in boxes]
    return np.concatenate(segs)


def scan_sequence(
    scanners: tuple[LaserScanner, ...],
    static_segments: ArrayLike,
    hull: Hull | None,
    planar_pose_at: object,
    stamps_s: list[np.ndarray],
    rng: np.random.Generator,
    person_at: object = None,
) -> list[np.ndarray]:
    """Scans (N_s, B) of every scanner at its stamps ``stamps_s[s]``.

    ``planar_pose_at(t) -> (3,)`` gives the robot's pose (or None: no robot); ``person_at(t) -> (2,)`` a
    person's position (or None).
    """
    out = []
    static = np.asarray(static_segments, dtype=float)
    for s, st in zip(scanners, stamps_s, strict=True):
        rows = []
        for t in st:
            segs = [static]
            if hull is not None and planar_pose_at is not None:
                pose = planar_pose_at(t)  # type: ignore[operator]
                if pose is not None:
                    segs.append(hull_segments_world(hull, pose))
            if person_at is not None:
                pp = person_at(t)  # type: ignore[operator]
                if pp is not None:
                    segs.append(person_segments(pp))
            rows.append(scan(s, np.concatenate(segs), rng))
        out.append(np.array(rows).reshape(len(st), s.beams))
    return out


def swept_scan_sequence(
    scanners: tuple[LaserScanner, ...],
    static_segments: ArrayLike,
    hull: Hull,
    planar_poses_at: Callable[[np.ndarray], np.ndarray],
    stamps_s: list[np.ndarray],
    rng: np.random.Generator,
) -> list[np.ndarray]:
    """Scans (N_s, B) of every scanner at its stamps ``stamps_s[s]``, each beam cast at the instant
    the device fires it (:meth:`LaserScanner.beam_delays_s`: a mirror sweep, or all at once), so that
    a fast robot moves during a scan as it does in front of a real scanner.

    ``planar_poses_at(t) -> (M, 3)`` gives the robot's poses at times ``t`` (M,).
    """
    out = []
    static = np.asarray(static_segments, dtype=float)
    corners_r = hull.corners_xy()
    for s, st in zip(scanners, stamps_s, strict=True):
        T = s.T_world_scanner.matrix()
        a = s.angles_rad
        dirs = np.column_stack([np.cos(a), np.sin(a), np.zeros_like(a)]) @ T[:3, :3].T
        dirs = dirs[:, :2] / np.linalg.norm(dirs[:, :2], axis=1, keepdims=True)
        r_static = cast_rays(T[:2, 3], dirs, static, np.inf)
        t_beam = np.asarray(st, dtype=float)[:, None] + s.beam_delays_s()[None, :]  # (N, B)
        poses = np.asarray(planar_poses_at(t_beam.ravel()), dtype=np.float64).reshape(*t_beam.shape, 3)
        c, sn = np.cos(poses[..., 2]), np.sin(poses[..., 2])
        # hull corners (N, B, 4, 2) at each beam's instant, then its sides against that beam only
        cw = np.stack([c[..., None] * corners_r[:, 0] - sn[..., None] * corners_r[:, 1],
                       sn[..., None] * corners_r[:, 0] + c[..., None] * corners_r[:, 1]], -1) + poses[..., None, :2]
        e = np.roll(cw, -1, axis=-2) - cw
        ao = cw - T[:2, 3]
        d = dirs[None, :, None, :]
        den = d[..., 0] * -e[..., 1] + d[..., 1] * e[..., 0]
        with np.errstate(divide="ignore", invalid="ignore"):
            tt = (ao[..., 0] * -e[..., 1] + ao[..., 1] * e[..., 0]) / den
            u = (d[..., 0] * ao[..., 1] - d[..., 1] * ao[..., 0]) / den
        hit = (np.abs(den) > 1e-12) & (tt > 1e-9) & (u >= 0) & (u <= 1)
        r_hull = np.where(hit, tt, np.inf).min(axis=-1)
        r = np.minimum(np.where(np.isfinite(r_static), r_static, np.inf)[None, :], r_hull)
        r = r + rng.normal(0.0, s.range_sigma_m, r.shape)
        r[~(r <= s.range_max_m)] = np.nan
        out.append(r)
    return out
