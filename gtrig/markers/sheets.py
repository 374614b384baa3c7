"""Printable sheets on a paper size: markers (several per sheet when they fit), chessboards, a scale ruler.

Every length is in millimetres on the page, origin at the paper's top-left corner, y down. A sheet is a
list of drawing primitives (black boxes, strokes, text) that :mod:`gtrig.markers.sheetfiles` writes as
PDF, SVG or PNG at exact physical size.

A marker's tile::

     --+                          +--     cut marks on the cut lines' extensions
       +--------------------------+       cut square = black square + white quiet zone
       |   +------------------+   |       quiet zone: max(1 cell, 5 mm)
       |   |  black square,   |   |
       |   |  side = side_mm  |   |
       |   +------------------+   |
       +--------------------------+
     --+                          +--
     artoolkitplus_simple id 14            label, outside the cut square
     black square 156 mm

Pages are filled row by row in the given order; each page takes the orientation (portrait or
landscape) that holds more of the remaining tiles. Nothing is drawn within :data:`PAGE_MARGIN_MM` of
the paper's edge, and every page carries a 100 mm ruler with millimetre ticks to check the printed
scale.
"""

from __future__ import annotations

import math
import re
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from gtrig.errors import InputError
from gtrig.markers.families import family_spec, marker_cells
from gtrig.rig.models import MarkerFamily

#: paper sizes, portrait (width, height) in mm: ISO 216 A4 and A3, US Letter (8.5 x 11 in)
PAPERS_MM: dict[str, tuple[float, float]] = {"a4": (210.0, 297.0), "letter": (215.9, 279.4), "a3": (297.0, 420.0)}
PAGE_MARGIN_MM = 6.0
TILE_GAP_MM = 4.0
CUT_GAP_MM = 1.0
CUT_LEN_MM = 4.0
CUT_STROKE_MM = 0.2
LABEL_MM = 2.5
LABEL_LINE_MM = 3.4
#: a Helvetica character's advance is at most about this fraction of the font size (W, M are 0.83-0.94,
#: but labels are lower case, digits and spaces, about 0.55 on average)
CHAR_WIDTH_EM = 0.62
RULER_MM = 100.0
RULER_BAND_MM = 17.0
RULER_TEXT = "print at 100 %, no fit-to-page; this bar must measure 100 mm"


@dataclass(frozen=True)
class Paper:
    """A paper size in portrait: ``width_mm <= height_mm``."""

    name: str
    width_mm: float
    height_mm: float

    def oriented(self, landscape: bool) -> tuple[float, float]:
        """(width, height) of the page in mm."""
        return (self.height_mm, self.width_mm) if landscape else (self.width_mm, self.height_mm)

    def usable_mm(self, landscape: bool) -> tuple[float, float]:
        """The area tiles may take: inside the margins, above the ruler's band."""
        w, h = self.oriented(landscape)
        return w - 2 * PAGE_MARGIN_MM, h - 2 * PAGE_MARGIN_MM - RULER_BAND_MM


def parse_paper(text: str) -> Paper:
    """``a4``, ``letter``, ``a3`` or ``WIDTHxHEIGHT`` in millimetres (a plotter's or print shop's sheet)."""
    key = text.strip().lower()
    if key in PAPERS_MM:
        w, h = PAPERS_MM[key]
        return Paper(key.upper() if key != "letter" else "Letter", w, h)
    m = re.fullmatch(r"(\d+(?:\.\d+)?)\s*x\s*(\d+(?:\.\d+)?)", key)
    if not m:
        raise InputError(f"--paper {text!r}: expected a4, letter, a3 or WIDTHxHEIGHT in mm (e.g. 1100x800)")
    w, h = sorted((float(m.group(1)), float(m.group(2))))
    if not (RULER_MM + 2 * PAGE_MARGIN_MM <= w and h <= 5000.0):
        raise InputError(f"--paper {text!r}: a sheet is {RULER_MM + 2 * PAGE_MARGIN_MM:g} to 5000 mm a side")
    return Paper("custom", w, h)


