"""CARMEN logs (the Radish / Freiburg ``*-corrected.log[.gz]`` files): odometry and 2-D laser scans.

Lines read (old CARMEN format, space separated, ``#`` comments)::

    ODOM x y theta tv rv accel ipc_timestamp ipc_hostname logger_timestamp
    FLASER n r_1 ... r_n x y theta odom_x odom_y odom_theta ipc_timestamp ipc_hostname logger_timestamp

``PARAM``, ``NEFF``, ``SYNC`` and other messages are counted and skipped.

Two properties of the "corrected" logs matter to anyone using their odometry: after each scan the
logger writes an ``ODOM`` record re-anchored on the scan's corrected pose, stamped 0 (so the next
odometry increment starts from the corrected pose, not from the previous raw one), and ``tv`` / ``rv``
are often zero. :meth:`CarmenLog.rebuilt_odometry` therefore rebuilds a continuous dead-reckoned
odometry from the pose increments between consecutive records, never across a re-anchoring. Some logs
(intel) hold ODOM stamps out of order by up to a few hundred milliseconds while the poses are in
order: such samples still chain the poses but are not emitted, and are counted.
"""

from __future__ import annotations

import gzip
import math
import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from gtrig.errors import FormatError


@dataclass(frozen=True)
class CarmenLog:
    """What a CARMEN log holds.

    Attributes
    ----------
    odom_stamps_s : (K,) stamps of the ODOM records with a stamp (re-anchorings excluded), file order.
    odom_xytheta : (K, 3) their poses (m, m, rad) in the log's odometry frame.
    odom_tv_rv : (K, 2) their forward speed (m/s) and turn rate (rad/s) as logged (often zero).
    odom_anchored : (K,) bool, True where the record's increment starts from a re-anchored pose.
    laser_stamps_s : (M,) scan stamps.
    laser_ranges : (M, n) ranges in metres (n beams, the same for every scan).
    laser_xytheta : (M, 3) the scans' corrected poses (the logs' scan-matching result).
    laser_odom_xytheta : (M, 3) the scans' odometry poses as logged.
    counts : records per kind: ``odom``, ``flaser``, ``reanchor``, ``odom_backwards``, ``skipped``.
    """

    odom_stamps_s: np.ndarray
    odom_xytheta: np.ndarray
    odom_tv_rv: np.ndarray
    odom_anchored: np.ndarray
    laser_stamps_s: np.ndarray
    laser_ranges: np.ndarray
    laser_xytheta: np.ndarray
    laser_odom_xytheta: np.ndarray
    counts: dict[str, int] = field(default_factory=dict)
    # the pose each odometry increment starts from (the previous record, or the re-anchoring)
    _prev_xytheta: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)), repr=False)

    def rebuilt_odometry(self) -> tuple[np.ndarray, np.ndarray]:
        """A continuous dead-reckoned odometry ``(stamps_s (L,), xytheta (L, 3))``, starting at the first
        record's pose, composed from the increment of each record relative to the pose it started from
        (the re-anchorings removed). Every record chains the poses; the samples emitted are the largest
        set whose stamps increase in file order (the others' stamps are out of order: chained, not emitted)."""
        if not len(self.odom_stamps_s):
            return np.zeros(0), np.zeros((0, 3))
        a, b = self._prev_xytheta, self.odom_xytheta
        c, s = np.cos(a[:, 2]), np.sin(a[:, 2])
        dx, dy = b[:, 0] - a[:, 0], b[:, 1] - a[:, 1]
        # increments in the frame of the pose they start from
        inc = np.column_stack([c * dx + s * dy, -s * dx + c * dy, np.angle(np.exp(1j * (b[:, 2] - a[:, 2])))])
        inc[0] = 0.0
        out = np.empty_like(b)
        x, y, th = b[0]
        for i in range(len(b)):  # a running composition: sequential by nature, 10^4 records
            ci, si = math.cos(th), math.sin(th)
            x, y, th = x + ci * inc[i, 0] - si * inc[i, 1], y + si * inc[i, 0] + ci * inc[i, 1], th + inc[i, 2]
            out[i] = x, y, th
        keep = _increasing_subsequence(self.odom_stamps_s)
        out[:, 2] = np.angle(np.exp(1j * out[:, 2]))
        return self.odom_stamps_s[keep], out[keep]


