"""Greyscale PNG decoding for the stages' image reads, byte-identical to OpenCV's ``IMREAD_GRAYSCALE``.

A camera frame of 1024 x 768 costs about 6 ms to decode through OpenCV (libpng), 4 ms of it in zlib's
inflate: the largest share of GTvision's CPU per tracked image. ISA-L's inflate (the ``isal`` package)
takes a quarter of zlib's time on these streams and the rows' filters are undone by a compiled kernel,
which brings a frame to about 2 ms. Without ``isal`` the standard library's zlib inflates (the output is
the same; only the time differs).

Handled here: greyscale (colour type 0) of 8 or 16 bits per sample, not interlaced, without a
transparency (``tRNS``) or Exif (``eXIf``) chunk: what gtrig's simulator, its bag import and
machine-vision cameras write. 16-bit samples keep their high byte, as OpenCV's 8-bit read does. Any other
PNG (colour, palette, alpha, sub-byte depths, Adam7 interlacing) returns None for the caller to read with
OpenCV, and so does a file that is damaged (a chunk's CRC, the zlib stream, a row's filter type), so that
OpenCV's reading of it, or its refusal, stays the one answer.
"""

from __future__ import annotations

import struct
import zlib
from types import ModuleType

import numba as nb
import numpy as np

__all__ = ["PNG_SIGNATURE", "decode_grey_png", "inflate_module"]

PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"


def inflate_module() -> ModuleType:
    """The zlib-compatible module that inflates: ``isal.isal_zlib`` when installed, else :mod:`zlib`."""
    try:
        from isal import isal_zlib
    except ImportError:  # a platform without ISA-L's wheel: same bytes, slower
        return zlib
    return isal_zlib


_INFLATE = inflate_module()
# chunks after which OpenCV's grey read is not the raw samples: transparency becomes alpha, Exif may rotate
_FALLBACK_CHUNKS = (b"tRNS", b"eXIf")


