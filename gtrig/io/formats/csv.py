"""gtrig's one-file trajectory CSV, for spreadsheets and scripts: the pose, its status and reason, and
its covariance on one row.

::

    # gtrig trajectory v1; source=GTlaser; frame_id=world; child_frame_id=robot
    stamp_s,x,y,z,qx,qy,qz,qw,yaw,status,reason,cov_x_x,cov_x_y,...
    12.34,1.5,2.0,0.0,0.0,0.0,0.38268343236508984,0.9238795325112867,0.7853981633974483,ok,,1e-06,...

``yaw`` (rad, (-pi, pi]) is written for convenience and ignored on reading (the quaternion is the
pose). ``stamp_s`` is written from the track's integer nanoseconds, as every format writes them
(gtrig.stamps: the digits it was read with), and read back exactly. The covariance columns are those of
the covariance CSV (gtrig.io.posetrack): row-major over ``x, y, yaw`` / ``x, y, z, rx, ry, rz`` /
``x, y, z``, world-frame perturbation. Every other number is Python's shortest round-trip ``repr``:
exact.
"""

from __future__ import annotations

import csv
import io
import os
from pathlib import Path

import numpy as np

from gtrig.errors import FormatError
from gtrig.io.atomic import atomic_write_text
from gtrig.io.formats._common import check_stamps, read_lines, unit_quaternions
from gtrig.trajectory import COV_AXES, CovKind, PoseStatus, PoseTrack

MAGIC = "# gtrig trajectory v1"
POSE_COLUMNS = ("stamp_s", "x", "y", "z", "qx", "qy", "qz", "qw", "yaw", "status", "reason")


def csv_text(track: PoseTrack) -> str:
    buf = io.StringIO()
    buf.write(f"{MAGIC}; source={track.source}; frame_id={track.frame_id}; child_frame_id={track.child_frame_id}\n")
    axes = COV_AXES[track.cov_kind] if track.cov is not None else ()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(list(POSE_COLUMNS) + [f"cov_{a}_{b}" for a in axes for b in axes])
    yaw = track.yaw_rad()
    from gtrig.io.tum import stamp_texts

    stamps = stamp_texts(track)
    for i in range(len(track)):
        row = [stamps[i]] + [repr(float(v)) for v in (*track.xyz[i], *track.quat_xyzw[i], yaw[i])]
        row += [PoseStatus(int(track.status[i])).name.lower(), track.reasons[i]]
        if track.cov is not None:
            row += [repr(float(v)) for v in track.cov[i].ravel()]
        w.writerow(row)
    return buf.getvalue()


def write_csv(track: PoseTrack, path: str | os.PathLike[str]) -> list[Path]:
    atomic_write_text(path, csv_text(track))
    return [Path(path)]


def read_csv(path: str | os.PathLike[str]) -> PoseTrack:
    """A gtrig trajectory CSV (see the module docstring)."""
    p, lines = read_lines(path)
    meta: dict[str, str] = {}
    if lines and lines[0].startswith(MAGIC):
        for part in lines[0][len(MAGIC):].split(";"):
            if "=" in part:
                k, v = part.split("=", 1)
                meta[k.strip()] = v.strip()
    rows = [(i + 1, r) for i, r in enumerate(csv.reader(lines)) if r and not r[0].startswith("#")]
    if not rows or tuple(rows[0][1][:len(POSE_COLUMNS)]) != POSE_COLUMNS:
        raise FormatError(f"{p}: not a gtrig trajectory CSV (header must start {','.join(POSE_COLUMNS[:4])},...)")
    header = rows[0][1]
    cov_names = header[len(POSE_COLUMNS):]
    kind: CovKind | None = None
    for k, axes in COV_AXES.items():
        if cov_names == [f"cov_{a}_{b}" for a in axes for b in axes]:
            kind = k  # type: ignore[assignment]
    if cov_names and kind is None:
        raise FormatError(f"{p}:{rows[0][0]}: covariance columns {cov_names[:3]}... are not those of any layout")
    body = rows[1:]
    if not body:
        raise FormatError(f"{p}: no poses")
    nums, status, reasons, numbers, stamp_cells = [], [], [], [], []
    for line, r in body:
        if len(r) != len(header):
            raise FormatError(f"{p}:{line}: {len(r)} values, the header has {len(header)}")
        try:
            nums.append([float(c) for c in r[:9]] + [float(c) for c in r[len(POSE_COLUMNS):]])
        except ValueError:
            raise FormatError(f"{p}:{line}: not a number in {','.join(r)[:80]!r}") from None
        try:
            status.append(PoseStatus[r[9].upper()])
        except KeyError:
            raise FormatError(f"{p}:{line}: status {r[9]!r} is none of "
                              f"{', '.join(s.name.lower() for s in PoseStatus)}") from None
        reasons.append(r[10])
        numbers.append(line)
        stamp_cells.append(r[0])
    a = np.array(nums, float)
    if not np.all(np.isfinite(a[:, :8])):
        raise FormatError(f"{p}:{numbers[int(np.argmax(~np.all(np.isfinite(a[:, :8]), axis=1)))]}: a pose is "
                          "not finite")
    check_stamps(p, a[:, 0], numbers)
    q = unit_quaternions(p, a[:, 4:8], numbers)
    cov = None
    if kind is not None:
        dim = len(COV_AXES[kind])
        cov = a[:, 9:].reshape(-1, dim, dim)
    from gtrig.stamps import ns_from_decimals

    return PoseTrack(a[:, 0], a[:, 1:4], q, cov, kind or "se3", np.array(status, np.uint8), tuple(reasons),
                     meta.get("source", p.stem), meta.get("frame_id", "world"), meta.get("child_frame_id", "robot"),
                     ns_from_decimals(stamp_cells))
