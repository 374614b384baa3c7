"""TUM (``timestamp tx ty tz qx qy qz qw``) and gtrig's TUM + covariance CSV pair.

Precision kept: stamps 1 us, positions 1 nm, quaternion components 1e-12 (gtrig.io.tum.tum_text).
The pair's covariance CSV is written with Python's shortest round-trip ``repr``: exact.

A TUM file ``NAME.tum`` has its covariance in ``NAME_cov.csv`` beside it (the pipeline's
``results/gt_laser.tum`` + ``results/gt_laser_cov.csv``); the reader picks it up when it exists.
"""

from __future__ import annotations

import os
from pathlib import Path

from gtrig.io.posetrack import read_pose_track, write_pose_track
from gtrig.io.tum import tum_text
from gtrig.trajectory import PoseTrack


def cov_path_for(path: str | os.PathLike[str]) -> Path:
    """``NAME_cov.csv`` beside ``NAME.tum`` (or ``NAME.txt``)."""
    p = Path(path)
    return p.with_name(f"{p.stem}_cov.csv")


def read_tum_track(path: str | os.PathLike[str], cov_path: str | os.PathLike[str] | None = None,
                   pair: bool | None = None) -> PoseTrack:
    """A TUM file as a pose track, with its covariance CSV when one is given or sits beside it.

    ``pair=True`` requires the covariance CSV (the ``gtrig`` format); ``False`` ignores it.
    """
    cov = Path(cov_path) if cov_path is not None else cov_path_for(path)
    if pair is False and cov_path is None:
        return read_pose_track(path)
    if cov_path is None and not cov.is_file():
        if pair:
            from gtrig.errors import FormatError

            raise FormatError(f"{path}: the gtrig pair needs its covariance CSV {cov} (not found)")
        return read_pose_track(path)
    return read_pose_track(path, cov)


def write_tum_track(track: PoseTrack, path: str | os.PathLike[str], pair: bool = False) -> list[Path]:
    """Write TUM only, or (``pair``) the TUM file and ``NAME_cov.csv`` together; returns the paths."""
    if pair:
        write_pose_track(track, path, cov_path_for(path))
        return [Path(path), cov_path_for(path)]
    from gtrig.io.atomic import atomic_write_text

    atomic_write_text(path, tum_text(track))
    return [Path(path)]
