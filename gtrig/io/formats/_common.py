"""Helpers shared by the trajectory text formats: reading numeric rows with one-line errors, and the
checks every reader applies before it builds a :class:`~gtrig.trajectory.PoseTrack`."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from gtrig.errors import FormatError
from gtrig.io.text import decode_text, read_bytes, read_text

_WHAT = "trajectory file"
#: 1-based line numbers of the rows, for the messages
LineNumbers = list[int] | np.ndarray


def read_lines(path: str | os.PathLike[str]) -> tuple[Path, list[str]]:
    """The lines of a text file; a missing or binary file is one :class:`FormatError`."""
    p = Path(path)
    return p, read_text(p, _WHAT, encoding="utf-8-sig").splitlines()


def read_numeric(path: str | os.PathLike[str], ncols: tuple[int, ...], sep: str | None, what: str
                 ) -> tuple[Path, np.ndarray, np.ndarray, np.ndarray | None]:
    """``(path, rows, line_numbers, first_int)``: :func:`numeric_rows` of a whole file, by the compiled
    parser (gtrig.io._numtext, 10^6 lines in a fraction of a second) when the file is plain, else by the
    line loop, whose one-line errors name the file and line. ``first_int``: the first column's exact
    integers when every one is a plain integer (from the compiled parser only), else ``None``."""
    from gtrig.io._numtext import parse_numeric

    p = Path(path)
    data = read_bytes(p, _WHAT)
    fast = parse_numeric(data, ncols, comma=sep == ",") if sep in (None, ",") else None
    if fast is None:
        lines = decode_text(p, data, _WHAT, encoding="utf-8-sig").splitlines()
        a, numbers = numeric_rows(p, lines, ncols, sep, what)
        return p, a, np.asarray(numbers, np.int64), None
    _check_finite(p, fast.values, fast.line_numbers)
    return p, fast.values, fast.line_numbers, fast.first_int


def numeric_rows(p: Path, lines: list[str], ncols: tuple[int, ...], sep: str | None, what: str
                 ) -> tuple[np.ndarray, list[int]]:
    """``(rows, line_numbers)``: every non-empty, non-``#`` line split on ``sep`` (whitespace when
    ``None``) into one of ``ncols`` numbers; all rows must have the same count. ``what`` names the
    layout in errors ("8 values 'timestamp tx ty tz qx qy qz qw'")."""
    rows: list[list[float]] = []
    numbers: list[int] = []
    width = None
    for i, line in enumerate(lines, 1):
        s = line.strip()
        if not s or s.startswith("#"):
            continue
        parts = [c.strip() for c in s.split(sep)] if sep else s.split()
        if len(parts) not in ncols or (width is not None and len(parts) != width):
            raise FormatError(f"{p}:{i}: expected {what}, got {len(parts)} values")
        width = len(parts)
        try:
            rows.append([float(c) for c in parts])
        except ValueError:
            raise FormatError(f"{p}:{i}: not a number in {s[:80]!r}") from None
        numbers.append(i)
    if not rows:
        raise FormatError(f"{p}: no poses")
    a = np.array(rows, dtype=float)
    _check_finite(p, a, numbers)
    return a, numbers


def _check_finite(p: Path, a: np.ndarray, numbers: LineNumbers) -> None:
    finite = np.isfinite(a).all(axis=1)
    if not finite.all():
        raise FormatError(f"{p}:{numbers[int(np.argmin(finite))]}: a value is not finite")


def check_stamps(p: Path, stamps_s: np.ndarray, line_numbers: LineNumbers | None = None) -> None:
    """Stamps must increase strictly (a :class:`PoseTrack` requires it); the error names the line."""
    bad = np.flatnonzero(np.diff(stamps_s) <= 0)
    if bad.size:
        k = int(bad[0]) + 1
        where = f":{line_numbers[k]}" if line_numbers is not None else f": pose {k + 1}"
        raise FormatError(f"{p}{where}: time stamps do not increase ({stamps_s[k - 1]!r} then {stamps_s[k]!r})")


def unit_quaternions(p: Path, quat_xyzw: np.ndarray, line_numbers: LineNumbers) -> np.ndarray:
    """Normalised quaternions with ``w >= 0``; one further than 1e-3 from unit is an error. Those
    within 1e-12 of unit are kept as they are (an exact format reads back bit for bit)."""
    n = np.linalg.norm(quat_xyzw, axis=1)
    bad = np.abs(n - 1) > 1e-3
    if np.any(bad):
        raise FormatError(f"{p}:{line_numbers[int(np.argmax(bad))]}: the quaternion is not unit (norm "
                          f"{n[int(np.argmax(bad))]:.6f})")
    q = np.where(np.abs(n - 1)[:, None] > 1e-12, quat_xyzw / n[:, None], quat_xyzw)
    q[q[:, 3] < 0] *= -1
    return q


def rotation_matrices(p: Path, R: np.ndarray, line_numbers: LineNumbers) -> None:
    """Rotation blocks must be orthonormal with determinant +1 to 1e-4 (KITTI writes 6-9 digits)."""
    err = np.abs(R @ np.swapaxes(R, 1, 2) - np.eye(3)).max(axis=(1, 2))
    det = np.linalg.det(R)
    bad = (err > 1e-4) | (det < 0)
    if np.any(bad):
        i = int(np.argmax(bad))
        raise FormatError(f"{p}:{line_numbers[i]}: the 3x3 block is not a rotation (|R R^T - I| = {err[i]:.2g}, "
                          f"det {det[i]:.3f})")
