"""The recording layout (docs/formats.md): paths, and a summary of what a recording holds."""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

from gtrig.errors import InputError

SEQUENCES = ("run", "validation")


@dataclass(frozen=True)
class ItemSummary:
    """One kind of data in a recording: where, how many files or rows, and bytes on disk."""

    what: str
    path: str
    count: int
    unit: str
    bytes: int


def recording_dir(path: str | os.PathLike[str]) -> Path:
    """Check that ``path`` is a recording folder (it holds ``rig.yaml``) and return it."""
    p = Path(path)
    if not p.is_dir():
        raise InputError(f"{p}: no such recording folder")
    if not (p / "rig.yaml").is_file():
        raise InputError(f"{p}: not a recording (no rig.yaml; see docs/formats.md)")
    return p


def _folder_size(p: Path) -> tuple[int, int]:
    files = [f for f in p.rglob("*") if f.is_file()]
    return len(files), sum(f.stat().st_size for f in files)


def _rows(p: Path) -> int:
    with open(p, "rb") as f:
        return max(sum(1 for _ in f) - 1, 0)


def summarize(rec: str | os.PathLike[str]) -> list[ItemSummary]:
    """What a recording holds, per sensor and sequence."""
    root = recording_dir(rec)
    out: list[ItemSummary] = []
    for seq in (*SEQUENCES, "background"):
        cams = root / seq / "cameras"
        if cams.is_dir():
            for cam in sorted(cams.iterdir()):
                n, b = _folder_size(cam)
                out.append(ItemSummary(f"{seq} images {cam.name}", str(cam.relative_to(root)), n - 1, "frames", b))
        for kind in ("lasers", "onboard"):
            d = root / seq / kind
            if d.is_dir():
                for f in sorted(d.glob("*.csv")):
                    out.append(ItemSummary(f"{seq} {kind} {f.stem}", str(f.relative_to(root)), _rows(f), "scans",
                                           f.stat().st_size))
        odo = root / seq / "odometry.csv"
        if odo.is_file():
            out.append(ItemSummary(f"{seq} odometry", str(odo.relative_to(root)), _rows(odo), "rows",
                                   odo.stat().st_size))
    for sub in ("calib/intrinsics", "calib/pairs", "calib/world_board", "handheld/images"):
        d = root / sub
        if d.is_dir():
            n, b = _folder_size(d)
            out.append(ItemSummary(sub.replace("/", " "), sub, n, "images", b))
    d = root / "survey"
    if d.is_dir():
        for f in sorted(d.glob("*.csv")):
            out.append(ItemSummary(f"survey {f.stem}", str(f.relative_to(root)), _rows(f), "rows", f.stat().st_size))
    return out
