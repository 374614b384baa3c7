"""ChArUco boards: geometry, board files (gtrig's and caliscope's ``charuco.toml``), corner detection.

Board frame
-----------
The layout of OpenCV's ``cv2.aruco.CharucoBoard``: ``squares_x`` x ``squares_y`` squares of ``square_m``
metres, ArUco markers of ``marker_m`` metres in the white squares. Inner corner ``k`` (its ChArUco ID) is
at ``((c + 1) * square_m, (r + 1) * square_m, 0)`` with ``k = r * (squares_x - 1) + c``: the origin is the
board's outer corner, x along a row of squares, y down the columns, z into the board (a camera that sees
the printed side is on its ``-z`` side), as OpenCV's ``getChessboardCorners``. A view of the board sees
any subset of the corners, each with its ID, so the views are partial corner sets (unlike a chessboard's
full grid) and carry no orientation ambiguity.

``legacy_pattern`` is OpenCV's ``setLegacyPattern``: boards printed before OpenCV 4.6 with an even number
of rows start with a marker instead of a black square.

Markers may be printed inverted (white on black); the detector then looks for inverted markers
(``DetectorParameters.detectInvertedMarker``).

Board files
-----------
:func:`read_board_file` reads gtrig's board file (YAML or TOML; docs/calibrate-from-video.md)::

    type: charuco
    squares: [4, 5]          # along x, along y
    square_m: 0.054
    marker_m: 0.0405
    dictionary: DICT_4X4_1000
    inverted: true           # optional, default false
    legacy_pattern: false    # optional

and caliscope's ``charuco.toml`` (``columns``, ``rows``, ``dictionary``, ``aruco_scale``, ``inverted``,
``square_size_override_cm`` or else ``board_width`` / ``board_height`` in ``units`` (inch or cm), the
square then being the largest that fits).
"""

from __future__ import annotations

import logging
import os
import tomllib
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from gtrig.calib.saddle import SaddleFit, local_homographies, refine_saddles
from gtrig.errors import FormatError, InputError
from gtrig.io.yamlfile import load_yaml

log = logging.getLogger(__name__)

#: the fewest corners of one view kept (a pose from fewer is not determined well)
MIN_CORNERS = 4
#: the saddle refinement's reach along the squares' edges, squares (the chessboard's window, 0.35 of the
#: corner spacing; on the simulator's sweeps 0.25 / 0.35 / 0.45 give 0.030 / 0.027 / 0.026 px RMS)
SADDLE_REACH = 0.35


def aruco_dictionaries() -> dict[str, int]:
    """OpenCV's predefined ArUco / AprilTag dictionaries by name (``DICT_4X4_50``, ...)."""
    return {n: int(getattr(cv2.aruco, n)) for n in dir(cv2.aruco) if n.startswith("DICT_")}


