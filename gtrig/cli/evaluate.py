# ruff: noqa: B008  (typer.Option in defaults is the Typer idiom, as in the other CLI modules)
"""``gtrig evaluate poses``: compare poses with reference poses."""

from __future__ import annotations

from pathlib import Path

import typer

from gtrig.cli.common import console, handle_errors

app = typer.Typer(help="Evaluate estimates against references.", no_args_is_help=True)


def _cols(s: str | None) -> tuple[str, ...] | None:
    return None if s is None else tuple(c.strip() for c in s.split(","))


@app.command("poses")
@handle_errors
def poses(
    reference: Path = typer.Option(
        ..., "--reference", help="Reference poses: CSV (pose,x,y,theta | th | val_x,val_y,val_th) or TUM."
    ),
    estimate: Path = typer.Option(..., "--estimate", help="Estimated poses: CSV or TUM."),
    fmt: str = typer.Option("table", "--format", help="table, csv or md."),
    reference_columns: str | None = typer.Option(None, "--reference-columns", help="e.g. val_x,val_y,val_th"),
    estimate_columns: str | None = typer.Option(None, "--estimate-columns", help="e.g. x,y,th"),
    method: str | None = typer.Option(
        None, "--method", help="Keep estimate rows of this method (e.g. genetic)."
    ),
    per_pose: bool = typer.Option(False, "--per-pose", help="Also print the per-pose errors."),
    plot: Path | None = typer.Option(None, "--plot", help="Figure: both trajectories, errors, ellipses."),
) -> None:
    """Per-pose errors (reference - estimate, angles wrapped) and per-axis statistics."""
    from gtrig.errors import InputError
    from gtrig.evaluate import poses as ev
    from gtrig.io.survey_csv import read_pose_table

    if fmt not in ("table", "csv", "md"):
        raise InputError(f"--format must be table, csv or md, got {fmt!r}")
    c = ev.compare_poses(
        read_pose_table(reference, _cols(reference_columns)),
        read_pose_table(estimate, _cols(estimate_columns), method),
    )
    if fmt == "csv":
        typer.echo(ev.summary_csv(c), nl=False)
        if per_pose:
            typer.echo(ev.per_pose_csv(c), nl=False)
    elif fmt == "md":
        typer.echo(ev.summary_markdown(c), nl=False)
        if per_pose:
            typer.echo("\n```\n" + ev.per_pose_csv(c) + "```")
    else:
        from rich.table import Table

        t = Table(
            "statistic",
            "x (m)",
            "y (m)",
            "theta (rad)",
            "position (m)",
            title=f"errors = reference - estimate; poses localized {len(c.names)}/{c.n_reference}",
        )
        for r in ev.summary_rows(c):
            t.add_row(*r)
        console.print(t)
        if c.missing:
            console.print(f"not localized: {', '.join(c.missing)}")
        if per_pose:
            t = Table("pose", "err x (m)", "err y (m)", "err theta (rad)", "err pos (m)")
            for n, e, p in zip(c.names, c.err_xytheta, c.err_pos_m, strict=True):
                t.add_row(n, f"{e[0]:.4f}", f"{e[1]:.4f}", f"{e[2]:.4f}", f"{p:.4f}")
            console.print(t)
    if plot is not None:
        from gtrig.evaluate.plots import plot_comparison

        plot_comparison(c, plot, reference.name, estimate.name + (f" ({method})" if method else ""))
