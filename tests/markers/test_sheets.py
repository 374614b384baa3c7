"""Printable sheets read back: paper size in points, the printed square and ruler measured on a
rendering of the PDF (PDFium, an independent reader), the IDs decoded from it, refusals, --rig and boards."""

from __future__ import annotations

import re
import struct
from pathlib import Path

import cv2
import numpy as np
import pytest
import yaml
from typer.testing import CliRunner

from gtrig.cli.main import app
from gtrig.markers.detect import MarkerDetector
from gtrig.markers.sheets import PAGE_MARGIN_MM, lay_out, marker_tile, parse_paper
from gtrig.rig import load_rig

pdfium = pytest.importorskip("pypdfium2")
runner = CliRunner()
PT_PER_MM = 72 / 25.4
PAPER_PT = {"a4": (595.276, 841.890), "letter": (612.0, 792.0), "a3": (841.890, 1190.551)}


def _make(tmp_path: Path, *args: str, out: str = "m.pdf") -> tuple[Path, str]:
    p = tmp_path / out
    r = runner.invoke(app, ["markers", "make", *args, "--out", str(p)])
    assert r.exit_code == 0, r.output
    return p, r.output


def _render(pdf: Path, dpi: float) -> list[np.ndarray]:
    """Every page as grey pixels at ``dpi``."""
    doc = pdfium.PdfDocument(str(pdf))
    pages = []
    for i in range(len(doc)):
        img = np.asarray(doc[i].render(scale=dpi / 72, grayscale=True).to_pil().convert("L"))
        pages.append(img)
    doc.close()
    return pages


def _page_sizes_pt(pdf: Path) -> list[tuple[float, float]]:
    doc = pdfium.PdfDocument(str(pdf))
    sizes = [tuple(doc[i].get_size()) for i in range(len(doc))]
    doc.close()
    return sizes  # type: ignore[return-value]


@pytest.mark.parametrize("paper", ["a4", "letter", "a3"])
def test_page_is_the_paper_in_points(tmp_path: Path, paper: str) -> None:
    pdf, _ = _make(tmp_path, "--family", "aruco_4x4_50", "--id", "0-3", "--size-mm", "40", "--paper", paper)
    w, h = PAPER_PT[paper]
    sizes = _page_sizes_pt(pdf)
    assert sizes
    for pw, ph in sizes:
        assert sorted((pw, ph)) == pytest.approx([w, h], abs=0.01)
    # the MediaBox as written, in points
    for m in re.finditer(rb"/MediaBox \[0 0 ([\d.]+) ([\d.]+)\]", pdf.read_bytes()):
        assert sorted((float(m.group(1)), float(m.group(2)))) == pytest.approx([w, h], abs=1e-3)


def _components(img: np.ndarray) -> np.ndarray:
    """Stats (x, y, w, h, area) of the dark connected components."""
    n, _, stats, _ = cv2.connectedComponentsWithStats((img < 128).astype(np.uint8), connectivity=8)
    return stats[1:n]


def test_square_and_ruler_measure_true_and_the_id_reads_back(tmp_path: Path) -> None:
    """The 160 mm marker the old single-marker page could not fit on A4, printed on A4."""
    pdf, out = _make(tmp_path, "--family", "artoolkitplus_simple", "--id", "14", "--size-mm", "160")
    assert "A4 portrait (210 x 297 mm)" in out
    dpi = 600.0
    (img,) = _render(pdf, dpi)
    mm = 25.4 / dpi
    stats = _components(img)
    # the black square: the largest component, its outer border one piece
    sq = stats[np.argmax(stats[:, 4])]
    assert abs(sq[2] * mm - 160.0) <= 0.1 and abs(sq[3] * mm - 160.0) <= 0.1, sq[2:4] * mm
    # the ruler: the widest flat component (bar and its ticks); the bar's row spans 100 mm
    flat = stats[stats[:, 3] * mm < 8.0]
    bar = flat[np.argmax(flat[:, 2])]
    row = img[bar[1] + bar[3] - round(0.75 / mm), :] < 128
    run = np.flatnonzero(row)
    assert abs((run[-1] - run[0] + 1) * mm - 100.0) <= 0.1
    assert np.all(row[run[0]:run[-1] + 1])
    # nothing within the paper's margin
    edge = round(PAGE_MARGIN_MM / mm) - 2
    assert img[:edge].min() > 128 and img[-edge:].min() > 128 and img[:, :edge].min() > 128
    # as a camera sees it: 1/6 of the resolution, blurred
    small = cv2.GaussianBlur(cv2.resize(img, None, fx=1 / 6, fy=1 / 6, interpolation=cv2.INTER_AREA), (0, 0), 0.8)
    assert [d.id for d in MarkerDetector("artoolkitplus_simple").detect(small)] == [14]


def test_several_per_sheet_decoded_by_opencv(tmp_path: Path) -> None:
    pdf, out = _make(tmp_path, "--family", "aruco_4x4_50", "--id", "0-11", "--size-mm", "50", "--paper", "letter")
    pages = _render(pdf, 150)
    assert len(pages) == 2 and "Letter landscape" in out
    det = cv2.aruco.ArucoDetector(cv2.aruco.getPredefinedDictionary(cv2.aruco.DICT_4X4_50))
    seen = []
    for img in pages:
        corners, ids, _ = det.detectMarkers(img)
        seen.append(sorted(int(i) for i in ids.ravel()))
        # every square 50 mm within a pixel at 150 dpi (0.17 mm)
        for c in corners:
            side_px = np.linalg.norm(np.diff(c[0], axis=0, append=c[0][:1]), axis=1)
            assert np.all(np.abs(side_px * 25.4 / 150 - 50.0) < 0.35)
    assert seen == [[0, 1, 2, 3, 4, 5], [6, 7, 8, 9, 10, 11]]


