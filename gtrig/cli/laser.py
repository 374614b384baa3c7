"""``gtrig laser calibrate`` and ``gtrig laser track``: GTlaser (docs/laser.md)."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from gtrig.cli.common import console, handle_errors
from gtrig.cli.scale import chunk_bar, dask_option, executor

app = typer.Typer(help="GTlaser: fixed-scanner calibration and hull tracking.", no_args_is_help=True)


@app.command("calibrate")
@handle_errors
def calibrate(
    rig: Annotated[Path, typer.Option("--rig", help="rig.yaml with nominal scanner poses")],
    static: Annotated[Path, typer.Option("--static", help="static sequence: DIR/lasers/<scanner>.csv")],
    out: Annotated[Path, typer.Option("--out", help="calibrated rig file to write")],
    object_file: Annotated[
        Path | None,
        typer.Option("--object", help="world object outline(s) (YAML corners_xy, or objects: [...]); "
                     "default: <recording>/calib/laser_object.yaml"),
    ] = None,
) -> None:
    """Calibrate the fixed scanners' poses from a static sequence and the world-defining object."""
    from gtrig.cli import checks
    from gtrig.io.atomic import atomic_group
    from gtrig.laser.recording import (
        calibrate_recording,
        calibration_cov_path,
        load_object_outline,
        write_calibration_cov,
    )
    from gtrig.laser.report import calibration_lines
    from gtrig.rig import load_rig
    from gtrig.rig.load import dump_rig

    cov_path = calibration_cov_path(out)
    checks.input_folder("--static", static)
    checks.outputs([rig, object_file], [out, cov_path])
    r = load_rig(rig)
    obj = load_object_outline(object_file) if object_file is not None else None
    new, report = calibrate_recording(static.parent, rig=r, static_dir=static, object_corners_world_xy=obj)
    with atomic_group(out, cov_path) as (tmp_rig, tmp_cov):  # both or neither: one calibration
        dump_rig(new, tmp_rig)
        write_calibration_cov(tmp_cov, new, report)
    for line in calibration_lines(report):
        console.print(line, highlight=False)
    console.print(f"wrote {out} and {cov_path} (calibration covariance)")


@app.command("track")
@handle_errors
def track(
    rig: Annotated[Path, typer.Option("--rig", help="rig.yaml with calibrated scanner poses")],
    recording: Annotated[
        Path, typer.Option("--recording", help="recording folder (background/ and the sequence)")
    ],
    out: Annotated[Path, typer.Option("--out", help="TUM trajectory to write (localized frames only)")],
    covariance: Annotated[
        Path | None, typer.Option("--covariance", help="covariance CSV, same rows as the TUM file")
    ] = None,
    sequence: Annotated[str, typer.Option("--sequence", help="run or validation")] = "run",
    include_flagged: Annotated[
        bool, typer.Option("--include-flagged", help="also write degenerate and heading-ambiguous frames")
    ] = False,
    calibration_cov: Annotated[
        Path | None,
        typer.Option("--calibration-cov", help="scanners' calibration covariance "
                     "(default: <rig stem>.laser_cov.yaml next to --rig, when present)"),
    ] = None,
    workers: Annotated[int, typer.Option("--workers", min=0, help="Processes (0: one per core).")] = 0,
    dask: Annotated[str | None, dask_option(annotated=True)] = None,
) -> None:
    """Track the robot's hull through a sequence and write its poses and covariances."""
    import time

    from gtrig.cli import checks
    from gtrig.laser.recording import (
        calibration_cov_path,
        load_backgrounds,
        read_calibration_cov,
        track_sequence,
        write_track,
    )
    from gtrig.rig import load_rig

    checks.choice("--sequence", sequence, ("run", "validation"))
    checks.input_folder("--recording", recording)
    checks.outputs([rig, calibration_cov], [out, covariance])
    r = load_rig(rig)
    if calibration_cov is None and calibration_cov_path(rig).is_file():
        calibration_cov = calibration_cov_path(rig)
    cov_cal = read_calibration_cov(calibration_cov, r) if calibration_cov is not None else None
    if cov_cal is None:
        console.print("no calibration covariance: pose covariances leave out the scanners' calibration")
    t0 = time.perf_counter()
    bgs = load_backgrounds(recording / "background", r)
    with executor(dask) as ex, chunk_bar("GTlaser") as bar:
        res = track_sequence(r, recording / sequence, bgs, scanner_cov=cov_cal, executor=ex, workers=workers,
                             progress=bar.progress)
    dt = time.perf_counter() - t0
    n = write_track(res, out, covariance, include_flagged=include_flagged)
    c = res.counts()
    console.print(
        f"{len(res)} frames in {dt:.1f} s: " + ", ".join(f"{k} {v}" for k, v in c.items()), highlight=False
    )
    console.print(f"wrote {n} poses to {out}" + (f" and {covariance}" if covariance else ""))
