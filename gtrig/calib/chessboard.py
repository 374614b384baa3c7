"""Chessboard geometry, image folders, and subpixel corner detection.

Board frame
-----------
A board with ``cols x rows`` *inner* corners and squares of ``square_m`` metres. Corner ``k = r * cols + c``
(row-major, ``c`` along the long side, as OpenCV's ``patternSize=(cols, rows)``) is at
``(c * square_m, r * square_m, 0) - origin``. ``origin="corner"`` (default, OpenCV's and Bouguet's
convention) puts the frame at the first inner corner; ``"centre"`` at the centre of the corner grid.
z points into the board, away from a camera that sees the printed side: a camera looking at the board
is on its ``-z`` side.

Detection (:func:`detect_corners`) uses ``cv2.findChessboardCorners`` then ``cv2.cornerSubPix``, falling
back to ``cv2.findChessboardCornersSB``. The grid is re-ordered so that the board frame is right-handed
with the camera on its ``-z`` side; what remains ambiguous for a board whose squares are even in both
directions (such as the seeds' 10 x 6 squares) is a half turn about the board's z axis, which
:func:`flip_half_turn` applies and the network step resolves with the nominal rig.
"""

from __future__ import annotations

import logging
import os
import re
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from gtrig import geometry as geo
from gtrig.calib.idboards import IdBoard, id_board_from_dict
from gtrig.errors import FormatError, InputError
from gtrig.io.yamlfile import load_yaml

log = logging.getLogger(__name__)

IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff", ".pgm", ".ppm", ".webp")
# Detection runs on images scaled down to at most this many pixels on the long side; corners are then
# refined at full resolution (large real images make findChessboardCorners slow and no more reliable).
DETECT_MAX_SIDE_PX = 1600


@dataclass(frozen=True)
class Board:
    """A planar chessboard: ``cols`` x ``rows`` inner corners, squares of ``square_m`` metres."""

    cols: int
    rows: int
    square_m: float
    origin: str = "corner"

    def __post_init__(self) -> None:
        if self.cols < 2 or self.rows < 2:
            raise InputError(f"board {self.cols}x{self.rows}: needs at least 2 x 2 inner corners")
        if not 0.0 < self.square_m < 2.0:
            raise InputError(
                f"board square {self.square_m:g} m is implausible (millimetres given as metres?)"
            )
        if self.origin not in ("corner", "centre"):
            raise InputError(f"board origin {self.origin!r}: expected 'corner' or 'centre'")

    @property
    def pattern_size(self) -> tuple[int, int]:
        """``(cols, rows)`` as OpenCV's ``patternSize``."""
        return (self.cols, self.rows)

    @property
    def n_corners(self) -> int:
        return self.cols * self.rows

    def object_points(self) -> geo.Array:
        """Inner corners (N, 3) in the board frame, metres, in detection order."""
        c, r = np.meshgrid(np.arange(self.cols), np.arange(self.rows))
        p = np.column_stack([c.ravel(), r.ravel(), np.zeros(c.size)]).astype(np.float64) * self.square_m
        if self.origin == "centre":
            p[:, :2] -= np.array([(self.cols - 1) * self.square_m / 2, (self.rows - 1) * self.square_m / 2])
        return p

    def spec(self) -> str:
        return f"{self.cols}x{self.rows}x{self.square_m:g}"


def parse_board(spec: str, origin: str = "corner") -> Board:
    """``"9x5x0.100"`` (inner corners along x, along y, square side in metres) to a :class:`Board`."""
    m = re.fullmatch(r"\s*(\d+)\s*[xX]\s*(\d+)\s*[xX]\s*([0-9.eE+-]+)\s*", spec)
    if not m:
        raise InputError(
            f"--board {spec!r}: expected COLSxROWSxSQUARE, e.g. 9x5x0.100 (inner corners, metres)"
        )
    try:
        square = float(m.group(3))
    except ValueError:
        raise InputError(f"--board {spec!r}: the square size {m.group(3)!r} is not a number") from None
    cols, rows = int(m.group(1)), int(m.group(2))
    if not (2 <= cols <= 200 and 2 <= rows <= 200):
        raise InputError(f"--board {spec!r}: a board has 2 to 200 inner corners along each side")
    if not 0.001 <= square <= 1.0:
        hint = " (millimetres given for metres?)" if square > 1.0 else ""
        raise InputError(f"--board {spec!r}: the square side must be 0.001 to 1 m, got {square:g}{hint}")
    return Board(int(m.group(1)), int(m.group(2)), square, origin)


