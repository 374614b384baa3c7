"""Greyscale PNG decoding (gtrig.io.png): every filter and depth it decodes gives OpenCV's pixels, everything
else is left to OpenCV, and a damaged file is never decoded into an image OpenCV would refuse."""

from __future__ import annotations

import struct
import zlib
from pathlib import Path

import cv2
import numpy as np
import pytest

from gtrig.errors import FormatError
from gtrig.io import png
from gtrig.io.frames import read_image
from gtrig.io.png import decode_grey_png
from gtrig.sim.render import encode_png

FILTERS = ("NONE", "SUB", "UP", "AVG", "PAETH")


def _chunk(kind: bytes, data: bytes) -> bytes:
    return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data) & 0xFFFFFFFF)


def _png(width: int, height: int, depth: int, colour: int, idat: bytes, interlace: int = 0,
         extra: bytes = b"") -> bytes:
    ihdr = struct.pack(">IIBBBBB", width, height, depth, colour, 0, 0, interlace)
    return png.PNG_SIGNATURE + _chunk(b"IHDR", ihdr) + extra + _chunk(b"IDAT", idat) + _chunk(b"IEND", b"")


def _image(rng: np.random.Generator, shape: tuple[int, int], dtype: type) -> np.ndarray:
    """Smooth content plus noise, so that every filter has neighbours worth predicting from."""
    top = np.iinfo(dtype).max
    y, x = np.mgrid[0:shape[0], 0:shape[1]]
    base = 0.5 * top * (1 + np.sin(x / 7.0) * np.cos(y / 5.0))
    return np.clip(base + rng.normal(0, 0.05 * top, shape), 0, top).astype(dtype)


@pytest.mark.parametrize("dtype", [np.uint8, np.uint16])
@pytest.mark.parametrize("name", FILTERS)
def test_every_filter_decodes_to_opencvs_pixels(name: str, dtype: type) -> None:
    rng = np.random.default_rng(7)
    for shape in ((1, 1), (2, 3), (37, 53), (64, 129)):
        img = _image(rng, shape, dtype)
        ok, buf = cv2.imencode(".png", img, [cv2.IMWRITE_PNG_FILTER, getattr(cv2, f"IMWRITE_PNG_FILTER_{name}")])
        assert ok
        got = decode_grey_png(buf.tobytes())
        assert got is not None and got.dtype == np.uint8
        np.testing.assert_array_equal(got, cv2.imdecode(buf, cv2.IMREAD_GRAYSCALE))


def test_adaptive_filters_and_the_simulators_frames_decode_to_opencvs_pixels(tmp_path: Path) -> None:
    rng = np.random.default_rng(3)
    img = _image(rng, (96, 160), np.uint8)
    for data in (cv2.imencode(".png", img)[1].tobytes(), encode_png(img), encode_png(img, compression=9)):
        np.testing.assert_array_equal(decode_grey_png(data), img)
    # libpng's adaptive choice mixes the filters row by row; a 16-bit image keeps its high byte
    wide = _image(rng, (40, 70), np.uint16)
    p = tmp_path / "deep.png"
    cv2.imwrite(str(p), wide)
    np.testing.assert_array_equal(read_image(p), cv2.imread(str(p), cv2.IMREAD_GRAYSCALE))
    np.testing.assert_array_equal(read_image(p), (wide >> 8).astype(np.uint8))


def test_the_standard_librarys_inflate_gives_the_same_pixels(monkeypatch: pytest.MonkeyPatch) -> None:
    img = _image(np.random.default_rng(5), (50, 80), np.uint8)
    data = encode_png(img)
    monkeypatch.setattr(png, "_INFLATE", zlib)
    np.testing.assert_array_equal(decode_grey_png(data), img)


def test_pngs_it_does_not_decode_are_left_to_opencv(tmp_path: Path) -> None:
    rng = np.random.default_rng(11)
    grey = _image(rng, (24, 31), np.uint8)
    colour = np.dstack([grey, grey[::-1], 255 - grey])
    raw_rows = b"".join(b"\x00" + bytes(r) for r in grey)
    cases = {
        "colour": cv2.imencode(".png", colour)[1].tobytes(),
        "grey_alpha": cv2.imencode(".png", np.dstack([colour, grey]))[1].tobytes(),
        # a transparent grey level turns into alpha in OpenCV's read
        "trns": _png(31, 24, 8, 0, zlib.compress(raw_rows), extra=_chunk(b"tRNS", b"\x00\x80")),
        # one bit per pixel: 4 bytes a row
        "one_bit": _png(31, 24, 1, 0, zlib.compress(b"".join(b"\x00" + bytes(4) for _ in range(24)))),
    }
    for name, data in cases.items():
        assert decode_grey_png(data) is None, name
        p = tmp_path / f"{name}.png"
        p.write_bytes(data)
        np.testing.assert_array_equal(read_image(p), cv2.imread(str(p), cv2.IMREAD_GRAYSCALE))
    # Adam7 interlacing is refused before any data is read
    assert decode_grey_png(_png(31, 24, 8, 0, zlib.compress(raw_rows), interlace=1)) is None
    assert decode_grey_png(_png(31, 24, 8, 0, zlib.compress(raw_rows))) is not None


def test_a_damaged_file_is_not_decoded_here(tmp_path: Path) -> None:
    img = _image(np.random.default_rng(13), (40, 60), np.uint8)
    good = encode_png(img)
    idat = good.index(b"IDAT")
    flipped = bytearray(good)
    flipped[idat + 40] ^= 0xFF  # inside the image data: its chunk's CRC no longer holds
    raw = zlib.compress(b"".join(b"\x05" + bytes(r) for r in img))  # filter type 5 does not exist
    cases = {"crc": bytes(flipped), "truncated": good[:len(good) // 2], "filter": _png(60, 40, 8, 0, raw),
             "short_stream": _png(60, 40, 8, 0, zlib.compress(b"\x00" * 61 * 39))}
    for name, data in cases.items():
        assert decode_grey_png(data) is None, name
        p = tmp_path / f"{name}.png"
        p.write_bytes(data)
        want = cv2.imread(str(p), cv2.IMREAD_GRAYSCALE)
        if want is None:
            with pytest.raises(FormatError, match="cannot read the image"):
                read_image(p)
        else:
            np.testing.assert_array_equal(read_image(p), want)


def test_an_image_beyond_the_pixel_limit_is_not_decoded() -> None:
    data = encode_png(np.zeros((20, 30), np.uint8))
    assert decode_grey_png(data, max_pixels=600) is not None
    assert decode_grey_png(data, max_pixels=599) is None


def test_runs_of_sub_rows_broken_by_other_filters_decode_to_the_image() -> None:
    # Sub rows are undone four at a time: runs of every length, cut by None and Up rows, must not shift rows
    img = _image(np.random.default_rng(13), (23, 45), np.uint8)
    kinds = [1, 1, 1, 1, 1, 0, 1, 1, 1, 2, 1, 1, 1, 1, 1, 1, 1, 1, 2, 1, 1, 1, 1]
    rows = []
    for r, k in enumerate(kinds):
        line = img[r].astype(np.int16)
        if k == 1:
            line = line - np.concatenate([[0], img[r, :-1]])
        elif k == 2:
            line = line - img[r - 1]
        rows.append(bytes([k]) + (line & 255).astype(np.uint8).tobytes())
    data = _png(45, 23, 8, 0, zlib.compress(b"".join(rows)))
    np.testing.assert_array_equal(decode_grey_png(data), img)
