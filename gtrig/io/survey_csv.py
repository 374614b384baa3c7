"""Readers and writers of the survey CSV files (see ``docs/formats.md``, "Survey CSVs").

Every reader skips blank lines and lines starting with ``#``, reads one header row, and raises a
one-line :class:`~gtrig.errors.FormatError` naming the file, the line and the field at fault. Units are
metres and radians. Values larger than :data:`MAX_DISTANCE_M` are refused as "millimetres given as
metres".

Files
-----
``reference_points.csv``  ``name,x,y[,sigma]``            reference points, world frame
``world_distances.csv``   ``point,reference,distance[,sigma]``  (or the wide layout
                          ``point,d_<ref>,...`` of ``../shared/reference/world_points.csv``)
``robot_points.csv``      ``name,x,y``                    points drawn on the floor, robot frame
``pose_distances.csv``    ``pose,robot_point,world_point,distance[,sigma]``
``POINTS.csv``            ``name,x,y,cov_xx,cov_xy,cov_yy[,...]`` output of ``gtrig survey points``
``POSES.csv``             ``pose,x,y,theta[,cov_xx,...,cov_tt]`` output of ``gtrig survey poses``
"""

from __future__ import annotations

import csv
import io
import math
import os
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from gtrig.errors import FormatError, InputError
from gtrig.io.atomic import atomic_write_text
from gtrig.io.text import read_text

#: Anything larger in a room survey is almost surely millimetres (metres expected).
MAX_DISTANCE_M = 100.0

POSE_COV_COLUMNS = ("cov_xx", "cov_xy", "cov_xt", "cov_yy", "cov_yt", "cov_tt")


@dataclass(frozen=True)
class Table:
    """A parsed CSV: ``header`` and ``rows`` of strings, with the 1-based file line of every row."""

    path: Path
    header: tuple[str, ...]
    rows: tuple[tuple[str, ...], ...]
    lines: tuple[int, ...]

    def column(self, name: str) -> list[str]:
        i = self.header.index(name)
        return [r[i] for r in self.rows]

    def has(self, name: str) -> bool:
        return name in self.header


def read_table(path: str | os.PathLike[str], required: Sequence[str] = ()) -> Table:
    """Read a CSV with ``#`` comment lines and one header row; check that ``required`` columns exist."""
    p = Path(path)
    text = read_text(p, "text CSV file", encoding="utf-8-sig")
    header: tuple[str, ...] | None = None
    rows: list[tuple[str, ...]] = []
    lines: list[int] = []
    for lineno, line in enumerate(text.splitlines(), 1):
        s = line.strip()
        if not s or s.startswith("#"):
            continue
        fields = tuple(f.strip() for f in next(csv.reader([s])))
        if header is None:
            header = tuple(f.lower() for f in fields)
            continue
        if len(fields) != len(header):
            raise FormatError(
                f"{p}:{lineno}: expected {len(header)} fields ({','.join(header)}), got {len(fields)}"
            )
        rows.append(fields)
        lines.append(lineno)
    if header is None:
        raise FormatError(f"{p}: empty file, expected a header row")
    missing = [c for c in required if c not in header]
    if missing:
        raise FormatError(
            f"{p}: missing column {missing[0]!r} (header: {','.join(header)}; expected {','.join(required)})"
        )
    if not rows:
        raise FormatError(f"{p}: no data rows")
    return Table(p, header, tuple(rows), tuple(lines))


def _float(t: Table, k: int, col: str) -> float:
    s = t.rows[k][t.header.index(col)]
    try:
        v = float(s)
    except ValueError:
        raise FormatError(f"{t.path}:{t.lines[k]}: {col} {s!r} is not a number") from None
    if math.isnan(v) or math.isinf(v):
        raise FormatError(f"{t.path}:{t.lines[k]}: {col} is {s}, expected a finite number")
    return v


def _metres(t: Table, k: int, col: str, *, positive: bool = False, limit: float = MAX_DISTANCE_M) -> float:
    v = _float(t, k, col)
    if positive and v <= 0:
        raise FormatError(f"{t.path}:{t.lines[k]}: {col} {v:g} must be positive")
    if abs(v) > limit:
        raise FormatError(
            f"{t.path}:{t.lines[k]}: {col} {v:g} m is implausible (limit {limit:g} m): "
            f"millimetres given as metres? write {v / 1000:g}"
        )
    return v


