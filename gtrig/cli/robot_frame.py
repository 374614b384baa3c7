"""``gtrig robot-frame``: tie the markers' robot frame to the surveyed one at the validation stops."""

from __future__ import annotations

from pathlib import Path

import typer

from gtrig.cli.common import console, err_console, handle_errors


@handle_errors
def command(
    rig: Path = typer.Option(..., "--rig", help="The rig with calibrated cameras and markers "
                             "(after 'gtrig markers calibrate-robot')."),
    recording: Path = typer.Option(..., "--recording", help="The recording folder (validation/ and survey/)."),
    out: Path = typer.Option(..., "--out", help="The rig to write, its markers in the surveyed robot frame."),
    anchor: int = typer.Option(14, "--anchor", help="The anchor marker, when the rig gives no "
                               "robot.markers_frame_cov (its hand placement: 0.3 mm, 0.1 deg about z)."),
    workers: int = typer.Option(0, "--workers", help="Processes (0: one per core)."),
) -> None:
    """Tie the markers' robot frame to the surveyed one at the validation stops; write the rig."""
    import math

    import numpy as np
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeRemainingColumn

    from gtrig.cli import checks
    from gtrig.errors import InputError
    from gtrig.io.survey_csv import read_table
    from gtrig.rig import load_rig
    from gtrig.rig.load import dump_rig
    from gtrig.survey import run_recording_survey
    from gtrig.vision.covariance import hand_placement_frame_covariance
    from gtrig.vision.robot_frame import fit_validation, rig_tied_to_survey, with_markers_frame_cov
    from gtrig.vision.sequence import run_recording

    checks.workers(workers)
    checks.input_folder("--recording", recording)
    checks.outputs([rig], [out])
    r = load_rig(rig)
    if r.robot.markers_frame_cov is None:
        try:
            T_anchor = r.marker(anchor).T_robot_marker.matrix()
        except KeyError:
            raise InputError(f"{rig}: marker {anchor} (--anchor) is not in robot.markers") from None
        r = with_markers_frame_cov(r, hand_placement_frame_covariance(T_anchor))
    survey = run_recording_survey(recording)
    with Progress(TextColumn("GTvision, validation stops"), BarColumn(), MofNCompleteColumn(),
                  TimeRemainingColumn(), console=err_console, transient=True) as prog:
        task = prog.add_task("stops", total=None)
        val = run_recording(recording, with_markers_frame_cov(r, None), "validation", True, workers,
                            progress=lambda d, n: prog.update(task, completed=d, total=n))
    names = read_table(Path(recording) / "validation" / "poses.csv", ("pose", "start_s", "end_s")).column("pose")
    fit = fit_validation(names, val, survey.poses.names, survey.poses.xytheta, survey.poses_cov_joint())
    dump_rig(rig_tied_to_survey(r, fit), out)
    d, sd = fit.d_xytheta, np.sqrt(np.diag(fit.cov_d))
    # rounded before printing, so that an offset below the last digit reads 0.00, never -0.00
    dx, dy, dth = round(1000 * d[0], 2) + 0.0, round(1000 * d[1], 2) + 0.0, round(math.degrees(d[2]), 4) + 0.0
    console.print(f"{out}: markers moved by {dx:.2f} mm, {dy:.2f} mm, {dth:.4f} deg "
                  f"(sigma {1000 * sd[0]:.2f} mm, {1000 * sd[1]:.2f} mm, {math.degrees(sd[2]):.4f} deg) "
                  f"from {int(fit.used.sum())} of {len(names)} stops; "
                  f"chi2 {fit.chi2:.1f} over {fit.dof} dof", highlight=False)
    for name in fit.excluded:
        console.print(f"left out: stop {name} (disagrees with the others)", highlight=False)
