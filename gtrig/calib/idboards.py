"""Boards whose corners carry IDs (ChArUco boards, AprilGrids): one type, one detector, one reader.

A view of such a board is any subset of its corners, each with its ID (a
:class:`gtrig.calib.charuco.CharucoView`), so partial views calibrate lenses and link cameras.

Board documents
---------------
:func:`id_board_from_dict` reads, besides the ChArUco documents of :mod:`gtrig.calib.charuco`, an
AprilGrid in gtrig's form::

    type: aprilgrid
    tags: [6, 6]        # along x, along y
    tag_m: 0.088        # a tag's black square, edge to edge
    spacing: 0.3        # the gap between tags over tag_m

or in Kalibr's target YAML (``target_type: aprilgrid``, ``tagCols``, ``tagRows``, ``tagSize``,
``tagSpacing``), read as it is.
"""

from __future__ import annotations

from typing import Any

from gtrig.calib.aprilgrid import AprilGrid, AprilGridDetector
from gtrig.calib.charuco import CharucoBoard, CharucoCornerDetector, board_from_dict
from gtrig.errors import FormatError

__all__ = ["AprilGrid", "CharucoBoard", "IdBoard", "aprilgrid_from_kalibr", "corner_detector", "id_board_from_dict"]

#: a board whose corners carry IDs
IdBoard = CharucoBoard | AprilGrid


def corner_detector(board: IdBoard) -> CharucoCornerDetector | AprilGridDetector:
    """The detector of ``board``'s corners; both return a ``CharucoView`` (IDs and pixels) or None."""
    if isinstance(board, AprilGrid):
        return AprilGridDetector(board)
    return CharucoCornerDetector(board)


def _number(d: dict[str, Any], key: str, where: str, kind: type = float) -> Any:
    if key not in d:
        raise FormatError(f"{where}: {key}: missing field")
    v = d[key]
    if isinstance(v, bool) or not isinstance(v, int | float) or (kind is int and not float(v).is_integer()):
        raise FormatError(f"{where}: {key}: expected {'an integer' if kind is int else 'a number'}, got {v!r}")
    return kind(v)


def aprilgrid_from_kalibr(d: dict[str, Any], where: str) -> AprilGrid:
    """Kalibr's ``target_type: aprilgrid`` target (tagCols, tagRows, tagSize in metres, tagSpacing ratio)."""
    return AprilGrid(_number(d, "tagCols", where, int), _number(d, "tagRows", where, int),
                     _number(d, "tagSize", where), _number(d, "tagSpacing", where))


def _aprilgrid_from_gtrig(d: dict[str, Any], where: str) -> AprilGrid:
    tags = d.get("tags")
    if not (isinstance(tags, list) and len(tags) == 2 and all(isinstance(t, int) for t in tags)):
        raise FormatError(f"{where}: tags: expected [cols, rows] (tags along x, along y)")
    return AprilGrid(int(tags[0]), int(tags[1]), _number(d, "tag_m", where), _number(d, "spacing", where))


def id_board_from_dict(data: Any, source: str = "<board>") -> IdBoard:
    """A ChArUco board or an AprilGrid from a parsed board document (module docstring)."""
    if isinstance(data, dict):
        if str(data.get("target_type", "")).lower() == "aprilgrid":
            return aprilgrid_from_kalibr(data, source)
        if str(data.get("type", "")).lower() == "aprilgrid":
            return _aprilgrid_from_gtrig(data, source)
        if "target_type" in data:
            raise FormatError(f"{source}: target_type {data['target_type']!r}: a board with corner IDs is a "
                              "Kalibr aprilgrid (a checkerboard has none)")
    return board_from_dict(data, source)
