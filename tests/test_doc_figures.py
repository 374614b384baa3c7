"""The figures the user docs quote, read from the .md files and computed again by the program: the
pipeline's stage table, the RAWSEEDS ground-truth pose counts (docs/interchange.md), the Bovisa GPS fixes
kept (docs/gps.md); and the wording of a check that could not be measured."""

from __future__ import annotations

import fnmatch
import math
import re
from pathlib import Path

import pytest

DOCS = Path(__file__).resolve().parents[1] / "docs"


def _table(md: str, first_header: str, holding: str = "") -> tuple[list[str], list[list[str]]]:
    """The header cells and body rows of the Markdown table whose first header cell is ``first_header``
    and whose header line holds ``holding``."""
    lines = md.splitlines()
    start = next(i for i, x in enumerate(lines)
                 if re.match(rf"\|\s*{re.escape(first_header)}\s*\|", x) and holding in x)
    cells = [[c.strip() for c in x.strip().strip("|").split("|")] for x in lines[start:] if x.startswith("|")]
    rows = []
    for x in lines[start + 2:]:
        if not x.startswith("|"):
            break
        rows.append([c.strip() for c in x.strip().strip("|").split("|")])
    return cells[0], rows


def test_pipeline_stage_table_lists_every_stage_in_order_with_what_it_reads() -> None:
    from gtrig.pipeline import STAGES

    header, rows = _table((DOCS / "pipeline.md").read_text(), "stage")
    names = [re.match(r"`([^`]+)`", r[0]).group(1) for r in rows]  # type: ignore[union-attr]
    assert names == [s.name for s in STAGES]
    col = header.index("reads in `REC/`")
    for st, row in zip(STAGES, rows, strict=True):
        quoted = re.findall(r"`([^`]+)`", row[col])
        for path in st.reads:
            assert any(fnmatch.fnmatch(path, q) or path.startswith(q.rstrip("/") + "/") or path == q.rstrip("/")
                       for q in quoted), (st.name, path, quoted)


def test_rawseeds_ground_truth_pose_counts(shared_dir: Path) -> None:
    from gtrig.io.formats.rawseeds import read_rawseeds_rows

    m = re.search(r"GROUNDTRUTH files \((\d+), (\d+) and (\d+) poses\)", (DOCS / "interchange.md").read_text())
    assert m is not None
    files = sorted((shared_dir / "data" / "rawseeds").glob("Bicocca_*/*-GROUNDTRUTH.csv"))
    assert [len(read_rawseeds_rows(f)) for f in files] == [int(v) for v in m.groups()]


def test_bovisa_gps_fixes_kept_by_each_command(shared_dir: Path) -> None:
    from gtrig.gps.filter import FilterOptions
    from gtrig.gps.groundtruth import GpsOptions, gps_ground_truth

    header, rows = _table((DOCS / "gps.md").read_text(), "log", "kept (default)")
    options = {"kept (default)": GpsOptions(),
               "kept (`--fix any`)": GpsOptions(filter=FilterOptions(fix="any")),
               "kept (`--fix any --no-outlier-test`)": GpsOptions(filter=FilterOptions(fix="any", outlier_gate=None))}
    assert set(options) <= set(header), header
    for row in rows:
        log = shared_dir / "data" / "rawseeds" / row[0] / f"{row[0]}-GPS.csv"
        for col, opt in options.items():
            assert len(gps_ground_truth(log, opt).track) == int(row[header.index(col)]), (row[0], col)


@pytest.mark.parametrize(("value", "target", "line"), [
    (math.nan, "verdict ok (docs/sync.md)",
     "sync: offset (unobservable) is not measured (expected verdict ok (docs/sync.md))"),
    (math.nan, "", "sync: offset (unobservable) is not measured"),
    (2.5, "", "sync: offset (unobservable) is 2.5 ms"),
])
def test_a_check_reads_as_a_sentence(value: float, target: str, line: str) -> None:
    from gtrig.pipeline.context import AccuracyRow
    from gtrig.pipeline.rows import check_line

    assert check_line(AccuracyRow("sync", "offset (unobservable)", value, "ms", target, False)) == line


def test_run_prints_no_nan_and_no_empty_expectation(capsys: pytest.CaptureFixture[str]) -> None:
    from gtrig.cli.run import print_result
    from gtrig.pipeline import PipelineResult
    from gtrig.pipeline.context import AccuracyRow

    checks = (AccuracyRow("sync", "vision clock offset to odometry (unobservable)", math.nan, "ms",
                          "verdict ok (docs/sync.md)", False),
              AccuracyRow("GTlaser", "track on vision's clock: not made (no offsets)", math.nan, "", "", False))
    print_result(PipelineResult((), {}, {}, checks), False)
    warnings = [x for x in capsys.readouterr().out.splitlines() if x.startswith("warning")]
    assert len(warnings) == 2 and not any("nan" in w or "(expected )" in w for w in warnings), warnings
