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
from pathlib import Path

import numpy as np

from gtrig.errors import FormatError
from gtrig.io.atomic import atomic_group
from gtrig.io.text import read_text
from gtrig.io.tum import read_tum, tum_text
from gtrig.trajectory import COV_AXES, CovKind, PoseStatus, PoseTrack

log = logging.getLogger(__name__)

_MAGIC = "# gtrig pose covariance v1"
_LASER_V0 = ("cov_xx", "cov_xy", "cov_xtheta", "cov_yy", "cov_ytheta", "cov_thetatheta")


def covariance_text(track: PoseTrack) -> str:
    """The covariance CSV of ``track`` as text (``track.cov`` may be ``None``: then no covariance columns)."""
    buf = io.StringIO()
    buf.write(f"{_MAGIC}; source={track.source}; frame_id={track.frame_id}; "
              f"child_frame_id={track.child_frame_id}\n")
    axes = COV_AXES[track.cov_kind] if track.cov is not None else ()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(["stamp_s", "status", "reason"] + [f"cov_{a}_{b}" for a in axes for b in axes])
    for i in range(len(track)):
        row = [f"{track.stamps_s[i]:.6f}", PoseStatus(int(track.status[i])).name.lower(), track.reasons[i]]
        if track.cov is not None:
            row += [repr(float(v)) for v in track.cov[i].ravel()]
        w.writerow(row)
    return buf.getvalue()


def write_pose_track(track: PoseTrack, tum_path: str | os.PathLike[str],
                     cov_path: str | os.PathLike[str] | None = None) -> None:
    """Write the TUM file and (when ``cov_path`` is given) the covariance CSV, both or neither."""
    paths = [tum_path] if cov_path is None else [tum_path, cov_path]
    texts = [tum_text(track)] + ([] if cov_path is None else [covariance_text(track)])
    with atomic_group(*paths) as tmps:
        for tmp, text in zip(tmps, texts, strict=True):
            tmp.write_text(text, encoding="utf-8", newline="\n")


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


def read_covariance_csv(path: str | os.PathLike[str]) -> tuple[np.ndarray, np.ndarray | None, CovKind,
                                                                 np.ndarray, tuple[str, ...], dict[str, str]]:
    """``(stamps_s, cov or None, cov_kind, status, reasons, meta)`` from a covariance CSV of any layout."""
    p = Path(path)
    lines = read_text(p, "pose covariance CSV").splitlines()
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


def read_pose_track(tum_path: str | os.PathLike[str], cov_path: str | os.PathLike[str] | None = None,
                    source: str = "") -> PoseTrack:
    """A pose track from a TUM file and, optionally, its covariance CSV (same rows, stamps checked)."""
    traj = read_tum(tum_path)
    if cov_path is None:
        return PoseTrack(traj.stamps_s, traj.xyz, traj.quat_xyzw, source=source)
    stamps, cov, kind, status, reasons, meta = read_covariance_csv(cov_path)
    if stamps.shape != traj.stamps_s.shape:
        raise FormatError(f"{cov_path}: {stamps.size} rows, but {tum_path} has {len(traj)} poses")
    bad = np.abs(stamps - traj.stamps_s) > 5e-6
    if np.any(bad):
        i = int(np.argmax(bad))
        raise FormatError(f"{cov_path}: row {i + 1} is stamped {stamps[i]:.6f}, pose {i + 1} of {tum_path} "
                          f"{traj.stamps_s[i]:.6f}")
    if cov is not None:
        finite = np.all(np.isfinite(cov), axis=(1, 2))
        sym_ok = np.allclose(cov[finite], np.swapaxes(cov[finite], 1, 2), rtol=1e-6, atol=1e-15)
        if not sym_ok:
            raise FormatError(f"{cov_path}: a covariance is not symmetric")
    return PoseTrack(traj.stamps_s, traj.xyz, traj.quat_xyzw, cov, kind, status, reasons,
                     source or meta.get("source", ""), meta.get("frame_id", "world"),
                     meta.get("child_frame_id", "robot"))
