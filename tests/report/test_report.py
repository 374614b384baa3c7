"""``gtrig report``: every section present for a full folder (the run's checks, sync, fusion, per-camera and
per-scanner coverage, the tracks against truth in the plane), absent parts named and nothing named that is on
the page, and the page as a person sees it in headless Chromium (every figure decoded and at the page's width,
every table there, no section twice, Markdown lists as lists, no console error, loaded in under 2 s)."""

from __future__ import annotations

import html
import re
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest
from report_folder import MD_WARNINGS, TRUTH_HEIGHT_M
from typer.testing import CliRunner

from gtrig.cli.main import app
from gtrig.report import build_report
from gtrig.report.markdown import markdown_to_html

SECTIONS = ("checks", "accuracy", "tracks", "track-gt_fused", "track-gt_laser", "track-gt_vision_run", "consistency",
            "fusion", "cameras", "scanners", "survey", "calibration", "sync", "summaries")
# tables: checks, accuracy.csv + tracks against truth, tracks, consistency (3 pairs), fusion sources +
# segments + outliers, cameras (2 checkpoints), scanners, survey, sync, the Markdown summary's
N_TABLES = 16


def _figures(text: str) -> int:
    return len(re.findall(r'<img alt="[^"]*" src="data:image/png;base64,', text))


def _section(text: str, key: str) -> str:
    m = re.search(rf'<section id="{key}">(.*?)</section>', text, re.S)
    assert m is not None, key
    return m.group(1)


def _rows(fragment: str) -> list[list[str]]:
    """The body rows of every table in ``fragment``, as cell texts."""
    return [[html.unescape(re.sub(r"<[^>]+>", "", c)) for c in re.findall(r"<td[^>]*>(.*?)</td>", r)]
            for r in re.findall(r"<tr>(.*?)</tr>", fragment) if "<td" in r]


