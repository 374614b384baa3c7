"""A :class:`~gtrig.trajectory.PoseTrack` on disk: a TUM file and one covariance CSV, same rows.

The covariance CSV (docs/formats.md, "Pose covariances"), one layout for every source::

    # gtrig pose covariance v1; source=GTlaser; frame_id=world; child_frame_id=robot
    stamp_s,status,reason,cov_x_x,cov_x_y,cov_x_yaw,cov_y_x,...
    12.340000,ok,,1e-06,...

``status`` is a :class:`~gtrig.trajectory.PoseStatus` name in lower case; the covariance is written
row-major over the axes its column names give (``x, y, yaw``; ``x, y, z, rx, ry, rz``; or ``x, y, z``),
world-frame perturbation as gtrig.trajectory documents. The rows are the TUM file's rows.

The layouts written before this one still read, with a deprecation warning: GTvision's
``stamp_s,c_x_x,...`` and GTlaser's ``timestamp,x,y,theta,cov_xx,...,status,...``.
"""

from __future__ import annotations

import csv
import io
import logging
import os
from collections.abc import Iterator, Mapping
from pathlib import Path

import numpy as np

from gtrig.errors import FormatError
from gtrig.io.atomic import atomic_group
from gtrig.io.text import decode_text, read_bytes
from gtrig.io.tum import ROWS_PER_PIECE, read_tum, stamp_text_pieces, tum_pieces, write_pieces
from gtrig.trajectory import COV_AXES, CovKind, PoseStatus, PoseTrack

log = logging.getLogger(__name__)

_MAGIC = "# gtrig pose covariance v1"
_LASER_V0 = ("cov_xx", "cov_xy", "cov_xtheta", "cov_yy", "cov_ytheta", "cov_thetatheta")


def covariance_pieces(track: PoseTrack, rows: int = ROWS_PER_PIECE) -> Iterator[str]:
    """:func:`covariance_text` in pieces of ``rows`` rows (their concatenation is the text)."""
    axes = COV_AXES[track.cov_kind] if track.cov is not None else ()
    buf = io.StringIO()
    buf.write(f"{_MAGIC}; source={track.source}; frame_id={track.frame_id}; child_frame_id={track.child_frame_id}\n")
    csv.writer(buf, lineterminator="\n").writerow(["stamp_s", "status", "reason"] +
                                                  [f"cov_{a}_{b}" for a in axes for b in axes])
    yield buf.getvalue()
    for a, stamps in zip(range(0, len(track), rows), stamp_text_pieces(track, rows), strict=True):
        buf = io.StringIO()
        w = csv.writer(buf, lineterminator="\n")
        for i in range(a, min(a + rows, len(track))):
            row = [stamps[i - a], PoseStatus(int(track.status[i])).name.lower(), track.reasons[i]]
            if track.cov is not None:
                row += [repr(float(v)) for v in track.cov[i].ravel()]
            w.writerow(row)
        yield buf.getvalue()


def covariance_text(track: PoseTrack) -> str:
    """The covariance CSV of ``track`` as text (``track.cov`` may be ``None``: then no covariance columns)."""
    return "".join(covariance_pieces(track))


def write_pose_track(track: PoseTrack, tum_path: str | os.PathLike[str],
                     cov_path: str | os.PathLike[str] | None = None,
                     extra: Mapping[Path, str] | None = None) -> None:
    """Write the TUM file and (when ``cov_path`` is given) the covariance CSV, a few thousand rows at a
    time (never the whole text in memory), and the texts of ``extra`` (path -> text, e.g. a report
    written with the track): all of them or none."""
    texts = dict(extra or {})
    paths = [tum_path] + ([] if cov_path is None else [cov_path]) + list(texts)
    with atomic_group(*paths) as tmps:
        write_pieces(tmps[0], tum_pieces(track))
        if cov_path is not None:
            write_pieces(tmps[1], covariance_pieces(track))
        for tmp, text in zip(tmps[len(paths) - len(texts):], texts.values(), strict=True):
            write_pieces(tmp, [text])


def _header_meta(first: str) -> dict[str, str]:
    meta: dict[str, str] = {}
    for part in first[len(_MAGIC):].split(";"):
        if "=" in part:
            k, v = part.split("=", 1)
            meta[k.strip()] = v.strip()
    return meta


def _kind_from_axes(p: Path, names: list[str], prefix: str) -> CovKind | None:
    if not names:
        return None
    for kind, axes in COV_AXES.items():
        if names == [f"{prefix}{a}_{b}" for a in axes for b in axes]:
            return kind  # type: ignore[return-value]
    raise FormatError(f"{p}: covariance columns {names[:3]}... are not those of any known layout")


