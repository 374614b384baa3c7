"""Write laid-out sheets (:mod:`gtrig.markers.sheets`) at exact physical size.

PDF: one page per sheet, MediaBox = the paper in points (mm * 72 / 25.4), boxes as filled rectangles,
text in the standard Helvetica font. SVG: one sheet, the user unit is the millimetre. PNG: one sheet,
its resolution stored as pixels per metre (``pHYs``); the resolution is chosen at or above ``dpi`` so
that the first marker of the sheet has a whole number of pixels per cell (see
:func:`gtrig.markers.generate.png_resolution`), and every box edge is rounded to the nearest pixel.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from gtrig.errors import InputError
from gtrig.io.atomic import atomic_write_bytes, atomic_write_text
from gtrig.markers.families import family_spec
from gtrig.markers.generate import MM_PER_INCH, PT_PER_MM, png_bytes, png_resolution
from gtrig.markers.pdfdoc import pdf_document, pdf_string
from gtrig.markers.sheets import Page

SUFFIXES = (".pdf", ".svg", ".png")


def _page_stream(page: Page) -> bytes:
    """The content stream of one page (PDF y axis up, points)."""
    _, H = page.size_mm

    def p(v: float) -> str:
        return f"{v * PT_PER_MM:.4f}"

    ops = ["0 g"]
    ops += [f"{p(b.x)} {p(H - b.y - b.h)} {p(b.w)} {p(b.h)} re" for b in page.boxes]
    ops.append("f")
    ops.append("0 G 0 J")
    for s in page.strokes:
        ops.append(f"{s.width * PT_PER_MM:.4f} w {p(s.x0)} {p(H - s.y0)} m {p(s.x1)} {p(H - s.y1)} l S")
    for t in page.texts:
        ops.append(f"BT /F1 {t.size * PT_PER_MM:.3f} Tf {p(t.x)} {p(H - t.y)} Td ({pdf_string(t.text)}) Tj ET")
    return "\n".join(ops).encode("latin-1")


def to_pdf(pages: Sequence[Page]) -> bytes:
    """The sheets as one PDF 1.4 document, one page each at the paper's exact size."""
    return pdf_document([(p.size_mm[0] * PT_PER_MM, p.size_mm[1] * PT_PER_MM, _page_stream(p)) for p in pages])


def to_svg(page: Page) -> str:
    """One sheet as an SVG document whose user unit is the millimetre."""
    w, h = page.size_mm
    f = "{:.4f}".format
    path = "".join(f"M{f(b.x)} {f(b.y)}h{f(b.w)}v{f(b.h)}h{f(-b.w)}z" for b in page.boxes)
    lines = "".join(f'<line x1="{f(s.x0)}" y1="{f(s.y0)}" x2="{f(s.x1)}" y2="{f(s.y1)}" stroke-width="{f(s.width)}"/>'
                    for s in page.strokes)
    texts = "".join(
        f'<text x="{f(t.x)}" y="{f(t.y)}" font-size="{f(t.size)}">'
        + t.text.replace("&", "&amp;").replace("<", "&lt;").replace(">", "&gt;") + "</text>\n"
        for t in page.texts)
    return (
        '<?xml version="1.0" encoding="UTF-8"?>\n'
        f'<svg xmlns="http://www.w3.org/2000/svg" width="{f(w)}mm" height="{f(h)}mm" viewBox="0 0 {f(w)} {f(h)}">\n'
        f'<rect x="0" y="0" width="{f(w)}" height="{f(h)}" fill="#ffffff"/>\n'
        f'<path d="{path}" fill="#000000" shape-rendering="crispEdges"/>\n'
        f'<g stroke="#000000">{lines}</g>\n'
        f'<g font-family="Helvetica, Arial, sans-serif" fill="#000000">\n{texts}</g>\n'
        "</svg>\n"
    )


def png_px_per_metre(page: Page, dpi: float) -> int:
    """The sheet's PNG resolution: whole pixels per cell of its first marker, else ``dpi``."""
    if page.markers:
        m = page.markers[0]
        n = family_spec(m.family).data_cells + 2 * family_spec(m.family).border_cells
        return png_resolution(m.side_mm, n, dpi)[1]
    return math.ceil(dpi / MM_PER_INCH * 1000.0)


def to_png_image(page: Page, dpi: float = 600.0) -> tuple[NDArray[np.uint8], int]:
    """Rasterise one sheet: (image (H, W) uint8, pixels per metre)."""
    import cv2

    ppm = png_px_per_metre(page, dpi)
    s = ppm / 1000.0
    w, h = page.size_mm
    img = np.full((round(h * s), round(w * s)), 255, np.uint8)
    for b in page.boxes:
        img[round(b.y * s):round((b.y + b.h) * s), round(b.x * s):round((b.x + b.w) * s)] = 0
    for st in page.strokes:
        t = max(1, round(st.width * s))
        cv2.line(img, (round(st.x0 * s), round(st.y0 * s)), (round(st.x1 * s), round(st.y1 * s)), 0, t)
    for tx in page.texts:
        th = max(1, round(0.1 * tx.size * s))
        scale = cv2.getFontScaleFromHeight(cv2.FONT_HERSHEY_SIMPLEX, max(1, round(0.72 * tx.size * s)), th)
        cv2.putText(img, tx.text, (round(tx.x * s), round(tx.y * s)), cv2.FONT_HERSHEY_SIMPLEX, scale, 0, th,
                    cv2.LINE_AA)
    return img, ppm


def write_sheets(pages: Sequence[Page], out: str | Path, dpi: float = 600.0) -> None:
    """Write the sheets; the format follows the suffix of ``out`` (.pdf: any number; .svg, .png: one).

    Raises
    ------
    InputError
        Unknown suffix, several sheets for a one-sheet format, or an implausible ``dpi``.
    """
    out = Path(out)
    suffix = out.suffix.lower()
    if suffix not in SUFFIXES:
        raise InputError(f"{out}: unknown output format {suffix or '(none)'!r}; use .pdf, .svg or .png")
    if not (50.0 <= dpi <= 10000.0):
        raise InputError(f"--dpi {dpi:g} is implausible (expected 50 to 10000)")
    if suffix != ".pdf" and len(pages) != 1:
        raise InputError(f"{out}: {len(pages)} sheets, and a {suffix} file holds one: write a .pdf")
    if suffix == ".pdf":
        atomic_write_bytes(out, to_pdf(pages))
    elif suffix == ".svg":
        atomic_write_text(out, to_svg(pages[0]))
    else:
        img, ppm = to_png_image(pages[0], dpi)
        atomic_write_bytes(out, png_bytes(img, ppm))
