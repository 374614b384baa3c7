"""Odometry CSV files: ``stamp_s,x,y,theta,v,omega`` (docs/formats.md, "Odometry").

The robot's dead-reckoned planar pose in its own start frame (metres, radians), its measured forward
speed (m/s) and turn rate (rad/s). Time stamps strictly increase; every value is a finite number.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from gtrig.errors import FormatError
from gtrig.io.atomic import atomic_open
from gtrig.io.scans import check_stamps, data_lines, parse_numbers

COLUMNS = ("stamp_s", "x", "y", "theta", "v", "omega")


@dataclass(frozen=True)
class OdometryLog:
    """Wheel odometry.

    Attributes
    ----------
    stamps_s : (N,) strictly increasing seconds.
    xytheta : (N, 3) dead-reckoned pose in the odometry's start frame (metres, radians; theta
        continuous, not wrapped).
    v_mps : (N,) measured forward speed, m/s.
    omega_radps : (N,) measured turn rate, rad/s.
    """

    stamps_s: np.ndarray
    xytheta: np.ndarray
    v_mps: np.ndarray
    omega_radps: np.ndarray

    def __post_init__(self) -> None:
        st = np.asarray(self.stamps_s, dtype=float)
        n = st.shape[0] if st.ndim == 1 else -1
        arrs = [np.asarray(a, dtype=float) for a in (self.xytheta, self.v_mps, self.omega_radps)]
        if n < 0 or arrs[0].shape != (n, 3) or arrs[1].shape != (n,) or arrs[2].shape != (n,):
            raise ValueError("OdometryLog: stamps_s (N,), xytheta (N, 3), v_mps, omega_radps (N,) expected")
        for name, a in zip(("stamps_s", "xytheta", "v_mps", "omega_radps"), [st, *arrs], strict=True):
            object.__setattr__(self, name, a)
            a.setflags(write=False)

    def __len__(self) -> int:
        return int(self.stamps_s.size)


def read_odometry(path: str | os.PathLike[str]) -> OdometryLog:
    """Read an odometry CSV; one-line :class:`FormatError` naming the file and line on bad input."""
    p = Path(path)
    header, lines, line_no = data_lines(p)
    names = tuple(h.strip() for h in header.split(","))
    if names != COLUMNS:
        raise FormatError(f"{p}: header must be '{','.join(COLUMNS)}', got {header[:60]!r}")
    a = parse_numbers(p, lines, line_no, len(COLUMNS))
    check_stamps(p, a[:, 0], line_no)
    bad = np.flatnonzero(~np.isfinite(a[:, 1:]).all(axis=1))
    if bad.size:
        i = int(bad[0])
        j = int(np.argmax(~np.isfinite(a[i, 1:]))) + 1
        raise FormatError(f"{p}:{line_no[i]}: {COLUMNS[j]} is not a finite number")
    return OdometryLog(a[:, 0].copy(), a[:, 1:4].copy(), a[:, 4].copy(), a[:, 5].copy())


def write_odometry_csv(path: str | os.PathLike[str], log: OdometryLog) -> None:
    """Write an odometry CSV atomically (every column with 9 decimals)."""
    data = np.column_stack([log.stamps_s, log.xytheta, log.v_mps, log.omega_radps]).tolist()
    fmt = "%.9f,%.9f,%.9f,%.9f,%.9f,%.9f"
    with atomic_open(path, "w", encoding="utf-8", newline="\n") as f:
        f.write(",".join(COLUMNS) + "\n")
        f.write("\n".join(fmt % tuple(row) for row in data))
        if data:
            f.write("\n")
