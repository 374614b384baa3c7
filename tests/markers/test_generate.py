"""Printable markers: physical size, formats, and the round trip PNG -> detector -> ID."""

from __future__ import annotations

import json
import re
import struct
from pathlib import Path

import cv2
import numpy as np
import pytest
from typer.testing import CliRunner

from gtrig.cli.main import app
from gtrig.markers.apriltag3 import at3_family
from gtrig.markers.detect import MarkerDetector
from gtrig.markers.families import AT3_NAMES, family_spec
from gtrig.markers.generate import layout, png_resolution, to_png_image
from gtrig.markers.sheetfiles import to_pdf as sheet_pdf
from gtrig.markers.sheets import lay_out, marker_tile, parse_paper
from gtrig.rig.models import MarkerFamily

runner = CliRunner()


def _phys(png: bytes) -> int:
    i = png.index(b"pHYs")
    ppx, ppy, unit = struct.unpack(">IIB", png[i + 4 : i + 13])
    assert ppx == ppy and unit == 1
    return ppx


@pytest.mark.parametrize("family", list(MarkerFamily))
def test_png_round_trip_every_family(family: MarkerFamily) -> None:
    lay = layout(family, 3, 80.0)
    img, ppm, k = to_png_image(lay, dpi=100)
    n = lay.cells.shape[0]
    assert abs(n * k / ppm * 1000 - 80.0) <= 0.5 / ppm * 1000 + 1e-9
    # as a camera would see it: smaller, blurred, noisy
    small = cv2.resize(img, None, fx=0.5, fy=0.5, interpolation=cv2.INTER_AREA)
    small = cv2.GaussianBlur(small, (0, 0), 0.8)
    small = np.clip(small + np.random.default_rng(0).normal(0, 3, small.shape), 0, 255).astype(np.uint8)
    dets = MarkerDetector(family).detect(small)
    assert [d.id for d in dets] == [3]
    # corners: the black square starts at the marker's pixel offset (pixel edges at -0.5); AprilTag 3's
    # newer families' corners span their border square, AprilTag 3's own corners
    spec = family_spec(family)
    a, b, tol = (0, n, 0.1) if spec.edge_model else (*_border_square(family), 0.5)
    x0 = round(lay.marker_xy_mm[0] * ppm / 1000)
    y0 = round(lay.marker_xy_mm[1] * ppm / 1000)
    tl = (np.array([x0, y0]) + a * k - 0.5) * 0.5 - 0.25  # half-size image: u' = (u + 0.5) / 2 - 0.5
    br = (np.array([x0, y0]) + b * k - 0.5) * 0.5 - 0.25
    np.testing.assert_allclose(dets[0].corners_px[0], tl, atol=tol)
    np.testing.assert_allclose(dets[0].corners_px[2], br, atol=tol)


def _border_square(family: MarkerFamily) -> tuple[int, int]:
    """First and past-the-last cell of an AprilTag 3 newer family's border square in its printed pattern."""
    fam = at3_family(AT3_NAMES[family.value])
    start = (fam.total_width - fam.width_at_border) // 2
    return start, start + fam.width_at_border


def test_cli_make_formats(tmp_path: Path) -> None:
    """One marker on an A4 sheet in each format (tests/markers/test_sheets.py reads the sheets back)."""
    for suffix in ("png", "svg", "pdf"):
        out = tmp_path / f"m.{suffix}"
        r = runner.invoke(app, ["markers", "make", "--family", "artoolkitplus_simple", "--id", "14",
                                "--size-mm", "100", "--out", str(out), "--dpi", "150"])
        assert r.exit_code == 0, r.output
    png = (tmp_path / "m.png").read_bytes()
    ppm = _phys(png)
    k, ppm2 = png_resolution(100.0, 12, 150)
    assert ppm == ppm2 and 150 <= ppm * 0.0254 < 160
    img = cv2.imdecode(np.frombuffer(png, np.uint8), cv2.IMREAD_GRAYSCALE)
    assert img.shape[1] == pytest.approx(210.0 * ppm / 1000, abs=1)
    svg = (tmp_path / "m.svg").read_text()
    assert 'width="210.0000mm"' in svg and "id 14" in svg
    pdf = (tmp_path / "m.pdf").read_bytes()
    assert pdf.startswith(b"%PDF-1.4") and pdf.rstrip().endswith(b"%%EOF")
    box = re.search(rb"/MediaBox \[0 0 ([\d.]+) ([\d.]+)\]", pdf)
    assert box and float(box.group(1)) == pytest.approx(210.0 * 72 / 25.4, abs=1e-3)
    # the cross-reference table points at the objects (catalog, pages, font, page, content)
    xref = int(pdf[pdf.rindex(b"startxref") + 9 :].split()[0])
    offsets = [int(line[:10]) for line in pdf[xref:].split(b"\n")[3:8]]
    for i, off in enumerate(offsets, start=1):
        assert pdf[off:].startswith(b"%d 0 obj" % i)
    # the content stream has one black run per row segment of the pattern, and the ruler's bar
    lay = layout("artoolkitplus_simple", 14, 100)
    assert pdf.count(b" re\n") == len(lay.black_runs_mm()) + 1
    pages = lay_out([marker_tile("artoolkitplus_simple", 14, 100.0)], parse_paper("a4"))
    assert sheet_pdf(pages) == pdf


def test_cli_errors_and_detect(tmp_path: Path) -> None:
    r = runner.invoke(app, ["markers", "make", "--family", "aruco_4x4_50", "--id", "50", "--size-mm", "50",
                            "--out", str(tmp_path / "x.png")])
    assert r.exit_code == 2 and "out of range" in r.output
    r = runner.invoke(app, ["markers", "make", "--family", "aruco_4x4_50", "--id", "5", "--size-mm", "50",
                            "--out", str(tmp_path / "x.jpg")])
    assert r.exit_code == 2 and "unknown output format" in r.output
    lay = layout("apriltag_36h11", 9, 40.0)
    img, _, _ = to_png_image(lay, dpi=100)
    cv2.imwrite(str(tmp_path / "a.png"), img)
    out = tmp_path / "det.json"
    r = runner.invoke(app, ["markers", "detect", str(tmp_path), "--family", "apriltag_36h11",
                            "--out", str(out)])
    assert r.exit_code == 0, r.output
    doc = json.loads(out.read_text())
    (im,) = doc["images"]
    assert im["file"].endswith("a.png")
    (d,) = im["detections"]
    assert d["id"] == 9 and np.array(d["corners"]).shape == (4, 2)
    assert np.array(d["corner_cov"]).shape == (4, 2, 2)
    r = runner.invoke(app, ["markers", "detect", str(tmp_path / "none.png"), "--family", "apriltag_36h11",
                            "--out", str(out)])
    assert r.exit_code == 2