def list_images(folder: str | os.PathLike[str]) -> list[Path]:
    """The image files of ``folder`` (not recursive), sorted by name; errors if there are none."""
    d = Path(folder)
    if not d.is_dir():
        raise InputError(f"{d}: no such folder")
    files = sorted(p for p in d.iterdir() if p.is_file() and p.suffix.lower() in IMAGE_SUFFIXES)
    if not files:
        raise InputError(f"{d}: no images ({', '.join(IMAGE_SUFFIXES)})")
    return files


def read_grey(path: str | os.PathLike[str]) -> np.ndarray:
    """Any image OpenCV reads (grey, colour, 16-bit) as 8-bit grey (H, W)."""
    p = Path(path)
    img = cv2.imread(str(p), cv2.IMREAD_UNCHANGED)
    if img is None:
        raise FormatError(f"{p}: cannot read the image")
    if img.dtype != np.uint8:
        img = img.astype(np.float64)
        hi = float(img.max()) or 1.0
        img = np.clip(img * (255.0 / hi), 0, 255).astype(np.uint8)
    if img.ndim == 3:
        code = cv2.COLOR_BGRA2GRAY if img.shape[2] == 4 else cv2.COLOR_BGR2GRAY
        img = cv2.cvtColor(img, code)
    return img


def _subpix_window(corners: np.ndarray, board: Board) -> int:
    g = corners.reshape(board.rows, board.cols, 2)
    d = np.concatenate(
        [
            np.linalg.norm(np.diff(g, axis=1), axis=2).ravel(),
            np.linalg.norm(np.diff(g, axis=0), axis=2).ravel(),
        ]
    )
    return int(np.clip(0.35 * float(np.min(d)), 2, 15))


def _orient(corners: np.ndarray, board: Board) -> np.ndarray:
    """Re-order a detected grid so that the board frame is right-handed with the camera on its -z side.

    In the image (x right, y down, z forward), board x (along a row) crossed with board y (down the
    columns) must point forward, away from the camera.
    """
    g = corners.reshape(board.rows, board.cols, 2)
    ex = g[:, -1].mean(axis=0) - g[:, 0].mean(axis=0)
    ey = g[-1].mean(axis=0) - g[0].mean(axis=0)
    if ex[0] * ey[1] - ex[1] * ey[0] < 0:
        g = g[:, ::-1]
    return g.reshape(-1, 2)


def flip_half_turn(corners: np.ndarray) -> np.ndarray:
    """The other valid ordering of a grid: a half turn about the board's z axis (reverse the order)."""
    return np.ascontiguousarray(np.asarray(corners)[::-1])


def detect_corners(img: np.ndarray, board: Board, *, refine: bool = True) -> np.ndarray | None:
    """Subpixel inner corners (N, 2) of ``board`` in an 8-bit grey image, or None if not found.

    Pixel centres at integer coordinates (OpenCV). The order is ``k = r * cols + c`` with the
    orientation fixed as in the module docstring (up to a half turn).
    """
    h, w = img.shape[:2]
    scale = min(1.0, DETECT_MAX_SIDE_PX / max(h, w))
    small = (
        cv2.resize(img, (round(w * scale), round(h * scale)), interpolation=cv2.INTER_AREA)
        if scale < 1
        else img
    )
    flags = cv2.CALIB_CB_ADAPTIVE_THRESH | cv2.CALIB_CB_NORMALIZE_IMAGE
    found, corners = cv2.findChessboardCorners(small, board.pattern_size, flags=flags)
    sb = False
    if not found:
        found, corners = cv2.findChessboardCornersSB(
            small, board.pattern_size, flags=cv2.CALIB_CB_EXHAUSTIVE | cv2.CALIB_CB_ACCURACY
        )
        sb = True
    if not found or corners is None or len(corners) != board.n_corners:
        return None
    corners = corners.reshape(-1, 2).astype(np.float32)
    if scale < 1:
        corners = (corners + 0.5) / scale - 0.5
    if refine and (not sb or scale < 1):
        win = _subpix_window(corners, board)
        crit = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 100, 1e-4)
        corners = cv2.cornerSubPix(img, corners.reshape(-1, 1, 2), (win, win), (-1, -1), crit).reshape(-1, 2)
    return _orient(corners.astype(np.float64), board)


