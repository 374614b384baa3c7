"""EuRoC MAV ground truth: ``state_groundtruth_estimate0/data.csv``.

Header ``#timestamp, p_RS_R_x [m], p_RS_R_y [m], p_RS_R_z [m], q_RS_w [], q_RS_x [], q_RS_y [],
q_RS_z [], v_RS_R_x [m s^-1], ..., b_w_RS_S_x [rad s^-1], ..., b_a_RS_S_x [m s^-2], ...``: integer
nanosecond stamps, position, quaternion **w first**, velocity in the world frame, gyroscope and
accelerometer biases (17 columns; the 8-column pose-only variant, as evo's, also reads).

gtrig writes the velocity from central differences of the positions (``numpy.gradient`` over the
stamps) and zero biases (a GT room measures none). Precision kept: stamps 1 ns (integers; read back
as float seconds, 0.2 us at a 2009 epoch), positions 1e-9 m, quaternions 1e-12.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from gtrig.io.atomic import atomic_write_text
from gtrig.io.formats._common import LineNumbers, read_lines, read_numeric, unit_quaternions
from gtrig.io.stamp_order import stamp_order
from gtrig.stamps import seconds_from_ns
from gtrig.trajectory import PoseTrack

HEADER = ("#timestamp, p_RS_R_x [m], p_RS_R_y [m], p_RS_R_z [m], q_RS_w [], q_RS_x [], q_RS_y [], q_RS_z [], "
          "v_RS_R_x [m s^-1], v_RS_R_y [m s^-1], v_RS_R_z [m s^-1], b_w_RS_S_x [rad s^-1], "
          "b_w_RS_S_y [rad s^-1], b_w_RS_S_z [rad s^-1], b_a_RS_S_x [m s^-2], b_a_RS_S_y [m s^-2], "
          "b_a_RS_S_z [m s^-2]")


def read_euroc(path: str | os.PathLike[str]) -> PoseTrack:
    """A EuRoC ground-truth CSV as a pose track (no covariance)."""
    p, a, numbers, stamps_ns = read_numeric(path, (8, 17), ",", "8 or 17 comma-separated values (EuRoC "
                                            "'#timestamp, p_RS_R_x, ..., q_RS_w, q_RS_x, q_RS_y, q_RS_z, ...')")
    if stamps_ns is None:
        stamps_ns = _stamps_ns(p, read_lines(p)[1], numbers)
    # as evo reads them (gtrig.io.stamp_order); seconds from the first stamp keep the nanoseconds apart
    keep = stamp_order(p, (stamps_ns - stamps_ns[0]).astype(float) * 1e-9, numbers)
    if keep is not None:
        a, numbers, stamps_ns = a[keep], numbers[keep], stamps_ns[keep]
    stamps = seconds_from_ns(stamps_ns)
    q = unit_quaternions(p, a[:, [5, 6, 7, 4]], numbers)
    return PoseTrack(stamps, a[:, 1:4], q, source=p.parent.name if p.name == "data.csv" else p.stem,
                     stamps_ns=stamps_ns)


def _stamps_ns(p: Path, lines: list[str], numbers: LineNumbers) -> np.ndarray:
    """Integer nanoseconds from the first cells, line by line (stamps not all plain integers)."""
    out = np.empty(len(numbers), np.int64)
    for k, n in enumerate(numbers):
        cell = lines[n - 1].split(",", 1)[0].strip()
        try:
            ns = int(cell)
        except ValueError:
            ns = int(round(float(cell)))
        out[k] = ns
    return out


def euroc_text(track: PoseTrack) -> str:
    stamps_ns = track.integer_stamps_ns()
    if len(track) > 1:
        vel = np.gradient(track.xyz, track.stamps_s, axis=0)
    else:
        vel = np.zeros((len(track), 3))
    q = track.quat_xyzw
    out = [HEADER]
    for i in range(len(track)):
        x, y, z = track.xyz[i]
        out.append(f"{stamps_ns[i]},{x:.9f},{y:.9f},{z:.9f},{q[i, 3]:.12f},{q[i, 0]:.12f},{q[i, 1]:.12f},"
                   f"{q[i, 2]:.12f},{vel[i, 0]:.9f},{vel[i, 1]:.9f},{vel[i, 2]:.9f},0,0,0,0,0,0")
    return "\n".join(out) + "\n"


def write_euroc(track: PoseTrack, path: str | os.PathLike[str]) -> list[Path]:
    """Write the EuRoC layout to ``path`` (conventionally ``state_groundtruth_estimate0/data.csv``)."""
    atomic_write_text(path, euroc_text(track))
    return [Path(path)]
