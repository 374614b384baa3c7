"""``gtrig vision``: GTvision, the robot pose from every marker in every camera."""

from __future__ import annotations

import math
from pathlib import Path
from typing import TYPE_CHECKING

import typer

from gtrig.cli.common import console, err_console, handle_errors
from gtrig.cli.scale import chunk_bar, dask_option, executor

if TYPE_CHECKING:
    from gtrig.rig.models import Rig
    from gtrig.vision.sequence import VisionResult


@handle_errors
def command(
    rig: Path | None = typer.Option(None, "--rig", help="The calibrated rig (rig.calibrated.yaml)."),
    recording: Path | None = typer.Option(None, "--recording", help="The recording folder."),
    out: Path = typer.Option(..., "--out", help="Output trajectory (TUM, T_world_robot)."),
    covariance: Path | None = typer.Option(None, "--covariance",
                                           help="Output CSV: one covariance per pose, row-major."),
    planar: bool = typer.Option(False, "--planar", help="Floor prior on height, roll and pitch; "
                                "covariances over x, y, yaw."),
    sequence: str = typer.Option("run", "--sequence", help="run or validation."),
    workers: int = typer.Option(0, "--workers", help="Processes (0: one per core)."),
    dask: str = dask_option(),
    detector: str = typer.Option("auto", "--detector", help="auto, gtrig or aruco."),
    track: bool = typer.Option(True, "--track/--no-track", help="Search each image where its markers are "
                               "expected and where it changed (whole-image passes on loss, at each chunk's "
                               "start and every --full-every-s); --no-track: every image whole."),
    full_every_s: float = typer.Option(1.0, "--full-every-s", help="A whole-image pass at least this often per "
                                       "camera when tracking, seconds."),
    floor_sigma_mm: float = typer.Option(3.0, "--floor-sigma-mm", help="Floor height deviation (planar)."),
    floor_tilt_deg: float = typer.Option(0.3, "--floor-tilt-deg", help="Floor tilt deviation (planar)."),
    camera_sigma_mm: float = typer.Option(3.0, "--camera-sigma-mm",
                                          help="Camera position sigma, for cameras without pose_cov in the rig."),
    camera_sigma_deg: float = typer.Option(0.05, "--camera-sigma-deg",
                                           help="Camera orientation sigma, for cameras without pose_cov."),
    marker_sigma_mm: float = typer.Option(2.0, "--marker-sigma-mm",
                                          help="Marker position sigma on the robot, for markers without "
                                          "pose_cov (hand-measured: 2)."),
    marker_sigma_deg: float = typer.Option(0.5, "--marker-sigma-deg",
                                           help="Marker orientation sigma, for markers without pose_cov "
                                           "(hand-measured: 0.5)."),
    board: Path | None = typer.Option(None, "--board", help="Track this ChArUco board file instead of a robot: "
                                      "with --videos and --cameras (docs/calibrate-from-video.md)."),
    videos: Path | None = typer.Option(None, "--videos", help="With --board: folder of <cam>.mp4 and their "
                                       "frame times."),
    cameras: Path | None = typer.Option(None, "--cameras", help="With --board: gtrig calib video's output "
                                        "folder or caliscope's camera_array.toml."),
    step: int = typer.Option(1, "--step", help="With --board: read every n-th frame."),
    sigma_px: float = typer.Option(0.3, "--sigma-px", help="With --board: a corner's pixel sigma."),
    line_delay: bool = typer.Option(False, "--line-delay", help="With --board: also estimate each camera's "
                                    "rolling-shutter line delay."),
    drift: bool = typer.Option(False, "--drift", help="With --board: each camera's offset drifts linearly over "
                               "the recording (offsets stated at its midpoint, with their drift)."),
    timing_windows: int = typer.Option(0, "--timing-windows", help="With --board: also print the offsets of "
                                       "this many equal spans of the recording, each fitted apart."),
) -> None:
    """Robot poses from the markers seen by all cameras at each instant, with covariances; with --board, a
    ChArUco board's poses from the cameras' videos."""
    from gtrig.errors import InputError

    if board is not None:
        from gtrig.cli.vision_board import run

        if videos is None or cameras is None:
            raise InputError("--board needs --videos and --cameras")
        run(board, videos, cameras, out, covariance, step, sigma_px, line_delay, drift, timing_windows)
        return
    if rig is None or recording is None:
        raise InputError("--rig and --recording are required (or --board with --videos and --cameras)")

    from gtrig.cli import checks
    from gtrig.rig import load_rig
    from gtrig.vision.covariance import RigUncertainty
    from gtrig.vision.estimate import VisionOptions
    from gtrig.vision.refine import PlanarPrior
    from gtrig.vision.sequence import run_recording, write_pose_track_files
    from gtrig.vision.track import TrackOptions

    checks.choice("--sequence", sequence, ("run", "validation"))
    checks.choice("--detector", detector, ("auto", "gtrig", "aruco"))
    checks.workers(workers)
    for opt, v, hi, unit in (("--floor-sigma-mm", floor_sigma_mm, 500.0, "mm"),
                             ("--floor-tilt-deg", floor_tilt_deg, 45.0, "deg"),
                             ("--camera-sigma-mm", camera_sigma_mm, 500.0, "mm"),
                             ("--camera-sigma-deg", camera_sigma_deg, 45.0, "deg"),
                             ("--marker-sigma-mm", marker_sigma_mm, 500.0, "mm"),
                             ("--marker-sigma-deg", marker_sigma_deg, 45.0, "deg"),
                             ("--full-every-s", full_every_s, 3600.0, "s")):
        checks.number(opt, v, lo=0.0, lo_open=True, hi=hi, unit=unit)
    checks.input_folder("--recording", recording)
    checks.outputs([rig], [out, covariance])
    r = load_rig(rig)
    for a in _assumed_uncertainties(r, planar, camera_sigma_mm, camera_sigma_deg, marker_sigma_mm, marker_sigma_deg,
                                    floor_sigma_mm, floor_tilt_deg):
        err_console.print(f"assumed: {a}", highlight=False, soft_wrap=True)
    ru = RigUncertainty(camera_sigma_mm / 1000, math.radians(camera_sigma_deg), marker_sigma_mm / 1000,
                        math.radians(marker_sigma_deg))
    opts = VisionOptions(planar=planar, prior=PlanarPrior(0.0, floor_sigma_mm / 1000,
                                                          math.radians(floor_tilt_deg)), rig_uncertainty=ru)
    checkpoint = out.with_name(out.name + ".checkpoint.jsonl")
    with executor(dask) as ex, chunk_bar("GTvision") as bar:
        result = run_recording(recording, r, sequence, planar, workers, options=opts, detector=detector,
                               checkpoint=checkpoint, progress=bar.progress, executor=ex,
                               track=TrackOptions(enabled=track, full_every_s=full_every_s))
    write_pose_track_files(result, out, covariance)
    checkpoint.unlink(missing_ok=True)
    _print_summary(result, out, sequence)