@dataclass(frozen=True)
class Box:
    """A black rectangle: top-left (x, y), width, height, mm."""

    x: float
    y: float
    w: float
    h: float


@dataclass(frozen=True)
class Stroke:
    """A black line from (x0, y0) to (x1, y1), ``width`` thick, mm."""

    x0: float
    y0: float
    x1: float
    y1: float
    width: float


@dataclass(frozen=True)
class Text:
    """One line of text: baseline start (x, y) and font size (cap-to-descender em), mm."""

    x: float
    y: float
    size: float
    text: str


@dataclass(frozen=True)
class PrintedMarker:
    """Where a marker's black square lies on its page: top-left (x_mm, y_mm), side ``side_mm``."""

    family: MarkerFamily
    marker_id: int
    side_mm: float
    x_mm: float
    y_mm: float


@dataclass(frozen=True)
class Tile:
    """Something to print, drawn relative to its own top-left corner; ``w_mm x h_mm`` with its label."""

    what: str
    w_mm: float
    h_mm: float
    boxes: tuple[Box, ...]
    strokes: tuple[Stroke, ...] = ()
    texts: tuple[Text, ...] = ()
    marker: PrintedMarker | None = None
    #: what its size includes besides the pattern, for a refusal
    extras: str = "its white margin and label"


@dataclass(frozen=True)
class Page:
    """One sheet: its paper, orientation and everything drawn on it, in page millimetres."""

    paper: Paper
    landscape: bool
    boxes: tuple[Box, ...]
    strokes: tuple[Stroke, ...]
    texts: tuple[Text, ...]
    markers: tuple[PrintedMarker, ...] = ()
    contents: tuple[str, ...] = field(default=())

    @property
    def size_mm(self) -> tuple[float, float]:
        return self.paper.oriented(self.landscape)

    @property
    def orientation(self) -> str:
        return "landscape" if self.landscape else "portrait"


def text_width_mm(text: str, size_mm: float) -> float:
    """An upper estimate of a Helvetica line's width."""
    return len(text) * size_mm * CHAR_WIDTH_EM


def _labels(lines: Sequence[str], x: float, y_top: float) -> tuple[tuple[Text, ...], float, float]:
    """Text lines from ``y_top`` down; returns them, their width and their height."""
    texts = tuple(Text(x, y_top + (i + 1) * LABEL_LINE_MM - (LABEL_LINE_MM - LABEL_MM), LABEL_MM, s)
                  for i, s in enumerate(lines))
    w = max((text_width_mm(s, LABEL_MM) for s in lines), default=0.0)
    return texts, w, len(lines) * LABEL_LINE_MM


def black_runs(cells: NDArray[np.uint8], x0: float, y0: float, cell_mm: float) -> list[Box]:
    """Black cells (0) merged into horizontal runs, as boxes from the pattern's top-left (x0, y0)."""
    out: list[Box] = []
    for r in range(cells.shape[0]):
        d = np.diff(np.concatenate([[1], cells[r], [1]]).astype(np.int8))
        for a, b in zip(np.flatnonzero(d == -1), np.flatnonzero(d == 1), strict=True):
            out.append(Box(float(x0 + a * cell_mm), float(y0 + r * cell_mm), float((b - a) * cell_mm), cell_mm))
    return out


def _cut_marks(x: float, y: float, s: float) -> list[Stroke]:
    """Two marks per corner of the cut square (x, y, side), on the cut lines' extensions."""
    g, ln = CUT_GAP_MM, CUT_LEN_MM
    out = []
    for cx, sx in ((x, -1.0), (x + s, 1.0)):
        for cy, sy in ((y, -1.0), (y + s, 1.0)):
            out.append(Stroke(cx + sx * g, cy, cx + sx * (g + ln), cy, CUT_STROKE_MM))
            out.append(Stroke(cx, cy + sy * g, cx, cy + sy * (g + ln), CUT_STROKE_MM))
    return out