def decode_grey_png(data: bytes, max_pixels: int | None = None) -> np.ndarray | None:
    """The 8-bit grey image (H, W) uint8 of the PNG file ``data`` (its bytes), or None when the file is not
    one this module decodes (module docstring), is damaged, or has more than ``max_pixels`` pixels."""
    layout = _grey_layout(data)
    if layout is None:
        return None
    width, height, depth, idat = layout
    if max_pixels is not None and width * height > max_pixels:
        return None
    row_bytes = width * depth // 8
    size = height * (row_bytes + 1)
    try:
        raw = _INFLATE.decompress(idat, 15, size)
    except Exception:  # noqa: BLE001 (zlib.error or isal's IsalError: a damaged stream, OpenCV's to judge)
        return None
    if len(raw) != size:
        return None
    filtered = np.frombuffer(raw, np.uint8).reshape(height, row_bytes + 1)
    rows = np.empty((height, row_bytes), np.uint8)
    if not unfilter_rows(filtered, depth // 8, rows):
        return None
    return rows if depth == 8 else np.ascontiguousarray(rows[:, 0::2])  # big-endian: the high byte first


def _grey_layout(data: bytes) -> tuple[int, int, int, bytes] | None:
    """``(width, height, bit_depth, zlib_stream)`` of a non-interlaced 8- or 16-bit greyscale PNG whose
    header and image chunks pass their CRCs, or None."""
    if not data.startswith(PNG_SIGNATURE) or len(data) < 33 or data[12:16] != b"IHDR":
        return None
    width, height, depth, colour, method, filt, interlace = struct.unpack(">IIBBBBB", data[16:29])
    if (colour != 0 or depth not in (8, 16) or method or filt or interlace or not width or not height
            or struct.unpack(">I", data[29:33])[0] != zlib.crc32(data[12:29])):
        return None
    view = memoryview(data)  # the chunks sliced without copies
    parts = []
    pos = 33
    while pos + 12 <= len(data):
        length, kind = struct.unpack_from(">I4s", data, pos)
        end = pos + 12 + length
        if end > len(data) or kind in _FALLBACK_CHUNKS:
            return None
        if kind == b"IDAT":
            if struct.unpack_from(">I", data, end - 4)[0] != _INFLATE.crc32(view[pos + 4:end - 4]):
                return None
            parts.append(view[pos + 8:end - 4])
        elif kind == b"IEND":
            break
        pos = end
    else:
        return None  # no IEND: a file cut short
    return (width, height, depth, b"".join(parts)) if parts else None


@nb.njit(nb.void(nb.types.Array(nb.uint8, 2, "C", readonly=True), nb.uint8[:, ::1]), cache=True, nogil=True)
def _sub_rows4(filtered: np.ndarray, out: np.ndarray) -> None:
    """Undo the Sub filter of four 8-bit rows at once: ``filtered`` (4, 1 + B), ``out`` (4, B) uint8.

    Each row is a running sum modulo 256, one byte after the other; a single row's sum waits on its
    previous byte at every step, so four independent rows are carried side by side (about half the time
    of one row after the other)."""
    n = out.shape[1]
    s0, s1, s2, s3 = filtered[0, 1:], filtered[1, 1:], filtered[2, 1:], filtered[3, 1:]
    d0, d1, d2, d3 = out[0], out[1], out[2], out[3]
    a0 = a1 = a2 = a3 = np.uint8(0)
    for i in range(n):
        a0 = np.uint8(s0[i] + a0)
        a1 = np.uint8(s1[i] + a1)
        a2 = np.uint8(s2[i] + a2)
        a3 = np.uint8(s3[i] + a3)
        d0[i] = a0
        d1[i] = a1
        d2[i] = a2
        d3[i] = a3


@nb.njit(nb.boolean(nb.types.Array(nb.uint8, 2, "C", readonly=True), nb.int64, nb.uint8[:, ::1]),
         cache=True, nogil=True)
def unfilter_rows(filtered: np.ndarray, bpp: int, out: np.ndarray) -> bool:
    """Undo PNG's per-row filters (None, Sub, Up, Average, Paeth; the PNG specification, section 9).

    Parameters
    ----------
    filtered : (H, 1 + B) uint8
        The inflated stream: each row's filter type, then its B filtered bytes.
    bpp : int
        Bytes per pixel (the left neighbour's distance): 1 for 8-bit grey, 2 for 16-bit.
    out : (H, B) uint8
        Filled with the rows' bytes.

    Returns
    -------
    bool
        False when a row's filter type is not one of the five (``out`` is then incomplete).
    """
    h, n = out.shape
    zero = np.zeros(n, np.uint8)
    r = -1
    while r + 1 < h:
        r += 1
        f = filtered[r, 0]
        if f == 1 and bpp == 1 and r + 4 <= h and filtered[r + 1, 0] == 1 and filtered[r + 2, 0] == 1 \
                and filtered[r + 3, 0] == 1:
            _sub_rows4(filtered[r:r + 4], out[r:r + 4])
            r += 3
            continue
        src = filtered[r, 1:]
        dst = out[r]
        up = out[r - 1] if r > 0 else zero
        if f == 0:
            dst[:] = src
        elif f == 2:
            for i in range(n):
                dst[i] = (np.int32(src[i]) + np.int32(up[i])) & 255
        elif f == 1:
            # the left neighbour carried in a register, per byte of a pixel: each byte depends on the one
            # before it, and reloading that from memory would set the pace
            for lane in range(bpp):
                a = np.int32(0)
                for i in range(lane, n, bpp):
                    a = (np.int32(src[i]) + a) & 255
                    dst[i] = a
        elif f == 3:
            for lane in range(bpp):
                a = np.int32(0)
                for i in range(lane, n, bpp):
                    a = (np.int32(src[i]) + ((a + np.int32(up[i])) >> 1)) & 255
                    dst[i] = a
        elif f == 4:
            for lane in range(bpp):
                a = np.int32(0)
                c = np.int32(0)
                for i in range(lane, n, bpp):
                    b = np.int32(up[i])
                    p = a + b - c
                    pa, pb, pc = abs(p - a), abs(p - b), abs(p - c)
                    a = (np.int32(src[i]) + (a if pa <= pb and pa <= pc else (b if pb <= pc else c))) & 255
                    dst[i] = a
                    c = b
        else:
            return False
    return True

