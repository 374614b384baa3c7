"""Camera frame sequences: ``cameras/<cam>/timestamps.csv`` (``frame,stamp_s,file``) plus images, or a
video (``video.mp4``, ``video.mkv``, ...) decoded with OpenCV, its frame count checked against the stamps."""

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
#: ``<video>#frame=<n>``: an image source naming one frame of a video (:func:`read_image`)
VIDEO_FRAME_SEP = "#frame="


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

    def source(self, i: int) -> str:
        """Where frame ``i`` is: its image file, or ``<video>#frame=<n>`` (:func:`read_image` reads both)."""
        if self.video is not None:
            return f"{self.video}{VIDEO_FRAME_SEP}{int(self.frames[i])}"
        return str(self.path(i))

    def read(self, i: int) -> np.ndarray:
        """Frame ``i`` as an 8-bit grey image (from its image file, or decoded from the video)."""
        return read_image(self.source(i))

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


class _VideoDecoder:
    """One open video, decoded forward; a frame behind the position, or far ahead, is sought."""

    def __init__(self, path: str) -> None:
        self.path = path
        self.cap = cv2.VideoCapture(path)
        if not self.cap.isOpened():
            raise FormatError(f"{path}: OpenCV cannot open this video")
        self.next = 0

    def frame(self, n: int) -> np.ndarray:
        if n < self.next or n > self.next + 64:
            self.cap.set(cv2.CAP_PROP_POS_FRAMES, n)
            self.next = n
        while self.next < n:
            if not self.cap.grab():
                raise FormatError(f"{self.path}: ends before frame {n}")
            self.next += 1
        ok, img = self.cap.read()
        if not ok:
            raise FormatError(f"{self.path}: cannot read frame {n}")
        self.next += 1
        return img if img.ndim == 2 else cv2.cvtColor(img, cv2.COLOR_BGR2GRAY)


_DECODERS: dict[str, _VideoDecoder] = {}


def read_image(source: str | os.PathLike[str]) -> np.ndarray:
    """An 8-bit grey image from an image file or from ``<video>#frame=<n>`` (:meth:`FrameIndex.source`).

    Greyscale PNGs are decoded by :mod:`gtrig.io.png`, every other file by OpenCV (``IMREAD_GRAYSCALE``);
    both give the same pixels.

    Videos are decoded forward by one decoder per video and process (the stages read frames in time
    order, so a sequence costs one decode of the video, not one seek per frame).
    """
    s = str(source)
    if VIDEO_FRAME_SEP in s:
        path, n = s.rsplit(VIDEO_FRAME_SEP, 1)
        dec = _DECODERS.get(path)
        if dec is None:
            if len(_DECODERS) >= 8:  # one per camera is the usual need
                _DECODERS.pop(next(iter(_DECODERS))).cap.release()
            dec = _DECODERS[path] = _VideoDecoder(path)
        return dec.frame(int(n))
    img = _read_grey_png(s) if s[-4:].lower() == ".png" else None
    if img is None:
        img = cv2.imread(s, cv2.IMREAD_GRAYSCALE)
    if img is None:
        raise FormatError(f"{s}: cannot read the image")
    check_image_size(img, s)
    return img


def _read_grey_png(path: str) -> np.ndarray | None:
    """A greyscale PNG decoded by :func:`gtrig.io.png.decode_grey_png` (the same pixels as OpenCV's, in a
    third of its time), or None: any other PNG, one beyond :data:`MAX_IMAGE_PIXELS`, or a file that cannot be
    opened, is OpenCV's to read (and refuse)."""
    from gtrig.io.png import decode_grey_png  # compiled on first use, not by every reader of timestamps

    try:
        with open(path, "rb") as fh:
            data = fh.read()
    except OSError:
        return None
    return decode_grey_png(data, MAX_IMAGE_PIXELS)


#: the largest image a stage processes: 64 megapixels (a 12 MP photo is far inside; a 20000 x 20000 px
#: image would hold the detector for minutes in more than a gigabyte)
MAX_IMAGE_PIXELS = 64_000_000


def check_image_size(img: np.ndarray, source: str | os.PathLike[str]) -> None:
    """Refuse an image beyond :data:`MAX_IMAGE_PIXELS` with one line naming it."""
    n = int(img.shape[0]) * int(img.shape[1])
    if n > MAX_IMAGE_PIXELS:
        raise FormatError(f"{source}: {img.shape[1]} x {img.shape[0]} px is more than the "
                          f"{MAX_IMAGE_PIXELS / 1e6:g} megapixels gtrig processes; downscale or crop it")


def video_frame_count(video: Path) -> int:
    """Frames in ``video``: the container's count when it states one, else every frame grabbed
    (FFV1 in Matroska states none; grabbing decodes, about as fast as reading the video once)."""
    cap = cv2.VideoCapture(str(video))
    try:
        if not cap.isOpened():
            raise FormatError(f"{video}: OpenCV cannot open this video")
        n = int(cap.get(cv2.CAP_PROP_FRAME_COUNT))
        if video.suffix.lower() == ".mkv" or n <= 0:
            n = 0
            while cap.grab():
                n += 1
        return n
    finally:
        cap.release()


def write_frame_index(folder: str | os.PathLike[str], stamps_s: np.ndarray, files: list[str]) -> None:
    """Write ``timestamps.csv`` for the images already in ``folder``."""
    with atomic_open(Path(folder) / "timestamps.csv", "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["frame", "stamp_s", "file"])
        for i, (t, name) in enumerate(zip(stamps_s, files, strict=True)):
            w.writerow([i, f"{t:.6f}", name])


#: frame numbers are counts of images: a billion is a year of video at 30 frames per second
MAX_FRAME = 10**9


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
        if not 0 <= frames[-1] < MAX_FRAME:
            raise FormatError(f"{p}:{line}: frame {row[0].strip()[:30]} is not a frame number (0 to {MAX_FRAME - 1})")
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
    if video is not None:
        n_video = video_frame_count(video)
        if n_video != len(frames):
            raise FormatError(f"{video}: {n_video} frames, but {p} stamps {len(frames)}")
        fr = np.array(frames, dtype=int)
        if np.any(fr != np.arange(len(fr))):
            bad = int(np.argmax(fr != np.arange(len(fr))))
            raise FormatError(f"{p}:{bad + 2}: frame {fr[bad]}, expected {bad} (a video's frames are numbered "
                              "0, 1, 2, ...)")
    return FrameIndex(folder.name, folder, np.array(frames, dtype=int), st, tuple(files), video)
