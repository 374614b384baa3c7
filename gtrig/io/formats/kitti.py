"""KITTI odometry poses: one line per pose, the 3 x 4 matrix ``[R | t]`` of ``T_world_body`` row-major
(12 numbers, space separated), with its stamps in a separate ``times`` file (one second count per
line, as KITTI's ``sequences/NN/times.txt``).

gtrig writes ``NAME.kitti`` (or ``NAME.txt``) and ``NAME_times.txt`` beside it. Precision kept: 13
significant digits for the matrix (``%.12e``: 1e-12 relative); stamps as the TUM writer prints them
(gtrig.stamps: 6 decimals when each is a whole microsecond, else 9: the digits they were read with). The reader
takes the times file given, else ``NAME_times.txt``, else ``times.txt`` in the same folder; without
any it numbers the poses 0, 1, 2, ... seconds and says so (KITTI poses alone carry no time).

The frame convention is the file's: KITTI's own ground truth is the left camera (z forward) in the
first camera pose; gtrig writes ``T_world_robot`` as it is (REP 103 axes, x forward).
"""

from __future__ import annotations

import logging
import os
from pathlib import Path

import numpy as np

from gtrig.errors import FormatError
from gtrig.io.atomic import atomic_group
from gtrig.io.formats._common import check_stamps, read_numeric, rotation_matrices
from gtrig.trajectory import PoseTrack

log = logging.getLogger(__name__)


def times_path_for(path: str | os.PathLike[str]) -> Path:
    p = Path(path)
    return p.with_name(f"{p.stem}_times.txt")


def read_kitti(path: str | os.PathLike[str], times_path: str | os.PathLike[str] | None = None) -> PoseTrack:
    """KITTI poses (and their times) as a pose track without covariance."""
    p, a, numbers, _ = read_numeric(path, (12,), None, "12 values (a 3x4 pose matrix, row-major)")
    T = np.tile(np.eye(4), (len(a), 1, 1))
    T[:, :3, :] = a.reshape(-1, 3, 4)
    rotation_matrices(p, T[:, :3, :3], numbers)
    # project onto SO(3): printed digits leave a 1e-9 skew that Rotation.from_matrix would absorb anyway
    u, _, vt = np.linalg.svd(T[:, :3, :3])
    T[:, :3, :3] = u @ vt
    candidates = [Path(times_path)] if times_path is not None else [times_path_for(p), p.with_name("times.txt")]
    for tp in candidates:
        if tp.is_file() or times_path is not None:
            tpp, t, tn, _ = read_numeric(tp, (1,), None, "one time stamp per line")
            stamps_ns = _exact_ns(tpp)
            if len(t) != len(a):
                if times_path is None and tp.name == "times.txt":
                    continue
                raise FormatError(f"{tpp}: {len(t)} stamps, but {p} has {len(a)} poses")
            stamps = t[:, 0]
            check_stamps(tpp, stamps, tn)
            break
    else:
        log.warning("%s: no times file beside it (%s): poses numbered 0, 1, 2, ... s", p, times_path_for(p).name)
        stamps = np.arange(len(a), dtype=float)
        stamps_ns = None
    return PoseTrack.from_matrices(stamps, T, source=p.stem, stamps_ns=stamps_ns)


def _exact_ns(p: Path) -> np.ndarray | None:
    """The times file's stamps as exact nanoseconds when it prints more digits than a float keeps."""
    from gtrig.io.formats._common import read_lines
    from gtrig.io.stamp_text import needs_text_stamps, text_stamps_ns

    lines = read_lines(p)[1]
    return text_stamps_ns(lines) if needs_text_stamps(lines) else None


def kitti_text(track: PoseTrack) -> tuple[str, str]:
    """(poses text, times text)."""
    M = track.matrices()[:, :3, :].reshape(-1, 12)
    poses = "".join(" ".join(f"{v:.12e}" for v in row) + "\n" for row in M)
    from gtrig.io.tum import stamp_texts

    times = "".join(f"{t}\n" for t in stamp_texts(track))
    return poses, times


def write_kitti(track: PoseTrack, path: str | os.PathLike[str]) -> list[Path]:
    """Write ``path`` and ``NAME_times.txt`` together (all or none); returns both paths."""
    poses, times = kitti_text(track)
    out = [Path(path), times_path_for(path)]
    with atomic_group(*out) as tmps:
        tmps[0].write_text(poses, encoding="utf-8", newline="\n")
        tmps[1].write_text(times, encoding="utf-8", newline="\n")
    return out
