"""``gtrig gps``: RTK-GPS ground truth from an NMEA, RAWSEEDS or RTKLIB log (docs/gps.md)."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from gtrig.cli.common import console, handle_errors


@handle_errors
def command(
    log: Annotated[Path, typer.Option("--log", help="GPS log: NMEA 0183, RAWSEEDS 'unixtime, sentence', RTKLIB .pos")],
    out: Annotated[Path, typer.Option("--out", help="TUM trajectory of the antenna to write")],
    covariance: Annotated[Path, typer.Option("--covariance", help="covariance CSV (x, y, z), same rows as --out")],
    fmt: Annotated[str, typer.Option("--format", help="auto, rawseeds, nmea or rtklib")] = "auto",
    fix: Annotated[str, typer.Option("--fix", help="fixed (RTK fixed only), float (and RTK float) or any")] = "fixed",
    max_sigma: Annotated[float, typer.Option(
        "--max-sigma", help="keep fixes whose lat and lon sigmas are both below this (m); 0 = no cut")] = 0.2,
    frame: Annotated[str, typer.Option("--frame", help="enu (at the origin) or utm (minus the origin's)")] = "enu",
    origin: Annotated[str, typer.Option(
        "--origin", help="first (the first kept fix) or LAT,LON,H (deg, deg, m ellipsoidal)")] = "first",
    clock: Annotated[str, typer.Option("--clock", help="stamps: auto, log (the log's own clock) or utc")] = "auto",
    lever_arm: Annotated[str | None, typer.Option(
        "--antenna-lever-arm", help="X,Y,Z of the antenna in the robot frame (m); used with --odometry")] = None,
    odometry: Annotated[Path | None, typer.Option(
        "--odometry", help="odometry CSV (same clock) to smooth the fixes with (fusion)")] = None,
    no_outliers: Annotated[bool, typer.Option("--no-outlier-test", help="skip the multipath outlier test")] = False,
    max_malformed: Annotated[float, typer.Option(
        "--max-malformed", help="refuse a log with more than this share of malformed sentences")] = 0.01,
    report: Annotated[Path | None, typer.Option("--report", help="JSON report to write")] = None,
    plot: Annotated[Path | None, typer.Option(
        "--plot", help="folder for the coverage map and time-series figures")] = None,
) -> None:
    """RTK-GPS ground truth: fix-aware filtering, ENU/UTM, covariances from GST (docs/gps.md)."""
    from gtrig.cli import checks
    from gtrig.gps.filter import FilterOptions
    from gtrig.gps.frames import Origin
    from gtrig.gps.groundtruth import GpsOptions, gps_ground_truth
    from gtrig.gps.report import gps_report, report_lines
    from gtrig.io.posetrack import write_pose_track

    arm = _checked_args(fmt, fix, frame, clock, max_sigma, max_malformed, lever_arm, origin, odometry)
    checks.outputs([log, odometry], [out, covariance, report, report.with_suffix(".md") if report else None])
    if plot is not None:
        checks.output_folder("--plot", plot)
    opts = GpsOptions(format=fmt, frame=frame, clock=clock,  # type: ignore[arg-type]
                      origin=None if origin == "first" else Origin.parse(origin), max_malformed=max_malformed,
                      filter=FilterOptions(fix=fix, max_sigma_m=max_sigma or None,  # type: ignore[arg-type]
                                           outlier_gate=None if no_outliers else FilterOptions().outlier_gate))
    res = gps_ground_truth(log, opts)
    track = res.track
    if arm is not None and odometry is None:
        # a purely vertical lever arm needs no heading (level ground)
        from dataclasses import replace

        track = replace(track, xyz=track.xyz - [0.0, 0.0, arm[2]], child_frame_id="robot")
    if odometry is not None:
        from gtrig.gps.smooth import smooth_with_odometry
        from gtrig.io.odometry import read_odometry

        track = smooth_with_odometry(res, read_odometry(odometry), arm or (0.0, 0.0, 0.0))
    rep = gps_report(res)
    if odometry is not None:
        rep["smoothed"] = {"poses": len(track), **track.counts(),
                           "heading_not_observable": int(sum("heading" in r for r in track.reasons))}
    outs: list[Path] = [out, covariance]
    write_pose_track(track, out, covariance)
    outs += _write_figures_and_report(rep, plot, report)
    for line in report_lines(rep):
        console.print(line, highlight=False)
    if "smoothed" in rep:
        s = rep["smoothed"]
        console.print(f"smoothed with odometry: {s['poses']} poses, {s['ok']} observed, {s['bridged']} bridged, "
                      f"{s['heading_not_observable']} with the heading not observable", highlight=False)
    console.print("wrote " + ", ".join(str(p) for p in outs), highlight=False)


def _checked_args(fmt: str, fix: str, frame: str, clock: str, max_sigma: float, max_malformed: float,
                  lever_arm: str | None, origin: str, odometry: Path | None) -> tuple[float, float, float] | None:
    """Refuse options out of their sets or ranges (one :class:`InputError` naming the option); returns the
    antenna's lever arm (m, robot frame) or None."""
    from gtrig.cli import checks
    from gtrig.errors import InputError
    from gtrig.gps.filter import FIX_SETS

    choices = {"--format": (fmt, ("auto", "rawseeds", "nmea", "rtklib")), "--fix": (fix, tuple(FIX_SETS)),
               "--frame": (frame, ("enu", "utm")), "--clock": (clock, ("auto", "log", "utc"))}
    for name, (val, allowed) in choices.items():
        if val not in allowed:
            raise InputError(f"{name} {val!r}: expected one of {', '.join(allowed)}")
    checks.number("--max-sigma", max_sigma, lo=0.0, hi=1000.0, unit="m")
    checks.number("--max-malformed", max_malformed, lo=0.0, hi=1.0)
    xyz = checks.floats("--antenna-lever-arm", lever_arm, 3, "metres")
    arm = None if xyz is None else (xyz[0], xyz[1], xyz[2])
    if arm is not None:
        checks.number("--antenna-lever-arm", max(abs(v) for v in arm), hi=10.0, unit="m",
                      unit_hint="millimetres given for metres")
    if origin != "first":
        checks.floats("--origin", origin, 3, "deg, deg, m")
    if arm is not None and odometry is None and any(abs(v) > 0 for v in arm[:2]):
        raise InputError("--antenna-lever-arm with a horizontal offset needs --odometry (the heading)")
    return arm


def _write_figures_and_report(rep: dict, plot: Path | None, report: Path | None) -> list[Path]:
    """The coverage and time-series figures in ``plot``, the JSON ``report`` and a Markdown summary beside it
    that `gtrig report` shows with the figures; returns the files written."""
    import json
    import os

    from gtrig.io.atomic import atomic_write_text

    outs: list[Path] = []
    figures: list[Path] = []
    if plot is not None:
        from gtrig.gps.plots import coverage_figure, lost_since_first, time_series_figure
        from gtrig.plotting import save

        figures = [plot / "gps_coverage.png", plot / "gps_time.png"]
        save(coverage_figure(rep["coverage"]), figures[0])
        save(time_series_figure(rep["series_1hz"], lost_since_first(rep)), figures[1])
        outs += figures
    if report is not None:
        from gtrig.gps.report import report_markdown

        md = report.with_suffix(".md")
        rel = [os.path.relpath(f, md.parent) for f in figures]
        atomic_write_text(report, json.dumps(rep, indent=1) + "\n")
        atomic_write_text(md, report_markdown(rep, rel))
        outs += [report, md]
    return outs
