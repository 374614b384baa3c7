"""``gtrig rig check``."""

from __future__ import annotations

from pathlib import Path

import typer

from gtrig.cli.common import console, handle_errors, styled
from gtrig.errors import ConfigError

app = typer.Typer(help="Rig files: start one from a template, validate and summarise.", no_args_is_help=True)


@app.command("init")
@handle_errors
def init(
    out: Path = typer.Option(..., "--out", help="rig.yaml to write (an existing file is not replaced)."),
    cameras: int | None = typer.Option(
        None, "--cameras", help="Fixed cameras watching the robot's markers (default 4).", show_default=False),
    scanners: int | None = typer.Option(
        None, "--scanners", help="Fixed 2D laser scanners seeing the robot's hull (default 4).",
        show_default=False),
    odometry_only: bool = typer.Option(
        False, "--odometry-only", help="Only the robot's odometry and onboard scanner (importing odometry or "
        "a bag without the room's sensors); takes no --cameras or --scanners."),
) -> None:
    """Write a commented rig.yaml template: every field with what it is, its unit, frame and a typical value."""
    from gtrig.cli import checks
    from gtrig.errors import InputError
    from gtrig.io.atomic import atomic_write_text
    from gtrig.rig.template import MAX_SENSORS, template_rig, template_text

    checks.count("--cameras", cameras, lo=0, hi=MAX_SENSORS)
    checks.count("--scanners", scanners, lo=0, hi=MAX_SENSORS)
    if odometry_only:
        given = "--cameras" if cameras is not None else "--scanners" if scanners is not None else None
        if given:
            raise InputError(f"--odometry-only takes no {given} (its rig has no room sensors)")
        cameras = scanners = 0
    else:
        cameras = 4 if cameras is None else cameras
        scanners = 4 if scanners is None else scanners
        if cameras == 0 and scanners == 0:
            raise InputError("--cameras 0 --scanners 0: a rig without room sensors is --odometry-only")
    checks.outputs([], [out])
    if out.exists():
        raise InputError(f"{out}: exists; a template does not replace a rig (remove it or choose another --out)")
    atomic_write_text(out, template_text(template_rig(cameras, scanners, odometry_only)))
    what = "odometry-only rig" if odometry_only else f"{cameras} camera(s), {scanners} scanner(s)"
    console.print(f"{out}: template with {what}; edit it, then `gtrig rig check {out}`", highlight=False)



@app.command("check")
@handle_errors
def check(rig: Path = typer.Argument(..., help="rig.yaml")) -> None:
    """Validate a rig file and print a summary of it."""
    import numpy as np
    from rich.table import Table

    from gtrig import geometry as geo
    from gtrig.cli.common import err_console
    from gtrig.rig import load_rig
    from gtrig.rig.load import RigValidationError

    try:
        r = load_rig(rig)
    except RigValidationError as e:
        # every problem of the file at once, one line each: a new rig is fixed in one pass
        for p in e.problems[:-1]:
            err_console.print(styled("error:", "red"), p, highlight=False, soft_wrap=True)
        raise ConfigError(e.problems[-1]) from None
    console.print(styled(rig, "bold"), f": valid rig '{r.world.name}'", sep="")
    t = Table("camera", "resolution", "fx, fy (px)", "position (m)", "tilt down (deg)", "rate (Hz)")
    for c in r.cameras:
        T = c.T_world_cam.matrix()
        tilt = np.degrees(np.arcsin(-T[2, 2]))
        t.add_row(c.name, f"{c.resolution[0]} x {c.resolution[1]}", f"{c.K[0, 0]:.1f}, {c.K[1, 1]:.1f}",
                  ", ".join(f"{v:.3f}" for v in c.T_world_cam.xyz), f"{tilt:.1f}",
                  "stills" if c.rate_hz is None else f"{c.rate_hz:g}")
    if r.cameras:
        console.print(t)
    t = Table("scanner", "position (m)", "yaw (deg)", "beams", "fov (deg)", "rate (Hz)")
    for s in r.laser_scanners:
        T = s.T_world_scanner.matrix()
        t.add_row(s.name, ", ".join(f"{v:.3f}" for v in s.T_world_scanner.xyz),
                  f"{np.degrees(geo.T_to_se2(T)[2]):.1f}", str(s.beams),
                  f"{np.degrees(abs(s.angle_increment_rad) * s.beams):.1f}", f"{s.rate_hz:g}")
    if r.laser_scanners:
        console.print(t)
    t = Table("marker", "family", "side (mm)", "position on robot (m)")
    for m in r.robot.markers:
        t.add_row(str(m.id), m.family.value, f"{m.side_m * 1000:.1f}",
                  ", ".join(f"{v:.3f}" for v in m.T_robot_marker.xyz))
    if r.robot.markers:
        console.print(t)
    h = r.robot.hull
    hull = "no hull" if h is None else (
        f"hull: {h.length_m * 1000:.0f} x {h.width_m * 1000:.0f} mm, z {h.z_min_m:.2f}-{h.z_max_m:.2f} m")
    console.print(f"{hull}; "
                  f"{len(r.robot.onboard_scanners)} onboard scanner(s); odometry {r.robot.odometry.rate_hz:g} Hz; "
                  f"{len(r.survey.reference_points)} survey reference point(s)")
