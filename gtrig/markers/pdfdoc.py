"""A minimal PDF 1.4 writer for vector sheets: pages of filled rectangles, lines and Helvetica text."""

from __future__ import annotations

from collections.abc import Sequence


def pdf_document(pages: Sequence[tuple[float, float, bytes]]) -> bytes:
    """A PDF of ``pages``, each ``(width_pt, height_pt, content_stream)``, in order.

    Objects: 1 catalog, 2 page tree, 3 the Helvetica font (resource ``/F1``), then for page ``i`` its page
    object ``4 + 2 i`` and its content stream ``5 + 2 i``; a cross-reference table points at each.
    """
    n = len(pages)
    kids = " ".join(f"{4 + 2 * i} 0 R" for i in range(n))
    objs: list[bytes] = [
        b"<< /Type /Catalog /Pages 2 0 R >>",
        f"<< /Type /Pages /Kids [{kids}] /Count {n} >>".encode(),
        b"<< /Type /Font /Subtype /Type1 /BaseFont /Helvetica /Encoding /WinAnsiEncoding >>",
    ]
    for i, (w_pt, h_pt, content) in enumerate(pages):
        objs.append((f"<< /Type /Page /Parent 2 0 R /MediaBox [0 0 {w_pt:.4f} {h_pt:.4f}] "
                     f"/Resources << /Font << /F1 3 0 R >> >> /Contents {5 + 2 * i} 0 R >>").encode())
        objs.append(b"<< /Length %d >>\nstream\n" % len(content) + content + b"\nendstream")
    out = bytearray(b"%PDF-1.4\n%\xe2\xe3\xcf\xd3\n")
    offsets = []
    for i, o in enumerate(objs, start=1):
        offsets.append(len(out))
        out += b"%d 0 obj\n" % i + o + b"\nendobj\n"
    xref = len(out)
    out += b"xref\n0 %d\n0000000000 65535 f \n" % (len(objs) + 1)
    for off in offsets:
        out += b"%010d 00000 n \n" % off
    out += b"trailer\n<< /Size %d /Root 1 0 R >>\nstartxref\n%d\n%%%%EOF\n" % (len(objs) + 1, xref)
    return bytes(out)


def pdf_string(text: str) -> str:
    """``text`` as the body of a PDF literal string (Latin-1, backslash and parentheses escaped)."""
    s = text.encode("latin-1", "replace").decode("latin-1")
    return s.replace("\\", "\\\\").replace("(", "\\(").replace(")", "\\)")
