"""A camera's video with a frame-time file: frames read on demand, dropped and duplicated frames reported.

Frame-time files (docs/formats.md, "Camera videos")
---------------------------------------------------
- gtrig's plain ``timestamps.csv``: ``frame,stamp_s[,file]``, one row per video frame (the file column
  empty), as for a camera folder's ``video.mp4``.
- caliscope's ``timestamps.csv``: ``sync_index,cam_id[,frame_index],frame_time``, the rows of every camera
  of a recording in one file; a camera's rows are those of its ``cam_id``. Without ``frame_index`` the
  camera's rows are its video's frames in order. ``sync_index`` groups the cameras' frames of one instant.

Frame timing
------------
The nominal period is the median of the stamps' differences. A gap of more than 1.5 periods is
``round(gap / period) - 1`` dropped frames; a difference under a quarter of the period is a duplicated
frame (the same instant stamped twice). Both are reported (:class:`FrameTiming`), never repaired.
"""

from __future__ import annotations

import csv
import logging
import os
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from gtrig.errors import FormatError

log = logging.getLogger(__name__)

DROP_GAP_PERIODS = 1.5
DUPLICATE_GAP_PERIODS = 0.25


@dataclass(frozen=True)
class FrameTiming:
    """Frame timing of one camera (module docstring).

    Attributes
    ----------
    period_s : nominal frame period (median stamp difference), seconds.
    n_dropped : frames missing in the gaps.
    dropped_after : (G,) indices of the frames after which frames are missing.
    n_duplicated : frames stamped within a quarter period of the previous one.
    duplicated_at : (D,) indices of those frames.
    """

    period_s: float
    n_dropped: int
    dropped_after: np.ndarray
    n_duplicated: int
    duplicated_at: np.ndarray

    def summary(self) -> str:
        return (f"{1.0 / self.period_s:.2f} frames/s, {self.n_dropped} dropped, "
                f"{self.n_duplicated} duplicated")


def frame_timing(stamps_s: np.ndarray) -> FrameTiming:
    """The nominal period, dropped and duplicated frames of stamps (N,), seconds, in time order."""
    t = np.asarray(stamps_s, dtype=float).ravel()
    if t.size < 2:
        return FrameTiming(float("nan"), 0, np.zeros(0, int), 0, np.zeros(0, int))
    d = np.diff(t)
    period = float(np.median(d))
    if not period > 0:
        raise FormatError("frame stamps: the median frame period is not positive")
    gaps = np.flatnonzero(d > DROP_GAP_PERIODS * period)
    n_drop = int(np.sum(np.round(d[gaps] / period) - 1))
    dup = np.flatnonzero(d < DUPLICATE_GAP_PERIODS * period) + 1
    return FrameTiming(period, n_drop, gaps, int(dup.size), dup)


@dataclass(frozen=True)
class CameraVideo:
    """One camera's video and its frames' times.

    Attributes
    ----------
    camera : the camera's name.
    video : the video file.
    frames : (N,) video frame numbers (0-based) of the stamped frames.
    stamps_s : (N,) their times, seconds.
    sync_index : (N,) the recording's instant of each frame (caliscope), or the frame numbers.
    timing : dropped and duplicated frames.
    """

    camera: str
    video: Path
    frames: np.ndarray
    stamps_s: np.ndarray
    sync_index: np.ndarray
    timing: FrameTiming

    def __len__(self) -> int:
        return int(self.frames.size)

    def iter_frames(self, step: int = 1) -> Iterator[tuple[int, np.ndarray]]:
        """``(k, grey image)`` for every ``step``-th stamped frame ``k``, decoded on demand in order.

        The video is decoded forward once; skipped frames are grabbed, not converted, and no more than
        one frame is held at a time.
        """
        if step < 1:
            raise ValueError("step must be at least 1")
        wanted = {int(self.frames[k]): k for k in range(0, len(self), step)}
        cap = cv2.VideoCapture(str(self.video))
        if not cap.isOpened():
            raise FormatError(f"{self.video}: OpenCV cannot open this video")
        try:
            n, last = 0, max(wanted, default=-1)
            while n <= last:
                if n in wanted:
                    ok, img = cap.read()
                    if not ok:
                        raise FormatError(f"{self.video}: ends before frame {n} listed in its frame-time file")
                    yield wanted[n], img if img.ndim == 2 else cv2.cvtColor(img, cv2.COLOR_BGR2GRAY)
                elif not cap.grab():
                    raise FormatError(f"{self.video}: ends before frame {n} listed in its frame-time file")
                n += 1
        finally:
            cap.release()


