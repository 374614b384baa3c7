"""``sensor_msgs/LaserScan`` messages decoded in bulk.

rosbags deserializes one message at a time in Python (about 20 us a scan); a scanner's messages all
share one layout, so after rosbags has decoded the first message of each message size, the others of
that size are read as NumPy views at the offsets that first message fixed: header stamp, the seven
geometry floats, the beam count and the ranges. Every message is checked to have the same frame_id
length and beam and intensity counts as that first one (a message that differs is decoded by
rosbags), so the fast path never guesses. ROS 1 and little-endian CDR (ROS 2); a big-endian CDR
message goes through rosbags.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

#: LaserScan's seven float32 after the header, in order
GEOMETRY = ("angle_min", "angle_max", "angle_increment", "time_increment", "scan_time", "range_min", "range_max")


@dataclass(frozen=True)
class ScanBatch:
    """Decoded scans of one topic: ``stamps_s`` (K,) header stamps, ``geometry`` (K, 7) float32 as
    :data:`GEOMETRY`, ``beams`` (K,) each message's beam count, ``ranges`` (K, max beams) float32 as
    published (``nan`` past a shorter message's beams)."""

    stamps_s: np.ndarray
    geometry: np.ndarray
    beams: np.ndarray
    ranges: np.ndarray


def _layout(raw: bytes, msg: Any) -> tuple[int, int, int] | None:
    """``(offset of the ranges, beams, intensities)`` in ``raw`` found from rosbags' decoding ``msg``."""
    n, m = len(msg.ranges), len(msg.intensities)
    want = np.asarray(msg.ranges, dtype="<f4").tobytes()
    for pad in range(8):
        off = len(raw) - 4 * m - 4 - 4 * n - pad
        if off >= 32 and raw[off:off + 4 * n] == want and int.from_bytes(raw[off - 4:off], "little") == n:
            return off, n, m
    return None


def decode_scans(raws: Sequence[bytes], ros2: bool, deserialize: Callable[[bytes], Any]) -> ScanBatch:
    """Decode ``raws`` (one topic's LaserScan messages, in bag order).

    Parameters
    ----------
    raws : the serialized messages.
    ros2 : CDR (ROS 2) rather than ROS 1 serialization.
    deserialize : rosbags' decoder for one message (used for the first of each size and the odd ones).
    """
    k = len(raws)
    if not k:
        return ScanBatch(np.zeros(0), np.zeros((0, 7), np.float32), np.zeros(0, np.int64),
                         np.zeros((0, 0), np.float32))
    lengths = np.fromiter((len(r) for r in raws), dtype=np.int64, count=k)
    stamps = np.empty(k)
    geometry = np.empty((k, 7), np.float32)
    blocks: list[tuple[np.ndarray, np.ndarray]] = []  # (message indices, their (m, beams) ranges)
    slow: list[int] = []
    for L in np.unique(lengths):
        idx = np.flatnonzero(lengths == L)
        first = raws[int(idx[0])]
        msg = deserialize(first)
        lay = None if (ros2 and first[1] != 1) else _layout(first, msg)
        if lay is None:
            slow.extend(int(i) for i in idx)
            continue
        off, n, m = lay
        A = np.frombuffer(b"".join(raws[int(i)] for i in idx), dtype=np.uint8).reshape(len(idx), int(L))
        same = np.all(A[:, 12:16] == A[0, 12:16], axis=1)  # frame_id length
        same &= np.all(A[:, off - 4:off] == A[0, off - 4:off], axis=1)  # beam count
        same &= np.all(A[:, off + 4 * n:off + 4 * n + 4] == A[0, off + 4 * n:off + 4 * n + 4], axis=1)
        if ros2:
            same &= A[:, 1] == 1  # little-endian CDR
        good = idx[same]
        G = A[same]
        sec = G[:, 4:8].copy().view("<i4").reshape(-1).astype(np.int64)
        nsec = G[:, 8:12].copy().view("<u4").reshape(-1).astype(np.int64)
        stamps[good] = sec + nsec * 1e-9
        geometry[good] = G[:, off - 32:off - 4].copy().view("<f4").reshape(-1, 7)
        blocks.append((good, G[:, off:off + 4 * n].copy().view("<f4").reshape(-1, n)))
        slow.extend(int(i) for i in idx[~same])
    for i in slow:
        msg = deserialize(raws[i])
        stamps[i] = msg.header.stamp.sec + msg.header.stamp.nanosec * 1e-9
        geometry[i] = [getattr(msg, g) for g in GEOMETRY]
        blocks.append((np.array([i]), np.asarray(msg.ranges, dtype=np.float32)[None, :]))
    beams = np.empty(k, np.int64)
    for idx, R in blocks:
        beams[idx] = R.shape[1]
    if len(blocks) == 1:
        return ScanBatch(stamps, geometry, beams, blocks[0][1])  # one layout, in bag order: no copy
    out = np.full((k, int(beams.max())), np.nan, np.float32)
    for idx, R in blocks:
        out[idx, :R.shape[1]] = R
    return ScanBatch(stamps, geometry, beams, out)