def test_a_marker_too_big_for_the_paper_is_refused(tmp_path: Path) -> None:
    out = tmp_path / "big.pdf"
    r = runner.invoke(app, ["markers", "make", "--family", "artoolkitplus_simple", "--id", "14", "--size-mm", "200",
                            "--out", str(out)])
    assert r.exit_code == 2 and not out.exists()
    lines = r.output.strip().splitlines()
    assert len(lines) == 1 and "does not fit the paper" in lines[0] and "A4 (210 x 297 mm)" in lines[0]
    # A3 holds it
    _make(tmp_path, "--family", "artoolkitplus_simple", "--id", "14", "--size-mm", "200", "--paper", "a3")
    # several sheets do not go into one PNG
    r = runner.invoke(app, ["markers", "make", "--family", "aruco_4x4_50", "--id", "0-11", "--size-mm", "50",
                            "--out", str(tmp_path / "x.png")])
    assert r.exit_code == 2 and "write a .pdf" in r.output
    r = runner.invoke(app, ["markers", "make", "--family", "aruco_4x4_50", "--id", "3", "--out", str(out)])
    assert r.exit_code == 2 and "go together" in r.output


def test_rig_prints_every_marker(tmp_path: Path) -> None:
    rig = tmp_path / "rig.yaml"
    assert runner.invoke(app, ["rig", "init", "--cameras", "2", "--scanners", "0", "--out", str(rig)]).exit_code == 0
    pdf, out = _make(tmp_path, "--rig", str(rig), "--paper", "a3")
    markers = load_rig(rig).robot.markers
    pages = _render(pdf, 100)
    assert len(pages) == 2 and out.count("A3 landscape") == 2  # two 156 mm markers a sheet
    found = []
    for img in pages:  # as a camera sees them: blurred a little
        found += [d.id for d in MarkerDetector("artoolkitplus_simple").detect(cv2.GaussianBlur(img, (0, 0), 0.8))]
    assert sorted(found) == sorted(m.id for m in markers)


def test_boards_from_boards_yaml(tmp_path: Path) -> None:
    boards = tmp_path / "boards.yaml"
    boards.write_text(yaml.safe_dump({
        "inner_corners": [7, 5], "square_m": 0.02,
        "T_board1_board2": {"xyz": [0.4, 0.0, 0.0], "rpy_deg": [0.0, 0.0, 0.0]},
        "T_world_board": {"xyz": [1.0, 2.0, 0.0], "rpy_deg": [180.0, 0.0, 90.0]}}))
    pdf, out = _make(tmp_path, "--boards", str(boards))
    assert "board 1" in out and "board 2" in out and "world board" in out
    dpi = 200
    pages = _render(pdf, dpi)
    assert len(pages) == 3 and out.count("A4 landscape") == 3  # 200 x 160 mm with the margin: one a sheet
    for img in pages:
        ok, corners = cv2.findChessboardCorners(img, (7, 5))
        assert ok
        c = corners.reshape(5, 7, 2)
        step = np.linalg.norm(np.diff(c, axis=1), axis=2).mean() * 25.4 / dpi
        assert step == pytest.approx(20.0, abs=0.1)
    # a room-sized board needs a plotter's sheet
    r = runner.invoke(app, ["markers", "make", "--board", "9x5x0.1", "--out", str(tmp_path / "b.pdf")])
    assert r.exit_code == 2 and "does not fit the paper" in r.output and "chessboard" in r.output
    pdf, _ = _make(tmp_path, "--board", "9x5x0.1", "--paper", "1300x900", out="b.pdf")
    assert sorted(_page_sizes_pt(pdf)[0]) == pytest.approx([900 * PT_PER_MM, 1300 * PT_PER_MM], abs=0.01)


def test_png_keeps_the_physical_size(tmp_path: Path) -> None:
    png, _ = _make(tmp_path, "--family", "apriltag_36h11", "--id", "9", "--size-mm", "60", "--dpi", "150",
                   out="m.png")
    data = png.read_bytes()
    i = data.index(b"pHYs")
    ppm, ppm_y, unit = struct.unpack(">IIB", data[i + 4 : i + 13])
    assert ppm == ppm_y and unit == 1 and ppm * 0.0254 >= 150
    img = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_GRAYSCALE)
    assert img.shape[1] * 1000 / ppm == pytest.approx(210.0, abs=0.5)  # A4 wide
    sq = _components(img)
    sq = sq[np.argmax(sq[:, 4])]
    assert abs(sq[2] * 1000 / ppm - 60.0) <= 0.5 * 1000 / ppm + 1e-9
    assert [d.id for d in MarkerDetector("apriltag_36h11").detect(img)] == [9]
    svg = _make(tmp_path, "--family", "apriltag_36h11", "--id", "9", "--size-mm", "60", out="m.svg")[0].read_text()
    assert 'width="210.0000mm" height="297.0000mm"' in svg and "apriltag_36h11 id 9" in svg


def test_layout_orientation_and_papers() -> None:
    a4 = parse_paper("a4")
    # one 156 mm marker per A4 sheet, portrait
    pages = lay_out([marker_tile("artoolkitplus_simple", i, 156.0) for i in (3, 6)], a4)
    assert [p.landscape for p in pages] == [False, False]
    assert parse_paper("1100x800").oriented(False) == (800.0, 1100.0)
    for p in pages:
        (m,) = p.markers
        w, h = p.size_mm
        assert PAGE_MARGIN_MM < m.x_mm and m.x_mm + m.side_mm < w - PAGE_MARGIN_MM and m.y_mm + m.side_mm < h