def _video_frames(video: Path) -> int:
    cap = cv2.VideoCapture(str(video))
    try:
        if not cap.isOpened():
            raise FormatError(f"{video}: OpenCV cannot open this video")
        return int(cap.get(cv2.CAP_PROP_FRAME_COUNT))
    finally:
        cap.release()


def _read_rows(path: Path) -> tuple[list[str], list[tuple[int, list[str]]]]:
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as e:
        raise FormatError(f"{path}: cannot read as a text CSV file ({e})") from None
    rows = csv.reader(text.splitlines())
    header = [h.strip() for h in next(rows, [])]
    body = [(line, row) for line, row in enumerate(rows, 2) if row and not row[0].startswith("#")]
    return header, body


def _caliscope_rows(path: Path, header: list[str], body: list[tuple[int, list[str]]],
                    cam_id: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    col = {h: i for i, h in enumerate(header)}
    sync, stamps = [], []
    for line, row in body:
        try:
            if int(row[col["cam_id"]]) != cam_id:
                continue
            sync.append(int(row[col["sync_index"]]))
            stamps.append(float(row[col["frame_time"]]))
        except (ValueError, IndexError):
            raise FormatError(f"{path}:{line}: expected {','.join(header)} as numbers") from None
    if not stamps:
        raise FormatError(f"{path}: no rows for cam_id {cam_id}")
    order = np.argsort(stamps, kind="stable")
    return np.arange(len(stamps)), np.asarray(stamps, float)[order], np.asarray(sync, int)[order]


def _plain_rows(path: Path, body: list[tuple[int, list[str]]]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    frames, stamps = [], []
    for line, row in body:
        try:
            frames.append(int(row[0]))
            stamps.append(float(row[1]))
        except (ValueError, IndexError):
            raise FormatError(f"{path}:{line}: expected 'frame,stamp_s'") from None
    fr = np.asarray(frames, int)
    return fr, np.asarray(stamps, float), fr.copy()


def read_camera_video(video: str | os.PathLike[str], stamps_file: str | os.PathLike[str],
                      camera: str | None = None, cam_id: int | None = None) -> CameraVideo:
    """A camera's video with its frame-time file (gtrig's plain or caliscope's layout, module docstring).

    Parameters
    ----------
    video : the video file (any OpenCV reads).
    stamps_file : its frame-time file.
    camera : the camera's name (default: the video's stem).
    cam_id : caliscope's camera number (default: the digits ending the video's stem, ``cam_2`` -> 2).

    Raises
    ------
    FormatError
        An unknown header, a malformed row (file and line named), a frame beyond the video, stamps
        not increasing.
    """
    vp, sp = Path(video), Path(stamps_file)
    if not vp.is_file():
        raise FormatError(f"{vp}: no such video")
    if not sp.is_file():
        raise FormatError(f"{sp}: no such frame-time file")
    header, body = _read_rows(sp)
    if header[:2] == ["frame", "stamp_s"]:
        frames, stamps, sync = _plain_rows(sp, body)
    elif {"sync_index", "cam_id", "frame_time"} <= set(header):
        if cam_id is None:
            digits = "".join(ch for ch in vp.stem.split("_")[-1] if ch.isdigit())
            if not digits:
                raise FormatError(f"{vp}: no camera number in the name; give cam_id for {sp}")
            cam_id = int(digits)
        frames, stamps, sync = _caliscope_rows(sp, header, body, cam_id)
    else:
        raise FormatError(f"{sp}:1: header must be 'frame,stamp_s[,file]' or caliscope's "
                          "'sync_index,cam_id[,frame_index],frame_time'")
    if not np.all(np.isfinite(stamps)):
        raise FormatError(f"{sp}: a frame time is not a finite number")
    if np.any(frames < 0) or np.any(np.diff(frames) <= 0):
        raise FormatError(f"{sp}: frame numbers must be distinct and not negative")
    if np.any(np.diff(stamps) < 0):
        raise FormatError(f"{sp}: frame times decrease after frame {int(frames[np.argmax(np.diff(stamps) < 0)])}")
    n_video = _video_frames(vp)
    if n_video > 0 and frames[-1] >= n_video:
        raise FormatError(f"{sp}: frame {int(frames[-1])} is beyond {vp}'s {n_video} frames")
    timing = frame_timing(stamps)
    if n_video > 0 and n_video != frames.size:
        log.warning("%s: %d frames, %d stamped in %s", vp, n_video, frames.size, sp)
    if timing.n_dropped or timing.n_duplicated:
        log.warning("%s: %s", vp, timing.summary())
    return CameraVideo(camera or vp.stem, vp, frames, stamps, sync, timing)
