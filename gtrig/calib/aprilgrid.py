"""AprilGrid boards (Kalibr's calibration target): geometry, printed pattern, corner detection.

Layout
------
``tag_cols`` x ``tag_rows`` tag36h11 tags of side ``tag_m`` (the black square, edge to edge), ``spacing``
x ``tag_m`` apart, tag IDs ``0 .. cols * rows - 1`` row by row from the bottom-left tag as printed. Each
tag has a 2-module black border around its 6 x 6 data bits (10 modules across; the standard tag36h11 has
one), its code is turned half a turn from the tag36h11 image (Kalibr's ``rotation=2``), and a black
square of ``spacing * tag_m`` sits diagonally off each of its corners, so that every tag corner is also a
chessboard-like saddle for sub-pixel refinement.

Corner IDs and the board frame
------------------------------
The corners are Kalibr's points: a grid of ``2 tag_rows`` x ``2 tag_cols`` tag corners, ID
``k = R * 2 tag_cols + C`` with ``C`` counting along x and ``R`` upwards from the bottom-left tag's
bottom-left corner; Kalibr puts corner ``k`` at ``(x_C, y_R, 0)`` with
``x_C = (C // 2) (1 + spacing) tag_m + (C % 2) tag_m`` (``y_R`` alike), in a frame with x right and y up
as printed. gtrig's board frame is that frame turned half a turn about x (``(x, -y, -z)``): x along a
row, y down the printed sheet, z into the board, as the chessboard's and the ChArUco board's frames, so
a camera that sees the print is on its ``-z`` side; ``T_kalibr_gtrig = diag(1, -1, -1)``.

Detection
---------
OpenCV's ``ArucoDetector`` with ``DICT_APRILTAG_36h11`` and ``markerBorderBits = 2`` finds the tags;
each tag's four corners are then refined with ``cv2.cornerSubPix`` on their saddle, in windows sized
from the tag's side in pixels; a corner whose saddle the window does not reach is left out
(:func:`_refine`).
"""

from __future__ import annotations

import functools
import logging
from dataclasses import dataclass
from typing import Literal

import cv2
import numpy as np

from gtrig.calib.charuco import MIN_CORNERS, CharucoView
from gtrig.errors import InputError

log = logging.getLogger(__name__)

#: modules across a tag: 6 data bits and a 2-module black border on each side
TAG_MODULES = 10
BORDER_MODULES = 2
#: tag36h11 has 587 codes
N_TAG36H11 = 587


