"""Independent check of a calibrated rig: a chessboard on a table at surveyed poses (the seeds' table
check, AD2.3: "a small chessboard placed on the corner of a table", compared with the validation pose).

``POSES.csv``: ``camera,image,x,y,z[,yaw_deg]``: for each image (``IMAGES/<camera>/<image>``) the
surveyed world position (metres) of the board origin (its first inner corner) and, optionally, the
heading of the board's x axis in the world x-y plane (degrees). The board is located by PnP with the
calibrated intrinsics and carried into the world with the calibrated ``T_world_cam``.
"""

from __future__ import annotations

import csv
import math
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from gtrig import geometry as geo
from gtrig.calib.anchor import board_pose
from gtrig.calib.chessboard import Board, detect_corners, read_grey
from gtrig.errors import FormatError, InputError
from gtrig.rig.models import Rig


@dataclass(frozen=True)
class CheckRow:
    """One checked image: estimated and surveyed board origin (world, metres), errors in mm / deg."""

    camera: str
    image: str
    xyz_est: np.ndarray
    xyz_true: np.ndarray
    err_mm: np.ndarray
    yaw_err_deg: float
    reproj_px: float


def _check_inside(csv_path: Path, line: int, image: str) -> None:
    """Refuse an image name that would leave ``IMAGES/<camera>/``: empty, absolute, or with ``..`` parts."""
    from pathlib import PurePosixPath, PureWindowsPath

    posix, windows = PurePosixPath(image), PureWindowsPath(image)
    if not image or posix.is_absolute() or windows.is_absolute() or windows.drive or ".." in windows.parts:
        raise FormatError(f"{csv_path}:{line}: image {image!r} is outside the images folder (an absolute path "
                          "or '..' parts); name it relative to IMAGES/<camera>/")


def read_check_poses(path: str | os.PathLike[str]) -> list[tuple[str, str, np.ndarray, float]]:
    """Rows ``(camera, image, xyz (3,), yaw_deg or NaN)`` of ``POSES.csv``."""
    p = Path(path)
    if not p.is_file():
        raise InputError(f"{p}: no such file")
    out = []
    with open(p, newline="", encoding="utf-8") as f:
        rows = csv.reader(f)
        header = [h.strip() for h in next(rows, [])]
        if header[:5] != ["camera", "image", "x", "y", "z"]:
            raise FormatError(f"{p}:1: header must be 'camera,image,x,y,z[,yaw_deg]'")
        for line, row in enumerate(rows, 2):
            if not row or row[0].startswith("#"):
                continue
            try:
                xyz = np.array([float(v) for v in row[2:5]])
                yaw = float(row[5]) if len(row) > 5 and row[5].strip() else math.nan
            except (ValueError, IndexError):
                raise FormatError(f"{p}:{line}: expected camera,image,x,y,z[,yaw_deg] with numbers") from None
            image = row[1].strip()
            _check_inside(p, line, image)
            out.append((row[0].strip(), image, xyz, yaw))
    if not out:
        raise FormatError(f"{p}: no rows")
    return out


def check_rig(
    rig: Rig, images_dir: str | os.PathLike[str], poses_csv: str | os.PathLike[str], board: Board
) -> list[CheckRow]:
    """Locate the board in every listed image and compare with its surveyed pose."""
    root = Path(images_dir)
    out = []
    for cam_name, image, xyz, yaw in read_check_poses(poses_csv):
        try:
            cam = rig.camera(cam_name)
        except KeyError:
            raise InputError(f"{poses_csv}: camera {cam_name!r} is not in the rig") from None
        p = root / cam_name / image
        if not p.is_file():
            raise InputError(f"{p}: no such image")
        c = detect_corners(read_grey(p), board)
        if c is None:
            raise InputError(f"{p}: no {board.cols}x{board.rows} chessboard found")
        # half-turn ambiguity of the grid: take the ordering closest to the surveyed heading, or, without
        # a heading, the one whose origin is nearest the surveyed point
        cands = []
        for cc in (c, c[::-1].copy()):
            T_cam_board, rms = board_pose(cam.K, cam.dist, cc, board)
            T = cam.T_world_cam.matrix() @ T_cam_board
            h = math.degrees(math.atan2(T[1, 0], T[0, 0]))
            dyaw = math.nan if math.isnan(yaw) else math.degrees(float(geo.wrap_angle(np.radians(h - yaw))))
            key = abs(dyaw) if not math.isnan(yaw) else float(np.linalg.norm(T[:3, 3] - xyz))
            cands.append((key, T, dyaw, rms))
        _, T_world_board, yaw_err, rms = min(cands, key=lambda t: t[0])
        est = T_world_board[:3, 3]
        out.append(CheckRow(cam_name, image, est, xyz, (est - xyz) * 1000, yaw_err, rms))
    return out