@dataclass(frozen=True)
class Detection:
    """The corners of one board in one image: ``corners_px`` (N, 2), pixels, board order."""

    file: str
    path: Path
    corners_px: np.ndarray
    image_size: tuple[int, int]


@dataclass(frozen=True)
class FolderDetections:
    """Detections over a folder: ``found`` in name order, ``missing`` names with no board."""

    folder: Path
    image_size: tuple[int, int]
    found: tuple[Detection, ...]
    missing: tuple[str, ...]


def _check_size(p: Path, img: np.ndarray, size: tuple[int, int] | None, first: str) -> tuple[int, int]:
    s = (int(img.shape[1]), int(img.shape[0]))
    if size is not None and s != size:
        raise InputError(
            f"{p}: mixed resolutions: {s[0]} x {s[1]} but {first} is {size[0]} x {size[1]} "
            f"(one camera per folder, one resolution)"
        )
    return s


def _wrong_board_hint(images: Sequence[tuple[Path, np.ndarray]], board: Board) -> str:
    """Look for a board of another size in a few images, to turn 'nothing found' into a useful hint."""
    tries = [
        (board.cols - 1, board.rows - 1),
        (board.cols + 1, board.rows + 1),
        (board.cols - 1, board.rows),
        (board.cols, board.rows - 1),
        (board.cols + 1, board.rows),
        (board.cols, board.rows + 1),
    ]
    for p, img in images[:3]:
        h, w = img.shape[:2]
        scale = min(1.0, 800 / max(h, w))
        small = cv2.resize(img, (round(w * scale), round(h * scale)), interpolation=cv2.INTER_AREA)
        for c, r in tries:
            if c < 2 or r < 2:
                continue
            ok, _ = cv2.findChessboardCorners(
                small, (c, r), flags=cv2.CALIB_CB_ADAPTIVE_THRESH | cv2.CALIB_CB_FAST_CHECK
            )
            if ok:
                sq = (
                    "; count inner corners, not squares" if (c, r) == (board.cols - 1, board.rows - 1) else ""
                )
                return (f", but a {c}x{r} board is in {p.name}: wrong board size? "
                        f"(--board {c}x{r}x{board.square_m:g}{sq})")
    return ""


def detect_folder(
    folder: str | os.PathLike[str], board: Board, files: Sequence[Path] | None = None
) -> FolderDetections:
    """Detect ``board`` in every image of ``folder`` (or in ``files``).

    Raises
    ------
    InputError
        Mixed resolutions; no board in any image (with a hint when a board of another size is seen).
    """
    d = Path(folder)
    paths = list(files) if files is not None else list_images(d)
    size: tuple[int, int] | None = None
    found: list[Detection] = []
    missing: list[str] = []
    misses: list[tuple[Path, np.ndarray]] = []
    for p in paths:
        img = read_grey(p)
        size = _check_size(p, img, size, paths[0].name)
        c = detect_corners(img, board)
        if c is None:
            missing.append(p.name)
            if len(misses) < 3:
                misses.append((p, img))
            log.debug("%s: no %dx%d board", p, board.cols, board.rows)
            if not found and len(missing) == 3 and len(paths) > 3:
                # three misses in a row from the start: a wrong board size is likely, say so now
                hint = _wrong_board_hint(misses, board)
                if hint:
                    raise InputError(
                        f"{d}: no {board.cols}x{board.rows} chessboard in the first 3 images" + hint
                    )
        else:
            found.append(Detection(p.name, p, c, size))
    if not found:
        raise InputError(
            f"{d}: no {board.cols}x{board.rows} chessboard found in any of {len(paths)} image(s)"
            + _wrong_board_hint(misses, board)
        )
    assert size is not None
    return FolderDetections(d, size, tuple(found), tuple(missing))


