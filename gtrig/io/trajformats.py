"""Read a trajectory in any of the formats SLAM results come in, as a :class:`~gtrig.trajectory.PoseTrack`.

The format is taken from ``fmt`` or the extension, never guessed from the numbers; a file whose lines do
not fit it is an error naming the file and line:

- ``tum`` (``.tum``, ``.txt``): ``t x y z qx qy qz qw``; a gtrig covariance CSV beside it
  (``NAME_cov.csv``, docs/formats.md) is read with it (the file is named in the log);
- ``kitti`` (``.kitti``): 12 values per line, the 3 x 4 ``[R | t]`` row-major; KITTI poses carry no stamps,
  so ``times.txt`` (one stamp per line, KITTI odometry's) beside it or ``kitti_times`` is required;
- ``euroc`` (``.csv`` whose header is EuRoC's ``#timestamp [ns],p_RS_R_x ...``): nanoseconds, ``qw`` first;
- ``rawseeds`` (``.csv`` without a header): ``t,x,y,theta`` and optionally the 3 x 3 covariance of
  ``(x, y, theta)`` row by row (the RAWSEEDS GROUNDTRUTH files).

Interim reader of the evaluation branch (h20) until the io branch's readers (h22) land; then this module
goes and the CLI uses theirs.
"""

from __future__ import annotations

import logging
import os
from pathlib import Path

import numpy as np

from gtrig.errors import FormatError
from gtrig.trajectory import PoseTrack

log = logging.getLogger(__name__)

FORMATS: tuple[str, ...] = ("tum", "kitti", "euroc", "rawseeds")
_EXT = {".tum": "tum", ".txt": "tum", ".kitti": "kitti", ".csv": "csv"}


def _numbers(p: Path, delimiter: str | None, ncols: tuple[int, ...], what: str) -> np.ndarray:
    try:
        text = p.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise FormatError(f"{p}: no such file") from None
    except UnicodeDecodeError:
        raise FormatError(f"{p}: not a text file") from None
    lines = [(i, s.strip()) for i, s in enumerate(text.splitlines(), 1)]
    lines = [(i, s) for i, s in lines if s and not s.startswith("#")]
    if not lines:
        raise FormatError(f"{p}: no poses")
    first_n = len(lines[0][1].split(delimiter)) if delimiter else len(lines[0][1].split())
    if first_n not in ncols:
        raise FormatError(f"{p}:{lines[0][0]}: {first_n} values, a {what} line has {' or '.join(map(str, ncols))}")
    try:
        a = np.loadtxt([s for _, s in lines], delimiter=delimiter, ndmin=2)
    except ValueError:
        for i, s in lines:
            parts = s.split(delimiter) if delimiter else s.split()
            try:
                vals = [float(x) for x in parts]
            except ValueError:
                raise FormatError(f"{p}:{i}: not a number in {s!r}") from None
            if len(vals) != first_n:
                raise FormatError(f"{p}:{i}: {len(vals)} values, the first line has {first_n}") from None
        raise FormatError(f"{p}: unreadable {what} file") from None
    if not np.all(np.isfinite(a)):
        row = int(np.argmax(~np.all(np.isfinite(a), axis=1)))
        raise FormatError(f"{p}:{lines[row][0]}: a non-finite value")
    return a


def _increasing(p: Path, t: np.ndarray) -> None:
    bad = np.nonzero(np.diff(t) <= 0)[0]
    if bad.size:
        raise FormatError(f"{p}: time stamps do not increase at pose {int(bad[0]) + 2}")


def _unit_quat(p: Path, q: np.ndarray) -> np.ndarray:
    n = np.linalg.norm(q, axis=1)
    bad = np.abs(n - 1) > 1e-3
    if np.any(bad):
        raise FormatError(f"{p}: quaternion of pose {int(np.argmax(bad)) + 1} is not unit (norm {n[bad][0]:.4f})")
    q = q / n[:, None]
    q[q[:, 3] < 0] *= -1
    return q


def _is_euroc_header(p: Path) -> bool:
    try:
        with open(p, encoding="utf-8") as f:
            first = f.readline()
    except (FileNotFoundError, UnicodeDecodeError):
        return False
    return first.startswith("#") and "timestamp" in first and "p_" in first


