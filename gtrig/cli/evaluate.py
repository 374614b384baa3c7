# ruff: noqa: B008  (typer.Option in defaults is the Typer idiom, as in the other CLI modules)
"""``gtrig evaluate poses``: compare poses with reference poses."""

from __future__ import annotations

import math
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import typer

from gtrig.cli.common import console, handle_errors, styled
from gtrig.io.survey_csv import PoseTable

if TYPE_CHECKING:
    from gtrig.evaluate.slam import SlamEvaluation

app = typer.Typer(help="Evaluate estimates against references.", no_args_is_help=True)


def _cols(s: str | None) -> tuple[str, ...] | None:
    return None if s is None else tuple(c.strip() for c in s.split(","))


def _pair_tum_by_stamp(reference: Path, estimate: Path, ref_t: PoseTable, est_t: PoseTable, max_dt: float
                       ) -> tuple[PoseTable, PoseTable]:
    """TUM poses are named by their stamps, never by their rows: a TUM input with non-integer stamps is paired
    with the other input's pose at the same stamp (the two nearest each other, within ``max_dt``; each pose
    in one pair at most), and both tables renamed by the reference's stamp."""
    from gtrig.errors import InputError
    from gtrig.evaluate.associate import mutual_nearest_indices
    from gtrig.io.survey_csv import looks_like_tum
    from gtrig.io.tum import read_tum

    tums = [looks_like_tum(p) for p in (reference, estimate)]
    stamps = [read_tum(p).stamps_s if t else None for p, t in zip((reference, estimate), tums, strict=True)]
    integral = [s is not None and bool(np.all(np.abs(s - np.round(s)) < 1e-9)) for s in stamps]
    if not any(tums) or all(t == i for t, i in zip(tums, integral, strict=True)):
        return ref_t, est_t  # names (or integer stamps used as pose numbers) on both sides
    if not all(tums):
        raise InputError("a TUM file with non-integer stamps cannot be paired with named poses: give two TUM files "
                         "(paired by stamp) or poses named alike")
    sr, se = stamps
    assert sr is not None and se is not None
    i_r, i_e = mutual_nearest_indices(sr, se, max_dt)
    if i_r.size == 0:
        raise InputError(f"no pair of TUM stamps within --max-dt {max_dt:g} s")
    names = tuple(f"{sr[i]:.6f}" for i in i_r)
    return (PoseTable(names + tuple(f"{sr[i]:.6f}" for i in np.setdiff1d(np.arange(sr.size), i_r)),
                      np.vstack([ref_t.xytheta[i_r], ref_t.xytheta[np.setdiff1d(np.arange(sr.size), i_r)]])),
            PoseTable(names, est_t.xytheta[i_e]))


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
    max_dt: float = typer.Option(0.01, "--max-dt", help="TUM inputs: largest stamp difference of a pair (s)."),
) -> None:
    """Per-pose errors (reference - estimate, angles wrapped) and per-axis statistics."""
    from gtrig.cli import checks
    from gtrig.errors import InputError
    from gtrig.evaluate import poses as ev
    from gtrig.io.survey_csv import read_pose_table

    if fmt not in ("table", "csv", "md"):
        raise InputError(f"--format must be table, csv or md, got {fmt!r}")
    checks.number("--max-dt", max_dt, lo=0.0, lo_open=True, hi=3600.0, unit="s")
    checks.outputs([reference, estimate], [plot])
    ref_t = read_pose_table(reference, _cols(reference_columns))
    est_t = read_pose_table(estimate, _cols(estimate_columns), method)
    ref_t, est_t = _pair_tum_by_stamp(reference, estimate, ref_t, est_t, max_dt)
    c = ev.compare_poses(ref_t, est_t)
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
            shown = ", ".join(c.missing[:20]) + (f", ... ({len(c.missing)} in all)" if len(c.missing) > 20 else "")
            console.print(f"not localized: {shown}", soft_wrap=True)
        if per_pose:
            t = Table("pose", "err x (m)", "err y (m)", "err theta (rad)", "err pos (m)")
            for n, e, p in zip(c.names, c.err_xytheta, c.err_pos_m, strict=True):
                t.add_row(n, f"{e[0]:.4f}", f"{e[1]:.4f}", f"{e[2]:.4f}", f"{p:.4f}")
            console.print(t)
    if plot is not None:
        from gtrig.evaluate.plots import plot_comparison

        plot_comparison(c, plot, reference.name, estimate.name + (f" ({method})" if method else ""))


def _formats_in(s: str | None) -> tuple[str | None, str | None]:
    if s is None:
        return None, None
    parts = [p.strip() or None for p in s.split(",")]
    return (parts[0], parts[0]) if len(parts) == 1 else (parts[0], parts[1])