@pytest.fixture(scope="module")
def report_html(results_dir: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("report") / "report.html"
    res = CliRunner().invoke(app, ["report", str(results_dir), "--out", str(out)])
    assert res.exit_code == 0, res.output
    return out


def test_every_section_of_a_full_folder(report_html: Path) -> None:
    text = report_html.read_text(encoding="utf-8")
    for key in SECTIONS:
        assert f'<section id="{key}">' in text, key
    # 3 tracks x 4 figures + consistency 3 x 2 + cameras 2 + survey 1 + calibration 2 + sync 1
    assert _figures(text) == 24
    # each pair of sources once, the denser one against the sparser one (interpolated at its stamps)
    pairs = re.findall(r"<h3>(gt_\w+) against (gt_\w+)</h3>", _section(text, "consistency"))
    assert sorted(pairs) == [("gt_fused", "gt_vision_run"), ("gt_laser", "gt_fused"), ("gt_laser", "gt_vision_run")]
    assert text.count("<table>") == N_TABLES
    assert 'class="miss">miss' in text and "Not in this folder" not in text and "no input" not in text
    assert "http://" not in text.replace("http://www.w3.org", "") and "https://" not in text  # nothing fetched


def test_planar_tracks_are_compared_in_the_plane(report_html: Path) -> None:
    """The truth stands 0.3 m above the floor, tilted 0.4 deg; the planar tracks' RMSE is their simulated
    1, 1.5 and 2.5 mm noise per axis, in both tables (in 3-D it would be the height: 300 mm)."""
    text = report_html.read_text(encoding="utf-8")
    rmse = {r[0]: float(r[10]) for r in _rows(_section(text, "tracks")) if r[0].startswith("gt_")}
    assert 1.0 < rmse["gt_fused"] < 1.8 and 1.5 < rmse["gt_laser"] < 2.7 and 2.8 < rmse["gt_vision_run"] < 4.5, rmse
    against = {r[0]: r for r in _rows(_section(text, "accuracy")) if r[0].startswith("gt_")}
    assert {n: r[1] for n, r in against.items()} == dict.fromkeys(rmse, "in the plane")
    assert all(float(against[n][3]) == pytest.approx(v, abs=0.006) for n, v in rmse.items())
    assert max(rmse.values()) < 1000 * TRUTH_HEIGHT_M / 50


def test_what_a_run_without_truth_tells(report_html: Path) -> None:
    """The checks with their warnings, the sync offsets and verdicts, the fusion's gated and bridged fixes,
    each camera's and scanner's coverage."""
    text = report_html.read_text(encoding="utf-8")
    checks = _section(text, "checks")
    assert "GTvision: run, corner residual RMS is 1.7 px (target &lt;= 1)" in checks
    assert "sync: laser clock offset to odometry (unobservable): not measured" in checks
    assert len(_rows(checks)) == 5
    sync = {r[0]: r for r in _rows(_section(text, "sync"))}
    assert sync["vision"][1:4] == ["ok", "+12.300", "+11.800 .. +12.800"]
    assert sync["laser"][1] == "unobservable" and sync["laser"][-1] == "the robot hardly turns"
    assert sync["laser/laser0"][4:6] == ["-2.100", "-2.300 .. -1.900"]
    fusion = _rows(_section(text, "fusion"))
    assert ["vision", "1770", "1765", "5", "2", "+12.300", "0.200"] in fusion
    assert ["1", "0.00", "58.50", "2000", "30", "0.40"] in fusion  # the segment, 30 poses bridged
    assert ["vision", "11.750", "31.40", "3", "gate"] in fusion  # the gated fix, 11.75 s after the first pose
    cams = _section(text, "cameras")
    per_cam = {r[0]: r for r in _rows(cams) if r[0].startswith("cam") and r[1] == "48"}  # the run's 48 images
    assert [per_cam[c][2] for c in ("cam0", "cam1", "cam2")] == ["24", "16", "0"]
    assert "gt_vision_run: cam2 saw no marker" in cams
    assert _rows(_section(text, "scanners")) == [["laser0", "5", "ok", "5210 observations in 5 blocks of time"]]


def test_missing_parts_are_named(results_dir: Path, tmp_path: Path) -> None:
    only = tmp_path / "results"
    only.mkdir()
    for f in ("gt_laser.tum", "gt_laser_cov.csv"):
        shutil.copy(results_dir / f, only / f)
    text = build_report(only)
    assert '<section id="track-gt_laser">' in text and '<section id="accuracy">' not in text
    for label in ("checks of the run", "accuracy against truth", "consistency of GT sources", "fusion",
                  "cameras", "scanners", "survey", "calibration", "time sync"):
        assert f"{label}: no input in the folder" in text
    assert "accuracy against truth: no input in the folder (no accuracy.csv and no truth folder: give --truth" in text
    assert _figures(text) == 2  # path and status: no truth


def test_truth_fills_the_accuracy_table(results_dir: Path, tmp_path: Path) -> None:
    """``--truth`` with a folder holding no accuracy.csv: the accuracy section is each track against the
    truth, and it is not named as missing."""
    only = tmp_path / "results"
    only.mkdir()
    for f in ("gt_laser.tum", "gt_laser_cov.csv"):
        shutil.copy(results_dir / f, only / f)
    out = tmp_path / "r.html"
    res = CliRunner().invoke(app, ["report", str(only), "--out", str(out), "--truth",
                                   str(results_dir.parent / "recording" / "truth")])
    assert res.exit_code == 0, res.output
    text = out.read_text(encoding="utf-8")
    (row,) = _rows(_section(text, "accuracy"))
    assert row[:2] == ["gt_laser", "in the plane"] and int(row[2]) > 4000 and 1.5 < float(row[3]) < 2.7
    assert "accuracy against truth: no input" not in text


def test_markdown_lists_are_lists() -> None:
    got = markdown_to_html("# Warnings\n\nTwo of them:\n- first\n- second,\n  continued\n\n1. one\n2. two\nend\n")
    assert got == ("<h3>Warnings</h3>\n<p>Two of them:</p>\n<ul><li>first</li><li>second, continued</li></ul>\n"
                   "<ol><li>one</li><li>two</li></ol>\n<p>end</p>")


def test_missing_folder_is_one_line(tmp_path: Path) -> None:
    res = CliRunner().invoke(app, ["report", str(tmp_path / "nope"), "--out", str(tmp_path / "r.html")])
    assert res.exit_code == 2 and "no such results folder" in res.output and not (tmp_path / "r.html").exists()
    res = CliRunner().invoke(app, ["report", str(tmp_path), "--out", str(tmp_path / "r.html"), "--truth",
                                   str(tmp_path / "nope")])
    assert res.exit_code == 2 and "--truth" in res.output and "no such folder" in res.output
    assert not (tmp_path / "r.html").exists()


CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")


@pytest.mark.skipif(CHROMIUM is None, reason="chromium not installed (.ci/run installs it)")
def test_chromium_sees_every_figure_and_table(report_html: Path, tmp_path: Path) -> None:
    out = report_html
    text = out.read_text(encoding="utf-8")
    flags = [CHROMIUM, "--headless", "--no-sandbox", "--disable-gpu", "--hide-scrollbars", "--enable-logging=stderr",
             "--v=0", f"--user-data-dir={tmp_path / 'profile'}", "--window-size=1400,4000"]
    shot = tmp_path / "shot.png"
    r = subprocess.run([*flags, f"--screenshot={shot}", out.as_uri()], capture_output=True, text=True, timeout=120)
    assert shot.is_file() and shot.stat().st_size > 50_000, r.stderr[-2000:]
    import matplotlib.image as mpimg

    img = mpimg.imread(shot)
    assert img.shape[0] == 4000 and float(np.std(img)) > 0.05  # a page with content, not a blank one
    r = subprocess.run([*flags, "--virtual-time-budget=5000", "--dump-dom", out.as_uri()], capture_output=True,
                       text=True, timeout=120)
    dom = r.stdout
    body = re.search(r"<body([^>]*)>", dom)
    assert body is not None, r.stderr[-2000:]
    attrs = dict(re.findall(r'([\w-]+)="([^"]*)"', body.group(1)))
    assert attrs["data-figures-loaded"] == attrs["data-figures-expected"] == str(_figures(text))
    assert int(attrs["data-tables"]) == N_TABLES == len(re.findall(r"<table>", dom))
    assert int(attrs["data-figure-min-width-pct"]) >= 95  # every figure across the section, none at half width
    assert int(attrs["data-load-ms"]) < 2000
    # every section once, each with its table(s); no heading twice within a section; nothing named as missing
    ids = re.findall(r'<section id="([\w-]+)">', dom)
    assert sorted(ids) == sorted(set(ids)) and set(SECTIONS) <= set(ids) and "skipped" not in ids
    for key in ("checks", "accuracy", "tracks", "consistency", "fusion", "cameras", "scanners", "survey", "sync"):
        assert "<table>" in _section(dom, key), key
    for key in ids:
        h3 = re.findall(r"<h3>(.*?)</h3>", _section(dom, key))
        assert len(h3) == len(set(h3)), (key, h3)
    assert "no input" not in dom
    # the Markdown summary's list is a list
    items = re.findall(r"<li>(.*?)</li>", _section(dom, "summaries"))
    assert [html.unescape(i) for i in items] == list(MD_WARNINGS)
    console = [ln for ln in r.stderr.splitlines() if "CONSOLE" in ln]
    assert not console, console