@dataclass(frozen=True)
class BoardsSpec:
    """``calib/boards.yaml``: the board geometry, the double board's transform and the world board.

    Attributes
    ----------
    board : Board
        Both boards of the double board and the world board share this geometry.
    T_board1_board2 : (4, 4) nominal pose of board 2 in board 1's frame (metres).
    T_world_board : (4, 4) pose of the world-anchoring board in the world, or None.
    sweep_board : the board of the intrinsic sweeps when it is a ChArUco board or an AprilGrid
        (``sweep_board:`` of the document, a board document of :mod:`gtrig.calib.idboards`); None: the
        sweeps show ``board``.
    """

    board: Board
    T_board1_board2: np.ndarray
    T_world_board: np.ndarray | None
    source: str = "<boards>"
    sweep_board: IdBoard | None = None


def _pose_from_yaml(v: Any, where: str) -> np.ndarray:
    from pydantic import ValidationError

    from gtrig.rig.models import Pose

    if isinstance(v, list | tuple) and len(v) == 4:
        T = np.asarray(v, dtype=float)
        if T.shape == (4, 4):
            return T
    try:
        return Pose.model_validate(v).matrix()
    except ValidationError as e:
        raise FormatError(
            f"{where}: expected a pose {{xyz, quat_xyzw | rpy_deg}} or a 4 x 4 matrix "
            f"({e.errors()[0]['msg']})"
        ) from None


def boards_spec_from_dict(data: Any, source: str = "<boards>") -> BoardsSpec:
    """Parse a boards document (see :func:`read_boards_yaml`)."""
    if not isinstance(data, dict):
        raise FormatError(f"{source}: expected a mapping with board, T_board1_board2, T_world_board")
    b = data.get(
        "board", data.get("chessboard", data if ("inner_corners" in data or "squares" in data) else None)
    )
    if not isinstance(b, dict):
        raise FormatError(f"{source}: board: missing (inner_corners: [cols, rows], square_m)")
    try:
        if "inner_corners" in b:
            cols, rows = (int(x) for x in b["inner_corners"])
        elif "squares" in b:
            cols, rows = (int(x) - 1 for x in b["squares"])
        else:
            raise KeyError("inner_corners")
        square = float(b["square_m"] if "square_m" in b else b["square"])
    except (KeyError, TypeError, ValueError):
        raise FormatError(f"{source}: board: expected inner_corners: [cols, rows] and square_m") from None
    board = Board(cols, rows, square, str(b.get("origin", "corner")))
    if "T_board1_board2" not in data:
        raise FormatError(f"{source}: T_board1_board2: missing field")
    T12 = _pose_from_yaml(data["T_board1_board2"], f"{source}: T_board1_board2")
    Twb = data.get("T_world_board")
    sweep = data.get("sweep_board")
    return BoardsSpec(
        board, T12, None if Twb is None else _pose_from_yaml(Twb, f"{source}: T_world_board"), source,
        None if sweep is None else id_board_from_dict(sweep, f"{source}: sweep_board"),
    )


def read_boards_yaml(path: str | os.PathLike[str]) -> BoardsSpec:
    """Read ``boards.yaml``::

    inner_corners: [9, 5]        # or squares: [10, 6]; may also sit under a "board:" key
    square_m: 0.100
    origin: corner               # optional: corner (first inner corner, default) or centre
    T_board1_board2: {xyz: [1.5, 0, 0], quat_xyzw: [0, 0, 0, 1]}
    T_world_board: {xyz: [...], rpy_deg: [180, 0, 0]}
    sweep_board: {type: charuco, squares: [10, 6], ...}  # optional: the sweeps' ChArUco board or AprilGrid
    """
    p = Path(path)
    return boards_spec_from_dict(load_yaml(p), str(p))
