"""Camera frame sequences: ``cameras/<cam>/timestamps.csv`` (``frame,stamp_s,file``) plus images."""

from __future__ import annotations

import csv
import os
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from gtrig.errors import FormatError
from gtrig.io.atomic import atomic_open

VIDEO_SUFFIXES = (".mp4", ".avi", ".mkv", ".mov")


@dataclass(frozen=True)
class FrameIndex:
    """The frames of one camera: ``frames`` (N,) frame numbers, ``stamps_s`` (N,), ``files`` (N,) image names
    (empty when the frames come from ``video``, where ``frames`` are the video's frame numbers)."""

    camera: str
    folder: Path
    frames: np.ndarray
    stamps_s: np.ndarray
    files: tuple[str, ...]

    video: Path | None = None

    def __len__(self) -> int:
        return int(self.frames.size)

    def path(self, i: int) -> Path:
        return self.folder / self.files[i]

    def read(self, i: int) -> np.ndarray:
        """Frame ``i`` as an 8-bit grey image (from its image file, or seeking in the video)."""
        if self.video is not None:
            cap = cv2.VideoCapture(str(self.video))
            try:
                cap.set(cv2.CAP_PROP_POS_FRAMES, int(self.frames[i]))
                ok, img = cap.read()
            finally:
                cap.release()
            if not ok:
                raise FormatError(f"{self.video}: cannot read frame {int(self.frames[i])}")
            return img if img.ndim == 2 else cv2.cvtColor(img, cv2.COLOR_BGR2GRAY)
        p = self.path(i)
        img = cv2.imread(str(p), cv2.IMREAD_GRAYSCALE)
        if img is None:
            raise FormatError(f"{p}: cannot read the image")
        return img

    def iter_images(self) -> Iterator[tuple[float, np.ndarray]]:
        """``(stamp_s, image)`` in order; a video is decoded sequentially, not seeked per frame."""
        if self.video is None:
            for i in range(len(self)):
                yield float(self.stamps_s[i]), self.read(i)
            return
        cap = cv2.VideoCapture(str(self.video))
        try:
            wanted = {int(f): k for k, f in enumerate(self.frames)}
            n = 0
            while wanted:
                ok, img = cap.read()
                if not ok:
                    raise FormatError(f"{self.video}: ends before frame {min(wanted)} listed in timestamps.csv")
                if n in wanted:
                    k = wanted.pop(n)
                    yield float(self.stamps_s[k]), img if img.ndim == 2 else cv2.cvtColor(img, cv2.COLOR_BGR2GRAY)
                n += 1
        finally:
            cap.release()


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
    try:
        text = p.read_text(encoding="utf-8")
    except UnicodeDecodeError:
        raise FormatError(f"{p}: not a text CSV file (undecodable bytes)") from None
    except OSError as e:
        raise FormatError(f"{p}: cannot read ({e.strerror or e})") from None
    if "\0" in text:
        raise FormatError(f"{p}: holds NUL bytes, not a CSV file")
    rows = csv.reader(text.splitlines())
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
        name = row[2].strip() if len(row) > 2 else ""
        if name and (Path(name).name != name or name in (".", "..")):
            # a recording is self-contained: an index may not point outside its camera's folder
            raise FormatError(f"{p}:{line}: file {name!r} is not a plain file name in this folder")
        files.append(name)
    st = np.array(stamps)
    if not np.all(np.isfinite(st)):
        raise FormatError(f"{p}: a time stamp is not a finite number")
    if st.size and np.any(np.diff(st) <= 0):
        raise FormatError(f"{p}: time stamps do not increase at line {int(np.argmax(np.diff(st) <= 0)) + 3}")
    videos = sorted(v for v in folder.glob("video.*") if v.suffix.lower() in VIDEO_SUFFIXES)
    video = videos[0] if videos and not any(files) else None
    if video is None and not all(files):
        raise FormatError(f"{p}: rows without a file name and no video.* beside it")
    return FrameIndex(folder.name, folder, np.array(frames, dtype=int), st, tuple(files), video)
