"""Small rendered chessboard image sets, shared by the calibration tests (rendered once per session)."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest

from gtrig.calib import synth
from gtrig.calib.aprilgrid import AprilGrid
from gtrig.calib.chessboard import Board

SIZE = (480, 360)
K = np.array([[420.0, 0, 241.3], [0, 421.0, 178.6], [0, 0, 1]])
DIST = np.array([-0.15, 0.08, 2e-4, -1e-4, 0.0])
BOARD = Board(9, 5, 0.03)


@pytest.fixture(scope="session")
def sweep_dir(tmp_path_factory) -> Path:
    """Twelve rendered views of a 9x5 board of 30 mm squares, as PNG, plus one JPEG without a board."""
    d = tmp_path_factory.mktemp("sweep")
    rng = np.random.default_rng(11)
    for i, T in enumerate(synth.random_intrinsic_views(rng, K, DIST, SIZE, BOARD, 12, depth_m=(0.4, 0.8))):
        img = synth.render_board_view(K, DIST, SIZE, T, BOARD, rng=rng, supersample=2)
        if i == 3:
            img = cv2.cvtColor(img, cv2.COLOR_GRAY2BGR)  # colour images are fine
        cv2.imwrite(str(d / f"{i:03d}.png"), img)
    cv2.imwrite(str(d / "blank.jpg"), np.full((SIZE[1], SIZE[0]), 128, np.uint8))
    return d


def aprilgrid_texture(g: AprilGrid) -> synth.Texture:
    """The printed AprilGrid ``g`` on a white sheet reaching 0.6 tag beyond its tags (NaN off the sheet)."""
    x0, y0, x1, y1 = g.extent_m()
    margin = 0.6 * g.tag_m

    def tex(x: np.ndarray, y: np.ndarray) -> np.ndarray:
        v = np.where(g.black(x, y), 25.0, 225.0)
        sheet = (x > x0 - margin) & (x < x1 + margin) & (y > y0 - margin) & (y < y1 + margin)
        return np.where(sheet, v, np.nan)

    return tex