def quiet_zone_mm(side_mm: float, n_cells: int) -> float:
    """The white zone kept around a marker's black square when it is cut out: one cell, at least 5 mm."""
    return max(side_mm / n_cells, 5.0)


def marker_tile(family: MarkerFamily | str, marker_id: int, side_mm: float) -> Tile:
    """A marker with its quiet zone, cut marks and label (family, ID, side), see the module docstring.

    Raises
    ------
    InputError
        Unknown family, an ID out of its range, or a side outside 5 to 2000 mm.
    """
    if not (math.isfinite(side_mm) and 5.0 <= side_mm <= 2000.0):
        raise InputError(f"marker side {side_mm:g} mm is implausible (expected 5 to 2000 mm)")
    fam = family_spec(family).family
    cells = marker_cells(fam, marker_id)
    n = cells.shape[0]
    q = quiet_zone_mm(side_mm, n)
    reach = CUT_GAP_MM + CUT_LEN_MM
    cut = side_mm + 2 * q
    label_lines = (f"{fam.value} id {int(marker_id)}", f"black square {side_mm:g} mm")
    texts, label_w, label_h = _labels(label_lines, 0.0, cut + 2 * reach)
    w = max(cut + 2 * reach, label_w)
    x0 = (w - cut) / 2 + q  # the black square's top-left
    y0 = reach + q
    boxes = tuple(black_runs(cells, x0, y0, side_mm / n))
    texts = tuple(Text(t.x + (w - label_w) / 2, t.y, t.size, t.text) for t in texts)
    return Tile(f"marker {int(marker_id)} ({fam.value}, {side_mm:g} mm)", w, cut + 2 * reach + label_h, boxes,
                tuple(_cut_marks(x0 - q, y0 - q, cut)), texts,
                PrintedMarker(fam, int(marker_id), float(side_mm), x0, y0), "its quiet zone, cut marks and label")


def chessboard_tile(cols: int, rows: int, square_mm: float, title: str, notes: Sequence[str] = ()) -> Tile:
    """A chessboard of ``cols x rows`` inner corners ((cols + 1) x (rows + 1) squares, the top-left one
    black) with a white margin of one square and a label under it."""
    sq_x, sq_y = cols + 1, rows + 1
    margin = square_mm
    boxes = tuple(Box(margin + c * square_mm, margin + r * square_mm, square_mm, square_mm)
                  for r in range(sq_y) for c in range(sq_x) if (r + c) % 2 == 0)
    lines = (title, f"{sq_x} x {sq_y} squares ({cols} x {rows} inner corners), square {square_mm:g} mm", *notes)
    h_board = sq_y * square_mm + 2 * margin
    texts, label_w, label_h = _labels(lines, margin, h_board)
    w = max(sq_x * square_mm + 2 * margin, label_w + margin)
    return Tile(f"{title} ({sq_x} x {sq_y} squares of {square_mm:g} mm)", w, h_board + label_h, boxes, (), texts)


def ruler(x: float, y: float) -> tuple[list[Box], list[Stroke], list[Text]]:
    """A :data:`RULER_MM` bar with millimetre ticks and the printing instruction; (x, y) is the band's
    top-left. The solid bar is ``RULER_MM`` long and 1.5 mm high; ticks rise from its top edge."""
    bar_y = y + 8.0
    boxes = [Box(x, bar_y, RULER_MM, 1.5)]
    strokes = []
    texts = []
    for mm in range(int(RULER_MM) + 1):
        ln = 4.0 if mm % 10 == 0 else 2.5 if mm % 5 == 0 else 1.5
        xm = x + mm if mm < RULER_MM else x + RULER_MM - 0.05
        xm = max(xm, x + 0.05)
        strokes.append(Stroke(xm, bar_y, xm, bar_y - ln, 0.1))
        if mm % 10 == 0:
            label = str(mm) if mm < RULER_MM else "100 mm"
            texts.append(Text(max(x, xm - 0.6 * len(str(mm))), bar_y - 4.6, 2.0, label))  # centred on the tick
    texts.append(Text(x, bar_y + 1.5 + 3.6, LABEL_MM, RULER_TEXT))
    return boxes, strokes, texts