def _sigma(t: Table, k: int, default: float | None, reading: bool = False) -> float:
    """The row's sigma (metres); a reading's must be positive (a zero would weigh it infinitely), a
    point's may be zero (a fixed reference)."""
    if t.has("sigma") and t.rows[k][t.header.index("sigma")] != "":
        v = _metres(t, k, "sigma", limit=1.0)
        if v < 0 or (reading and v == 0):
            raise FormatError(f"{t.path}:{t.lines[k]}: sigma {v:g} must be {'positive' if reading else 'not negative'}")
        return v
    if default is None:
        raise FormatError(f"{t.path}:{t.lines[k]}: no sigma given and no default hand-laser sigma")
    return default


def _names(t: Table, col: str) -> list[str]:
    out = t.column(col)
    for k, n in enumerate(out):
        if not n:
            raise FormatError(f"{t.path}:{t.lines[k]}: empty {col}")
    return out


def _unique(t: Table, names: list[str], what: str) -> None:
    seen: dict[str, int] = {}
    for k, n in enumerate(names):
        if n in seen:
            raise FormatError(f"{t.path}:{t.lines[k]}: {what} {n!r} appears twice (first on line {seen[n]})")
        seen[n] = t.lines[k]


@dataclass(frozen=True)
class NamedPoints:
    """Named 2D points with an isotropic standard deviation each.

    Attributes
    ----------
    names : tuple of N names.
    xy : (N, 2) coordinates, metres (world frame for reference and world points, robot frame for
        robot points).
    sigma_m : (N,) isotropic standard deviation per coordinate, metres (0 when exact).
    """

    names: tuple[str, ...]
    xy: np.ndarray
    sigma_m: np.ndarray

    def index(self) -> dict[str, int]:
        return {n: i for i, n in enumerate(self.names)}


@dataclass(frozen=True)
class Distances:
    """Hand-laser readings: ``distance_m[k]`` from ``a[k]`` to ``b[k]``, standard deviation ``sigma_m[k]``.

    For world distances ``a`` is the world point and ``b`` the reference point; for pose distances
    ``group`` is the pose, ``a`` the robot point and ``b`` the world point. ``source`` names the file and
    line of each reading, for messages.
    """

    group: tuple[str, ...]
    a: tuple[str, ...]
    b: tuple[str, ...]
    distance_m: np.ndarray
    sigma_m: np.ndarray
    source: tuple[str, ...]

    def subset(self, keep: np.ndarray) -> Distances:
        idx = np.flatnonzero(keep)
        return Distances(
            tuple(self.group[i] for i in idx),
            tuple(self.a[i] for i in idx),
            tuple(self.b[i] for i in idx),
            self.distance_m[idx],
            self.sigma_m[idx],
            tuple(self.source[i] for i in idx),
        )


def read_reference_points(path: str | os.PathLike[str], default_sigma_m: float = 0.002) -> NamedPoints:
    """``name,x,y[,sigma]``: reference points in the world frame (sigma per coordinate, metres)."""
    t = read_table(path, ("name", "x", "y"))
    names = _names(t, "name")
    _unique(t, names, "name")
    xy = np.array([[_metres(t, k, "x"), _metres(t, k, "y")] for k in range(len(t.rows))])
    sig = np.array([_sigma(t, k, default_sigma_m) for k in range(len(t.rows))])
    return NamedPoints(tuple(names), xy, sig)


def read_robot_points(path: str | os.PathLike[str]) -> NamedPoints:
    """``name,x,y[,sigma]``: points fixed to the robot, in the robot frame (metres)."""
    t = read_table(path, ("name", "x", "y"))
    names = _names(t, "name")
    _unique(t, names, "name")
    xy = np.array(
        [[_metres(t, k, "x", limit=10.0), _metres(t, k, "y", limit=10.0)] for k in range(len(t.rows))]
    )
    sig = np.array([_sigma(t, k, 0.0) for k in range(len(t.rows))])
    if len(xy) >= 2 and float(np.max(np.ptp(xy, axis=0))) < 0.01:
        # a pose's heading comes from the spread of these points: coincident ones leave it unmeasurable
        raise InputError(f"{t.path}: the robot points all lie within 1 cm of each other; a pose's heading needs "
                         "points spread over the robot (a degenerate geometry)")
    return NamedPoints(tuple(names), xy, sig)


