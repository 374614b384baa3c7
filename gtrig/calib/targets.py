"""Calibration targets from board files: gtrig's, caliscope's ``charuco.toml`` and Kalibr's target YAML.

:func:`read_target_file` returns a chessboard (:class:`gtrig.calib.chessboard.Board`), a ChArUco board or
an AprilGrid (:mod:`gtrig.calib.idboards`). Besides the documents those modules read, it reads
Kalibr's checkerboard target as it is::

    target_type: 'checkerboard'
    targetCols: 6            # inner corners along x
    targetRows: 7            # inner corners along y
    rowSpacingMeters: 0.06   # square side
    colSpacingMeters: 0.06

and gtrig's chessboard document ``type: chessboard``, ``inner_corners: [cols, rows]``, ``square_m``.
Kalibr's checkerboard frame and gtrig's share the first inner corner and the axes along the rows and
the columns; squares that are not square (row and column spacings differing) are refused.
"""

from __future__ import annotations

import logging
import os
from pathlib import Path
from typing import Any

from gtrig.calib.charuco import load_board_document
from gtrig.calib.chessboard import Board
from gtrig.calib.idboards import IdBoard, id_board_from_dict
from gtrig.errors import FormatError, InputError

log = logging.getLogger(__name__)

#: any board gtrig calibrates with
Target = Board | IdBoard


def chessboard_from_kalibr(d: dict[str, Any], where: str) -> Board:
    """Kalibr's ``target_type: checkerboard`` target as gtrig's chessboard."""
    try:
        cols, rows = d["targetCols"], d["targetRows"]
        dy, dx = float(d["rowSpacingMeters"]), float(d["colSpacingMeters"])
    except KeyError as e:
        raise FormatError(f"{where}: {e.args[0]}: missing field (Kalibr's checkerboard target)") from None
    except (TypeError, ValueError):
        raise FormatError(f"{where}: rowSpacingMeters, colSpacingMeters: expected numbers (metres)") from None
    if not (isinstance(cols, int) and isinstance(rows, int)):
        raise FormatError(f"{where}: targetCols, targetRows: expected integers (inner corners)")
    if abs(dx - dy) > 1e-9 * max(dx, dy):
        raise FormatError(f"{where}: rowSpacingMeters {dy:g} and colSpacingMeters {dx:g} differ: only square "
                          "squares are supported")
    return Board(cols, rows, dx)


def _chessboard_from_gtrig(d: dict[str, Any], where: str) -> Board:
    try:
        cols, rows = (int(v) for v in d["inner_corners"])
        return Board(cols, rows, float(d["square_m"]), str(d.get("origin", "corner")))
    except KeyError as e:
        raise FormatError(f"{where}: {e.args[0]}: missing field (type: chessboard needs inner_corners, "
                          "square_m)") from None
    except (TypeError, ValueError):
        raise FormatError(f"{where}: expected inner_corners: [cols, rows] and square_m as numbers") from None


def target_from_dict(data: Any, source: str = "<board>") -> Target:
    """A chessboard, ChArUco board or AprilGrid from a parsed board document (module docstring)."""
    if isinstance(data, dict):
        if str(data.get("target_type", "")).lower() == "checkerboard":
            return chessboard_from_kalibr(data, source)
        if str(data.get("type", "")).lower() == "chessboard":
            return _chessboard_from_gtrig(data, source)
    return id_board_from_dict(data, source)


def read_target_file(path: str | os.PathLike[str]) -> Target:
    """Read a board file: ``.toml`` (caliscope's ``charuco.toml`` or gtrig's) or YAML (gtrig's, Kalibr's)."""
    p = Path(path)
    board = target_from_dict(load_board_document(p), str(p))
    log.info("%s: %s", p, board.spec())
    return board


def read_id_board_file(path: str | os.PathLike[str]) -> IdBoard:
    """Read a board file that must describe a board with corner IDs (a ChArUco board or an AprilGrid)."""
    board = read_target_file(path)
    if isinstance(board, Board):
        raise InputError(f"{path}: a chessboard: this step needs a board whose corners carry IDs (a ChArUco "
                         "board or an AprilGrid), for partial views")
    return board
