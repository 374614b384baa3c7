"""A board's corners (ChArUco board or AprilGrid) in every (or every n-th) frame of the cameras' videos,
with frame times and instants."""

from __future__ import annotations

import logging
import os
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from gtrig.calib.charuco import CharucoView
from gtrig.calib.idboards import IdBoard, corner_detector
from gtrig.errors import InputError
from gtrig.io.video import CameraVideo, read_camera_video

log = logging.getLogger(__name__)

VIDEO_SUFFIXES = (".mp4", ".avi", ".mkv", ".mov")


@dataclass(frozen=True)
class VideoDetections:
    """A board's corners in one camera's video.

    Attributes
    ----------
    camera : the camera's name.
    image_size : (w, h) pixels.
    n_frames_read : frames decoded and searched.
    frame_k : (V,) indices into the camera's stamped frames of the views with the board.
    stamps_s : (V,) their times, seconds.
    sync_index : (V,) their instants (frames of one instant share it across cameras).
    views : (V,) the corners seen in each.
    """

    camera: str
    image_size: tuple[int, int]
    n_frames_read: int
    frame_k: np.ndarray
    stamps_s: np.ndarray
    sync_index: np.ndarray
    views: tuple[CharucoView, ...]


def detect_video(video: CameraVideo, board: IdBoard, step: int = 1, *, mirrored: bool = False) -> VideoDetections:
    """Detect ``board`` (a ChArUco board or an AprilGrid, by its own detector) in every ``step``-th frame of
    ``video`` (frames decoded one at a time); ``mirrored``: the video is left-right mirrored (the frame is
    flipped back before detection, :meth:`CharucoCornerDetector.detect`)."""
    detector = corner_detector(board)
    ks: list[int] = []
    views: list[CharucoView] = []
    size: tuple[int, int] = (0, 0)
    n = 0
    for k, grey in video.iter_frames(step):
        size = (int(grey.shape[1]), int(grey.shape[0]))
        n += 1
        v = detector.detect(grey, mirrored=mirrored)
        if v is not None:
            ks.append(k)
            views.append(v)
    kk = np.asarray(ks, dtype=int)
    log.info("%s: the board in %d of %d frames read", video.camera, len(views), n)
    return VideoDetections(video.camera, size, n, kk, video.stamps_s[kk], video.sync_index[kk], tuple(views))


def find_videos(folder: str | os.PathLike[str]) -> list[CameraVideo]:
    """The cameras' videos of a folder, each with its frame-time file.

    ``<cam>.mp4`` (or .avi, .mkv, .mov) with ``<cam>.timestamps.csv`` (gtrig's plain layout) beside it, or
    with the folder's ``timestamps.csv`` (caliscope's layout, all cameras in one file, ``cam_N`` videos).
    """
    d = Path(folder)
    if not d.is_dir():
        raise InputError(f"{d}: no such folder")
    videos = sorted(p for p in d.iterdir() if p.suffix.lower() in VIDEO_SUFFIXES and p.is_file())
    if not videos:
        raise InputError(f"{d}: no videos ({', '.join(VIDEO_SUFFIXES)})")
    out = []
    for v in videos:
        own = v.with_name(v.stem + ".timestamps.csv")
        shared = d / "timestamps.csv"
        if not own.is_file() and not shared.is_file():
            raise InputError(f"{v}: no frame-time file ({own.name} or timestamps.csv beside it)")
        out.append(read_camera_video(v, own if own.is_file() else shared))
    return out


def detect_videos(videos: Sequence[CameraVideo], board: IdBoard, step: int = 1,
                  mirrored: Sequence[str] = ()) -> dict[str, VideoDetections]:
    """:func:`detect_video` for each camera, by camera name; the cameras named in ``mirrored`` are flipped."""
    unknown = set(mirrored) - {v.camera for v in videos}
    if unknown:
        raise InputError(f"mirrored camera(s) {', '.join(sorted(unknown))}: no such video")
    return {v.camera: detect_video(v, board, step, mirrored=v.camera in mirrored) for v in videos}
