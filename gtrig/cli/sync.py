"""``gtrig sync``: each GT source's clock offset to the reference (odometry), with a 95 % interval."""

from __future__ import annotations

from pathlib import Path

import typer

from gtrig.cli.common import console, handle_errors


@handle_errors
def command(
    recording: Path | None = typer.Option(None, "--recording", help="The recording folder (for run/odometry.csv)."),
    reference: str = typer.Option("odometry", "--reference", help="The reference clock: odometry or a CSV path."),
    source: list[str] = typer.Option(..., "--source", help="NAME=track.tum[,cov.csv] (repeatable)."),
    out: Path = typer.Option(..., "--out", help="Output sync.yaml."),
    search_s: float = typer.Option(3.0, "--search-s", help="Lags searched, both signs, seconds."),
    figure: Path | None = typer.Option(None, "--figure", help="PNG of the correlation curves."),
    refine: bool = typer.Option(True, "--refine/--no-refine",
                                help="Refine with the offset as a parameter of the fusion's fit (needs covariances)."),
) -> None:
    """Clock offsets of GT sources to odometry: cross-correlation of heading rates, then a sub-sample fit."""
    from gtrig.errors import InputError
    from gtrig.fusion.measurements import fixes_from_track
    from gtrig.fusion.sync import estimate_offset, refine_by_fusion
    from gtrig.io.odometry import read_odometry
    from gtrig.io.offsets import CONVENTION, write_offsets
    from gtrig.io.posetrack import read_pose_track

    if reference == "odometry":
        if recording is None:
            raise InputError("--reference odometry needs --recording (its run/odometry.csv)")
        odo_path = recording / "run" / "odometry.csv"
    else:
        odo_path = Path(reference)
    odo = read_odometry(odo_path)
    results = {}
    for spec in source:
        if "=" not in spec:
            raise InputError(f"--source {spec!r}: expected NAME=track.tum[,cov.csv]")
        name, files = spec.split("=", 1)
        parts = files.split(",")
        track = read_pose_track(parts[0], parts[1] if len(parts) > 1 else None, source=name)
        use = track.usable()
        est = estimate_offset(odo.stamps_s, odo.xytheta[:, 2], use.stamps_s, use.yaw_rad(), name, search_s=search_s)
        if refine and track.cov is not None:
            est = refine_by_fusion(est, fixes_from_track(track, name), odo)
        results[name] = est
        ci = "" if est.verdict != "ok" else f" [{est.ci95_s[0] * 1e3:+.2f}, {est.ci95_s[1] * 1e3:+.2f}] ms"
        num = "" if est.verdict != "ok" else f" {est.offset_s * 1e3:+.3f} ms"
        console.print(f"{name}: {est.verdict}{num}{ci} ({est.reason})", highlight=False)
    if figure is not None:
        from gtrig.fusion.plots import correlation_figure

        correlation_figure(list(results.values()), figure)
    write_offsets(out, str(odo_path) if reference != "odometry" else "odometry",
                  {k: v.to_dict() for k, v in results.items()})
    console.print(f"{out}: {len(results)} source(s); {CONVENTION}", highlight=False)
