"""Printable markers at exact physical size: PNG (with DPI), SVG (mm units) and PDF.

Sheet layout (all lengths in millimetres, origin at the sheet's top-left, y down)::

      +-----------------------------------------+   sheet
      |   |                                 |   |
      | --+                                 +-- |   cut marks, outside the cut square
      |     +-----------------------------+     |   cut square = marker + white quiet zone
      |     |   +---------------------+   |     |
      |     |   |  black square,      |   |     |
      |     |   |  side = size_mm     |   |     |
      |     |   +---------------------+   |     |
      |     +-----------------------------+     |
      | --+                                 +-- |
      |   |                                 |   |
      |  artoolkitplus_simple  id 14  100 mm    |   label, outside the cut square
      +-----------------------------------------+

``size_mm`` is the side of the black square (``Marker.side_m`` in the rig file), border included.
The white quiet zone is ``max(2 cells, 5 mm)`` wide so that the marker can be detected after cutting.

Vector outputs (SVG, PDF) are exact. A PNG has square pixels and a pixels-per-metre value stored as
an integer (``pHYs``), so the marker is drawn with a whole number of pixels per cell and the
resolution is chosen at or above ``dpi`` to make the printed side match ``size_mm`` within half a
pixel (0.02 mm at 600 dpi); :func:`png_resolution` gives the exact numbers.
"""

from __future__ import annotations

import math
import struct
import zlib
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from gtrig.errors import InputError
from gtrig.io.atomic import atomic_write_bytes, atomic_write_text
from gtrig.markers.families import family_spec, marker_cells
from gtrig.markers.pdfdoc import pdf_document, pdf_string
from gtrig.markers.sheets import black_runs
from gtrig.rig.models import MarkerFamily

MM_PER_INCH = 25.4
PT_PER_MM = 72.0 / MM_PER_INCH

CUT_GAP_MM = 1.5
CUT_LEN_MM = 6.0
SHEET_MARGIN_MM = 10.0
LABEL_HEIGHT_MM = 4.0


@dataclass(frozen=True)
class SheetLayout:
    """Where everything goes on the sheet, in millimetres from the top-left corner (y down).

    Attributes
    ----------
    family, marker_id, size_mm : the marker.
    cells : numpy.ndarray, (n, n) uint8, the pattern (1 = white).
    width_mm, height_mm : sheet size.
    marker_xy_mm : (x, y) of the black square's top-left corner.
    quiet_mm : width of the white zone between the black square and the cut line.
    label : the text printed under the cut square.
    label_xy_mm : baseline start of the label.
    """

    family: MarkerFamily
    marker_id: int
    size_mm: float
    cells: NDArray[np.uint8]
    width_mm: float
    height_mm: float
    marker_xy_mm: tuple[float, float]
    quiet_mm: float
    label: str
    label_xy_mm: tuple[float, float]

    @property
    def cell_mm(self) -> float:
        return self.size_mm / self.cells.shape[0]

    @property
    def cut_square_mm(self) -> tuple[float, float, float]:
        """(x, y, side) of the cut square."""
        x, y = self.marker_xy_mm
        q = self.quiet_mm
        return x - q, y - q, self.size_mm + 2 * q

    def cut_marks_mm(self) -> list[tuple[float, float, float, float]]:
        """Cut-mark segments (x0, y0, x1, y1): two per corner, on the cut lines' extensions."""
        x, y, s = self.cut_square_mm
        g, ln = CUT_GAP_MM, CUT_LEN_MM
        segs = []
        for cx, sx in ((x, -1.0), (x + s, 1.0)):
            for cy, sy in ((y, -1.0), (y + s, 1.0)):
                segs.append((cx + sx * g, cy, cx + sx * (g + ln), cy))  # horizontal, on the cut line y
                segs.append((cx, cy + sy * g, cx, cy + sy * (g + ln)))  # vertical, on the cut line x
        return segs

    def black_runs_mm(self) -> list[tuple[float, float, float, float]]:
        """Black cells merged into horizontal runs: rectangles (x, y, w, h)."""
        x0, y0 = self.marker_xy_mm
        return [(b.x, b.y, b.w, b.h) for b in black_runs(self.cells, x0, y0, self.cell_mm)]


