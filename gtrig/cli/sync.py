"""``gtrig sync``: each GT source's clock offset to the reference (odometry), with a 95 % interval."""

from __future__ import annotations

import math
from pathlib import Path
from typing import TYPE_CHECKING

import typer

from gtrig.cli.common import console, handle_errors

if TYPE_CHECKING:
    from gtrig.io.odometry import OdometryLog
    from gtrig.sync.offset import OffsetEstimate
    from gtrig.trajectory import PoseTrack


@handle_errors
def command(
    recording: Path | None = typer.Option(None, "--recording", help="The recording folder (for run/odometry.csv)."),
    reference: str = typer.Option("odometry", "--reference",
                                  help="The reference clock: odometry, an odometry CSV path, or the NAME of one "
                                  "of the sources (a GT source pins time better than odometry's slip)."),
    source: list[str] = typer.Option(..., "--source", help="NAME=track.tum[,cov.csv] (repeatable)."),
    out: Path = typer.Option(..., "--out", help="Output sync.yaml."),
    search_s: float = typer.Option(3.0, "--search-s", help="Lags searched, both signs, seconds."),
    figure: Path | None = typer.Option(None, "--figure", help="PNG of the correlation curves."),
    refine: bool = typer.Option(True, "--refine/--no-refine",
                                help="Refine with the offset as a parameter of the fusion's fit (needs covariances)."),
    per_camera: bool = typer.Option(False, "--per-camera",
                                    help="Also each camera's offset (needs --rig, sources vision and laser)."),
    per_scanner: bool = typer.Option(False, "--per-scanner",
                                     help="Also each fixed scanner's offset (needs --rig and source vision)."),
    rig_path: Path | None = typer.Option(None, "--rig", help="rig.calibrated.yaml (cameras, scanners, hull)."),
) -> None:
    """Clock offsets of GT sources to odometry: cross-correlation of heading rates, then a sub-sample fit."""
    from gtrig.cli import checks
    from gtrig.errors import InputError
    from gtrig.io.offsets import CONVENTION, write_offsets
    from gtrig.sync.sensors import to_reference

    if (per_camera or per_scanner) and (recording is None or rig_path is None):
        raise InputError("--per-camera / --per-scanner need --recording and --rig (the calibrated rig)")

    checks.number("--search-s", search_s, lo=0.0, lo_open=True, hi=3600.0, unit="s")
    ins = [Path(f) for spec in source for f in spec.split("=", 1)[-1].split(",")]
    checks.outputs([*ins, recording / "run" / "odometry.csv" if recording else None], [out, figure])
    tracks = _read_sources(source)
    ref_track = tracks.get(reference)
    odo_path, odo = _reference_odometry(reference, recording, ref_track is not None)
    results = _offsets(tracks, reference, ref_track, odo, refine, search_s)
    # the joint camera fit needs GTvision's clock to odometry's: known when odometry is the reference
    vis = results.get("vision")
    odo_off = vis.offset_s if ref_track is None and vis is not None and vis.verdict == "ok" else math.nan
    sensors, clock = _per_sensor(recording, rig_path, tracks, results, per_camera, per_scanner, source, odo, odo_off)
    if ref_track is None and "vision" in results and "laser" in results and math.isfinite(clock[0]):
        _combine_with_laser_clock(results, clock)
    if figure is not None:
        from gtrig.sync.plots import correlation_figure

        correlation_figure(list(results.values()), figure)
        if sensors:
            correlation_figure(sensors, figure.with_name(figure.stem + "_sensors.png"))
    if ref_track is not None:
        results_doc = {reference: {"verdict": "ok", "offset_s": 0.0, "ci95_s": [0.0, 0.0], "reason": "the reference"}}
    else:
        results_doc = {}
    results_doc.update({k: v.to_dict() for k, v in results.items()})
    for e in sensors:
        results_doc[e.source] = to_reference(e, results["vision"])
    write_offsets(out, reference if (ref_track is not None or reference == "odometry") else str(odo_path),
                  results_doc)
    console.print(f"{out}: {len(results)} source(s) against {reference}; {CONVENTION}", highlight=False)


def _read_sources(source: list[str]) -> dict[str, PoseTrack]:
    """The tracks of ``--source NAME=track.tum[,cov.csv]``, by name."""
    from gtrig.errors import InputError
    from gtrig.io.posetrack import read_pose_track

    tracks = {}
    for spec in source:
        if "=" not in spec:
            raise InputError(f"--source {spec!r}: expected NAME=track.tum[,cov.csv]")
        name, files = spec.split("=", 1)
        parts = files.split(",")
        tracks[name] = read_pose_track(parts[0], parts[1] if len(parts) > 1 else None, source=name)
    return tracks


def _reference_odometry(reference: str, recording: Path | None, reference_is_source: bool) -> tuple[Path, OdometryLog]:
    """The odometry log and its path: the recording's (``--reference`` odometry or a source's name), else
    the CSV ``--reference`` names."""
    from gtrig.errors import InputError
    from gtrig.io.odometry import read_odometry

    if reference == "odometry" or reference_is_source:
        if recording is None:
            raise InputError(f"--reference {reference} needs --recording (its run/odometry.csv)")
        odo_path = recording / "run" / "odometry.csv"
    else:
        odo_path = Path(reference)
    return odo_path, read_odometry(odo_path)


