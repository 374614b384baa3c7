# ruff: noqa: B008  (typer.Option in defaults is the Typer idiom, as in the other CLI modules)
"""``gtrig import rosbag``: a ROS 1 or ROS 2 bag into the recording layout."""

from __future__ import annotations

from pathlib import Path

import typer

from gtrig.cli.common import console, handle_errors

app = typer.Typer(help="Import data recorded elsewhere into the recording layout.", no_args_is_help=True)


@app.command("rosbag")
@handle_errors
def rosbag(
    bags: list[Path] = typer.Argument(..., help="A ROS 1 .bag (or several), a ROS 2 bag folder or a .mcap file."),
    topics: Path | None = typer.Option(None, "--topics", help="topics.yaml: which topic is which rig sensor."),
    out: Path | None = typer.Option(None, "--out", help="The recording folder to write into."),
    rig: Path | None = typer.Option(None, "--rig", help="The rig (copied to OUT/rig.yaml); default OUT/rig.yaml."),
    list_: bool = typer.Option(False, "--list", help="Write a topics.yaml to start from on stdout (the topics' "
                               "table, with type, count and rate, on stderr): --list > topics.yaml."),
    stamp: str | None = typer.Option(None, "--stamp", help="header or receive (default: topics.yaml's, header)."),
    video: bool = typer.Option(False, "--video", help="One lossless FFV1 video.mkv per camera instead of images."),
    image_format: str = typer.Option("pgm", "--image-format", help="pgm (uncompressed, fastest) or png (lossless, "
                                     "under half the disk, about 10x slower)."),
    force: bool = typer.Option(False, "--force", help="Replace the sequence folder if it exists."),
) -> None:
    """Import a bag: images, laser scans, odometry and trajectories, checked against the rig."""
    from gtrig.errors import InputError
    from gtrig.io.rosbag.topics import list_topics, topics_template

    if list_:
        from rich.table import Table

        from gtrig.cli.common import err_console
        from gtrig.io.rosbag.tf_tree import propose_tf_trajectories, tf_edges
        from gtrig.rig import load_rig

        summaries = list_topics(bags)
        t = Table("topic", "type", "messages", "rate (Hz)", title=f"{bags[0]}")
        for s in summaries:
            t.add_row(s.topic, s.msgtype, str(s.count), f"{s.rate_hz:.2f}")
        err_console.print(t)
        tf_ids = propose_tf_trajectories(tf_edges(bags))
        typer.echo(topics_template(summaries, load_rig(rig) if rig is not None else None, tf_ids), nl=False)
        return
    if topics is None or out is None:
        raise InputError("give --topics topics.yaml and --out REC (or --list to start a topics.yaml)")
    if image_format not in ("png", "pgm"):
        raise InputError(f"--image-format must be png or pgm, got {image_format!r}")
    from gtrig.cli import checks

    checks.choice("--stamp", stamp, ("header", "receive"))
    checks.output_folder("--out", out)
    for b in bags:
        checks.not_inside("--out", out, b, "a bag")
    from gtrig.io.rosbag.record_import import import_bag

    with console.status("importing"):
        rep = import_bag(bags, topics, out, rig_path=rig, stamp=stamp, video=video,
                         image_format=image_format, force=force)  # type: ignore[arg-type]
    for what, n in rep.counts.items():
        console.print(f"{what}: {n} messages")
    for name in rep.trajectories:
        console.print(f"trajectory {name}: {rep.sequence_dir / 'trajectories' / (name + '.tum')}")
    console.print(f"wrote {rep.sequence_dir}")
