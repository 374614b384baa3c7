"""What to print: markers by ID list, every marker of a rig, the calibration boards of ``boards.yaml``."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from gtrig import geometry as geo
from gtrig.errors import InputError
from gtrig.markers.families import family_spec
from gtrig.markers.sheets import Tile, chessboard_tile, marker_tile
from gtrig.rig.models import MarkerFamily, Rig

if TYPE_CHECKING:
    from gtrig.calib.chessboard import Board, BoardsSpec


def parse_ids(text: str, family: MarkerFamily) -> list[int]:
    """``"14"``, ``"3,6,14"`` or ``"0-11"`` (ranges inclusive, mixed freely) as a list of IDs of ``family``."""
    ids: list[int] = []
    n_ids = family_spec(family).n_ids
    for tok in (t.strip() for t in text.split(",")):
        try:
            lo, _, hi = tok.partition("-")
            a = int(lo)
            b = int(hi) if hi else a
        except ValueError:
            raise InputError(f"--id {text!r}: expected IDs like 14, 3,6,14 or 0-11") from None
        if b < a or a < 0 or b >= n_ids:
            raise InputError(f"--id {tok!r}: out of range, {family.value} has IDs 0 to {n_ids - 1}")
        ids.extend(range(a, b + 1))
    if len(set(ids)) != len(ids):
        raise InputError(f"--id {text!r}: an ID is named twice")
    return ids


def rig_marker_tiles(rig: Rig, source: str) -> list[Tile]:
    """One tile per marker of ``rig.robot.markers``, in the rig's order, family and side from the rig."""
    if not rig.robot.markers:
        raise InputError(f"{source}: robot.markers is empty: no marker to print")
    return [marker_tile(m.family, m.id, m.side_m * 1000.0) for m in rig.robot.markers]


def _xyz_mm(T: np.ndarray) -> str:
    return ", ".join(f"{v * 1000:.0f}" for v in T[:3, 3])


def _rpy_deg(T: np.ndarray) -> str:
    return ", ".join(f"{np.degrees(a):.1f}" for a in geo.rpy_from_T(T))


def board_tile(board: Board, title: str, notes: tuple[str, ...] = ()) -> Tile:
    """One chessboard sheet of ``board``'s geometry."""
    return chessboard_tile(board.cols, board.rows, board.square_m * 1000.0, title, notes)


def boards_tiles(spec: BoardsSpec) -> list[Tile]:
    """The calibration boards of ``boards.yaml``: the double board's two boards (board 1 also serves the
    intrinsic sweeps) and, when ``T_world_board`` is given, the world board; one geometry for all."""
    T12 = spec.T_board1_board2
    tiles = [
        board_tile(spec.board, "double board: board 1 (also the intrinsic sweeps' board)",
                   ("mount board 2 rigidly at T_board1_board2 from it",)),
        board_tile(spec.board, "double board: board 2",
                   (f"in board 1's frame at xyz {_xyz_mm(T12)} mm, rpy {_rpy_deg(T12)} deg",)),
    ]
    if spec.T_world_board is not None:
        Tw = spec.T_world_board
        tiles.append(board_tile(spec.board, "world board",
                                (f"place at T_world_board: xyz {_xyz_mm(Tw)} mm, rpy {_rpy_deg(Tw)} deg",)))
    return tiles