def _distance(t: Table, k: int, col: str) -> float:
    s = t.rows[k][t.header.index(col)]
    try:
        v = float(s)
    except ValueError:
        raise FormatError(f"{t.path}:{t.lines[k]}: {col} {s!r} is not a number") from None
    if not math.isfinite(v):
        raise FormatError(f"{t.path}:{t.lines[k]}: {col} is {s}, expected a finite distance in metres")
    if v <= 0:
        raise FormatError(f"{t.path}:{t.lines[k]}: {col} {v:g} must be positive")
    if v > MAX_DISTANCE_M:
        raise FormatError(
            f"{t.path}:{t.lines[k]}: {col} {v:g} m is implausible (limit {MAX_DISTANCE_M:g} m): "
            f"millimetres given as metres? write {v / 1000:g}"
        )
    return v


def read_world_distances(path: str | os.PathLike[str], default_sigma_m: float | None = None) -> Distances:
    """World-point to reference-point distances.

    Long layout ``point,reference,distance[,sigma]``, one reading a row; or the wide layout of the
    published table (``point,d_O,d_A,...``: one column per reference point, empty cells allowed, other
    columns ignored).
    """
    t = read_table(path, ("point",))
    src: list[str] = []
    a: list[str] = []
    b: list[str] = []
    d: list[float] = []
    s: list[float] = []
    if t.has("reference") and t.has("distance"):
        for k in range(len(t.rows)):
            a.append(t.rows[k][t.header.index("point")])
            b.append(t.rows[k][t.header.index("reference")])
            d.append(_distance(t, k, "distance"))
            s.append(_sigma(t, k, default_sigma_m, reading=True))
            src.append(f"{t.path.name}:{t.lines[k]}")
    else:
        wide = [c for c in t.header if c.startswith("d_") and len(c) > 2]
        if not wide:
            raise FormatError(
                f"{t.path}: expected columns point,reference,distance[,sigma] "
                f"(or point,d_<reference>,...); header: {','.join(t.header)}"
            )
        # reference names keep the case written in the file
        with open(t.path, encoding="utf-8-sig") as f:
            raw_header = next(csv.reader(ln for ln in f if ln.strip() and not ln.lstrip().startswith("#")))
        raw = {h.strip().lower(): h.strip()[2:] for h in raw_header}
        for k in range(len(t.rows)):
            for c in wide:
                if t.rows[k][t.header.index(c)] == "":
                    continue
                a.append(t.rows[k][t.header.index("point")])
                b.append(raw[c])
                d.append(_distance(t, k, c))
                s.append(_sigma(t, k, default_sigma_m, reading=True))
                src.append(f"{t.path.name}:{t.lines[k]}")
    return Distances(tuple("" for _ in a), tuple(a), tuple(b), np.array(d), np.array(s), tuple(src))


def read_pose_distances(path: str | os.PathLike[str], default_sigma_m: float | None = None) -> Distances:
    """``pose,robot_point,world_point,distance[,sigma]``: robot-point to world-point readings."""
    t = read_table(path, ("pose", "robot_point", "world_point", "distance"))
    g, a, b, d, s, src = [], [], [], [], [], []
    for k in range(len(t.rows)):
        r = t.rows[k]
        g.append(r[t.header.index("pose")])
        a.append(r[t.header.index("robot_point")])
        b.append(r[t.header.index("world_point")])
        d.append(_distance(t, k, "distance"))
        s.append(_sigma(t, k, default_sigma_m, reading=True))
        src.append(f"{t.path.name}:{t.lines[k]}")
    return Distances(tuple(g), tuple(a), tuple(b), np.array(d), np.array(s), tuple(src))


@dataclass(frozen=True)
class PointsTable:
    """World points with covariance, as written by ``gtrig survey points``.

    ``cov_xy`` is (N, 2, 2), world frame, m^2.
    """

    names: tuple[str, ...]
    xy: np.ndarray
    cov_xy: np.ndarray