def _floats(p: Path, line: int, cells: list[str]) -> list[float]:
    try:
        return [float(c) for c in cells]
    except ValueError:
        raise FormatError(f"{p}:{line}: not a number in {cells!r}") from None


_Covariances = tuple[np.ndarray, "np.ndarray | None", CovKind, np.ndarray, tuple[str, ...], dict[str, str]]


def read_covariance_csv(path: str | os.PathLike[str]) -> _Covariances:
    """``(stamps_s, cov or None, cov_kind, status, reasons, meta)`` from a covariance CSV of any layout.

    The current layout is read by the compiled parser (gtrig.io._numtext: 10^6 rows in a few seconds);
    anything it does not take (an old layout, quotes, a bad row) by the csv module's line loop, whose
    one-line errors name the file and line."""
    p = Path(path)
    data = read_bytes(p, "pose covariance CSV")
    fast = _fast_covariances(p, data)
    if fast is not None:
        return fast
    lines = decode_text(p, data, "pose covariance CSV").splitlines()
    meta = _header_meta(lines[0]) if lines and lines[0].startswith(_MAGIC) else {}
    rows = [(i + 1, r) for i, r in enumerate(csv.reader(lines)) if r and not r[0].startswith("#")]
    if not rows:
        raise FormatError(f"{p}: empty covariance file")
    (_, header), body = rows[0], rows[1:]
    if header[:3] == ["stamp_s", "status", "reason"]:
        kind = _kind_from_axes(p, header[3:], "cov_")
        cov_cols = slice(3, None)
    elif header[:1] == ["stamp_s"]:
        log.warning("%s: GTvision's old covariance layout (read; rewrite it with this version)", p)
        kind = _kind_from_axes(p, header[1:], "c_")
        cov_cols = slice(1, None)
    elif header[:1] == ["timestamp"] and tuple(header[4:10]) == _LASER_V0:
        log.warning("%s: GTlaser's old covariance layout (read; rewrite it with this version)", p)
        return _read_laser_v0(p, header, body)
    else:
        raise FormatError(f"{p}:{rows[0][0]}: not a pose covariance file (header {','.join(header[:4])}...)")
    k = 0 if kind is None else len(COV_AXES[kind])
    stamps, covs, status, reasons = [], [], [], []
    for line, r in body:
        if len(r) != len(header):
            raise FormatError(f"{p}:{line}: {len(r)} values, the header has {len(header)}")
        stamps.append(_floats(p, line, r[:1])[0])
        covs.append(_floats(p, line, r[cov_cols]))
        if header[1] == "status":
            try:
                status.append(PoseStatus[r[1].upper()])
            except KeyError:
                raise FormatError(f"{p}:{line}: status {r[1]!r} is none of "
                                  f"{', '.join(s.name.lower() for s in PoseStatus)}") from None
            reasons.append(r[2])
        else:
            status.append(PoseStatus.OK)
            reasons.append("")
    cov = np.array(covs, float).reshape(len(body), k, k) if kind is not None else None
    return (np.array(stamps, float), cov, kind or "se3", np.array(status, np.uint8), tuple(reasons), meta)


def _fast_covariances(p: Path, data: bytes) -> _Covariances | None:
    """The current layout by the compiled parser, or None (the line loop decides)."""
    from gtrig.io._numtext import parse_numeric

    meta: dict[str, str] = {}
    pos = 0
    header = None
    while pos < len(data) and header is None:
        end = data.find(b"\n", pos)
        end = len(data) if end < 0 else end
        try:
            line = data[pos:end].decode("ascii").removesuffix("\r")
        except UnicodeDecodeError:
            return None
        if pos == 0 and line.startswith(_MAGIC):
            meta = _header_meta(line)
        pos = end + 1
        if line and not line.startswith("#"):
            header = line.split(",")  # as csv.reader splits an unquoted line
    if header is None or header[:3] != ["stamp_s", "status", "reason"] or any('"' in h for h in header):
        return None
    kind = _kind_from_axes(p, header[3:], "cov_")
    t = parse_numeric(data[pos:], (len(header),), comma=True, text_cols=(1, 2))
    if t is None:
        return None
    status = _statuses(t.buf, t.spans[:, 0])
    if status is None:
        return None
    n = len(t.values)
    empty = t.spans[:, 1, 1] == t.spans[:, 1, 0]
    reasons = [""] * n
    raw = t.buf.tobytes() if not empty.all() else b""
    for i in np.flatnonzero(~empty).tolist():  # reasons are rare: most poses are fine
        a, b = t.spans[i, 1]
        reasons[i] = raw[a:b].decode("ascii")
    k = 0 if kind is None else len(COV_AXES[kind])
    cov = np.ascontiguousarray(t.values[:, 3:]).reshape(n, k, k) if kind is not None else None
    return t.values[:, 0].copy(), cov, kind or "se3", status, tuple(reasons), meta