@dataclass(frozen=True)
class AprilGrid:
    """An AprilGrid (module docstring).

    Attributes
    ----------
    tag_cols, tag_rows : tags along x and along y.
    tag_m : side of a tag's black square, metres.
    spacing : the gap between two tags over ``tag_m`` (Kalibr's ``tagSpacing``).
    family : the tags' family (only tag36h11, Kalibr's).
    """

    tag_cols: int
    tag_rows: int
    tag_m: float
    spacing: float
    family: Literal["tag36h11"] = "tag36h11"

    def __post_init__(self) -> None:
        if not (1 <= self.tag_cols <= 50 and 1 <= self.tag_rows <= 50):
            raise InputError(f"AprilGrid {self.tag_cols} x {self.tag_rows} tags: 1 to 50 tags per side")
        if self.tag_cols * self.tag_rows > N_TAG36H11:
            raise InputError(f"AprilGrid needs {self.tag_cols * self.tag_rows} tags, tag36h11 has {N_TAG36H11}")
        if not 0.001 <= self.tag_m <= 2.0:
            raise InputError(f"AprilGrid tag size {self.tag_m:g} m: expected 0.001 to 2 m")
        if not 0.0 < self.spacing <= 1.0:
            raise InputError(f"AprilGrid tag spacing {self.spacing:g}: expected a ratio in (0, 1] of the tag size")

    @property
    def n_tags(self) -> int:
        return self.tag_cols * self.tag_rows

    @property
    def n_corners(self) -> int:
        return 4 * self.n_tags

    @property
    def pitch_m(self) -> float:
        """Distance between two neighbouring tags' origins, metres."""
        return (1.0 + self.spacing) * self.tag_m

    def object_points(self) -> np.ndarray:
        """Tag corners (N, 3) in gtrig's board frame, metres, indexed by corner ID (Kalibr's point index)."""
        k = np.arange(self.n_corners)
        C, R = k % (2 * self.tag_cols), k // (2 * self.tag_cols)
        x = (C // 2) * self.pitch_m + (C % 2) * self.tag_m
        y_up = (R // 2) * self.pitch_m + (R % 2) * self.tag_m
        return np.column_stack([x, -y_up, np.zeros(k.size)]).astype(np.float64)

    def tag_corner_ids(self, tag_id: int) -> np.ndarray:
        """The corner IDs (4,) of a tag in OpenCV's marker order (its code image's top-left, top-right,
        bottom-right, bottom-left): Kalibr prints the code turned half a turn, so these are the printed
        tag's bottom-right, bottom-left, top-left and top-right corners."""
        w = 2 * self.tag_cols
        base = (tag_id // self.tag_cols) * 2 * w + (tag_id % self.tag_cols) * 2
        return np.array([base + 1, base, base + w, base + w + 1])

    def extent_m(self) -> tuple[float, float, float, float]:
        """The printed pattern's bounds ``(x0, y0, x1, y1)`` in the board frame, corner squares included."""
        g = self.spacing * self.tag_m
        x1 = (self.tag_cols - 1) * self.pitch_m + self.tag_m + g
        y1 = (self.tag_rows - 1) * self.pitch_m + self.tag_m + g
        return (-g, -y1, x1, g)

    def black(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        """Whether the print is black at board points ``(x, y)`` (any equal shapes, metres)."""
        x, y = np.asarray(x, dtype=float), np.asarray(y, dtype=float)
        y_up = -y
        p = self.pitch_m
        # the tag whose cell [origin - gap, origin + tag) holds the point, and the position in it
        tc, tr = np.floor((x + self.spacing * self.tag_m) / p), np.floor((y_up + self.spacing * self.tag_m) / p)
        u, v = x - tc * p, y_up - tr * p  # from the tag's bottom-left corner, up
        in_grid = (tc >= 0) & (tc < self.tag_cols) & (tr >= 0) & (tr < self.tag_rows)
        in_tag = in_grid & (u >= 0) & (u < self.tag_m) & (v >= 0) & (v < self.tag_m)
        # the corner squares: in the gap on both axes, next to a tag corner of the grid
        gap_u, gap_v = u < 0, v < 0
        corner = (gap_u & gap_v) & (tc >= 0) & (tr >= 0) & (tc <= self.tag_cols) & (tr <= self.tag_rows)
        m = self.tag_m / TAG_MODULES
        # the code image turned half a turn: its row 0 at the tag's bottom, its column 0 at the tag's right
        col = np.clip(TAG_MODULES - 1 - np.floor(u / m), 0, TAG_MODULES - 1).astype(int)
        row = np.clip(np.floor(v / m), 0, TAG_MODULES - 1).astype(int)
        tag_id = np.clip(tr * self.tag_cols + tc, 0, self.n_tags - 1).astype(int)
        bits = tag_images(self.n_tags)[tag_id, row, col] == 0
        return (in_tag & bits) | corner

    def spec(self) -> str:
        return (f"AprilGrid {self.tag_cols} x {self.tag_rows} {self.family} tags of {1000 * self.tag_m:g} mm, "
                f"spacing {self.spacing:g}")


@functools.cache
def tag_images(n: int) -> np.ndarray:
    """Tags ``0 .. n - 1`` of tag36h11 as an AprilGrid prints them (n, 10, 10): 255 white, 0 black, row 0 at
    the top, the 2-module border included."""
    d = cv2.aruco.getPredefinedDictionary(cv2.aruco.DICT_APRILTAG_36h11)
    return np.array([cv2.aruco.generateImageMarker(d, i, TAG_MODULES, borderBits=BORDER_MODULES)
                     for i in range(n)])


class AprilGridDetector:
    """The tags of one AprilGrid in grey images (module docstring), set up once and used on many images."""

    def __init__(self, board: AprilGrid) -> None:
        self.board = board
        params = cv2.aruco.DetectorParameters()
        params.markerBorderBits = BORDER_MODULES
        params.cornerRefinementMethod = cv2.aruco.CORNER_REFINE_NONE
        params.perspectiveRemovePixelPerCell = 8  # small tags decode more often (measured: 10 % more tags)
        d = cv2.aruco.getPredefinedDictionary(cv2.aruco.DICT_APRILTAG_36h11)
        self._detector = cv2.aruco.ArucoDetector(d, params)

    def detect(self, grey: np.ndarray, min_corners: int = MIN_CORNERS, *, mirrored: bool = False
               ) -> CharucoView | None:
        """The board's tag corners in an 8-bit grey image (IDs of :meth:`AprilGrid.object_points`,
        increasing), or None with fewer than ``min_corners``; ``mirrored`` as
        :meth:`gtrig.calib.charuco.CharucoCornerDetector.detect`."""
        img = cv2.flip(grey, 1) if mirrored else grey
        xy, tag_ids = self._tags(img)
        corners, ok = _refine(img, xy, self.board.spacing)
        cid = np.array([self.board.tag_corner_ids(int(t)) for t in tag_ids]).reshape(-1, 4)[ok]
        corners = corners[ok]
        if cid.size < min_corners:
            return None
        order = np.argsort(cid)
        return CharucoView(cid[order].astype(np.int64), corners.reshape(-1, 2)[order])


    def _tags(self, img: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The board's tags (T, 4, 2) and their IDs (T,), each tag once.

        A tag touches its corner squares at its corners, and OpenCV's contours then merge them into one
        shape that is no quad; the tags are searched again in the image with the black shrunk by a pixel
        (a 3 x 3 grey dilation), which parts them; the two searches' tags are merged, the plain one's first.
        """
        found: dict[int, np.ndarray] = {}
        for pass_img in (img, cv2.dilate(img, np.ones((3, 3), np.uint8))):
            quads, ids, _rejected = self._detector.detectMarkers(pass_img)
            if ids is None:
                continue
            tag_ids = np.asarray(ids, dtype=np.int64).ravel()
            uniq, count = np.unique(tag_ids, return_counts=True)
            for q, t in zip(np.asarray(quads, dtype=np.float64).reshape(-1, 4, 2), tag_ids, strict=True):
                # a tag seen twice in one image is another board's or a reflection: left out
                if t < self.board.n_tags and count[np.searchsorted(uniq, t)] == 1 and int(t) not in found:
                    found[int(t)] = q
        ts = sorted(found)
        return np.array([found[t] for t in ts]).reshape(-1, 4, 2), np.array(ts, dtype=np.int64)


def _refine(grey: np.ndarray, quads_px: np.ndarray, spacing: float) -> tuple[np.ndarray, np.ndarray]:
    """Tag corners (T, 4, 2) refined on their saddles, with a window sized from each tag's side to stay
    inside the 2-module border and the corner square; and which (T, 4) converged (``cv2.cornerSubPix``
    leaves a corner where it was when the saddle is farther than its window)."""
    out = quads_px.copy()
    ok = np.zeros(quads_px.shape[:2], dtype=bool)
    crit = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 40, 1e-3)
    for t, q in enumerate(quads_px):
        side_px = float(np.min(np.linalg.norm(q - np.roll(q, 1, axis=0), axis=1)))
        if side_px < 12:
            continue
        half = int(np.clip(0.7 * min(BORDER_MODULES / TAG_MODULES, spacing) * side_px, 2, 15))
        pts = q.astype(np.float32).reshape(-1, 1, 2)
        out[t] = cv2.cornerSubPix(grey, pts.copy(), (half, half), (-1, -1), crit).reshape(4, 2)
        ok[t] = np.any(out[t] != q.astype(np.float32), axis=1)
    return out, ok