def read_points(path: str | os.PathLike[str], default_sigma_m: float = 0.0) -> PointsTable:
    """``name,x,y[,cov_xx,cov_xy,cov_yy]`` (or ``name,x,y,sigma``); without covariance the points get
    ``default_sigma_m`` per coordinate."""
    t = read_table(path, ("name", "x", "y"))
    names = _names(t, "name")
    _unique(t, names, "name")
    n = len(t.rows)
    xy = np.array([[_metres(t, k, "x"), _metres(t, k, "y")] for k in range(n)])
    cov = np.zeros((n, 2, 2))
    for k in range(n):
        if all(t.has(c) for c in ("cov_xx", "cov_xy", "cov_yy")):
            cxx, cxy, cyy = (_float(t, k, c) for c in ("cov_xx", "cov_xy", "cov_yy"))
            cov[k] = [[cxx, cxy], [cxy, cyy]]
            if cxx < 0 or cyy < 0 or cxx * cyy - cxy * cxy < -1e-18:
                raise FormatError(f"{t.path}:{t.lines[k]}: covariance is not positive semi-definite")
        else:
            sg = _sigma(t, k, default_sigma_m)
            cov[k] = np.eye(2) * sg**2
    return PointsTable(tuple(names), xy, cov)


def write_points(
    path: str | os.PathLike[str],
    names: Sequence[str],
    xy: np.ndarray,
    cov_xy: np.ndarray,
    extra: dict[str, Sequence[float]] | None = None,
) -> None:
    """Write ``name,x,y,cov_xx,cov_xy,cov_yy`` (+ ``extra`` columns) atomically, full precision."""
    extra = extra or {}
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(["name", "x", "y", "cov_xx", "cov_xy", "cov_yy", *extra])
    for i, n in enumerate(names):
        c = cov_xy[i]
        w.writerow(
            [
                n,
                f"{xy[i, 0]:.9f}",
                f"{xy[i, 1]:.9f}",
                f"{c[0, 0]:.6e}",
                f"{c[0, 1]:.6e}",
                f"{c[1, 1]:.6e}",
                *(f"{v[i]:.6g}" for v in extra.values()),
            ]
        )
    atomic_write_text(path, buf.getvalue())


def write_poses(
    path: str | os.PathLike[str],
    names: Sequence[str],
    xytheta: np.ndarray,
    cov_xytheta: np.ndarray,
    extra: dict[str, Sequence[float]] | None = None,
) -> None:
    """Write ``pose,x,y,theta`` and the upper triangle of the 3 x 3 covariance atomically."""
    extra = extra or {}
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(["pose", "x", "y", "theta", *POSE_COV_COLUMNS, *extra])
    iu = [(0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2)]
    for i, n in enumerate(names):
        c = cov_xytheta[i]
        w.writerow(
            [
                n,
                f"{xytheta[i, 0]:.9f}",
                f"{xytheta[i, 1]:.9f}",
                f"{xytheta[i, 2]:.9f}",
                *(f"{c[a, b]:.6e}" for a, b in iu),
                *(f"{v[i]:.6g}" for v in extra.values()),
            ]
        )
    atomic_write_text(path, buf.getvalue())


@dataclass(frozen=True)
class PoseTable:
    """Planar poses keyed by name (validation pose numbers, or TUM time stamps).

    Attributes
    ----------
    names : N pose names.
    xytheta : (N, 3) world frame, metres and radians.
    cov_xytheta : (N, 3, 3) or None.
    """

    names: tuple[str, ...]
    xytheta: np.ndarray
    cov_xytheta: np.ndarray | None = None


_COLUMN_SETS = (("x", "y", "theta"), ("x", "y", "th"), ("val_x", "val_y", "val_th"), ("x", "y", "yaw"))


def looks_like_tum(p: Path) -> bool:
    """Whether ``p`` is a TUM trajectory (by its suffix, else by its first data line) rather than a survey CSV."""
    if p.suffix.lower() in (".tum",):
        return True
    if p.suffix.lower() == ".csv":
        return False
    try:
        with open(p, encoding="utf-8") as f:
            for line in f:
                s = line.strip()
                if s and not s.startswith("#"):
                    return len(s.replace(",", " ").split()) == 8 and all(
                        _isfloat(x) for x in s.replace(",", " ").split()
                    )
    except (FileNotFoundError, UnicodeDecodeError):
        return False
    return False


def _isfloat(s: str) -> bool:
    try:
        float(s)
    except ValueError:
        return False
    return True


