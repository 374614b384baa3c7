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
    config: Path | None = typer.Option(None, "--config", help="YAML of simulator settings over the defaults, "
                                       "e.g. 'motion: {profile: agile, speed_mps: 1.5}' (docs/simulator.md)."),
) -> None:
    """Simulate a recording of the instrumented room, with its truth, in the real on-disk layout."""
    import time

    from gtrig.cli import checks
    from gtrig.sim.config import SimConfig
    from gtrig.sim.recording import simulate

    checks.seed(seed)
    checks.workers(workers)
    checks.output_folder("--out", out)
    checks.number("--odometry-offset-s", odometry_offset_s, lo=-3600, hi=3600, unit="s")
    base = SimConfig.quick_defaults(seed) if quick else SimConfig(seed=seed)
    cfg = base.model_copy(update={"scenario": scenario, "workers": workers,
                                  "odometry_clock_offset_s": odometry_offset_s})
    if config is not None:
        cfg = _with_file(cfg, config)
    t0 = time.perf_counter()
    with console.status("simulating") as status:
        timings = simulate(cfg, out, on_step=lambda name, i, n: status.update(f"[{i + 1}/{n}] {name}"))
    for name, secs in timings.items():
        console.print(f"  {name:<20} {secs:6.1f} s")
    console.print(f"wrote {out} in {time.perf_counter() - t0:.1f} s")


def _with_file(cfg, path: Path):  # noqa: ANN001, ANN202
    """``cfg`` with the settings of a YAML file merged over it, validated; one-line errors."""
    from pydantic import ValidationError

    from gtrig.errors import ConfigError
    from gtrig.io.yamlfile import load_yaml
    from gtrig.rig.load import deep_merge
    from gtrig.sim.config import SimConfig

    doc = load_yaml(path) or {}  # within the YAML limits; one line naming the file
    if not isinstance(doc, dict):
        raise ConfigError(f"{path}: the settings must be a mapping (motion: ..., laser: ...)")
    try:
        return SimConfig.model_validate(deep_merge(cfg.model_dump(), doc))
    except ValidationError as e:
        err = e.errors()[0]
        loc = ".".join(str(p) for p in err["loc"])
        raise ConfigError(f"{path}: {loc}: {err['msg']}") from None
