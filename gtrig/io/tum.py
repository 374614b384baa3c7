"""TUM trajectory files: ``timestamp tx ty tz qx qy qz qw`` per line."""

from __future__ import annotations

import os
from collections.abc import Iterable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
from scipy.spatial.transform import Rotation

from gtrig.errors import FormatError
from gtrig.geometry import yaw_of_quats
from gtrig.io.atomic import atomic_group
from gtrig.io.yamlfile import decode_text_file, read_bytes_file

if TYPE_CHECKING:
    from gtrig.trajectory import PoseTrack


@dataclass(frozen=True)
class Trajectory:
    """A time-stamped sequence of poses ``T_world_body``.

    Attributes
    ----------
    stamps_s : (N,) strictly increasing seconds.
    xyz : (N, 3) positions, metres.
    quat_xyzw : (N, 4) unit quaternions.
    rows : (N,) the 0-based pose rows of the file these poses are, when the reader dropped or reordered
        some (gtrig.io.stamp_order); ``None`` when they are the file's rows in order.
    stamps_ns : (N,) int64 the stamps' exact nanoseconds when the file prints more digits than a float
        keeps (gtrig.io.stamp_text), else ``None`` (gtrig.stamps.ns_from_seconds gives them).
    """

    stamps_s: np.ndarray
    xyz: np.ndarray
    quat_xyzw: np.ndarray
    rows: np.ndarray | None = None
    stamps_ns: np.ndarray | None = None

    def __post_init__(self) -> None:
        for a in (self.stamps_s, self.xyz, self.quat_xyzw):
            a.setflags(write=False)

    def __len__(self) -> int:
        return int(self.stamps_s.size)

    @staticmethod
    def from_matrices(stamps_s: np.ndarray, T_world_body: np.ndarray) -> Trajectory:
        T = np.asarray(T_world_body, dtype=float).reshape(-1, 4, 4)
        q = Rotation.from_matrix(T[:, :3, :3]).as_quat()
        q[q[:, 3] < 0] *= -1
        return Trajectory(np.asarray(stamps_s, dtype=float).copy(), T[:, :3, 3].copy(), q)

    def matrices(self) -> np.ndarray:
        """(N, 4, 4) transforms."""
        T = np.tile(np.eye(4), (len(self), 1, 1))
        T[:, :3, :3] = Rotation.from_quat(self.quat_xyzw).as_matrix()
        T[:, :3, 3] = self.xyz
        return T

    def yaw_rad(self) -> np.ndarray:
        """(N,) heading of the body x axis projected on the world x-y plane."""
        return yaw_of_quats(self.quat_xyzw)


def read_tum(path: str | os.PathLike[str]) -> Trajectory:
    """Read a TUM file; one-line errors name the file and line.

    Three paths, fastest first, each giving Python ``float()``'s numbers: the compiled whole-file parser
    (gtrig.io._numtext: 10^6 lines in about 0.4 s), NumPy's C parser over the lines (a file with
    non-ASCII comments), and the line loop, which also reads commas as separators and makes the error
    messages.
    """
    from gtrig.io._numtext import parse_numeric
    from gtrig.io.stamp_text import needs_text_stamps, text_stamps_ns

    p = Path(path)
    data = read_bytes_file(p)
    fast = parse_numeric(data, (8,), comma=False)
    lines: list[str] | None = None
    if fast is not None:
        a = fast.values
    else:
        lines = decode_text_file(p, data).splitlines()
        a = _fast_rows(lines)  # type: ignore[assignment]
        if a is None:
            a = _checked_rows(p, lines)
    head = data[:4096].decode("utf-8", "replace").splitlines()
    ns = None
    if needs_text_stamps(head):
        lines = lines if lines is not None else decode_text_file(p, data).splitlines()
        ns = text_stamps_ns(lines)
    if fast is not None:
        numbers = fast.line_numbers
    else:
        assert lines is not None
        numbers = np.array([i for i, s in enumerate(lines, 1) if s.strip() and not s.strip().startswith("#")])
    return _trajectory(p, a, ns, numbers)


def _fast_rows(lines: list[str]) -> np.ndarray | None:
    """The (n, 8) numbers by NumPy's C parser (10^6 lines in ~1 s, 6x the line loop), or None when the file
    needs the line loop (commas, a bad line: its error names the line)."""
    import warnings

    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            a = np.loadtxt(lines, comments="#", ndmin=2)
    except ValueError:
        return None
    return a if a.shape[1] == 8 and a.shape[0] > 0 else None


def _checked_rows(p: Path, lines: list[str]) -> np.ndarray:
    rows = []
    for i, line in enumerate(lines, 1):
        s = line.strip()
        if not s or s.startswith("#"):
            continue
        parts = s.replace(",", " ").split()
        if len(parts) != 8:
            raise FormatError(f"{p}:{i}: expected 8 values 'timestamp tx ty tz qx qy qz qw', got {len(parts)}")
        try:
            rows.append([float(x) for x in parts])
        except ValueError:
            raise FormatError(f"{p}:{i}: not a number in {s!r}") from None
    if not rows:
        raise FormatError(f"{p}: no poses")
    return np.array(rows)