def read_pose_table(
    path: str | os.PathLike[str], columns: Sequence[str] | None = None, method: str | None = None
) -> PoseTable:
    """Read planar poses from a CSV (``pose`` plus x, y, theta columns) or a TUM file.

    Parameters
    ----------
    columns : the three column names for x, y, theta; default: the first of ``x,y,theta``,
        ``x,y,th``, ``val_x,val_y,val_th``, ``x,y,yaw`` present.
    method : keep only rows whose ``method`` column equals this (e.g. ``genetic`` in
        ``gtlaser_onboard_poses.csv``); required when the file has a method column and repeated poses.

    TUM files: the pose name is the time stamp written as an integer when all stamps are integers (the
    simulator writes validation poses with stamps 1..N), else the 1-based row number; theta is the yaw
    of the body x axis.
    """
    p = Path(path)
    if looks_like_tum(p):
        from gtrig.io.tum import read_tum

        tr = read_tum(p)
        stamps = tr.stamps_s
        if np.all(np.abs(stamps - np.round(stamps)) < 1e-9):
            names = tuple(str(int(round(s))) for s in stamps)
        else:
            names = tuple(str(i + 1) for i in range(len(tr)))
        return PoseTable(names, np.column_stack([tr.xyz[:, :2], tr.yaw_rad()]))
    t = read_table(p, ("pose",))
    if columns is None:
        for cs in _COLUMN_SETS:
            if all(t.has(c) for c in cs):
                columns = cs
                break
        else:
            raise FormatError(
                f"{p}: no pose columns found (header: {','.join(t.header)}); expected "
                "x,y,theta (or th, or val_x,val_y,val_th), or name them with --columns"
            )
    columns = tuple(c.strip().lower() for c in columns)
    if len(columns) != 3:
        raise FormatError(f"{p}: expected three column names for x, y, theta, got {len(columns)}")
    for c in columns:
        if not t.has(c):
            raise FormatError(f"{p}: no column {c!r} (header: {','.join(t.header)})")
    keep = list(range(len(t.rows)))
    if t.has("method"):
        methods = t.column("method")
        if method is not None:
            keep = [k for k in keep if methods[k] == method]
            if not keep:
                raise FormatError(
                    f"{p}: no rows with method {method!r} (methods: {', '.join(sorted(set(methods)))})"
                )
        elif len(set(methods)) > 1:
            raise FormatError(
                f"{p}: rows of several methods ({', '.join(sorted(set(methods)))}); choose one with --method"
            )
    elif method is not None:
        raise FormatError(f"{p}: --method {method} given but the file has no method column")
    pose_names = [t.rows[k][t.header.index("pose")] for k in keep]
    sub = Table(t.path, t.header, tuple(t.rows[k] for k in keep), tuple(t.lines[k] for k in keep))
    _unique(sub, pose_names, "pose")
    xyt = np.array([[_float(sub, k, c) for c in columns] for k in range(len(keep))])
    cov = None
    if all(t.has(c) for c in POSE_COV_COLUMNS):
        cov = np.zeros((len(keep), 3, 3))
        for k in range(len(keep)):
            v = [_float(sub, k, c) for c in POSE_COV_COLUMNS]
            cov[k] = [[v[0], v[1], v[2]], [v[1], v[3], v[4]], [v[2], v[4], v[5]]]
    return PoseTable(tuple(pose_names), xyt, cov)


def write_named_xy(
    path: str | os.PathLike[str],
    names: Sequence[str],
    xy: np.ndarray,
    header: Sequence[str] = ("name", "x", "y"),
    sigma_m: np.ndarray | None = None,
) -> None:
    """Write ``name,x,y[,sigma]`` atomically."""
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow([*header, *(["sigma"] if sigma_m is not None else [])])
    for i, n in enumerate(names):
        row = [n, *(f"{v:.9f}" for v in xy[i])]
        if sigma_m is not None:
            row.append(f"{sigma_m[i]:.6g}")
        w.writerow(row)
    atomic_write_text(path, buf.getvalue())


def write_distances(
    path: str | os.PathLike[str], header: Sequence[str], rows: Sequence[Sequence[object]]
) -> None:
    """Write a distance table (``header`` then ``rows``; floats at 0.1 micrometre) atomically."""
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(header)
    for r in rows:
        w.writerow([f"{v:.7f}" if isinstance(v, float) else v for v in r])
    atomic_write_text(path, buf.getvalue())