def _assumed_uncertainties(r: Rig, planar: bool, camera_sigma_mm: float, camera_sigma_deg: float,
                           marker_sigma_mm: float, marker_sigma_deg: float, floor_sigma_mm: float,
                           floor_tilt_deg: float) -> list[str]:
    """What stands in for the uncertainties the rig does not give (it is used wherever it does), one
    line each."""
    assumed = []
    no_cov = [c.name for c in r.cameras if c.pose_cov is None]
    if no_cov:
        assumed.append(f"camera pose sigma {camera_sigma_mm:g} mm / {camera_sigma_deg:g} deg for {', '.join(no_cov)} "
                       "(--camera-sigma-mm/-deg)")
    no_cov = [str(m.id) for m in r.robot.markers if m.pose_cov is None]
    if no_cov:
        assumed.append(f"marker pose sigma {marker_sigma_mm:g} mm / {marker_sigma_deg:g} deg for marker(s) "
                       f"{', '.join(no_cov)} (--marker-sigma-mm/-deg)")
    if r.robot.markers_frame_cov is None:
        assumed.append("no error of the markers' robot frame (robot.markers_frame_cov absent: gtrig robot-frame "
                       "writes it)")
    if planar:
        assumed.append(f"floor prior {floor_sigma_mm:g} mm / {floor_tilt_deg:g} deg (--floor-sigma-mm/-tilt-deg)")
    no_jitter = [c.name for c in r.cameras if c.stamp_sigma_s == 0]
    if no_jitter:
        assumed.append(f"exact image time stamps for {', '.join(no_jitter)} (stamp_sigma_s absent)")
    return assumed


def _print_summary(result: VisionResult, out: Path, sequence: str) -> None:
    """The run in a few lines: instants localized, residuals, a table per camera, why instants failed."""
    from rich.table import Table

    from gtrig.vision.report import summarize

    rep = summarize(result)
    console.print(f"{out}: {rep.localized} of {rep.instants} instants localized ({sequence}, "
                  f"detector {result.detector}, {result.seconds['total']:.1f} s); residual RMS "
                  f"{rep.rms_px:.3f} px; corner variance factors "
                  f"{', '.join(f'{c} {f:.3g}' for c, f in result.corner_scale) or 'none'}", highlight=False)
    t = Table("camera", "images", "with markers", "views used", "rejected", "rms (px)")
    for c in rep.cameras:
        t.add_row(c.camera, str(c.images), str(c.images_with_markers), str(c.views_used),
                  str(c.views_rejected), f"{c.rms_px:.3f}")
    console.print(t)
    for reason, n in sorted(rep.failures.items()):
        console.print(f"not localized: {n} instant(s): {reason}", highlight=False)