def layout(family: MarkerFamily | str, marker_id: int, size_mm: float) -> SheetLayout:
    """Compute the sheet layout of one marker (see the module docstring)."""
    if not (math.isfinite(size_mm) and 5.0 <= size_mm <= 2000.0):
        raise InputError(f"--size-mm {size_mm:g} is implausible (expected 5 to 2000 mm)")
    spec = family_spec(family)
    fam = spec.family
    cells = marker_cells(fam, marker_id)
    n = cells.shape[0]
    quiet = max(2.0 * size_mm / n, 5.0)
    off = SHEET_MARGIN_MM + CUT_GAP_MM + CUT_LEN_MM + quiet
    cut_side = size_mm + 2 * quiet
    width = cut_side + 2 * (SHEET_MARGIN_MM + CUT_GAP_MM + CUT_LEN_MM)
    label_y = off - quiet + cut_side + CUT_GAP_MM + CUT_LEN_MM + LABEL_HEIGHT_MM + 2.0
    height = label_y + SHEET_MARGIN_MM
    label = (f"{fam.value}  id {int(marker_id)}  black square {size_mm:g} mm  "
             f"border {spec.border_fraction:.3g}")
    return SheetLayout(fam, int(marker_id), float(size_mm), cells, width, height, (off, off), quiet,
                       label, (SHEET_MARGIN_MM, label_y))


# ----------------------------------------------------------------------------------------- SVG


def to_svg(lay: SheetLayout) -> str:
    """The sheet as an SVG document whose user unit is the millimetre."""
    w, h = lay.width_mm, lay.height_mm
    f = "{:.4f}".format
    path = "".join(f"M{f(x)} {f(y)}h{f(rw)}v{f(rh)}h{f(-rw)}z" for x, y, rw, rh in lay.black_runs_mm())
    marks = "".join(
        f'<line x1="{f(a)}" y1="{f(b)}" x2="{f(c)}" y2="{f(d)}"/>' for a, b, c, d in lay.cut_marks_mm()
    )
    lx, ly = lay.label_xy_mm
    return (
        '<?xml version="1.0" encoding="UTF-8"?>\n'
        f'<svg xmlns="http://www.w3.org/2000/svg" width="{f(w)}mm" height="{f(h)}mm" '
        f'viewBox="0 0 {f(w)} {f(h)}">\n'
        f"<title>{lay.label}</title>\n"
        f'<rect x="0" y="0" width="{f(w)}" height="{f(h)}" fill="#ffffff"/>\n'
        f'<path d="{path}" fill="#000000" shape-rendering="crispEdges"/>\n'
        f'<g stroke="#000000" stroke-width="0.2">{marks}</g>\n'
        f'<text x="{f(lx)}" y="{f(ly)}" font-family="Helvetica, Arial, sans-serif" '
        f'font-size="{f(LABEL_HEIGHT_MM)}">{lay.label}</text>\n'
        "</svg>\n"
    )


# ----------------------------------------------------------------------------------------- PDF


def to_pdf(lay: SheetLayout) -> bytes:
    """The sheet as a one-page PDF 1.4 of exactly ``width_mm x height_mm`` (points = mm * 72 / 25.4)."""
    H = lay.height_mm

    def p(v: float) -> str:
        return f"{v * PT_PER_MM:.4f}"

    ops = ["0 g"]
    for x, y, rw, rh in lay.black_runs_mm():
        ops.append(f"{p(x)} {p(H - y - rh)} {p(rw)} {p(rh)} re")
    ops.append("f")
    ops.append(f"0 G {0.2 * PT_PER_MM:.4f} w")
    for a, b, c, d in lay.cut_marks_mm():
        ops.append(f"{p(a)} {p(H - b)} m {p(c)} {p(H - d)} l S")
    lx, ly = lay.label_xy_mm
    ops.append(f"BT /F1 {LABEL_HEIGHT_MM * PT_PER_MM:.3f} Tf {p(lx)} {p(H - ly)} Td ({pdf_string(lay.label)}) Tj ET")
    return pdf_document([(lay.width_mm * PT_PER_MM, H * PT_PER_MM, "\n".join(ops).encode("latin-1"))])


# ----------------------------------------------------------------------------------------- PNG


