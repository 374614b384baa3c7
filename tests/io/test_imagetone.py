"""The tone curve an image file declares (gtrig.io.imagetone): JPEG's display encoding and its Exif
Gamma, PNG's sRGB / iCCP / gAMA chunks, and no claim (linear) for everything else."""

from __future__ import annotations

import struct
import zlib
from pathlib import Path

import cv2
import numpy as np
import pytest

from gtrig.io.imagetone import declared_tone

REAL = Path(__file__).parents[2] / ".." / "shared" / "data" / "markers_real"


def _chunk(kind: bytes, data: bytes) -> bytes:
    return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data) & 0xFFFFFFFF)


def _png_with(tmp_path: Path, name: str, extra: bytes) -> Path:
    """OpenCV's PNG of a small image with ``extra`` chunks put right after IHDR."""
    ok, buf = cv2.imencode(".png", np.arange(64, dtype=np.uint8).reshape(8, 8))
    assert ok
    b = buf.tobytes()
    ihdr_end = 8 + 8 + 13 + 4
    p = tmp_path / name
    p.write_bytes(b[:ihdr_end] + extra + b[ihdr_end:])
    assert cv2.imread(str(p), cv2.IMREAD_GRAYSCALE) is not None  # still a valid PNG
    return p


def _jpeg_with_exif_gamma(tmp_path: Path, gamma: tuple[int, int], endian: str) -> Path:
    """A JPEG with an APP1 Exif block whose Exif sub-IFD holds Gamma (0xA500) = num / den."""
    e = "<" if endian == "II" else ">"
    # TIFF header, IFD0 with one entry (ExifIFD pointer), Exif IFD with one entry (Gamma), the rational
    ifd0 = 8
    exif_ifd = ifd0 + 2 + 12 + 4
    rational = exif_ifd + 2 + 12 + 4
    tiff = endian.encode() + struct.pack(e + "HI", 42, ifd0)
    tiff += struct.pack(e + "H", 1) + struct.pack(e + "HHII", 0x8769, 4, 1, exif_ifd) + struct.pack(e + "I", 0)
    tiff += struct.pack(e + "H", 1) + struct.pack(e + "HHII", 0xA500, 5, 1, rational) + struct.pack(e + "I", 0)
    tiff += struct.pack(e + "II", *gamma)
    app1 = b"Exif\x00\x00" + tiff
    ok, buf = cv2.imencode(".jpg", np.full((8, 8), 128, np.uint8))
    assert ok
    b = buf.tobytes()
    seg = b"\xff\xe1" + struct.pack(">H", len(app1) + 2) + app1
    p = tmp_path / f"gamma_{gamma[0]}_{endian}.jpg"
    p.write_bytes(b[:2] + seg + b[2:])
    assert cv2.imread(str(p), cv2.IMREAD_GRAYSCALE) is not None
    return p


def test_opencv_png_declares_nothing_and_is_linear(tmp_path: Path) -> None:
    p = tmp_path / "plain.png"
    cv2.imwrite(str(p), np.zeros((8, 8), np.uint8))
    assert declared_tone(p) == "linear"


@pytest.mark.parametrize(("chunk", "tone"), [
    (_chunk(b"sRGB", b"\x00"), "srgb"),
    (_chunk(b"iCCP", b"icc\x00\x00" + zlib.compress(b"profile")), "srgb"),
    (_chunk(b"gAMA", struct.pack(">I", 45455)), "srgb"),
    (_chunk(b"gAMA", struct.pack(">I", 100000)), "linear"),
    (_chunk(b"tEXt", b"Comment\x00made here"), "linear"),
])
def test_png_chunks(tmp_path: Path, chunk: bytes, tone: str) -> None:
    assert declared_tone(_png_with(tmp_path, "c.png", chunk)) == tone


def test_jpeg_is_srgb_unless_exif_gamma_says_linear(tmp_path: Path) -> None:
    p = tmp_path / "plain.jpg"
    cv2.imwrite(str(p), np.zeros((8, 8), np.uint8))
    assert declared_tone(p) == "srgb"
    for endian in ("II", "MM"):
        assert declared_tone(_jpeg_with_exif_gamma(tmp_path, (1, 1), endian)) == "linear"
        assert declared_tone(_jpeg_with_exif_gamma(tmp_path, (22, 10), endian)) == "srgb"


def test_other_and_broken_files(tmp_path: Path) -> None:
    tif = tmp_path / "a.tiff"
    cv2.imwrite(str(tif), np.zeros((8, 8), np.uint16))
    assert declared_tone(tif) == "linear"
    assert declared_tone(tmp_path / "missing.jpg") == "linear"
    assert declared_tone(f"{tmp_path / 'run.mkv'}#frame=3") == "linear"
    trunc = tmp_path / "trunc.png"
    trunc.write_bytes(b"\x89PNG\r\n\x1a\n\x00\x00\xff\xffsRG")  # a chunk cut short: no claim, no exception
    assert declared_tone(trunc) == "linear"
    bad = tmp_path / "bad.jpg"
    bad.write_bytes(b"\xff\xd8\xff\xe1\x00\x10Exif\x00\x00MM\x00\x2a\xff\xff\xff\xff")  # IFD offset past the end
    assert declared_tone(bad) == "srgb"


@pytest.mark.skipif(not REAL.is_dir(), reason="../shared/data/markers_real is not beside the repo")
def test_real_photos_are_srgb() -> None:
    """Every real JPEG of markers_real (phone, webcam) is sRGB-encoded; ARToolKitPlus' PNG makes no claim."""
    for p in REAL.glob("*.jpg"):
        assert declared_tone(p) == "srgb", p.name
    assert declared_tone(REAL / "image_320_240_8_marker_id_simple_nr321.png") == "linear"