def format_of(path: str | os.PathLike[str], fmt: str | None = None) -> str:
    """The format of ``path``: ``fmt`` when given (checked against the extension), else the extension's."""
    p = Path(path)
    if fmt is not None and fmt not in FORMATS:
        raise FormatError(f"--format-in must be one of {', '.join(FORMATS)}, got {fmt!r}")
    ext = _EXT.get(p.suffix.lower())
    if ext == "csv":
        ext = "euroc" if _is_euroc_header(p) else "rawseeds"
    if fmt is None:
        if ext is None:
            raise FormatError(f"{p}: unknown trajectory format (extension {p.suffix or 'none'!r}); "
                              f"name it with --format-in ({', '.join(FORMATS)})")
        return ext
    allowed = {"tum": ("tum", "kitti"), "kitti": ("kitti",), "euroc": ("euroc",), "rawseeds": ("rawseeds",)}
    if ext is not None and fmt not in allowed[ext]:
        raise FormatError(f"{p}: the file says {ext}, --format-in says {fmt}")
    return fmt


def read_trajectory(path: str | os.PathLike[str], fmt: str | None = None,
                    kitti_times: str | os.PathLike[str] | None = None) -> PoseTrack:
    """A pose track from ``path`` in format ``fmt`` (module docstring); one-line errors."""
    p = Path(path)
    f = format_of(p, fmt)
    if f == "tum":
        a = _numbers(p, None, (8,), "TUM (t x y z qx qy qz qw)")
        _increasing(p, a[:, 0])
        q = _unit_quat(p, a[:, 4:8])
        cov_path = p.with_name(p.stem + "_cov.csv")
        if cov_path.is_file():
            from gtrig.io.posetrack import read_pose_track

            log.debug("%s: covariances from %s", p, cov_path.name)
            return read_pose_track(p, cov_path, source=p.stem)
        return PoseTrack(a[:, 0], a[:, 1:4], q, source=p.stem)
    if f == "kitti":
        a = _numbers(p, None, (12,), "KITTI (3 x 4 [R|t] row-major)")
        tp = Path(kitti_times) if kitti_times is not None else p.with_name("times.txt")
        if not tp.is_file():
            raise FormatError(f"{p}: KITTI poses carry no time stamps and there is no {tp.name} beside them")
        t = _numbers(tp, None, (1,), "times.txt (one stamp)")[:, 0]
        if t.size != len(a):
            raise FormatError(f"{tp}: {t.size} stamps for {len(a)} poses in {p}")
        _increasing(tp, t)
        M = a.reshape(-1, 3, 4)
        T = np.tile(np.eye(4), (len(a), 1, 1))
        T[:, :3, :] = M
        return PoseTrack.from_matrices(t, T, source=p.stem)
    if f == "euroc":
        a = _numbers(p, ",", tuple(range(8, 40)), "EuRoC (#timestamp [ns], p xyz, q wxyz, ...)")
        t = a[:, 0] * 1e-9
        _increasing(p, t)
        q = _unit_quat(p, a[:, [5, 6, 7, 4]])
        return PoseTrack(t, a[:, 1:4], q, source=p.stem)
    a = _numbers(p, ",", (4, 13), "RAWSEEDS (t,x,y,theta[,3x3 covariance])")
    _increasing(p, a[:, 0])
    cov = a[:, 4:13].reshape(-1, 3, 3) if a.shape[1] == 13 else None
    if cov is not None:
        cov = 0.5 * (cov + np.swapaxes(cov, 1, 2))  # the files print 6 decimals: symmetric to rounding
    return PoseTrack.from_xytheta(a[:, 0], a[:, 1:4], cov=cov, source=p.stem)


def read_relations(path: str | os.PathLike[str]) -> np.ndarray:
    """(m, 5) ``t_i, t_j, dx, dy, dyaw`` from a RAWSEEDS relations file (``t1 t2 dx dy dz droll dpitch dyaw``)."""
    p = Path(path)
    a = _numbers(p, None, (8,), "relations (t1 t2 dx dy dz droll dpitch dyaw)")
    return a[:, [0, 1, 2, 3, 7]]


__all__ = ["FORMATS", "format_of", "read_relations", "read_trajectory"]
