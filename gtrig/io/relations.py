"""RAWSEEDS relations files: relative poses between two stamps of a ground truth, for the RPE.

One relation per line, whitespace-separated: ``t1 t2 dx dy dz droll dpitch dyaw`` (the pose at ``t2`` in
the frame of the pose at ``t1``; metres, radians), as the RAWSEEDS Metrics Computation Toolkit reads them
(benchmark.m keeps columns 1-4 and 8).
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from gtrig.errors import FormatError


def read_relations(path: str | os.PathLike[str]) -> np.ndarray:
    """(m, 5) ``t_i, t_j, dx, dy, dyaw``; one-line errors name the file and line."""
    p = Path(path)
    try:
        lines = p.read_text(encoding="utf-8").splitlines()
    except FileNotFoundError:
        raise FormatError(f"{p}: no such file") from None
    except UnicodeDecodeError:
        raise FormatError(f"{p}: not a text file") from None
    rows = [(i, s.split()) for i, s in enumerate(lines, 1) if s.strip() and not s.lstrip().startswith("#")]
    if not rows:
        raise FormatError(f"{p}: no relations")
    for i, parts in rows:
        if len(parts) != 8:
            raise FormatError(f"{p}:{i}: {len(parts)} values, a relation has 8 (t1 t2 dx dy dz droll dpitch dyaw)")
    try:
        a = np.array([[float(v) for v in parts] for _, parts in rows])
    except ValueError:
        bad = next(i for i, parts in rows if not all(_isfloat(v) for v in parts))
        raise FormatError(f"{p}:{bad}: not a number") from None
    if not np.all(np.isfinite(a)):
        raise FormatError(f"{p}: a non-finite value")
    return a[:, [0, 1, 2, 3, 7]]


def _isfloat(s: str) -> bool:
    try:
        float(s)
    except ValueError:
        return False
    return True