def _offsets(tracks: dict[str, PoseTrack], reference: str, ref_track: PoseTrack | None, odo: OdometryLog,
             refine: bool, search_s: float) -> dict[str, OffsetEstimate]:
    """Each source's clock offset to the reference's heading (the reference track's, else odometry's):
    cross-correlation, then, with ``refine`` and a covariance, the fusion's fit; printed as found."""
    from gtrig.errors import InputError
    from gtrig.fusion.measurements import fixes_from_track
    from gtrig.sync.offset import estimate_offset, refine_by_fusion

    if ref_track is not None:
        ru = ref_track.usable()
        ref_t, ref_yaw = ru.stamps_s, ru.yaw_rad()
        if refine and ref_track.cov is None:
            raise InputError(f"--reference {reference}: the refinement needs its covariance (NAME=track.tum,cov.csv)")
    else:
        ref_t, ref_yaw = odo.stamps_s, odo.xytheta[:, 2]
    results = {}
    for name, track in tracks.items():
        if name == reference:
            continue
        use = track.usable()
        est = estimate_offset(ref_t, ref_yaw, use.stamps_s, use.yaw_rad(), name, search_s=search_s)
        if refine and track.cov is not None:
            anchors = (fixes_from_track(ref_track, reference),) if ref_track is not None else ()
            est = refine_by_fusion(est, fixes_from_track(track, name), odo, anchors=anchors)
        results[name] = est
        ci = "" if est.verdict != "ok" else f" [{est.ci95_s[0] * 1e3:+.2f}, {est.ci95_s[1] * 1e3:+.2f}] ms"
        num = "" if est.verdict != "ok" else f" {est.offset_s * 1e3:+.3f} ms"
        console.print(f"{name}: {est.verdict}{num}{ci} ({est.reason})", highlight=False)
    return results


def _combine_with_laser_clock(results: dict[str, OffsetEstimate], clock: tuple[float, float]) -> None:
    """GTvision's and GTlaser's offsets made consistent with GTlaser's clock to GTvision's ``clock``
    (seconds, its sigma), in ``results``; printed."""
    from gtrig.sync.offset import combine_with_laser_clock

    results["vision"], results["laser"] = combine_with_laser_clock(results["vision"], results["laser"], *clock)
    for name in ("vision", "laser"):
        est = results[name]
        if est.verdict == "ok":
            console.print(f"{name}: {est.offset_s * 1e3:+.3f} ms [{est.ci95_s[0] * 1e3:+.2f}, "
                          f"{est.ci95_s[1] * 1e3:+.2f}] ({est.reason})", highlight=False)


def _per_sensor(recording: Path | None, rig_path: Path | None, tracks: dict, results: dict,  # noqa: ANN001
                per_camera: bool, per_scanner: bool, sources: list[str], odometry, odometry_offset_s: float,  # noqa: ANN001
                ) -> tuple[list, tuple[float, float]]:
    """Each camera's / scanner's offset to GTvision's clock (gtrig.sync.sensors), printed, and
    GTlaser's clock to GTvision's with its sigma (nan when not measured); the cameras' refined jointly with
    ``odometry`` when ``odometry_offset_s`` (GTvision's clock minus odometry's) is finite."""
    if not (per_camera or per_scanner):
        return [], (float("nan"), float("nan"))
    from gtrig.errors import InputError
    from gtrig.rig import load_rig
    from gtrig.sync.sensors import sensor_offsets_and_laser_clock

    assert recording is not None and rig_path is not None  # checked before any work
    for need in ("vision", "laser") if per_camera else ("vision",):
        if need not in tracks or need not in results:
            raise InputError(f"--per-camera / --per-scanner need --source {need}=track.tum,cov.csv (not the reference)")
    # GTvision's checkpoint of detections beside its track (gt_vision_run.tum -> gt_vision_run.checkpoint)
    ck = next((Path(s.split("=", 1)[1].split(",")[0]).with_suffix(".checkpoint") for s in sources
               if s.startswith("vision=")), None)
    if ck is not None and not ck.is_file():
        console.print(f"{ck}: no GTvision checkpoint; each pose is taken at its stamp (up to 2.5 ms off for a "
                      "one-camera pose of a multi-camera instant)", highlight=False)
        ck = None
    out, clock = sensor_offsets_and_laser_clock(recording, load_rig(rig_path), tracks["vision"], tracks.get("laser"),
                                                per_camera, per_scanner, checkpoint=ck, odometry=odometry,
                                                odometry_offset_s=odometry_offset_s)
    for e in out:
        num = "" if e.verdict != "ok" else (f" {e.offset_s * 1e3:+.3f} ms [{e.ci95_s[0] * 1e3:+.2f}, "
                                            f"{e.ci95_s[1] * 1e3:+.2f}] to GTvision's clock")
        console.print(f"{e.source}: {e.verdict}{num} ({e.reason})", highlight=False)
    return out, clock
