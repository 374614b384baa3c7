# ruff: noqa: B008  (typer.Option in defaults is the Typer idiom, as in the other CLI modules)
"""``gtrig survey points|poses|adjust|predict``: the hand-laser survey (GTvalidation)."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import typer

from gtrig.cli.common import console, handle_errors

app = typer.Typer(help="Hand-laser survey: world points, validation poses, planning.", no_args_is_help=True)

_AMBIG = typer.Option("refuse", "--on-ambiguity", help="refuse (exit 3) or warn when a second solution fits.")
_OUTLIER = typer.Option(
    "exclude", "--on-outlier", help="exclude (with a warning), refuse, or keep a bad reading."
)
_SIGMA = typer.Option(None, "--sigma", help="Hand-laser sigma (m) for rows without one \\[default 0.002].")
_REF_SIGMA = typer.Option(0.002, "--reference-sigma", help="Reference sigma (m) if REF.csv has none.")


def _policies(on_ambiguity: str, on_outlier: str) -> None:
    from gtrig.cli import checks

    checks.choice("--on-ambiguity", on_ambiguity, ("refuse", "warn"))
    checks.choice("--on-outlier", on_outlier, ("exclude", "refuse", "keep"))


@app.command("points")
@handle_errors
def points(
    reference: Path = typer.Option(..., "--reference", help="REF.csv: name,x,y[,sigma] (world frame, m)."),
    distances: Path = typer.Option(
        ...,
        "--distances",
        help="D.csv: point,reference,distance[,sigma] (or point,d_<ref>,... wide); reference may name "
        "another world point (network readings).",
    ),
    out: Path = typer.Option(..., "--out", help="POINTS.csv: name,x,y,cov_xx,cov_xy,cov_yy,..."),
    sigma: float | None = _SIGMA,
    reference_sigma: float = _REF_SIGMA,
    on_ambiguity: str = _AMBIG,
    on_outlier: str = _OUTLIER,
    plot: Path | None = typer.Option(
        None, "--plot", help="Figure of the points with 3-sigma ellipses (x10)."
    ),
) -> None:
    """World points by trilateration from distances to the reference points (and to each other)."""
    from gtrig.cli import checks
    from gtrig.io.survey_csv import read_reference_points, read_world_distances, write_points
    from gtrig.survey.points import estimate_world_points

    checks.sigma_m("--sigma", sigma)
    checks.sigma_m("--reference-sigma", reference_sigma)
    _policies(on_ambiguity, on_outlier)
    checks.outputs([reference, distances], [out, plot])

    refs = read_reference_points(reference, reference_sigma)
    d = read_world_distances(distances, 0.002 if sigma is None else sigma)
    r = estimate_world_points(refs, d, on_ambiguity=on_ambiguity, on_outlier=on_outlier)
    extra: dict[str, Sequence[float]] = {
        "chi2": [p.chi2 for p in r.points],
        "dof": [p.dof for p in r.points],
        "rms_residual_m": [p.rms_residual_m for p in r.points],
        "basin_radius_m": [p.basin.radius_m if p.basin else float("nan") for p in r.points],
    }
    write_points(out, r.names, r.xy, r.cov_xy, extra)
    if plot is not None:
        from gtrig.survey.plots import plot_world_points

        plot_world_points(r.names, r.xy, r.cov_xy, plot, refs.names, refs.xy)
    from rich.table import Table

    t = Table("point", "x (m)", "y (m)", "sigma x, y (mm)", "chi2/dof", "basin (m)")
    for p in r.points:
        sd = 1000 * __import__("numpy").sqrt(__import__("numpy").diag(p.cov_xy))
        t.add_row(
            p.name,
            f"{p.xy[0]:.4f}",
            f"{p.xy[1]:.4f}",
            f"{sd[0]:.1f}, {sd[1]:.1f}",
            f"{p.chi2:.2f}/{p.dof}",
            f">= {p.basin.radius_m:g}" if p.basin else "",
        )
    console.print(t)
    console.print(f"{len(r.names)} world points written to {out}; {len(r.excluded)} reading(s) excluded")


@app.command("poses")
@handle_errors
def poses(
    points: Path = typer.Option(..., "--points", help="POINTS.csv from 'gtrig survey points' (or name,x,y)."),
    robot_points: Path = typer.Option(..., "--robot-points", help="RP.csv: name,x,y (robot frame, m)."),
    distances: Path = typer.Option(
        ..., "--distances", help="D.csv: pose,robot_point,world_point,distance[,sigma]."
    ),
    out: Path = typer.Option(..., "--out", help="POSES.csv: pose,x,y,theta and the 3 x 3 covariance."),
    initial: Path | None = typer.Option(None, "--initial", help="INIT.csv: pose,x,y,theta (hand measured)."),
    sigma: float | None = _SIGMA,
    on_ambiguity: str = _AMBIG,
    on_outlier: str = _OUTLIER,
    plot: Path | None = typer.Option(None, "--plot", help="Figure of the poses with 3-sigma ellipses (x10)."),
) -> None:
    """Validation poses from robot-point to world-point distances."""
    import numpy as np

    from gtrig.cli import checks
    from gtrig.io.survey_csv import (
        read_points,
        read_pose_distances,
        read_pose_table,
        read_robot_points,
        write_poses,
    )
    from gtrig.survey.poses import estimate_poses

    checks.sigma_m("--sigma", sigma)
    _policies(on_ambiguity, on_outlier)
    checks.outputs([points, robot_points, distances, initial], [out, plot])

    wp = read_points(points)
    init = read_pose_table(initial) if initial is not None else None
    r = estimate_poses(
        (wp.names, wp.xy, wp.cov_xy),
        read_robot_points(robot_points),
        read_pose_distances(distances, 0.002 if sigma is None else sigma),
        initial=init,
        on_ambiguity=on_ambiguity,
        on_outlier=on_outlier,
    )
    extra: dict[str, Sequence[float]] = {
        "chi2": [p.chi2 for p in r.poses],
        "dof": [p.dof for p in r.poses],
        "basin_radius_m": [p.basin.radius_m if p.basin else float("nan") for p in r.poses],
    }
    write_poses(out, r.names, r.xytheta, r.cov_xytheta, extra)
    if plot is not None:
        from gtrig.survey.plots import plot_poses

        plot_poses(r.names, r.xytheta, r.cov_xytheta, plot, wp.xy)
    from rich.table import Table

    t = Table(
        "pose",
        "x (m)",
        "y (m)",
        "theta (deg)",
        "sigma x, y (mm)",
        "sigma theta (deg)",
        "chi2/dof",
        "basin (m)",
    )
    for p in r.poses:
        sd = np.sqrt(np.diag(p.cov_xytheta))
        t.add_row(
            p.name,
            f"{p.xytheta[0]:.4f}",
            f"{p.xytheta[1]:.4f}",
            f"{np.degrees(p.xytheta[2]):.3f}",
            f"{sd[0] * 1000:.1f}, {sd[1] * 1000:.1f}",
            f"{np.degrees(sd[2]):.3f}",
            f"{p.chi2:.2f}/{p.dof}",
            f">= {p.basin.radius_m:g}" if p.basin else "",
        )
    console.print(t)
    console.print(f"{len(r.names)} poses written to {out}; {len(r.excluded)} reading(s) excluded")


@app.command("adjust")
@handle_errors
def adjust(
    reference: Path = typer.Option(..., "--reference", help="REF.csv: name,x,y[,sigma] (world frame, m)."),
    distances: Path = typer.Option(..., "--distances", help="World-point readings, as for 'survey points'."),
    robot_points: Path = typer.Option(..., "--robot-points", help="RP.csv: name,x,y[,sigma] (robot frame, m)."),
    pose_distances: Path = typer.Option(
        ..., "--pose-distances", help="PD.csv: pose,robot_point,world_point,distance[,sigma]."
    ),
    out_points: Path = typer.Option(..., "--out-points", help="POINTS.csv of the joint adjustment."),
    out_poses: Path = typer.Option(..., "--out-poses", help="POSES.csv of the joint adjustment."),
    sigma: float | None = _SIGMA,
    reference_sigma: float = _REF_SIGMA,
    on_ambiguity: str = _AMBIG,
    on_outlier: str = _OUTLIER,
) -> None:
    """World points and validation poses adjusted together from every reading (a free-station network):
    'survey points' then 'survey poses', then one least squares over all of them."""
    import numpy as np

    from gtrig.cli import checks
    from gtrig.io.survey_csv import (
        read_pose_distances,
        read_reference_points,
        read_robot_points,
        read_world_distances,
        write_points,
        write_poses,
    )
    from gtrig.survey import run_survey

    checks.sigma_m("--sigma", sigma)
    checks.sigma_m("--reference-sigma", reference_sigma)
    _policies(on_ambiguity, on_outlier)
    checks.outputs([reference, distances, robot_points, pose_distances], [out_points, out_poses])

    s = 0.002 if sigma is None else sigma
    r = run_survey(read_reference_points(reference, reference_sigma), read_world_distances(distances, s),
                   read_robot_points(robot_points), read_pose_distances(pose_distances, s),
                   on_ambiguity=on_ambiguity, on_outlier=on_outlier)
    from gtrig.io.atomic import atomic_group

    # both or neither: the two tables are one adjustment
    with atomic_group(out_points, out_poses) as (tmp_points, tmp_poses):
        write_points(tmp_points, r.points.names, r.points.xy, r.points.cov_xy)
        write_poses(tmp_poses, r.poses.names, r.poses.xytheta, r.poses.cov_xytheta)
    sd_w = 1000 * np.sqrt(r.points.cov_xy[:, [0, 1], [0, 1]])
    sd_p = np.sqrt(r.poses.cov_xytheta[:, [0, 1, 2], [0, 1, 2]])
    jt = r.joint
    test = f"; chi2 {jt.test.chi2:.1f} over {jt.test.dof} dof" if jt is not None else ""
    console.print(
        f"{len(r.points.names)} world points (sigma up to {sd_w.max():.2f} mm) to {out_points}, "
        f"{len(r.poses.names)} poses (sigma up to {1000 * sd_p[:, :2].max():.2f} mm, "
        f"{np.degrees(sd_p[:, 2].max()):.3f} deg) to {out_poses}{test}; "
        f"{len(r.points.excluded) + len(r.poses.excluded)} reading(s) excluded", highlight=False)


@app.command("predict")
@handle_errors
def predict(
    points: Path = typer.Option(..., "--points", help="POINTS.csv (world points, optional covariance)."),
    robot_points: Path = typer.Option(..., "--robot-points", help="RP.csv: name,x,y (robot frame)."),
    sigma: float = typer.Option(0.002, "--sigma", help="Hand-laser sigma (m)."),
    step: float = typer.Option(0.25, "--step", help="Grid step (m)."),
    margin: float = typer.Option(0.0, "--margin", help="Grid margin around the world points (m)."),
    out: Path | None = typer.Option(None, "--out", help="CSV x,y,sigma_pos_m,sigma_theta_rad."),
    plot: Path | None = typer.Option(None, "--plot", help="Map figure (PNG)."),
) -> None:
    """Expected pose uncertainty at every place of the room for this layout of world points."""
    import numpy as np

    from gtrig.cli import checks
    from gtrig.io.atomic import atomic_write_text
    from gtrig.io.survey_csv import read_points, read_robot_points
    from gtrig.survey.predict import predict_pose_uncertainty

    checks.sigma_m("--sigma", sigma)
    checks.number("--step", step, lo=0.001, unit="m")
    checks.number("--margin", margin, lo=0.0, hi=1000.0, unit="m")
    checks.outputs([points, robot_points], [out, plot])

    wp = read_points(points)
    m = predict_pose_uncertainty(
        wp.xy, wp.cov_xy, read_robot_points(robot_points).xy, sigma, step_m=step, margin_m=margin
    )
    if out is not None:
        lines = ["x,y,sigma_pos_m,sigma_theta_rad"]
        for j, y in enumerate(m.y_m):
            for i, x in enumerate(m.x_m):
                lines.append(f"{x:.3f},{y:.3f},{m.sigma_pos_m[j, i]:.6g},{m.sigma_theta_rad[j, i]:.6g}")
        atomic_write_text(out, "\n".join(lines) + "\n")
    if plot is not None:
        from gtrig.survey.plots import plot_uncertainty_map

        plot_uncertainty_map(m.x_m, m.y_m, m.sigma_pos_m, m.sigma_theta_rad, wp.xy, plot)
    console.print(
        f"grid {m.x_m.size} x {m.y_m.size}: position sigma {np.nanmin(m.sigma_pos_m) * 1000:.2f} to "
        f"{np.nanmax(m.sigma_pos_m) * 1000:.2f} mm, heading sigma up to "
        f"{np.degrees(np.nanmax(m.sigma_theta_rad)):.3f} deg (worst heading)"
    )
