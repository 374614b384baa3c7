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
    rig: Path | None = typer.Option(None, "--rig", help="A planned rig.yaml (as gtrig plan reads it) to install "
                                    "in the GT room instead of its own (docs/simulator.md)."),
    path: Path | None = typer.Option(None, "--path", help="A TUM trajectory for the continuous run instead of "
                                     "the built-in path (world frame, inside the GT room)."),
) -> None:
    """Simulate a recording of the instrumented room, with its truth, in the real on-disk layout."""
    import time

    from gtrig.cli import checks
    from gtrig.errors import InputError
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
    plan = _planned_rig(rig) if rig is not None else None
    planned_path = _planned_path(path) if path is not None else None
    if (plan is not None or planned_path is not None) and cfg.scenario != "gtroom":
        raise InputError("--rig and --path simulate the GT room: leave --scenario at gtroom")
    t0 = time.perf_counter()
    with console.status("simulating") as status:
        timings = simulate(cfg, out, on_step=lambda name, i, n: status.update(f"[{i + 1}/{n}] {name}"),
                           plan=plan, path=planned_path)
    for name, secs in timings.items():
        console.print(f"  {name:<20} {secs:6.1f} s")
    console.print(f"wrote {out} in {time.perf_counter() - t0:.1f} s")


def _planned_rig(path: Path):  # noqa: ANN202
    """The planned rig, loaded and checked for the simulator (one line naming the field otherwise)."""
    from gtrig.errors import InputError
    from gtrig.rig.load import load_rig
    from gtrig.sim.install import check_plan

    if not path.is_file():
        raise InputError(f"{path}: no such rig file")
    plan = load_rig(path)
    try:
        check_plan(plan)
    except InputError as e:
        raise InputError(f"{path}: {e}") from None
    return plan


def _planned_path(path: Path):  # noqa: ANN202
    """The continuous run's path from a TUM file: stamps from its first pose, x, y and the heading."""
    import numpy as np

    from gtrig import geometry as geo
    from gtrig.errors import InputError
    from gtrig.io.tum import read_tum
    from gtrig.sim.recording import PlannedPath

    if not path.is_file():
        raise InputError(f"{path}: no such trajectory file")
    traj = read_tum(path)
    if len(traj.stamps_s) < 2:
        raise InputError(f"{path}: the path needs at least 2 poses")
    xyth = np.column_stack([traj.xyz[:, :2], np.unwrap(geo.yaw_of_quats(traj.quat_xyzw))])
    return PlannedPath(np.asarray(traj.stamps_s - traj.stamps_s[0], dtype=float), xyth)


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
