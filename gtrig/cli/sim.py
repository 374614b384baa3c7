"""``gtrig sim``."""

from __future__ import annotations

from pathlib import Path

import typer

from gtrig.cli.common import console, handle_errors


@handle_errors
def command(
    scenario: str = typer.Option("gtroom", help="Scenario to simulate."),
    out: Path = typer.Option(..., "--out", help="Recording folder to write (resumes an interrupted run)."),
    seed: int = typer.Option(0, help="Random seed: the same seed gives identical output."),
    quick: bool = typer.Option(False, "--quick", help="Short sequences, for tests."),
    workers: int = typer.Option(0, help="Processes for rendering; 0 = one per core."),
    odometry_offset_s: float = typer.Option(0.0, "--odometry-offset-s",
                                            help="The robot's clock (odometry, onboard scans) minus the GT clock."),
) -> None:
    """Simulate a recording of the instrumented room, with its truth, in the real on-disk layout."""
    import time

    from gtrig.sim.config import SimConfig
    from gtrig.sim.recording import simulate

    base = SimConfig.quick_defaults(seed) if quick else SimConfig(seed=seed)
    cfg = base.model_copy(update={"scenario": scenario, "workers": workers,
                                  "odometry_clock_offset_s": odometry_offset_s})
    t0 = time.perf_counter()
    with console.status("simulating") as status:
        timings = simulate(cfg, out, on_step=lambda name, i, n: status.update(f"[{i + 1}/{n}] {name}"))
    for name, secs in timings.items():
        console.print(f"  {name:<20} {secs:6.1f} s")
    console.print(f"wrote {out} in {time.perf_counter() - t0:.1f} s")
