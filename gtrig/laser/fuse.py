"""Scans of all scanners to foreground points in the world frame, grouped into time frames.

Every scanner is free running at its own phase. A *frame* is one period of the reference scanner (the
one with the most scans); each scan of the other scanners joins the frame whose reference stamp is
nearest, and every point keeps its own time offset ``dt_s`` so that the tracker can compensate the
robot's motion within the frame. The whole recording is converted in one vectorised pass; the tracker
then walks the frames through ``frame_start``.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace
from typing import Protocol

import numpy as np

from gtrig.errors import InputError
from gtrig.rig.models import LaserScanner


@dataclass(frozen=True)
class FramedPoints:
    """Foreground points of a whole sequence, in the world frame, sorted by frame.

    Attributes
    ----------
    frame_stamps_s : (F,) time of each frame (a reference-scanner stamp), seconds.
    frame_start : (F + 1,) points of frame ``k`` are ``[frame_start[k], frame_start[k + 1])``.
    xy_world : (P, 2) foreground points, world frame, metres.
    scanner_index : (P,) index of the scanner (into ``scanner_xy_world``) that saw each point.
    dir_world : (P, 2) unit beam direction of each point in the world x-y plane.
    dt_s : (P,) firing time of the point's beam minus the frame stamp, seconds.
    scanner_xy_world : (S, 2) scanner origins in the world, metres.
    sigma_m : (S,) range noise of each scanner, metres.
    scanner_names : (S,) names.
    scan_of_frame : (S, F) index of each scanner's scan in frame ``k`` (-1 when none).
    ranges_m : per scanner, (N_s, B_s) all ranges, metres (for the free-space test of the global search).
    masks : per scanner, (N_s, B_s) foreground masks.
    beam_dirs : per scanner, (B_s, 2) unit beam directions in the world.
    stamp_sigma_s : (S,) standard deviation of each scanner's clock offset, seconds (None: exact).
    """

    frame_stamps_s: np.ndarray
    frame_start: np.ndarray
    xy_world: np.ndarray
    scanner_index: np.ndarray
    dir_world: np.ndarray
    dt_s: np.ndarray
    scanner_xy_world: np.ndarray
    sigma_m: np.ndarray
    scanner_names: tuple[str, ...]
    scan_of_frame: np.ndarray
    ranges_m: tuple[np.ndarray, ...]
    masks: tuple[np.ndarray, ...]
    beam_dirs: tuple[np.ndarray, ...]
    stamp_sigma_s: np.ndarray | None = None

    @property
    def n_frames(self) -> int:
        return int(self.frame_stamps_s.size)

    def frame(self, k: int) -> slice:
        return slice(int(self.frame_start[k]), int(self.frame_start[k + 1]))

    def window(self, a: int, b: int, scans: bool = True) -> FramedPoints:
        """Frames ``[a, b)`` (frame indices from 0 at ``a``): views of their points and, with ``scans``,
        of the raw scans (the global search's free-space test reads them), as :class:`FrameSource`."""
        p0, p1 = int(self.frame_start[a]), int(self.frame_start[b])
        raw = {} if scans else {"ranges_m": (), "masks": (), "beam_dirs": ()}
        return replace(self, frame_stamps_s=self.frame_stamps_s[a:b], frame_start=self.frame_start[a:b + 1] - p0,
                       xy_world=self.xy_world[p0:p1], scanner_index=self.scanner_index[p0:p1],
                       dir_world=self.dir_world[p0:p1], dt_s=self.dt_s[p0:p1],
                       scan_of_frame=self.scan_of_frame[:, a:b], **raw)  # type: ignore[arg-type]

    def part(self, a: int, b: int) -> FramedPoints:
        """Frames ``[a, b)`` to send to a worker: their points, without the raw scans."""
        return self.window(a, b, scans=False)

    def free_rays(self, k: int, range_max_m: float = 30.0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Beams of frame ``k`` that are not foreground: origins (R, 2), unit directions (R, 2) and the
        range (R,) up to which each saw free space (``range_max_m`` where there was no return)."""
        o, d, r = [], [], []
        for s, idx in enumerate(self.scan_of_frame[:, k]):
            if idx < 0:
                continue
            keep = ~self.masks[s][idx]
            rr = self.ranges_m[s][idx][keep]
            o.append(np.broadcast_to(self.scanner_xy_world[s], (rr.size, 2)))
            d.append(self.beam_dirs[s][keep])
            r.append(np.where(np.isfinite(rr), rr, range_max_m))
        if not o:
            return np.zeros((0, 2)), np.zeros((0, 2)), np.zeros(0)
        return np.concatenate(o), np.concatenate(d), np.concatenate(r)


class FrameSource(Protocol):
    """The frames of a sequence, read a time window at a time: :class:`FramedPoints` (all in memory)
    or :class:`gtrig.laser.recording.LoggedFrames` (from the scan logs on disk)."""

    @property
    def frame_stamps_s(self) -> np.ndarray: ...  # (F,) seconds

    @property
    def scanner_xy_world(self) -> np.ndarray: ...  # (S, 2) world frame, metres

    @property
    def sigma_m(self) -> np.ndarray: ...  # (S,) range noise, metres

    @property
    def stamp_sigma_s(self) -> np.ndarray | None: ...  # (S,) clock offsets' standard deviation, seconds

    @property
    def n_frames(self) -> int: ...

    def window(self, a: int, b: int, scans: bool = True) -> FramedPoints:
        """Frames ``[a, b)`` as :class:`FramedPoints`, frame indices from 0 at ``a`` (with the raw scans
        of those frames when ``scans``)."""
        ...

    def part(self, a: int, b: int) -> FrameSource:
        """Frames ``[a, b)`` as a small picklable source (what a worker is sent; its frames from 0)."""
        ...


def beam_dirs_world(scanner: LaserScanner, T_world_scanner: np.ndarray | None = None) -> np.ndarray:
    """Beam directions (B, 2) of ``scanner`` in the world x-y plane (unnormalised if the scanner is
    tilted)."""
    T = scanner.T_world_scanner.matrix() if T_world_scanner is None else T_world_scanner
    a = scanner.angles_rad
    d = np.column_stack([np.cos(a), np.sin(a), np.zeros_like(a)]) @ T[:3, :3].T
    return d[:, :2]


def scan_points_world(
    ranges_m: np.ndarray, scanner: LaserScanner, T_world_scanner: np.ndarray | None = None
) -> np.ndarray:
    """All returns of scans ``ranges_m`` (N, B) as world x-y points (N, B, 2); ``nan`` where no return."""
    T = scanner.T_world_scanner.matrix() if T_world_scanner is None else T_world_scanner
    d = beam_dirs_world(scanner, T)
    return T[:2, 3] + np.asarray(ranges_m, dtype=float)[..., None] * d


def beam_delays_s(scanner: LaserScanner) -> np.ndarray:
    """Firing time (B,) of each beam after the scan's stamp, seconds, as the rig says the device fires
    them (:meth:`gtrig.rig.models.LaserScanner.beam_delays_s`): a mirror sweep (SICK LMS, Hokuyo URG:
    beam ``i`` fires when the mirror points at its angle) or all at once, stamped at the start, middle
    or end of the sweep."""
    return scanner.beam_delays_s()


def check_stamps(stamps_s: np.ndarray, what: str) -> None:
    """Raise :class:`InputError` (one line) unless ``stamps_s`` strictly increase."""
    st = np.asarray(stamps_s, dtype=float)
    bad = np.flatnonzero(~(np.diff(st) > 0))
    if bad.size:
        i = int(bad[0]) + 1
        raise InputError(
            f"{what}: time stamps do not increase at scan {i + 1} ({st[i - 1]:.6f} then {st[i]:.6f} s)"
        )


@dataclass(frozen=True)
class FrameLayout:
    """Which scan of each scanner joins which frame, without the scans' ranges: what cutting a sequence
    into time windows of frames needs (:func:`frame_layout`; 17 bytes per scan).

    Attributes
    ----------
    frame_stamps_s : (F,) time of each frame (a reference-scanner stamp), seconds.
    stamps_s : per scanner, (N_s,) its scan stamps, seconds (the frames' clock).
    nearest : per scanner, (N_s,) the frame nearest each scan (non-decreasing).
    joins : per scanner, (N_s,) whether the scan joins that frame (within half a reference period).
    """

    frame_stamps_s: np.ndarray
    stamps_s: tuple[np.ndarray, ...]
    nearest: tuple[np.ndarray, ...]
    joins: tuple[np.ndarray, ...]

    @property
    def n_frames(self) -> int:
        return int(self.frame_stamps_s.size)

    def scans(self, s: int, a: int, b: int) -> tuple[int, int]:
        """The scans ``[lo, hi)`` of scanner ``s`` nearest the frames ``[a, b)`` (those that join them
        and the scans between them that join none)."""
        j = self.nearest[s]
        return int(np.searchsorted(j, a, "left")), int(np.searchsorted(j, b, "left"))

    def part(self, a: int, b: int) -> FrameLayout:
        """Frames ``[a, b)`` and the scans :meth:`scans` gives for them (frame indices from 0 at ``a``)."""
        lohi = [self.scans(i, a, b) for i in range(len(self.nearest))]
        def cut(arrays: tuple[np.ndarray, ...], minus: int = 0) -> tuple[np.ndarray, ...]:
            return tuple(x[lo:hi] - minus if minus else x[lo:hi] for x, (lo, hi) in zip(arrays, lohi, strict=True))

        return FrameLayout(self.frame_stamps_s[a:b], cut(self.stamps_s), cut(self.nearest, a), cut(self.joins))


def frame_layout(scanners: Sequence[LaserScanner], stamps_s: Sequence[np.ndarray]) -> FrameLayout:
    """The frames of a sequence and the frame each scan joins (the grouping of :func:`frame_points`).

    Parameters
    ----------
    scanners
        The scanners (their rates and beam timing).
    stamps_s
        Per scanner, (N_s,) strictly increasing scan stamps, seconds (one clock).
    """
    if not scanners:
        raise InputError("no laser scanners in the rig")
    for s, st in zip(scanners, stamps_s, strict=True):
        check_stamps(st, f"scanner {s.name}")
    ref = int(np.argmax([len(st) for st in stamps_s]))
    ref_st = np.asarray(stamps_s[ref], dtype=float)
    if ref_st.size == 0:
        raise InputError("no scans in the sequence")
    half = 0.5 / scanners[ref].rate_hz
    ref_delays = beam_delays_s(scanners[ref])
    ref_mid = 0.5 * (ref_delays[0] + ref_delays[-1])
    nearest, joins = [], []
    for s, st in zip(scanners, stamps_s, strict=True):
        st = np.asarray(st, dtype=float)
        # a scan joins the frame whose reference sweep is nearest in the middle of the sweeps: scanners
        # whose stamps refer to different instants of the sweep (start, end) still pair up right
        delays = beam_delays_s(s)
        mid = st + 0.5 * (delays[0] + delays[-1]) - ref_mid
        if len(ref_st) == 1:
            j = np.zeros(len(st), dtype=np.intp)
        else:
            j = np.clip(np.searchsorted(ref_st, mid), 1, len(ref_st) - 1)
            j = np.where(np.abs(ref_st[j - 1] - mid) <= np.abs(ref_st[j] - mid), j - 1, j)
        nearest.append(j)
        joins.append(np.abs(mid - ref_st[j]) <= half * 1.0001)
    return FrameLayout(ref_st.copy(), tuple(np.asarray(st, dtype=float) for st in stamps_s), tuple(nearest),
                       tuple(joins))


def window_points(
    scanners: Sequence[LaserScanner],
    layout: FrameLayout,
    a: int,
    b: int,
    ranges_m: Sequence[np.ndarray],
    masks: Sequence[np.ndarray],
) -> FramedPoints:
    """The frames ``[a, b)`` of ``layout`` as :class:`FramedPoints` (frame indices from 0 at ``a``).

    Parameters
    ----------
    scanners
        The scanners of ``layout``, with their (calibrated) ``T_world_scanner``.
    layout
        :func:`frame_layout` of the sequence.
    a, b
        The window's frames.
    ranges_m, masks
        Per scanner, (hi - lo, B_s) the ranges (metres) and foreground masks of its scans ``[lo, hi)`` =
        ``layout.scans(s, a, b)``.

    Each point's values and the points' order are those of :func:`frame_points` over the whole sequence
    (every value is computed point by point), so windows give the same bits as one pass.
    """
    ref_st = layout.frame_stamps_s
    xy, sid, dirs, dts, fidx = [], [], [], [], []
    origins, all_dirs = [], []
    scan_of_frame = np.full((len(scanners), b - a), -1, dtype=np.intp)
    for i, (s, r, m) in enumerate(zip(scanners, ranges_m, masks, strict=True)):
        T = s.T_world_scanner.matrix()
        origins.append(T[:2, 3].copy())
        dd = beam_dirs_world(s, T)
        all_dirs.append(dd / np.linalg.norm(dd, axis=1, keepdims=True))
        lo, hi = layout.scans(i, a, b)
        if hi <= lo:
            continue
        j, keep_scan = layout.nearest[i][lo:hi], layout.joins[i][lo:hi]
        delays = beam_delays_s(s)
        dt = layout.stamps_s[i][lo:hi] - ref_st[j]
        scan_of_frame[i, j[keep_scan] - a] = np.flatnonzero(keep_scan)
        mm = m & keep_scan[:, None]
        n_idx, b_idx = np.nonzero(mm)
        d = beam_dirs_world(s, T)
        rr = r[n_idx, b_idx]
        xy.append(T[:2, 3] + rr[:, None] * d[b_idx])
        dn = d[b_idx]
        dirs.append(dn / np.linalg.norm(dn, axis=1, keepdims=True))
        sid.append(np.full(n_idx.size, i, dtype=np.int32))
        dts.append(dt[n_idx] + delays[b_idx])
        fidx.append(j[n_idx] - a)
    if xy:
        fi = np.concatenate(fidx)
        order = np.argsort(fi, kind="stable")
        xy_a = np.concatenate(xy)[order]
        sid_a = np.concatenate(sid)[order]
        dir_a = np.concatenate(dirs)[order]
        dt_a = np.concatenate(dts)[order]
        fi = fi[order]
    else:
        fi = np.zeros(0, dtype=int)
        xy_a, dir_a = np.zeros((0, 2)), np.zeros((0, 2))
        sid_a, dt_a = np.zeros(0, dtype=np.int32), np.zeros(0)
    start = np.searchsorted(fi, np.arange(b - a + 1))
    return FramedPoints(
        frame_stamps_s=ref_st[a:b].copy(),
        frame_start=start,
        xy_world=np.ascontiguousarray(xy_a),
        scanner_index=sid_a,
        dir_world=np.ascontiguousarray(dir_a),
        dt_s=dt_a,
        scanner_xy_world=np.array(origins),
        sigma_m=np.array([s.range_sigma_m for s in scanners]),
        scanner_names=tuple(s.name for s in scanners),
        scan_of_frame=scan_of_frame,
        ranges_m=tuple(np.asarray(r, dtype=float) for r in ranges_m),
        masks=tuple(masks),
        beam_dirs=tuple(all_dirs),
        stamp_sigma_s=np.array([s.stamp_sigma_s for s in scanners]),
    )


def frame_points(
    scanners: Sequence[LaserScanner],
    stamps_s: Sequence[np.ndarray],
    ranges_m: Sequence[np.ndarray],
    masks: Sequence[np.ndarray],
) -> FramedPoints:
    """Group the foreground returns of every scanner into frames, in the world frame.

    Parameters
    ----------
    scanners
        The scanners, with their (calibrated) ``T_world_scanner``.
    stamps_s
        Per scanner, (N_s,) strictly increasing scan stamps, seconds (one clock).
    ranges_m
        Per scanner, (N_s, B_s) ranges, metres.
    masks
        Per scanner, (N_s, B_s) foreground mask (:func:`gtrig.laser.foreground.foreground_mask`).
    """
    if not scanners:
        raise InputError("no laser scanners in the rig")
    for s, r in zip(scanners, ranges_m, strict=True):
        if r.shape[1] != s.beams:
            raise InputError(f"scanner {s.name}: scans have {r.shape[1]} beams, the rig says {s.beams}")
    layout = frame_layout(scanners, stamps_s)
    F = layout.n_frames
    lohi = [layout.scans(i, 0, F) for i in range(len(scanners))]
    return window_points(scanners, layout, 0, F, [r[lo:hi] for r, (lo, hi) in zip(ranges_m, lohi, strict=True)],
                         [m[lo:hi] for m, (lo, hi) in zip(masks, lohi, strict=True)])