def _interval(s: str | None) -> tuple[float, float] | None:
    from gtrig.errors import InputError

    if s is None:
        return None
    try:
        t0, t1 = (float(v) for v in s.split(","))
    except ValueError:
        raise InputError(f"--align-interval must be T0,T1 in seconds, got {s!r}") from None
    if not (math.isfinite(t0) and math.isfinite(t1) and t1 > t0):
        raise InputError(f"--align-interval {s!r}: T0 and T1 must be finite, T1 after T0")
    return t0, t1


def _offset(s: str) -> float | str:
    from gtrig.errors import InputError

    if s == "auto":
        return "auto"
    try:
        return float(s)
    except ValueError:
        raise InputError(f"--t-offset must be seconds or auto, got {s!r}") from None


@app.command("slam")
@handle_errors
def slam(
    gt: Path = typer.Option(..., "--gt", help="Ground truth: TUM (+ NAME_cov.csv), KITTI, EuRoC or RAWSEEDS CSV."),
    estimate: Path = typer.Option(..., "--estimate", help="Estimated trajectory, same formats."),
    relations: Path | None = typer.Option(None, "--relations", help="RAWSEEDS relations file (for its RPE)."),
    metrics: str = typer.Option("all", "--metrics", help="rawseeds, evo or all."),
    align: str = typer.Option("se3", "--align", help="none, se2, yaw, se3, sim3 (or sim2)."),
    align_interval: str | None = typer.Option(None, "--align-interval", help="T0,T1: fit the alignment there."),
    assoc: str = typer.Option("auto", "--associate", help="auto (the denser track interpolated at the other's "
                              "stamps), nearest (evo's default), interpolate (the estimate at the GT stamps) "
                              "or interpolate-gt (the GT at the estimate's stamps)."),
    max_dt: float | None = typer.Option(
        None, "--max-dt", help="nearest: largest stamp difference; interpolation: longest interval bridged "
        "(default: from the sample periods, see docs/evaluation.md)."
    ),
    t_offset: str = typer.Option("0", "--t-offset", help="Seconds added to the estimate's stamps, or auto."),
    rpe_delta: int = typer.Option(1, "--rpe-delta", help="evo RPE step in paired poses."),
    fmt: str = typer.Option("table", "--format", help="table, csv, md or json."),
    format_in: str | None = typer.Option(
        None, "--format-in", help="Input format(s) (tum, gtrig, kitti, euroc, rawseeds, csv): FMT or GT_FMT,EST_FMT."
    ),
    plot: Path | None = typer.Option(None, "--plot", help="Folder for the figures."),
) -> None:
    """Score a SLAM result against a GT: evo's APE/RPE, RAWSEEDS' ATE/RPE and the GT-aware scores."""
    from gtrig.cli import checks
    from gtrig.errors import InputError
    from gtrig.evaluate import tables
    from gtrig.evaluate.slam import evaluate_slam
    from gtrig.io.formats import read_trajectory
    from gtrig.io.relations import read_relations

    if fmt not in ("table", "csv", "md", "json"):
        raise InputError(f"--format must be table, csv, md or json, got {fmt!r}")
    checks.choice("--metrics", metrics, ("rawseeds", "evo", "all"))
    checks.choice("--align", align, ("none", "se2", "yaw", "se3", "sim3", "sim2"))
    from gtrig.evaluate.associate import METHODS

    checks.choice("--associate", assoc, METHODS)
    checks.number("--max-dt", max_dt, lo=0.0, lo_open=True, hi=3600.0, unit="s")
    checks.count("--rpe-delta", rpe_delta, lo=1, hi=10**6)
    if t_offset != "auto":
        checks.number("--t-offset", _offset(t_offset), lo=-1e6, hi=1e6, unit="s")  # type: ignore[arg-type]
    _interval(align_interval)
    if plot is not None:
        checks.output_folder("--plot", plot)
    f_gt, f_est = _formats_in(format_in)
    g = read_trajectory(gt, f_gt)
    e = read_trajectory(estimate, f_est)
    rel = read_relations(relations) if relations is not None else None
    ev = evaluate_slam(g, e, metrics=metrics, align=align, align_interval_s=_interval(align_interval),  # type: ignore[arg-type]
                       method=assoc, max_dt_s=max_dt, t_offset_s=_offset(t_offset), relations=rel,  # type: ignore[arg-type]
                       rpe_delta=rpe_delta)
    if fmt == "csv":
        typer.echo(tables.rows_csv(ev.rows()), nl=False)
    elif fmt == "json":
        typer.echo(tables.rows_json(ev), nl=False)
    elif fmt == "md":
        typer.echo(tables.rows_markdown(ev), nl=False)
    else:
        _print_tables(ev)
    for w in ev.warnings:
        from gtrig.cli.common import err_console

        err_console.print(styled("warning:", "yellow"), w, highlight=False)
    if plot is not None:
        from gtrig.evaluate.plots import plot_slam

        for p in plot_slam(ev, plot, gt.stem, estimate.stem):
            console.print(f"wrote {p}")


