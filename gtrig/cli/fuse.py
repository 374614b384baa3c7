"""``gtrig fuse``: one smoothed trajectory from GTvision, GTlaser and odometry, a covariance per pose."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import typer

from gtrig.cli.common import console, handle_errors

if TYPE_CHECKING:
    import numpy as np

    from gtrig.fusion.fuse import FusionReport
    from gtrig.io.odometry import OdometryLog
    from gtrig.trajectory import PoseTrack


@handle_errors
def command(
    rig: Path | None = typer.Option(None, "--rig", help="The calibrated rig (checked; the odometry rate)."),
    recording: Path | None = typer.Option(None, "--recording", help="The recording (default odometry from it)."),
    vision: Path | None = typer.Option(None, "--vision", help="GTvision trajectory (TUM)."),
    vision_cov: Path | None = typer.Option(None, "--vision-cov", help="Its covariance CSV."),
    laser: Path | None = typer.Option(None, "--laser", help="GTlaser trajectory (TUM)."),
    laser_cov: Path | None = typer.Option(None, "--laser-cov", help="Its covariance CSV."),
    vision_bias: Path | None = typer.Option(None, "--vision-bias", help="GTvision's run-constant error "
                                            "(gt_vision_run_bias.yaml), considered in the covariance."),
    laser_bias: Path | None = typer.Option(None, "--laser-bias", help="GTlaser's run-constant error "
                                           "(gt_laser_bias.yaml), considered in the covariance."),
    odometry: Path | None = typer.Option(None, "--odometry", help="Odometry CSV (default REC/run/odometry.csv)."),
    no_odometry: bool = typer.Option(False, "--no-odometry", help="Constant-velocity model instead of odometry."),
    sync: Path | None = typer.Option(None, "--sync", help="sync.yaml from gtrig sync (offsets applied)."),
    rate: str = typer.Option("odometry", "--rate", help="'odometry' (a pose per odometry stamp) or a rate in Hz."),
    estimator: str = typer.Option("batch", "--estimator", help="batch (robust MAP) or ekf (EKF + RTS)."),
    max_gap: float | None = typer.Option(None, "--max-gap", help="End a segment after this long without a fix (s)."),
    out: Path = typer.Option(..., "--out", help="Output trajectory (TUM)."),
    covariance: Path = typer.Option(..., "--covariance", help="Output covariance CSV (x, y, yaw)."),
    report: Path | None = typer.Option(None, "--report", help="Output JSON report (outliers, parameters)."),
) -> None:
    """Fuse GT sources with odometry (EKF + RTS, then a robust batch MAP); bridged poses flagged."""
    import json

    from gtrig.cli import checks
    from gtrig.errors import InputError
    from gtrig.fusion import FusionOptions, fuse_tracks
    from gtrig.io.offsets import read_offsets
    from gtrig.io.posetrack import write_pose_track
    from gtrig.sync.offset import offset_sigmas

    if estimator not in ("batch", "ekf"):
        raise InputError(f"--estimator {estimator!r}: batch or ekf")
    checks.number("--max-gap", max_gap, lo=0.0, lo_open=True, hi=86400.0, unit="s")
    checks.outputs([rig, vision, vision_cov, laser, laser_cov, vision_bias, laser_bias, odometry, sync],
                   [out, covariance, report])
    if rig is not None:
        from gtrig.rig import load_rig

        load_rig(rig)
    tracks, bias = _read_sources((("vision", vision, vision_cov, vision_bias),
                                  ("laser", laser, laser_cov, laser_bias)))
    odo = None if no_odometry else _read_odometry(odometry, recording)
    rate_hz = _rate_hz(rate)
    offsets = read_offsets(sync) if sync is not None else {}
    sigmas = offset_sigmas(sync) if sync is not None else {}
    opts = FusionOptions(estimator=estimator, rate_hz=rate_hz, offsets_s=offsets,  # type: ignore[arg-type]
                         offsets_sigma_s=sigmas, max_gap_s=max_gap, bias_cov=bias)
    track, rep = fuse_tracks(tracks, odo, opts)
    extra = {report: json.dumps(rep.to_dict(), indent=1)} if report is not None else None
    write_pose_track(track, out, covariance, extra=extra)
    _print_report(track, rep, out)


def _read_sources(sources: tuple[tuple[str, Path | None, Path | None, Path | None], ...]
                  ) -> tuple[dict[str, PoseTrack], dict[str, np.ndarray]]:
    """The tracks given, by name, from ``(name, track.tum, cov.csv, bias.yaml)`` (absent: None), and the
    run-constant error covariance of those that give one."""
    from gtrig.errors import InputError
    from gtrig.io.biascov import read_bias_cov
    from gtrig.io.posetrack import read_pose_track

    tracks = {}
    bias = {}
    for name, tum, cov, b in sources:
        if tum is None:
            if b is not None:
                raise InputError(f"--{name}-bias without --{name}")
            continue
        if cov is None:
            raise InputError(f"--{name} needs --{name}-cov: fusion weighs every fix by its covariance")
        tracks[name] = read_pose_track(tum, cov, source=name)
        if b is not None:
            bias[name] = read_bias_cov(b)
    if not tracks:
        raise InputError("give at least one source (--vision / --laser)")
    return tracks, bias


def _read_odometry(odometry: Path | None, recording: Path | None) -> OdometryLog:
    """The odometry of ``--odometry``, else of the recording."""
    from gtrig.errors import InputError
    from gtrig.io.odometry import read_odometry

    path = odometry or (recording / "run" / "odometry.csv" if recording is not None else None)
    if path is None:
        raise InputError("no odometry: give --odometry, --recording, or --no-odometry")
    return read_odometry(path)


def _rate_hz(rate: str) -> float | None:
    """The output rate of ``--rate`` in Hz (None: a pose per odometry stamp)."""
    from gtrig.cli import checks
    from gtrig.errors import InputError

    if rate == "odometry":
        return None
    try:
        rate_hz = float(rate)
    except ValueError:
        raise InputError(f"--rate {rate!r}: 'odometry' or a number of Hz") from None
    checks.number("--rate", rate_hz, lo=0.0, lo_open=True, hi=10000.0, unit="Hz")
    return rate_hz


def _print_report(track: PoseTrack, rep: FusionReport, out: Path) -> None:
    """The fused track in a few lines: poses observed and bridged, each source's fixes, the odometry's
    fitted parameters per segment."""
    c = track.counts()
    console.print(f"{out}: {len(track)} poses ({c['ok']} observed, {c['bridged']} bridged), {rep.estimator}, "
                  f"{rep.seconds:.2f} s", highlight=False)
    for s, v in rep.sources.items():
        console.print(f"  {s}: {int(v['used'])} of {int(v['offered'])} fixes used, {int(v['rejected'])} rejected, "
                      f"{int(v['downweighted'])} down-weighted, offset {v['offset_s'] * 1e3:+.3f} ms", highlight=False)
    for seg in rep.segments:
        if seg.odometry_params:
            k = seg.odometry_params
            console.print(f"  odometry: distance scale {k[0]:.5f}, turn scale {k[1]:.5f}, curvature "
                          f"{k[2] * 1e3:+.3f} mrad/m", highlight=False)