def _statuses(buf: np.ndarray, spans: np.ndarray) -> np.ndarray | None:
    """(n,) uint8 :class:`PoseStatus` of the words at ``spans`` (n, 2) in ``buf``, written in lower case;
    None when one is not (the line loop then names it)."""
    start, length = spans[:, 0], spans[:, 1] - spans[:, 0]
    out = np.full(len(spans), 255, np.uint8)
    for st in PoseStatus:
        word = np.frombuffer(st.name.lower().encode(), np.uint8)
        idx = np.flatnonzero(length == word.size)
        if idx.size:
            match = np.all(buf[start[idx, None] + np.arange(word.size)] == word, axis=1)
            out[idx[match]] = int(st)
    return None if bool((out == 255).any()) else out


def _read_laser_v0(p: Path, header: list[str], body: list[tuple[int, list[str]]]) -> tuple[
        np.ndarray, np.ndarray, CovKind, np.ndarray, tuple[str, ...], dict[str, str]]:
    stamps, covs = [], []
    for line, r in body:
        if len(r) != len(header):
            raise FormatError(f"{p}:{line}: {len(r)} values, the header has {len(header)}")
        v = _floats(p, line, r[:10])
        stamps.append(v[0])
        xx, xy, xt, yy, yt, tt = v[4:10]
        covs.append([[xx, xy, xt], [xy, yy, yt], [xt, yt, tt]])
    n = len(body)
    return (np.array(stamps, float), np.array(covs, float).reshape(n, 3, 3), "xyyaw", np.zeros(n, np.uint8),
            ("",) * n, {"source": "GTlaser"})


def _symmetric(cov: np.ndarray) -> bool:
    """Every finite (n, k, k) covariance equals its transpose as ``np.allclose(C, C^T, rtol=1e-6,
    atol=1e-15)`` says, checked on the k (k - 1) / 2 pairs off the diagonal only (no (n, k, k) temporaries)."""
    i, j = np.triu_indices(cov.shape[1], 1)
    a, b = cov[:, i, j], cov[:, j, i]
    d = np.abs(a - b)
    ok = (d <= 1e-15 + 1e-6 * np.abs(b)) & (d <= 1e-15 + 1e-6 * np.abs(a))
    finite = np.isfinite(cov).all(axis=(1, 2))
    return bool(ok[finite].all())


def read_pose_track(tum_path: str | os.PathLike[str], cov_path: str | os.PathLike[str] | None = None,
                    source: str = "") -> PoseTrack:
    """A pose track from a TUM file and, optionally, its covariance CSV (same rows, stamps checked)."""
    traj = read_tum(tum_path)
    if cov_path is None:
        return PoseTrack(traj.stamps_s, traj.xyz, traj.quat_xyzw, source=source, stamps_ns=traj.stamps_ns)
    stamps, cov, kind, status, reasons, meta = read_covariance_csv(cov_path)
    if traj.rows is not None and stamps.size > int(traj.rows.max()):  # the TUM file's rows dropped or sorted
        stamps, status = stamps[traj.rows], status[traj.rows]
        cov = None if cov is None else cov[traj.rows]
        reasons = tuple(reasons[i] for i in traj.rows)
    if stamps.shape != traj.stamps_s.shape:
        raise FormatError(f"{cov_path}: {stamps.size} rows, but {tum_path} has {len(traj)} poses")
    bad = np.abs(stamps - traj.stamps_s) > 5e-6
    if np.any(bad):
        i = int(np.argmax(bad))
        raise FormatError(f"{cov_path}: row {i + 1} is stamped {stamps[i]:.6f}, pose {i + 1} of {tum_path} "
                          f"{traj.stamps_s[i]:.6f}")
    if cov is not None and not _symmetric(cov):
        raise FormatError(f"{cov_path}: a covariance is not symmetric")
    return PoseTrack(traj.stamps_s, traj.xyz, traj.quat_xyzw, cov, kind, status, reasons,
                     source or meta.get("source", ""), meta.get("frame_id", "world"),
                     meta.get("child_frame_id", "robot"), traj.stamps_ns)