def _print_tables(ev: SlamEvaluation) -> None:
    from rich.table import Table

    from gtrig.evaluate import tables

    a = ev.association
    console.print(
        a.describe() + f"; {len(a.gaps_s)} gaps ({a.summary()['gap_time_s']:.2f} s); alignment {ev.alignment.kind}, "
        f"scale {ev.alignment.scale:.6f}"
        + (f"; {ev.n_gt_unusable} GT poses rejected or bridged, not scored" if ev.n_gt_unusable else ""),
        highlight=False, soft_wrap=True,
    )
    if ev.time_offset is not None:
        to = ev.time_offset
        console.print(f"time offset {to.offset_s:+.4f} s (95 % {to.low_s:+.4f} .. {to.high_s:+.4f})")
    m = tables.evo_matrix(ev)
    if m:
        t = Table("evo", "rmse", "mean", "median", "std", "min", "max", title="evo's APE / RPE")
        for r in m:
            t.add_row(*r)
        console.print(t)
    for fam, title in (("rawseeds", "RAWSEEDS toolkit (get_ATE.m / get_RPE.m)"),
                       ("gt-aware", "GT-aware (the GT's covariance in the scores)")):
        fam_rows = [r for r in ev.rows() if r.family == fam]
        if fam_rows:
            t = Table("metric", "statistic", "value", "unit", title=title)
            for row in fam_rows:
                t.add_row(row.metric, row.statistic, f"{row.value:.6g}", row.unit)
            console.print(t)
    if ev.gt_aware is not None:
        g = ev.gt_aware
        verdict = styled("as good as the GT can tell", "green") if g.indistinguishable else "distinguished from the GT"
        console.print(f"{100 * g.share_resolved:.1f} % of poses within the GT's 95 % region (a perfect estimate: "
                      f"95 %); RMSE against the truth {1000 * g.rmse_trans_m.value:.2f} mm "
                      f"(95 % {1000 * g.rmse_trans_m.low:.2f} .. {1000 * g.rmse_trans_m.high:.2f});", verdict)


@app.command("compare")
@handle_errors
def compare(
    a: Path = typer.Option(..., "--a", help="First GT source (TUM + NAME_cov.csv, RAWSEEDS CSV, ...)."),
    b: Path = typer.Option(..., "--b", help="Second GT source, interpolated at the first one's stamps."),
    align: str = typer.Option("none", "--align", help="none (one world frame), se2, yaw, se3, sim3."),
    max_gap: float = typer.Option(0.2, "--max-gap", help="Longest gap of b bridged by interpolation (s)."),
    t_offset: float = typer.Option(0.0, "--t-offset", help="Seconds added to b's stamps."),
    fmt: str = typer.Option("table", "--format", help="table, csv or md."),
    format_in: str | None = typer.Option(None, "--format-in", help="FMT or A_FMT,B_FMT."),
) -> None:
    """Two GT sources of one run side by side on their common span (differences and covariance consistency)."""
    from gtrig.cli import checks
    from gtrig.errors import InputError
    from gtrig.evaluate.compare import compare_sources
    from gtrig.io.formats import read_trajectory

    if fmt not in ("table", "csv", "md"):
        raise InputError(f"--format must be table, csv or md, got {fmt!r}")
    checks.choice("--align", align, ("none", "se2", "yaw", "se3", "sim3", "sim2"))
    checks.number("--max-gap", max_gap, lo=0.0, lo_open=True, hi=3600.0, unit="s")
    checks.number("--t-offset", t_offset, lo=-1e6, hi=1e6, unit="s")
    fa, fb = _formats_in(format_in)
    c = compare_sources(read_trajectory(a, fa), read_trajectory(b, fb), align, max_gap, t_offset)  # type: ignore[arg-type]
    rows = c.rows()
    if fmt == "csv":
        typer.echo("metric,statistic,value,unit")
        for r in rows:
            typer.echo(f"{r[0]},{r[1]},{r[2]:.9g},{r[3]}")
    elif fmt == "md":
        typer.echo(f"{b.name} against {a.name}, alignment {c.alignment.kind}\n")
        typer.echo("| metric | statistic | value | unit |\n|---|---|---|---|")
        for r in rows:
            typer.echo(f"| {r[0]} | {r[1]} | {r[2]:.6g} | {r[3]} |")
    else:
        from rich.table import Table

        t = Table("metric", "statistic", "value", "unit", title=f"{b.name} against {a.name} (alignment "
                  f"{c.alignment.kind})")
        for r in rows:
            t.add_row(r[0], r[1], f"{r[2]:.6g}", r[3])
        console.print(t)
