"""``gtrig run``: every stage on a recording (a lab's own, or a simulated one)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import typer

from gtrig.cli.common import console, handle_errors, styled
from gtrig.cli.scale import chunk_bar, dask_option, executor


def print_result(result: object, has_truth: bool) -> None:
    """The accuracy table (with truth), the checks that need none, warnings and skipped stages."""
    from rich.table import Table

    from gtrig.pipeline import PipelineResult
    from gtrig.pipeline.rows import check_line, value_text

    assert isinstance(result, PipelineResult)

    def mark(ok: bool | None) -> Any:
        return "" if ok is None else (styled("ok", "green") if ok else styled("miss", "red"))

    if result.checks:
        t = Table("stage", "check", "value", "expected", "", title="what the recording says without truth")
        for r in result.checks:
            t.add_row(r.stage, r.metric, value_text(r), r.target, mark(r.ok))
        console.print(t)
    if result.rows:
        acc = Table("stage", "metric", "value", "target", "", title="accuracy against truth")
        for r in result.rows:
            acc.add_row(r.stage, r.metric, value_text(r), r.target, mark(r.ok))
        console.print(acc)
    elif not has_truth:
        console.print("no truth/ in the recording: accuracy is judged by the checks above", highlight=False)
    for w in result.warnings:
        console.print(styled("warning", "yellow"), check_line(w), highlight=False)
    if result.reused:
        console.print(f"reused (unchanged since their last run): {', '.join(result.reused)}", highlight=False)
    for name, why in result.skipped.items():
        if name not in result.refused:
            console.print(styled("skipped", "yellow"), f"{name}: {why}", highlight=False)


def exit_on_refusals(result: object) -> None:
    """Each stage's refusal as one ``error: <stage>: <why>`` line on stderr, then the run's exit code
    (2 bad input, 3 no convergence); nothing when every stage asked for gave its result."""
    from gtrig.cli.common import print_error
    from gtrig.pipeline import PipelineResult

    assert isinstance(result, PipelineResult)
    for name, why in result.refused.items():
        print_error(f"{name}: {why}")
    if result.exit_code:
        raise typer.Exit(result.exit_code)


@handle_errors
def command(
    recording: Path = typer.Option(None, "--recording", "-r", help="The recording folder (docs/formats.md)."),
    out: Path = typer.Option(None, "--out", "-o", help="Folder for every output (created)."),
    config: Path = typer.Option(None, "--config", "-c", help="A run.yaml overriding some defaults."),
    stages: str = typer.Option(None, "--stages", help="Comma-separated stages to run (default: all)."),
    from_stage: str = typer.Option(None, "--from", help="Run this stage and every later one again."),
    workers: int = typer.Option(None, "--workers", "-j", min=0, help="Processes (0 = one per core)."),
    dask: str = dask_option(),
    no_reuse: bool = typer.Option(False, "--no-reuse", help="Run every stage, even a finished one."),
    print_config: bool = typer.Option(False, "--print-config", help="Print the effective configuration and exit."),
) -> None:
    """Run every stage on a recording: survey, calibrations, GTlaser, GTvision; reuse finished stages."""
    import time

    from gtrig import pipeline
    from gtrig.cli import checks
    from gtrig.config import load_config
    from gtrig.errors import InputError

    checks.workers(workers or 0)
    if dask is not None:
        from gtrig.executor import parse_dask

        parse_dask(dask)  # its form, before anything else; the scheduler is reached when the run starts
    if recording is not None:
        checks.input_folder("--recording", recording)
    if out is not None:
        checks.output_folder("--out", out)
        if recording is not None:
            checks.not_inside("--out", out, recording)
    cfg = load_config(config)
    if workers is not None:
        cfg = cfg.model_copy(update={"workers": workers})
    if print_config:
        console.print(cfg.to_yaml(), end="", highlight=False, markup=False)
        return
    if recording is None or out is None:
        raise InputError("gtrig run needs --recording REC and --out DIR (or --print-config)")
    only = [s.strip() for s in stages.split(",") if s.strip()] if stages else None
    t0 = time.perf_counter()
    with executor(dask) as ex, chunk_bar() as bar:
        result = pipeline.run(recording, out, on_stage=bar.on_stage, config=cfg, only=only, from_stage=from_stage,
                              reuse=not no_reuse, executor=ex, progress=bar.progress)
    print_result(result, (recording / "truth").is_dir())
    console.print(f"finished in {time.perf_counter() - t0:.0f} s; outputs in {out}", highlight=False)
    exit_on_refusals(result)  # a stage refused its input: say so, and to scripts too
