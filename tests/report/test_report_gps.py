"""``gtrig report`` on a folder holding ``gtrig gps`` outputs (a real Bovisa log): the RTK-GPS section with the
fix-type shares and lost-fix intervals of the JSON, the coverage map in the fix types' colours, satellites and
HDOP over time; and the page as a person sees it in headless Chromium."""

from __future__ import annotations

import base64
import io
import json
import re
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from gtrig.cli.main import app
from gtrig.report import build_report

LOG = "Bovisa_2008-09-01"


@pytest.fixture(scope="module")
def gps_page(shared_dir: Path, tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    """(results folder, report.html) of `gtrig gps --report --plot` on the 2008-09-01 log."""
    log = shared_dir / "data" / "rawseeds" / LOG / f"{LOG}-GPS.csv"
    res = tmp_path_factory.mktemp("gps") / "results"
    res.mkdir()
    r = CliRunner().invoke(app, ["gps", "--log", str(log), "--out", str(res / "gps.tum"), "--covariance",
                                 str(res / "gps_cov.csv"), "--report", str(res / "gps_report.json"), "--plot",
                                 str(res)])
    assert r.exit_code == 0, r.output
    out = res.parent / "report.html"
    r = CliRunner().invoke(app, ["report", str(res), "--out", str(out)])
    assert r.exit_code == 0, r.output
    return res, out


def _section(text: str, key: str) -> str:
    m = re.search(rf'<section id="{key}">(.*?)</section>', text, re.S)
    assert m is not None, key
    return m.group(1)


def _images(section: str) -> dict[str, bytes]:
    return {alt: base64.b64decode(data) for alt, data in
            re.findall(r'<img alt="([^"]*)" src="data:image/png;base64,([^"]+)"', section)}


def test_gps_section_holds_the_reports_figures_and_tables(gps_page: tuple[Path, Path]) -> None:
    res, page = gps_page
    text = page.read_text(encoding="utf-8")
    rep = json.loads((res / "gps_report.json").read_text())
    sec = _section(text, "gps")
    imgs = _images(sec)
    assert len(imgs) == 2 and any("coverage map" in a for a in imgs) and any("HDOP" in a for a in imgs), list(imgs)
    # the fix-type shares: every type of the JSON, to the printed 0.1 %, adding up to the whole time
    tables = re.findall(r"<table>(.*?)</table>", sec, re.S)
    shares = dict(re.findall(r'<tr><td>([^<]+)</td><td class="n">([\d.]+)</td></tr>', tables[0]))
    kept = float(shares.pop("kept as ground truth"))
    assert set(shares) == set(rep["fix_share_time"]) and {"rtk_fixed", "rtk_float", "dgps", "no_fix"} <= set(shares)
    for k, v in rep["fix_share_time"].items():
        assert abs(float(shares[k]) - 100 * v) <= 0.051, k
    assert abs(sum(float(v) for v in shares.values()) - 100) < 0.3
    assert abs(kept - 100 * rep["kept_share_time"]) <= 0.051 and abs(kept - float(shares["rtk_fixed"])) < 0.2
    # the lost-fix intervals: one row each, their lengths those of the JSON (8 in this log)
    rows = re.findall(r'<tr><td class="n">(\d+)</td><td class="n">([\d.]+)</td><td class="n">([\d.]+)</td>'
                      r'<td class="n">([\d.]+)</td></tr>', tables[1])
    lost = rep["lost_fix_intervals"]
    assert len(rows) == lost["count"] == 8
    assert np.allclose([float(r[3]) for r in rows], [b - a for a, b in lost["intervals"]], atol=0.051)
    assert f"Lost-fix intervals: {lost['count']}" in sec and "log clock - UTC" in sec
    # the GPS track's own section, and the GPS summary not shown twice (nor its image links as text)
    assert '<section id="track-gps">' in text and '<section id="summaries">' not in text
    assert "![" not in text and "RTK-GPS" not in _section(text, "skipped")


def test_coverage_map_shows_the_fix_types(gps_page: tuple[Path, Path]) -> None:
    import matplotlib.image as mpimg

    _, page = gps_page
    imgs = _images(_section(page.read_text(encoding="utf-8"), "gps"))
    rgb = mpimg.imread(io.BytesIO(next(v for k, v in imgs.items() if "coverage map" in k)), format="png")[..., :3]
    px = np.round(rgb.reshape(-1, 3) * 255)
    # matplotlib's tab:green (RTK fixed), tab:orange (float), tab:blue (DGPS), and black (the kept fixes)
    for name, colour in {"green": (44, 160, 44), "orange": (255, 127, 14), "blue": (31, 119, 180),
                         "black": (0, 0, 0)}.items():
        n = int(np.sum(np.all(np.abs(px - colour) <= 12, axis=1)))
        assert n > 200, (name, n)


def test_a_folder_without_gps_does_not_name_it_and_odd_jsons_are_handled(gps_page: tuple[Path, Path],
                                                                        tmp_path: Path) -> None:
    res, _ = gps_page
    plain = tmp_path / "plain"
    plain.mkdir()
    shutil.copy(res / "gps.tum", plain / "track.tum")
    (plain / "gps_settings.json").write_text('{"rate_hz": 5}')  # a JSON of another kind: ignored
    text = build_report(plain)
    assert '<section id="gps">' not in text and "RTK-GPS" not in text
    rep = json.loads((res / "gps_report.json").read_text())
    del rep["coverage"]  # written by an older gtrig: the rest is shown, the map is asked for
    (plain / "old_gps_report.json").write_text(json.dumps(rep))
    (plain / "sub").mkdir()
    (plain / "sub" / "gps_report.json").write_text("{not json")
    text = build_report(plain)
    sec = _section(text, "gps")
    assert len(_images(sec)) == 1 and "no coverage data" in sec and "Lost-fix intervals: 8" in sec
    assert "not read" in _section(text, "gps-2")


CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")


@pytest.mark.skipif(CHROMIUM is None, reason="chromium not installed (.ci/run installs it)")
def test_chromium_draws_the_gps_section(gps_page: tuple[Path, Path], tmp_path: Path) -> None:
    _, page = gps_page
    text = page.read_text(encoding="utf-8")
    flags = [CHROMIUM, "--headless", "--no-sandbox", "--disable-gpu", "--hide-scrollbars", "--enable-logging=stderr",
             "--v=0", f"--user-data-dir={tmp_path / 'profile'}"]
    r = subprocess.run([*flags, "--virtual-time-budget=5000", "--dump-dom", page.as_uri()], capture_output=True,
                       text=True, timeout=120)
    body = re.search(r"<body([^>]*)>", r.stdout)
    assert body is not None, r.stderr[-2000:]
    attrs = dict(re.findall(r'([\w-]+)="([^"]*)"', body.group(1)))
    n_img = len(re.findall(r'<img alt="[^"]*" src="data:image/png;base64,', text))
    assert attrs["data-figures-loaded"] == attrs["data-figures-expected"] == str(n_img) == "4"
    assert int(attrs["data-tables"]) == text.count("<table>")
    # the GPS section's place on the page: its coverage map is drawn, in the fix types' colours
    shot = tmp_path / "shot.png"
    r = subprocess.run([*flags, "--window-size=1300,3400", f"--screenshot={shot}", page.as_uri()],
                       capture_output=True, text=True, timeout=120)
    assert shot.is_file(), r.stderr[-2000:]
    import matplotlib.image as mpimg

    px = np.round(mpimg.imread(shot)[..., :3].reshape(-1, 3) * 255)
    assert int(np.sum(np.all(np.abs(px - (44, 160, 44)) <= 12, axis=1))) > 200  # RTK fixed, green
    assert int(np.sum(np.all(np.abs(px - (255, 127, 14)) <= 12, axis=1))) > 100  # RTK float, orange