@dataclass(frozen=True)
class CharucoBoard:
    """A ChArUco board (module docstring).

    Attributes
    ----------
    squares_x, squares_y : squares along the board's x and y axes.
    square_m : side of a square, metres.
    marker_m : side of a marker, metres (less than ``square_m``).
    dictionary : an OpenCV dictionary name, e.g. ``"DICT_4X4_1000"``.
    inverted : markers printed white on black.
    legacy_pattern : OpenCV's pre-4.6 layout (only differs for an even ``squares_y``).
    """

    squares_x: int
    squares_y: int
    square_m: float
    marker_m: float
    dictionary: str
    inverted: bool = False
    legacy_pattern: bool = False

    def __post_init__(self) -> None:
        if not (2 <= self.squares_x <= 100 and 2 <= self.squares_y <= 100):
            raise InputError(f"ChArUco board {self.squares_x} x {self.squares_y}: 2 to 100 squares per side")
        if not 0.001 <= self.square_m <= 1.0:
            raise InputError(f"ChArUco square {self.square_m:g} m: expected 0.001 to 1 m")
        if not 0.0 < self.marker_m < self.square_m:
            raise InputError(
                f"ChArUco marker {self.marker_m:g} m: must be positive and smaller than the square "
                f"({self.square_m:g} m)"
            )
        names = aruco_dictionaries()
        if self.dictionary not in names:
            known = ", ".join(sorted(names)[:6])
            raise InputError(f"ChArUco dictionary {self.dictionary!r}: not one of OpenCV's ({known}, ...)")
        n_markers = (self.squares_x * self.squares_y) // 2
        size = cv2.aruco.getPredefinedDictionary(names[self.dictionary]).bytesList.shape[0]
        if n_markers > size:
            raise InputError(f"ChArUco board needs {n_markers} markers, {self.dictionary} has {size}")

    @property
    def n_corners(self) -> int:
        return (self.squares_x - 1) * (self.squares_y - 1)

    def object_points(self) -> np.ndarray:
        """Inner corners (N, 3) in the board frame, metres, indexed by ChArUco corner ID."""
        cols = self.squares_x - 1
        k = np.arange(self.n_corners)
        c, r = k % cols, k // cols
        return np.column_stack([(c + 1) * self.square_m, (r + 1) * self.square_m, np.zeros(k.size)])

    def opencv_board(self) -> cv2.aruco.CharucoBoard:
        """The equivalent ``cv2.aruco.CharucoBoard``."""
        d = cv2.aruco.getPredefinedDictionary(aruco_dictionaries()[self.dictionary])
        b = cv2.aruco.CharucoBoard((self.squares_x, self.squares_y), self.square_m, self.marker_m, d)
        b.setLegacyPattern(self.legacy_pattern)
        return b

    def spec(self) -> str:
        inv = ", inverted" if self.inverted else ""
        return (f"ChArUco {self.squares_x} x {self.squares_y} squares of {1000 * self.square_m:g} mm, markers "
                f"{1000 * self.marker_m:g} mm, {self.dictionary}{inv}")


@dataclass(frozen=True)
class CharucoView:
    """The corners of a board with corner IDs (a ChArUco board, an AprilGrid) seen in one image.

    Attributes
    ----------
    ids : (N,) corner IDs (indices into the board's ``object_points()``), increasing.
    corners_px : (N, 2) subpixel corner positions, pixels (pixel centres at integers).
    cov_px : (N, 2, 2) each corner's covariance, px^2, when the detector states one (else None); NaN for
        a corner it could not refine (:class:`CharucoCornerDetector`).
    """

    ids: np.ndarray
    corners_px: np.ndarray
    cov_px: np.ndarray | None = None


