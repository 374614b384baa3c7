"""The candidate stage on blobs of low solidity (issue 16, the harder set): a marker whose thin border is
broken where white cells touch it keeps its square outline; clutter of low solidity gives no candidate."""

from __future__ import annotations

import cv2
import numpy as np

from gtrig.markers.detect.candidates import CandidateParams, _blob_quad, find_candidates


def _broken_marker(gaps: int) -> tuple[np.ndarray, np.ndarray]:
    """A 40 px dark square (border 5 px) with white cells inside, ``gaps`` of them opened through the
    border to the paper: the outer contour runs into the square there."""
    img = np.full((120, 120), 220, np.uint8)
    x0, y0, s = 40, 40, 40
    img[y0:y0 + s, x0:x0 + s] = 30
    # white data cells (5 px) in a chessboard-like pattern
    for i in range(1, 7):
        for j in range(1, 7):
            if (i * 3 + j * 5) % 4 == 0:
                img[y0 + 5 * i:y0 + 5 * i + 5, x0 + 5 * j:x0 + 5 * j + 5] = 220
    # the gaps: a white cell next to the border, joined to the paper through the border
    for i, j in [(1, 3), (6, 2), (3, 6), (4, 1)][:gaps]:
        img[y0 + 5 * i:y0 + 5 * i + 5, x0 + 5 * j:x0 + 5 * j + 5] = 220
        if i == 1:
            img[y0:y0 + 5, x0 + 5 * j:x0 + 5 * j + 4] = 220
        elif i == 6:
            img[y0 + 35:y0 + 40, x0 + 5 * j:x0 + 5 * j + 4] = 220
        elif j == 6:
            img[y0 + 5 * i:y0 + 5 * i + 4, x0 + 35:x0 + 40] = 220
        else:
            img[y0 + 5 * i:y0 + 5 * i + 4, x0:x0 + 5] = 220
    truth = np.array([[x0, y0], [x0 + s, y0], [x0 + s, y0 + s], [x0, y0 + s]], float) - 0.5
    return img, truth


def _solidity(img: np.ndarray) -> float:
    cs, _ = cv2.findContours((img < 100).astype(np.uint8), cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
    c = max(cs, key=cv2.contourArea)
    return cv2.contourArea(c) / cv2.contourArea(cv2.convexHull(c))


def test_broken_border_keeps_its_square() -> None:
    """Four gaps take the blob's solidity under the 0.85 limit; the candidate is still the square."""
    img, truth = _broken_marker(4)
    assert _solidity(img) < CandidateParams().min_solidity
    quads = find_candidates(img, CandidateParams(more_thresholds=()), 0.9)
    assert len(quads) == 1
    err = np.min([np.abs(np.roll(quads[0], r, axis=0) - truth).max() for r in range(4)])
    assert err < 1.0


def test_low_solidity_clutter_gives_nothing() -> None:
    """An L, a cross and a comb (solidity under the limit, hull not a traced quadrilateral): no candidate."""
    img = np.full((200, 300), 220, np.uint8)
    img[20:80, 20:35] = 30
    img[65:80, 20:80] = 30  # an L
    img[100:160, 140:155] = 30
    img[122:137, 115:180] = 30  # a cross
    img[20:35, 200:270] = 30
    for x in range(200, 270, 14):
        img[20:80, x:x + 5] = 30  # a comb
    cs, hier = cv2.findContours((img < 100).astype(np.uint8), cv2.RETR_CCOMP, cv2.CHAIN_APPROX_NONE)
    for i, c in enumerate(cs):
        if hier[0][i][3] < 0:
            q, why = _blob_quad(c, cs, hier[0], i, CandidateParams(), 0.9)
            assert q is None and why is not None and why.startswith("solidity")
    assert find_candidates(img, CandidateParams(), 0.9) == []
