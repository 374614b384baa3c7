"""Camera frame sequences: ``cameras/<cam>/timestamps.csv`` (``frame,stamp_s,file``) plus images."""

from __future__ import annotations

import csv
import os
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from gtrig.errors import FormatError
from gtrig.io.atomic import atomic_open


@dataclass(frozen=True)
class FrameIndex:
    """The frames of one camera: ``frames`` (N,) ints, ``stamps_s`` (N,), ``files`` (N,) paths."""

    camera: str
    folder: Path
    frames: np.ndarray
    stamps_s: np.ndarray
    files: tuple[str, ...]

    def path(self, i: int) -> Path:
        return self.folder / self.files[i]

    def read(self, i: int) -> np.ndarray:
        """Frame ``i`` as an 8-bit grey image."""
        p = self.path(i)
        img = cv2.imread(str(p), cv2.IMREAD_GRAYSCALE)
        if img is None:
            raise FormatError(f"{p}: cannot read the image")
        return img


def write_frame_index(folder: str | os.PathLike[str], stamps_s: np.ndarray, files: list[str]) -> None:
    """Write ``timestamps.csv`` for the images already in ``folder``."""
    with atomic_open(Path(folder) / "timestamps.csv", "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["frame", "stamp_s", "file"])
        for i, (t, name) in enumerate(zip(stamps_s, files, strict=True)):
            w.writerow([i, f"{t:.6f}", name])


def read_frame_index(folder: str | os.PathLike[str]) -> FrameIndex:
    """Read ``<folder>/timestamps.csv``; errors name the file and line."""
    folder = Path(folder)
    p = folder / "timestamps.csv"
    if not p.is_file():
        raise FormatError(f"{p}: no such file (each camera folder needs frame,stamp_s,file)")
    frames, stamps, files = [], [], []
    with open(p, newline="", encoding="utf-8") as f:
        rows = csv.reader(f)
        header = next(rows, None)
        if header is None or [h.strip() for h in header[:2]] != ["frame", "stamp_s"]:
            raise FormatError(f"{p}:1: header must be 'frame,stamp_s,file'")
        for line, row in enumerate(rows, 2):
            if not row or row[0].startswith("#"):
                continue
            try:
                frames.append(int(row[0]))
                stamps.append(float(row[1]))
            except (ValueError, IndexError):
                raise FormatError(f"{p}:{line}: expected 'frame,stamp_s,file'") from None
            files.append(row[2] if len(row) > 2 else "")
    st = np.array(stamps)
    if st.size and np.any(np.diff(st) <= 0):
        raise FormatError(f"{p}: time stamps do not increase at line {int(np.argmax(np.diff(st) <= 0)) + 3}")
    return FrameIndex(folder.name, folder, np.array(frames, dtype=int), st, tuple(files))
