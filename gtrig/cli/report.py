"""``gtrig report RESULTS_DIR --out report.html``."""

from __future__ import annotations

from pathlib import Path

import typer

from gtrig.cli.common import console, handle_errors


@handle_errors
def command(
    results: Path = typer.Argument(..., help="A pipeline output folder (e.g. demo_out/results)."),
    out: Path = typer.Option(Path("report.html"), "--out", help="The HTML file to write."),
    truth: Path | None = typer.Option(None, "--truth", help="The recording's truth/ folder (found beside the "
                                      "results when not given): adds each track's accuracy against it."),
) -> None:
    """One self-contained HTML page of a results folder: the run's checks, tracks, sync, fusion, coverage,
    every stage's summary and figures; with truth, the accuracy."""
    import time

    from gtrig.cli import checks
    from gtrig.report import write_report

    checks.outputs([], [out])
    t0 = time.perf_counter()
    p = write_report(results, out, truth)
    console.print(f"report: {p} ({p.stat().st_size / 1e6:.1f} MB, {time.perf_counter() - t0:.1f} s)")