def png_resolution(size_mm: float, n_cells: int, dpi: float) -> tuple[int, int]:
    """Pixels per cell and pixels per metre for a PNG of a marker.

    Returns ``(px_per_cell, px_per_metre)`` with ``px_per_metre`` an integer (PNG stores it so) at or
    above ``dpi`` such that ``n_cells * px_per_cell / px_per_metre`` is within half a pixel of
    ``size_mm / 1000``.
    """
    k = max(1, math.ceil(dpi / MM_PER_INCH * size_mm / n_cells))
    ppm = round(k * n_cells * 1000.0 / size_mm)
    return k, int(ppm)


def png_bytes(img: NDArray[np.uint8], px_per_metre: int) -> bytes:
    """Encode an 8-bit grayscale image as PNG with a ``pHYs`` chunk (pixels per metre)."""

    def chunk(tag: bytes, data: bytes) -> bytes:
        return struct.pack(">I", len(data)) + tag + data + struct.pack(">I", zlib.crc32(tag + data))

    h, w = img.shape
    raw = np.hstack([np.zeros((h, 1), np.uint8), img]).tobytes()  # filter type 0 per row
    return (
        b"\x89PNG\r\n\x1a\n"
        + chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, 8, 0, 0, 0, 0))
        + chunk(b"pHYs", struct.pack(">IIB", px_per_metre, px_per_metre, 1))
        + chunk(b"IDAT", zlib.compress(raw, 9))
        + chunk(b"IEND", b"")
    )


def to_png_image(lay: SheetLayout, dpi: float = 600.0) -> tuple[NDArray[np.uint8], int, int]:
    """Rasterise the sheet.

    Returns
    -------
    image : numpy.ndarray, (H, W) uint8
    px_per_metre : int
    px_per_cell : int
        The black square occupies ``n * px_per_cell`` pixels from pixel
        ``round(marker_xy_mm * px_per_metre / 1000)``.
    """
    import cv2

    n = lay.cells.shape[0]
    k, ppm = png_resolution(lay.size_mm, n, dpi)
    s = ppm / 1000.0  # px per mm
    W = int(math.ceil(lay.width_mm * s))
    H = int(math.ceil(lay.height_mm * s))
    img = np.full((H, W), 255, np.uint8)
    x0 = round(lay.marker_xy_mm[0] * s)
    y0 = round(lay.marker_xy_mm[1] * s)
    big = np.kron(lay.cells, np.ones((k, k), np.uint8)) * 255
    img[y0 : y0 + n * k, x0 : x0 + n * k] = big
    t = max(1, round(0.2 * s))
    for a, b, c, d in lay.cut_marks_mm():
        cv2.line(img, (round(a * s), round(b * s)), (round(c * s), round(d * s)), 0, t)
    lx, ly = lay.label_xy_mm
    scale = cv2.getFontScaleFromHeight(cv2.FONT_HERSHEY_SIMPLEX, max(1, round(LABEL_HEIGHT_MM * s)), t)
    cv2.putText(img, lay.label, (round(lx * s), round(ly * s)), cv2.FONT_HERSHEY_SIMPLEX, scale, 0, t,
                cv2.LINE_AA)
    return img, ppm, k


def to_png(lay: SheetLayout, dpi: float = 600.0) -> bytes:
    """The sheet as PNG bytes with its physical resolution stored (see :func:`png_resolution`)."""
    img, ppm, _ = to_png_image(lay, dpi)
    return png_bytes(img, ppm)


def write_marker(
    family: MarkerFamily | str, marker_id: int, size_mm: float, out: str | Path, dpi: float = 600.0
) -> SheetLayout:
    """Write a printable marker sheet; the format follows the suffix of ``out`` (.pdf, .svg, .png).

    Raises
    ------
    InputError
        Unknown suffix, family, out-of-range ID or implausible size.
    """
    out = Path(out)
    suffix = out.suffix.lower()
    if suffix not in (".pdf", ".svg", ".png"):
        raise InputError(f"{out}: unknown output format {suffix or '(none)'!r}; use .pdf, .svg or .png")
    if not (50.0 <= dpi <= 10000.0):
        raise InputError(f"--dpi {dpi:g} is implausible (expected 50 to 10000)")
    lay = layout(family, marker_id, size_mm)
    if suffix == ".svg":
        atomic_write_text(out, to_svg(lay))
    elif suffix == ".pdf":
        atomic_write_bytes(out, to_pdf(lay))
    else:
        atomic_write_bytes(out, to_png(lay, dpi))
    return lay