def _fits(tile: Tile, paper: Paper, landscape: bool) -> bool:
    uw, uh = paper.usable_mm(landscape)
    return tile.w_mm <= uw + 1e-9 and tile.h_mm <= uh + 1e-9


def _too_big(tile: Tile, paper: Paper) -> InputError:
    uw, uh = paper.usable_mm(False)
    lw, lh = paper.usable_mm(True)
    pw, ph = paper.oriented(False)
    return InputError(
        f"{tile.what} does not fit the paper: it needs {tile.w_mm:.0f} x {tile.h_mm:.0f} mm with {tile.extras}, "
        f"and {paper.name} ({pw:g} x {ph:g} mm) leaves {uw:.0f} x {uh:.0f} mm "
        f"(landscape {lw:.0f} x {lh:.0f}) inside its margins and ruler: choose a larger --paper (a3, or "
        "WIDTHxHEIGHT in mm for a plotter) or a smaller size")


def _shelf(tiles: Sequence[Tile], paper: Paper, landscape: bool) -> list[tuple[Tile, float, float]]:
    """Place tiles from the first on, row by row, until one does not fit; (tile, x, y) on the page."""
    uw, uh = paper.usable_mm(landscape)
    placed: list[tuple[Tile, float, float]] = []
    x = y = row_h = 0.0
    for t in tiles:
        if x > 0 and x + t.w_mm > uw + 1e-9:
            x, y, row_h = 0.0, y + row_h + TILE_GAP_MM, 0.0
        if x + t.w_mm > uw + 1e-9 or y + t.h_mm > uh + 1e-9:
            break
        placed.append((t, PAGE_MARGIN_MM + x, PAGE_MARGIN_MM + y))
        x += t.w_mm + TILE_GAP_MM
        row_h = max(row_h, t.h_mm)
    return placed


def _page(paper: Paper, landscape: bool, placed: list[tuple[Tile, float, float]]) -> Page:
    boxes: list[Box] = []
    strokes: list[Stroke] = []
    texts: list[Text] = []
    markers: list[PrintedMarker] = []
    for t, x, y in placed:
        boxes += [Box(b.x + x, b.y + y, b.w, b.h) for b in t.boxes]
        strokes += [Stroke(s.x0 + x, s.y0 + y, s.x1 + x, s.y1 + y, s.width) for s in t.strokes]
        texts += [Text(s.x + x, s.y + y, s.size, s.text) for s in t.texts]
        if t.marker is not None:
            m = t.marker
            markers.append(PrintedMarker(m.family, m.marker_id, m.side_mm, m.x_mm + x, m.y_mm + y))
    _, h = paper.oriented(landscape)
    rb, rs, rt = ruler(PAGE_MARGIN_MM, h - PAGE_MARGIN_MM - RULER_BAND_MM)
    return Page(paper, landscape, tuple(boxes + rb), tuple(strokes + rs), tuple(texts + rt), tuple(markers),
                tuple(t.what for t, _, _ in placed))


def lay_out(tiles: Sequence[Tile], paper: Paper) -> list[Page]:
    """Pages holding ``tiles`` in order, each in the orientation that takes more of them.

    Raises
    ------
    InputError
        A tile fits the paper in neither orientation (one line: what, its size, the paper's room).
    """
    for t in tiles:
        if not (_fits(t, paper, False) or _fits(t, paper, True)):
            raise _too_big(t, paper)
    pages = []
    rest = list(tiles)
    while rest:
        portrait = _shelf(rest, paper, False)
        landscape = _shelf(rest, paper, True)
        use_landscape = len(landscape) > len(portrait)
        placed = landscape if use_landscape else portrait
        pages.append(_page(paper, use_landscape, placed))
        rest = rest[len(placed):]
    return pages
