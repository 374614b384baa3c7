"""``gtrig report``: every section present for a full folder, absent parts named, and the page as a person sees
it in headless Chromium (every figure decoded, every table there, no console error, loaded in under 2 s)."""

from __future__ import annotations

import re
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from gtrig.cli.main import app
from gtrig.report import build_report

# figures of the folder in conftest: 3 tracks x (path, errors, d2, status) minus the truth-less parts, ...
SECTIONS = ("accuracy", "tracks", "track-gt_laser", "track-gt_vision_run", "consistency", "cameras", "survey",
            "calibration", "sync", "summaries")


def _figures(text: str) -> int:
    return len(re.findall(r'<img alt="[^"]*" src="data:image/png;base64,', text))


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
    # 2 tracks x 4 figures + consistency 2 + cameras 1 + survey 1 + calibration 2 + sync 1
    assert _figures(text) == 15
    assert 'class="miss">miss' in text and "Not in this folder" not in text
    assert "http://" not in text.replace("http://www.w3.org", "") and "https://" not in text  # nothing fetched
    # the accuracy of each track against truth is in the table: RMSE about the simulated 1.5 and 2.5 mm sigmas
    rows = re.findall(r"<tr><td>(gt_\w+)</td>((?:<td>[^<]*</td>)+)</tr>", text)
    rmse = {n: float(re.findall(r"<td>([^<]*)</td>", cells)[9]) for n, cells in rows}
    assert 1.5 < rmse["gt_laser"] < 2.7 and 2.8 < rmse["gt_vision_run"] < 4.5, rmse


def test_missing_parts_are_named(results_dir: Path, tmp_path: Path) -> None:
    only = tmp_path / "results"
    only.mkdir()
    for f in ("gt_laser.tum", "gt_laser_cov.csv"):
        shutil.copy(results_dir / f, only / f)
    text = build_report(only)
    assert '<section id="track-gt_laser">' in text and '<section id="accuracy">' not in text
    for label in ("accuracy against truth", "consistency of GT sources", "cameras", "survey", "calibration",
                  "time sync"):
        assert f"{label}: no input in the folder" in text
    assert _figures(text) == 2  # path and status: no truth


def test_missing_folder_is_one_line(tmp_path: Path) -> None:
    res = CliRunner().invoke(app, ["report", str(tmp_path / "nope"), "--out", str(tmp_path / "r.html")])
    assert res.exit_code == 2 and "no such results folder" in res.output and not (tmp_path / "r.html").exists()


CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")


@pytest.mark.skipif(CHROMIUM is None, reason="chromium not installed (.ci/run installs it)")
def test_chromium_sees_every_figure_and_table(report_html: Path, tmp_path: Path) -> None:
    out = report_html
    text = out.read_text(encoding="utf-8")
    flags = [CHROMIUM, "--headless", "--no-sandbox", "--disable-gpu", "--hide-scrollbars", "--enable-logging=stderr",
             "--v=0", f"--user-data-dir={tmp_path / 'profile'}"]
    shot = tmp_path / "shot.png"
    r = subprocess.run([*flags, "--window-size=1300,4000", f"--screenshot={shot}", out.as_uri()],
                       capture_output=True, text=True, timeout=120)
    assert shot.is_file() and shot.stat().st_size > 50_000, r.stderr[-2000:]
    import matplotlib.image as mpimg

    img = mpimg.imread(shot)
    assert img.shape[0] == 4000 and float(np.std(img)) > 0.05  # a page with content, not a blank one
    r = subprocess.run([*flags, "--virtual-time-budget=5000", "--dump-dom", out.as_uri()], capture_output=True,
                       text=True, timeout=120)
    body = re.search(r"<body([^>]*)>", r.stdout)
    assert body is not None, r.stderr[-2000:]
    attrs = dict(re.findall(r'([\w-]+)="([^"]*)"', body.group(1)))
    assert attrs["data-figures-loaded"] == attrs["data-figures-expected"] == str(_figures(text))
    assert int(attrs["data-tables"]) == text.count("<table>")
    assert int(attrs["data-load-ms"]) < 2000
    console = [ln for ln in r.stderr.splitlines() if "CONSOLE" in ln]
    assert not console, console