def _trajectory(p: Path, a: np.ndarray, stamps_ns: np.ndarray | None = None,
                line_numbers: np.ndarray | None = None) -> Trajectory:
    if not np.isfinite(a).all():
        raise FormatError(f"{p}: non-finite values")
    from gtrig.io.stamp_order import stamp_order

    rows = stamp_order(p, a[:, 0], line_numbers)
    if rows is not None:
        a = a[rows]
        stamps_ns = None if stamps_ns is None else stamps_ns[rows]
    stamps = a[:, 0].copy()
    qx, qy, qz, qw = (a[:, k] for k in range(4, 8))
    # np.linalg.norm(q, axis=1)'s sum, in its order (the same bits), without its (n, 4) temporaries
    n = np.sqrt(qx * qx + qy * qy + qz * qz + qw * qw)
    off = np.abs(n - 1) > 1e-3
    if off.any():
        i = int(np.argmax(off)) if rows is None else int(rows[int(np.argmax(off))])
        raise FormatError(f"{p}: quaternion of pose {i + 1} is not unit")
    return Trajectory(stamps, a[:, 1:4].copy(), a[:, 4:8] / n[:, None], rows, stamps_ns)


#: rows per piece of a text written piece by piece: an hour's track (~270,000 rows) as one string, its rows'
#: strings and its encoded bytes held at once took ~130 MB of a client's peak
ROWS_PER_PIECE = 8192


def integer_stamps_ns(traj: Trajectory | PoseTrack) -> np.ndarray:
    """(N,) int64 nanoseconds of a trajectory's or pose track's stamps: those it read, else those of its
    float stamps (gtrig.stamps)."""
    from gtrig.stamps import ns_from_seconds

    ns = getattr(traj, "stamps_ns", None)
    return ns if ns is not None else ns_from_seconds(traj.stamps_s)


def stamp_texts(traj: Trajectory | PoseTrack, decimals: int | None = None) -> list[str]:
    """The stamps as every text format writes them (gtrig.stamps.format_seconds): 6 decimals when each is a
    whole microsecond, else 9. Stamps past what int64 nanoseconds hold (nanoseconds read as seconds) are
    printed from the floats, ``decimals`` (default 6) of them."""
    return [t for piece in stamp_text_pieces(traj, len(traj.stamps_s) or 1, decimals) for t in piece]


def stamp_text_pieces(traj: Trajectory | PoseTrack, rows: int = ROWS_PER_PIECE, decimals: int | None = None
                      ) -> Iterator[list[str]]:
    """:func:`stamp_texts` ``rows`` at a time (one number of decimals for the whole track)."""
    from gtrig.stamps import MAX_NS_STAMP_S, decimals_needed, format_seconds

    n = len(traj.stamps_s)
    if getattr(traj, "stamps_ns", None) is None and n and not bool(np.all(np.abs(traj.stamps_s) < MAX_NS_STAMP_S)):
        d = 6 if decimals is None else decimals
        for a in range(0, n, rows):
            yield [f"{t:.{d}f}" for t in traj.stamps_s[a:a + rows]]
        return
    ns = integer_stamps_ns(traj)
    d = decimals_needed(ns) if decimals is None else decimals
    for a in range(0, n, rows):
        yield format_seconds(ns[a:a + rows], d)


def tum_pieces(traj: Trajectory | PoseTrack, rows: int = ROWS_PER_PIECE) -> Iterator[str]:
    """:func:`tum_text` in pieces of ``rows`` rows (their concatenation is the text)."""
    yield "# timestamp tx ty tz qx qy qz qw\n"
    if len(traj.stamps_s) == 0:
        yield "\n"
    for a, stamps in zip(range(0, len(traj.stamps_s), rows), stamp_text_pieces(traj, rows), strict=True):
        out = [
            f"{t} {x:.9f} {y:.9f} {z:.9f} {qx:.12f} {qy:.12f} {qz:.12f} {qw:.12f}"
            for t, (x, y, z), (qx, qy, qz, qw) in zip(stamps, traj.xyz[a:a + rows],
                                                      traj.quat_xyzw[a:a + rows], strict=True)
        ]
        yield "\n".join(out) + "\n"


def tum_text(traj: Trajectory | PoseTrack) -> str:
    """The TUM text of a trajectory or pose track (microsecond stamps, nanometre positions, 12-digit
    quaternions)."""
    return "".join(tum_pieces(traj))


def write_pieces(path: str | os.PathLike[str], pieces: Iterable[str]) -> None:
    """Write text ``pieces`` one after the other to ``path`` (UTF-8, ``\\n`` line ends); not atomic: for a
    temporary of :func:`gtrig.io.atomic.atomic_group`."""
    with open(path, "w", encoding="utf-8", newline="\n") as f:
        for piece in pieces:
            f.write(piece)


def write_tum(path: str | os.PathLike[str], traj: Trajectory | PoseTrack) -> None:
    """Write a TUM file atomically (see :func:`tum_text`)."""
    with atomic_group(path) as (tmp,):
        write_pieces(tmp, tum_pieces(traj))