def _increasing_subsequence(t: np.ndarray) -> np.ndarray:
    """(N,) bool: a longest strictly increasing subsequence of ``t`` (patience sorting, O(N log N))."""
    import bisect

    tails: list[float] = []
    tail_idx: list[int] = []
    parent = np.full(len(t), -1)
    for i, v in enumerate(t):
        k = bisect.bisect_left(tails, v)
        if k == len(tails):
            tails.append(v)
            tail_idx.append(i)
        else:
            tails[k], tail_idx[k] = v, i
        parent[i] = tail_idx[k - 1] if k else -1
    keep = np.zeros(len(t), bool)
    i = tail_idx[-1] if tail_idx else -1
    while i >= 0:
        keep[i] = True
        i = parent[i]
    return keep


def _lines(p: Path) -> list[str]:
    try:
        raw = gzip.decompress(p.read_bytes()) if p.suffix == ".gz" else p.read_bytes()
    except FileNotFoundError:
        raise FormatError(f"{p}: no such file") from None
    except (OSError, EOFError) as e:
        raise FormatError(f"{p}: not a readable gzip file ({e})") from None
    try:
        return raw.decode("ascii").splitlines()
    except UnicodeDecodeError:
        raise FormatError(f"{p}: not a text CARMEN log") from None


def _nums(p: Path, i: int, cells: list[str]) -> list[float]:
    try:
        v = [float(c) for c in cells]
    except ValueError:
        raise FormatError(f"{p}:{i}: not a number in {' '.join(cells)[:60]!r}") from None
    if not all(math.isfinite(x) for x in v):
        raise FormatError(f"{p}:{i}: non-finite value")
    return v


def read_carmen(path: str | os.PathLike[str]) -> CarmenLog:
    """Read a CARMEN log (plain or ``.gz``); malformed ODOM / FLASER lines are errors naming the line."""
    p = Path(path)
    odom: list[list[float]] = []
    prev: list[list[float]] = []
    scans: list[list[float]] = []
    laser: list[list[float]] = []
    counts = {"odom": 0, "flaser": 0, "reanchor": 0, "odom_backwards": 0, "skipped": 0}
    last_pose: list[float] | None = None
    after_scan = False
    n_beams: int | None = None
    last_t = -math.inf
    for i, line in enumerate(_lines(p), 1):
        f = line.split()
        if not f or f[0].startswith("#"):
            continue
        if f[0] == "ODOM":
            if len(f) != 10:
                raise FormatError(f"{p}:{i}: ODOM has {len(f) - 1} fields, expected 9")
            v = _nums(p, i, f[1:8])
            if after_scan and v[6] == 0.0:
                # the logger's re-anchoring on the corrected pose: where the next increment starts
                counts["reanchor"] += 1
                last_pose, after_scan = v[:3], False
                continue
            counts["odom"] += 1
            if v[6] <= last_t:
                counts["odom_backwards"] += 1
            last_t = max(last_t, v[6])
            prev.append(last_pose if last_pose is not None else v[:3])
            odom.append(v)
            last_pose = v[:3]
        elif f[0] == "FLASER":
            try:
                n = int(f[1])
            except (IndexError, ValueError):
                raise FormatError(f"{p}:{i}: FLASER without a beam count") from None
            if len(f) != n + 11:
                raise FormatError(f"{p}:{i}: FLASER with {n} beams has {len(f) - 1} fields, expected {n + 10}")
            if n_beams is None:
                n_beams = n
            elif n != n_beams:
                raise FormatError(f"{p}:{i}: FLASER has {n} beams, earlier scans {n_beams}")
            v = _nums(p, i, f[2:n + 8] + [f[n + 8]])
            counts["flaser"] += 1
            scans.append(v[:n])
            laser.append(v[n:])
            after_scan = True
        else:
            counts["skipped"] += 1
    if not odom and not laser:
        raise FormatError(f"{p}: no ODOM or FLASER record")
    o = np.array(odom, float).reshape(-1, 7)
    la = np.array(laser, float).reshape(-1, 7)
    return CarmenLog(
        odom_stamps_s=o[:, 6], odom_xytheta=o[:, :3], odom_tv_rv=o[:, 3:5],
        odom_anchored=np.array([False] + [not np.array_equal(a, b[:3]) for a, b in zip(prev[1:], odom[:-1],
                                                                                      strict=True)], bool)
        if odom else np.zeros(0, bool),
        laser_stamps_s=la[:, 6], laser_ranges=np.array(scans, float).reshape(len(la), n_beams or 0),
        laser_xytheta=la[:, :3], laser_odom_xytheta=la[:, 3:6], counts=counts,
        _prev_xytheta=np.array(prev, float).reshape(-1, 3),
    )
