"""How an image file stores light: the tone curve its format declares.

The detector's edge model is linear in light (:mod:`gtrig.markers.detect.tone`); a file stores either
light itself (machine-vision cameras, raw sensor dumps, the simulator's PNGs) or light through a
display tone curve, about sRGB's (phones, webcams, almost every JPEG). Fitted in the wrong space a
blurred edge's midpoint moves into the black by a share of the blur (on the 12 MP phone photo
``taggridphoto.jpg``: 0.1-0.4 px, docs/markers.md). Nothing in the pixels tells the two apart
reliably (the edge's texture hides the profile's asymmetry), but the file usually says:

- JPEG (JFIF / Exif) is a display-referred format: its samples are gamma-encoded (JFIF assumes
  sRGB-like primaries and transfer, Exif's ``ColorSpace`` is sRGB or "uncalibrated" display data);
  an Exif ``Gamma`` tag of 1.0, which a camera writing linear JPEGs would set, is read as linear.
- PNG states it in chunks before the image data: ``sRGB`` or ``iCCP`` (a display profile) is sRGB,
  ``gAMA`` gives the encoding exponent (0.45455 for sRGB-like, 1.0 for linear). With none, the file
  makes no claim; scientific and machine-vision writers (OpenCV's ``imwrite`` among them) add none,
  and the data are taken as linear.
- Anything else (TIFF, PGM, BMP, 16-bit data, a video's frames) is taken as linear; a camera of the rig
  can say otherwise (``tone`` in rig.yaml).
"""

from __future__ import annotations

import os
import struct
from typing import Literal

DeclaredTone = Literal["linear", "srgb"]

_PNG_SIG = b"\x89PNG\r\n\x1a\n"
_HEAD_BYTES = 1 << 16  # Exif and PNG's colour chunks come before the image data, within the first 64 kB


def declared_tone(path: str | os.PathLike[str]) -> DeclaredTone:
    """``"srgb"`` or ``"linear"``: how the image file ``path`` declares its samples (module docstring).

    A file that cannot be opened, or a ``<video>#frame=<n>`` source, is ``"linear"``: no claim.
    """
    try:
        with open(path, "rb") as fh:
            head = fh.read(_HEAD_BYTES)
    except OSError:
        return "linear"
    if head.startswith(b"\xff\xd8"):
        return "linear" if _exif_gamma(head) == 1.0 else "srgb"
    if head.startswith(_PNG_SIG):
        return _png_tone(head)
    return "linear"


def _png_tone(head: bytes) -> DeclaredTone:
    """The tone a PNG's chunks before ``IDAT`` declare; linear when they declare none."""
    pos = len(_PNG_SIG)
    while pos + 8 <= len(head):
        length, kind = struct.unpack(">I4s", head[pos:pos + 8])
        if kind in (b"IDAT", b"IEND"):
            break
        if kind in (b"sRGB", b"iCCP"):
            return "srgb"
        if kind == b"gAMA" and length == 4 and pos + 12 <= len(head):
            # the file's encoding exponent x 100000: 45455 for sRGB-like data, 100000 for linear
            (g,) = struct.unpack(">I", head[pos + 8:pos + 12])
            return "srgb" if g < 80000 else "linear"
        pos += 12 + length
    return "linear"


def _exif_gamma(head: bytes) -> float | None:
    """The Exif ``Gamma`` tag (0xA500) of a JPEG's APP1 segment, or ``None`` where there is none."""
    pos = 2
    while pos + 4 <= len(head) and head[pos] == 0xFF:
        marker = head[pos + 1]
        if marker in (0xDA, 0xD9):  # start of scan / end of image: no metadata after it
            return None
        (seg_len,) = struct.unpack(">H", head[pos + 2:pos + 4])
        seg = head[pos + 4:pos + 2 + seg_len]
        if marker == 0xE1 and seg.startswith(b"Exif\x00\x00"):
            return _tiff_tag_rational(seg[6:], 0xA500)
        pos += 2 + seg_len
    return None


def _tiff_tag_rational(tiff: bytes, tag: int) -> float | None:
    """A RATIONAL tag of an Exif TIFF block, searched in IFD0 and the Exif sub-IFD."""
    if len(tiff) < 8 or tiff[:2] not in (b"II", b"MM"):
        return None
    e = "<" if tiff[:2] == b"II" else ">"

    def entries(off: int) -> list[tuple[int, int, int, int]]:
        if off + 2 > len(tiff):
            return []
        (n,) = struct.unpack(e + "H", tiff[off:off + 2])
        out = []
        for k in range(n):
            p = off + 2 + 12 * k
            if p + 12 > len(tiff):
                break
            t, typ, cnt = struct.unpack(e + "HHI", tiff[p:p + 8])
            (val,) = struct.unpack(e + "I", tiff[p + 8:p + 12])
            out.append((t, typ, cnt, val))
        return out

    (ifd0,) = struct.unpack(e + "I", tiff[4:8])
    todo, seen = [ifd0], set()
    while todo:
        off = todo.pop()
        if off in seen:
            continue
        seen.add(off)
        for t, typ, _cnt, val in entries(off):
            if t == 0x8769:  # the Exif sub-IFD
                todo.append(val)
            elif t == tag and typ == 5 and val + 8 <= len(tiff):
                num, den = struct.unpack(e + "II", tiff[val:val + 8])
                return num / den if den else None
    return None