class CharucoCornerDetector:
    """OpenCV's ``CharucoDetector`` for one board, set up once and used on many images; its corners are
    then refined on their saddles (:mod:`gtrig.calib.saddle`) with the strip along the squares' edges that
    the markers leave free, and given a covariance. A corner the refinement cannot take (squares too small
    in the image for the strip, a window over the image's edge, a saddle that does not converge near its
    seed) keeps OpenCV's position and a NaN covariance.
    """

    def __init__(self, board: CharucoBoard) -> None:
        self.board = board
        params = cv2.aruco.DetectorParameters()
        params.detectInvertedMarker = board.inverted
        self._detector = cv2.aruco.CharucoDetector(board.opencv_board(), cv2.aruco.CharucoParameters(), params)

    def detect(self, grey: np.ndarray, min_corners: int = MIN_CORNERS, *, mirrored: bool = False) -> CharucoView | None:
        """The board's corners in an 8-bit grey image, or None with fewer than ``min_corners``.

        ``mirrored``: the image is a left-right mirror of what the lens saw (a webcam's mirror mode); it is
        flipped back before detection, and the corners are in the unmirrored image.
        """
        img = cv2.flip(grey, 1) if mirrored else grey
        corners, ids, _mc, _mi = self._detector.detectBoard(img)
        if ids is None or len(ids) < min_corners:
            return None
        ids_ = np.asarray(ids, dtype=np.int64).ravel()
        order = np.argsort(ids_)
        ids_, xy = ids_[order], np.asarray(corners, dtype=np.float64).reshape(-1, 2)[order]
        fit = self.refine(img, ids_, xy)
        return CharucoView(ids_, fit.corners_px, fit.cov_px)

    def refine(self, grey: np.ndarray, ids: np.ndarray, corners_px: np.ndarray) -> SaddleFit:
        """Corners ``corners_px`` (N, 2) with IDs ``ids`` (N,) refined on their saddles in ``grey``."""
        b = self.board
        cols = b.squares_x - 1
        board_uv = np.column_stack([ids % cols, ids // cols]).astype(np.float64)
        H = local_homographies(board_uv, corners_px)
        margin = 0.5 * (b.square_m - b.marker_m) / b.square_m
        return refine_saddles(grey, corners_px, H, margin, SADDLE_REACH)


def _board_from_gtrig(d: dict[str, Any], where: str) -> CharucoBoard:
    try:
        sx, sy = (int(v) for v in d["squares"])
        square = float(d["square_m"])
        marker = float(d["marker_m"]) if "marker_m" in d else square * float(d["marker_scale"])
        return CharucoBoard(sx, sy, square, marker, str(d["dictionary"]), bool(d.get("inverted", False)),
                            bool(d.get("legacy_pattern", False)))
    except KeyError as e:
        raise FormatError(f"{where}: {e.args[0]}: missing field (type: charuco needs squares, square_m, "
                          "marker_m, dictionary)") from None
    except (TypeError, ValueError):
        raise FormatError(f"{where}: expected squares: [x, y], square_m, marker_m as numbers") from None


_UNITS_M = {"inch": 0.0254, "inches": 0.0254, "in": 0.0254, "cm": 0.01, "mm": 0.001, "m": 1.0}


def _board_from_caliscope(d: dict[str, Any], where: str) -> CharucoBoard:
    try:
        cols, rows = int(d["columns"]), int(d["rows"])
        if "square_size_override_cm" in d:
            square = float(d["square_size_override_cm"]) / 100.0
        else:
            unit = _UNITS_M.get(str(d.get("units", "inch")).lower())
            if unit is None:
                raise FormatError(f"{where}: units {d.get('units')!r}: expected inch or cm")
            square = min(float(d["board_width"]) / cols, float(d["board_height"]) / rows) * unit
        scale = float(d.get("aruco_scale", 0.75))
        square = round(square, 9)  # to the nanometre: 5.4 cm is 0.054 m, not 0.054000000000000006
        return CharucoBoard(cols, rows, square, round(square * scale, 9), str(d["dictionary"]),
                            bool(d.get("inverted", False)), bool(d.get("legacy_pattern", False)))
    except KeyError as e:
        raise FormatError(f"{where}: {e.args[0]}: missing field (caliscope's charuco.toml)") from None
    except (TypeError, ValueError):
        raise FormatError(f"{where}: columns, rows and sizes must be numbers") from None


def board_from_dict(data: Any, source: str = "<board>") -> CharucoBoard:
    """A ChArUco board from a parsed board document (gtrig's or caliscope's, see the module docstring)."""
    if not isinstance(data, dict):
        raise FormatError(f"{source}: expected a mapping describing a ChArUco board")
    if isinstance(data.get("charuco"), dict):  # caliscope's config.toml holds its board under [charuco]
        data = data["charuco"]
    if "columns" in data and "rows" in data:
        return _board_from_caliscope(data, source)
    kind = str(data.get("type", "charuco")).lower()
    if kind != "charuco":
        raise FormatError(f"{source}: type {kind!r}: only 'charuco' boards are read from a board file")
    return _board_from_gtrig(data, source)


def charuco_board_document(board: CharucoBoard) -> dict[str, Any]:
    """``board`` as gtrig's board document (module docstring); :func:`board_from_dict` reads it back."""
    return {"type": "charuco", "squares": [board.squares_x, board.squares_y], "square_m": board.square_m,
            "marker_m": board.marker_m, "dictionary": board.dictionary, "inverted": board.inverted,
            "legacy_pattern": board.legacy_pattern}


def load_board_document(path: str | os.PathLike[str]) -> Any:
    """The parsed document of a board file: ``.toml`` as TOML, anything else as YAML; one-line errors."""
    p = Path(path)
    if not p.is_file():
        raise InputError(f"{p}: no such board file")
    if p.suffix.lower() == ".toml":
        try:
            return tomllib.loads(p.read_text(encoding="utf-8"))
        except (tomllib.TOMLDecodeError, UnicodeDecodeError) as e:
            raise FormatError(f"{p}: not a TOML file ({e})") from None
    return load_yaml(p)


def read_board_file(path: str | os.PathLike[str]) -> CharucoBoard:
    """Read a ChArUco board file: ``.toml`` (caliscope's ``charuco.toml`` or gtrig's) or YAML."""
    p = Path(path)
    board = board_from_dict(load_board_document(p), str(p))
    log.info("%s: %s", p, board.spec())
    return board
