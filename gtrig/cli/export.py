# ruff: noqa: B008  (typer.Option in defaults is the Typer idiom, as in the other CLI modules)
"""``gtrig export``: a trajectory (or a recording's sensor data) in the formats others read."""

from __future__ import annotations

from pathlib import Path

import typer

from gtrig.cli.common import console, handle_errors

#: formats that keep each pose's status: every pose is written to them
_KEEP_STATUS = ("gtrig", "csv")


@handle_errors
def command(
    traj: Path = typer.Argument(..., help="A trajectory (TUM, KITTI, EuRoC, RAWSEEDS, CSV, bag) or a recording."),
    to: str = typer.Option(..., "--to", help="tum, gtrig, kitti, euroc, rawseeds, csv, rosbag1 or rosbag2."),
    out: Path = typer.Option(..., "--out", help="The file (or ROS 2 bag folder, or NAME.mcap) to write."),
    covariance: Path | None = typer.Option(None, "--covariance", help="The covariance CSV of a TUM trajectory."),
    from_: str | None = typer.Option(None, "--from", help="TRAJ's format (default: from its name or content)."),
    topic: str | None = typer.Option(None, "--topic", help="The topic to read when TRAJ is a bag."),
    frame_id: str | None = typer.Option(None, "--frame-id", help="World frame in a bag (default: the track's)."),
    child_frame_id: str | None = typer.Option(None, "--child-frame-id", help="Body frame in a bag."),
    storage: str = typer.Option("sqlite3", "--storage", help="ROS 2 storage: sqlite3 or mcap (NAME.mcap: mcap)."),
    sequence: str = typer.Option("run", "--sequence", help="The sequence of a recording to export to a bag."),
    all_poses: bool = typer.Option(False, "--all", help="Also write bridged and rejected poses (formats "
                                   "without a status column get only ok and flagged poses otherwise)."),
    force: bool = typer.Option(False, "--force", help="Overwrite an existing output."),
) -> None:
    """Write a trajectory in another format, or a recording's images, scans and odometry into a bag."""
    from gtrig.errors import InputError
    from gtrig.io.formats import FORMATS, read_trajectory, write_trajectory

    if to not in FORMATS:
        raise InputError(f"--to must be one of {', '.join(FORMATS)}, got {to!r}")
    if storage not in ("sqlite3", "mcap"):
        raise InputError(f"--storage must be sqlite3 or mcap, got {storage!r}")
    from gtrig.cli import checks

    checks.choice("--from", from_, FORMATS)
    if out.resolve() in {traj.resolve(), *([covariance.resolve()] if covariance else [])}:
        raise InputError(f"{out}: an output may not overwrite an input")
    checks.not_inside("--out", out, traj, "the input")
    if traj.is_dir() and (traj / "rig.yaml").is_file():
        if to not in ("rosbag1", "rosbag2"):
            raise InputError(f"{traj}: a recording exports to rosbag1 or rosbag2, not {to}")
        from gtrig.io.rosbag.record_export import export_recording

        with console.status("exporting"):
            topics = export_recording(traj, out, 1 if to == "rosbag1" else 2, sequence=sequence,
                                      storage=storage, force=force)  # type: ignore[arg-type]
        console.print(f"wrote {out}: " + ", ".join(f"{k} {v}" for k, v in topics.items()
                                                     if k in ("cameras", "lasers", "onboard", "odometry")))
        return
    opts: dict[str, object] = {}
    if covariance is not None:
        opts["cov_path"] = covariance
    if topic is not None:
        opts["topic"] = topic
    track = read_trajectory(traj, from_, **opts)
    n_all = len(track)
    if not all_poses and to not in _KEEP_STATUS:
        track = track.usable()
    wopts: dict[str, object] = {}
    if to in ("rosbag1", "rosbag2"):
        wopts = {"frame_id": frame_id, "child_frame_id": child_frame_id, "storage": storage}
    elif frame_id or child_frame_id:
        raise InputError(f"--frame-id / --child-frame-id apply to bags, not to {to}")
    paths = write_trajectory(track, out, to, force=force, **wopts)
    dropped = n_all - len(track)
    console.print(f"wrote {len(track)} poses" + (f" ({dropped} bridged or rejected left out; --all keeps them)"
                                                  if dropped else "") + ": " + ", ".join(str(p) for p in paths))
