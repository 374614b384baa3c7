"""``gtrig demo``."""

from __future__ import annotations

from pathlib import Path

import typer

from gtrig.cli.common import console, handle_errors, styled
from gtrig.cli.run import exit_on_refusals, print_result
from gtrig.cli.scale import chunk_bar, dask_option, executor


@handle_errors
def command(
    out: Path = typer.Option(Path("demo_out"), "--out", help="Folder for the recording and every output."),
    seed: int = typer.Option(0, help="Simulator seed."),
    quick: bool = typer.Option(False, "--quick", help="Short sequences (a smoke test)."),
    workers: int = typer.Option(0, "--workers", "-j", min=0, help="Processes (0 = one per core)."),
    dask: str = dask_option(),
) -> None:
    """Simulate the GT room, then run every stage on it (what `gtrig run` does) and print the accuracy against
    truth."""
    import time

    from rich.table import Table

    from gtrig import pipeline
    from gtrig.cli import checks

    checks.seed(seed)
    checks.output_folder("--out", out)
    from gtrig.io.recording import summarize
    from gtrig.sim.config import SimConfig
    from gtrig.sim.recording import simulate

    t0 = time.perf_counter()
    rec = out / "recording"
    cfg = SimConfig.quick_defaults(seed) if quick else SimConfig(seed=seed)
    with console.status("simulating") as status:
        simulate(cfg, rec, on_step=lambda name, i, n: status.update(f"simulating [{i + 1}/{n}] {name}"))
    t_sim = time.perf_counter() - t0

    table = Table("recording", "count", "MB", title=f"simulated recording {rec} ({t_sim:.0f} s)")
    for item in summarize(rec):
        table.add_row(item.what, f"{item.count} {item.unit}", f"{item.bytes / 1e6:.1f}")
    console.print(table)

    from gtrig.config import RunConfig

    with executor(dask) as ex, chunk_bar() as bar:
        result = pipeline.run(rec, out / "results", on_stage=bar.on_stage, config=RunConfig(workers=workers),
                              executor=ex, progress=bar.progress)
    print_result(result, True)
    _scanmatch_validate(rec, out / "results")
    from gtrig.report import write_report

    with console.status("writing the report"):
        report = write_report(out / "results", out / "report.html", rec / "truth")
    console.print(f"demo finished in {time.perf_counter() - t0:.0f} s; outputs in {out}; report: {report}")
    exit_on_refusals(result)


def _scanmatch_validate(rec: Path, results: Path) -> None:
    """The validation stops from the onboard scans (docs/scanmatch.md), seeded by the survey's poses."""
    from gtrig.cli.scanmatch import validation_lines
    from gtrig.errors import GtrigError
    from gtrig.io.scanmatch import read_planar_poses
    from gtrig.scanmatch.validate import validate_recording

    sv_path = results / "survey" / "validation_poses.csv"
    try:
        sv = read_planar_poses(sv_path)[1] if sv_path.exists() else None
        res = validate_recording(rec, survey_poses=sv)
    except GtrigError as e:
        console.print(styled("skipped", "yellow"), f"scanmatch validate: {e}")
        return
    console.print("scanmatch validate: validation stops from the onboard scans, relative to stop 1")
    for line in validation_lines(res):
        console.print(line, highlight=False)
