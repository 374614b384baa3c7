"""``gtrig scanmatch pairs / validate / map / mounting``: onboard scan matching (docs/scanmatch.md)."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Annotated

import numpy as np
import typer

from gtrig.cli.common import console, handle_errors
from gtrig.cli.scale import chunk_bar, dask_option, executor

if TYPE_CHECKING:
    from gtrig.io.scans import ScanLog
    from gtrig.rig.models import Rig
    from gtrig.scanmatch.validate import StopValidation

app = typer.Typer(help="Onboard scan matching: relations, validation stops, map validation, mountings.",
                  no_args_is_help=True)


def _rig(rig: Path | None, recording: Path) -> Rig:
    from gtrig.rig import load_rig

    return load_rig(rig if rig is not None else recording / "rig.yaml")


def _logs(rig: Rig, recording: Path, sequence: str) -> dict[str, ScanLog]:
    from gtrig.errors import FormatError, InputError
    from gtrig.io.scans import read_scans

    if not rig.robot.onboard_scanners:
        raise InputError(f"{recording}: the rig describes no onboard scanner (robot.onboard_scanners)")
    logs = {}
    for sc in rig.robot.onboard_scanners:
        p = recording / sequence / "onboard" / f"{sc.name}.csv"
        lg = read_scans(p, sc)
        if not len(lg):
            raise FormatError(f"{p}: no scans")
        empty = np.flatnonzero(~np.any(np.isfinite(lg.ranges_m), axis=1))
        if empty.size:
            raise FormatError(f"{p}: scan {int(empty[0]) + 1} (stamp {lg.stamps_s[empty[0]]:.6f}) has no valid range")
        logs[sc.name] = lg
    return logs


@app.command("pairs")
@handle_errors
def pairs(
    recording: Annotated[Path, typer.Option("--recording", help="recording folder")],
    out: Annotated[Path, typer.Option("--out", help="relations.csv to write (and .relations beside it)")],
    guess: Annotated[str, typer.Option("--guess", help="'odometry' (SEQUENCE/odometry.csv) or a TUM trajectory")
                     ] = "odometry",
    sequence: Annotated[str, typer.Option("--sequence", help="run or validation")] = "run",
    rig: Annotated[Path | None, typer.Option("--rig", help="rig.yaml (default: the recording's)")] = None,
    max_dist: Annotated[float, typer.Option("--max-dist", help="pair search radius, m")] = 1.0,
    max_angle: Annotated[float, typer.Option("--max-angle", help="largest heading difference, deg")] = 30.0,
    every: Annotated[int, typer.Option("--every", help="use every N-th scan")] = 5,
    max_pairs: Annotated[int, typer.Option("--max-pairs", help="at most this many pairs (evenly thinned)")] = 2000,
    review: Annotated[Path | None, typer.Option("--review", help="HTML page with an overlay of every match")] = None,
    workers: Annotated[int, typer.Option("--workers", min=0, help="Processes (0: one per core).")] = 0,
    dask: Annotated[str | None, dask_option(annotated=True)] = None,
) -> None:
    """Candidate scan pairs near the guessed trajectory, matched and judged by the acceptance test."""
    from gtrig.cli import checks
    from gtrig.errors import InputError
    from gtrig.io.odometry import read_odometry
    from gtrig.io.scanmatch import write_relations
    from gtrig.io.tum import read_tum
    from gtrig.scanmatch import se2
    from gtrig.scanmatch.pairs import Guess, candidate_pairs, match_pairs, sequence_scans
    from gtrig.scanmatch.validate import ErrorModel, scanner_height_m, scanner_pose_xyth

    if sequence not in ("run", "validation"):
        raise InputError(f"--sequence must be run or validation, got {sequence!r}")
    checks.count("--every", every, lo=1, hi=10**6)
    checks.count("--max-pairs", max_pairs, lo=1, hi=10**7)
    checks.number("--max-dist", max_dist, lo=0.0, lo_open=True, hi=100.0, unit="m")
    checks.number("--max-angle", max_angle, lo=0.0, lo_open=True, hi=180.0, unit="deg")
    checks.input_folder("--recording", recording)
    checks.outputs([rig, None if guess == "odometry" else Path(guess)], [out, out.with_suffix(".relations"), review])
    r = _rig(rig, recording)
    logs = _logs(r, recording, sequence)
    if guess == "odometry":
        od = read_odometry(recording / sequence / "odometry.csv")
        g = Guess(od.stamps_s, od.xytheta)
    else:
        tr = read_tum(guess)
        T = tr.matrices()
        g = Guess(tr.stamps_s, se2.from_matrix(T))
    sc = r.robot.onboard_scanners
    model = ErrorModel()
    scans = sequence_scans(sc, logs, g, {s.name: scanner_pose_xyth(s) for s in sc}, model.range_sigma_m, every)
    poses = g.at(np.array([s.stamp_s for s in scans]))
    pr = candidate_pairs(poses, max_dist, np.radians(max_angle), min_index_gap=1)
    if len(pr) > max_pairs:
        pr = pr[np.linspace(0, len(pr) - 1, max_pairs).astype(int)]
    with executor(dask) as ex, chunk_bar("scan pairs") as bar:
        rels = match_pairs(scans, poses, pr, tilt_shift_m=scanner_height_m(r) * model.floor_tilt_sigma_rad,
                           executor=ex, workers=workers, progress=bar.progress)
    raw = out.with_suffix(".relations")
    write_relations(rels, out, raw)
    n_acc = sum(1 for x in rels if x.verdict.accepted)
    console.print(f"{len(scans)} scans, {len(rels)} candidate pairs, {n_acc} accepted "
                  f"({100.0 * n_acc / max(1, len(rels)):.1f} %); wrote {out} and {raw}")
    if review is not None:
        from gtrig.scanmatch.review import write_review

        items = []
        for (i, j), x in zip(pr, rels, strict=True):
            v = x.verdict
            items.append((f"{x.t1:.3f} -> {x.t2:.3f}", scans[i], scans[j], x.pose, v.accepted,
                          f"explained {v.explained:.2f}, share {v.inlier_share:.2f}, s {v.s_ratio:.2f}; {v.reason}"))
        write_review(review, items, f"scan pairs of {recording}")
        console.print(f"wrote {review}")


@app.command("validate")
@handle_errors
def validate(
    recording: Annotated[Path, typer.Option("--recording", help="recording folder (validation/onboard)")],
    out: Annotated[Path, typer.Option("--out", help="poses.csv to write (and POSES.tum, POSES_cov.csv)")],
    rig: Annotated[Path | None, typer.Option("--rig", help="rig.yaml (default: the recording's)")] = None,
    reference: Annotated[int, typer.Option("--reference", help="the reference stop's number")] = 1,
    survey: Annotated[Path | None, typer.Option("--survey", help="survey poses (pose,x,y,theta,...): guesses "
                                                "and comparison")] = None,
) -> None:
    """Every validation stop's pose relative to a reference stop, from both onboard scanners merged."""
    from gtrig.cli import checks
    from gtrig.errors import InputError
    from gtrig.io.atomic import atomic_group
    from gtrig.io.posetrack import covariance_text
    from gtrig.io.scanmatch import read_planar_poses, stop_poses_text
    from gtrig.io.tum import tum_text
    from gtrig.scanmatch.validate import validate_recording

    checks.count("--reference", reference, lo=1)
    checks.input_folder("--recording", recording)
    checks.outputs([rig, survey], [out, out.with_suffix(".tum"), out.with_name(out.stem + "_cov.csv")])
    r = _rig(rig, recording)
    sv = None
    if survey is not None:
        _ids, sv, _cov = read_planar_poses(survey)
    try:
        res = validate_recording(recording, r, reference, sv)
    except InputError:
        raise
    rows = res.rows()
    tum = out.with_suffix(".tum")
    cov = out.with_name(out.stem + "_cov.csv")
    with atomic_group(out, tum, cov) as (a, b, c):
        a.write_text(stop_poses_text(rows), encoding="utf-8")
        b.write_text(tum_text(res.track), encoding="utf-8")
        c.write_text(covariance_text(res.track), encoding="utf-8")
    for line in validation_lines(res):
        console.print(line, highlight=False)
    console.print(f"wrote {out}, {tum}, {cov}")


def validation_lines(res: StopValidation) -> list[str]:
    """The per-stop rows as aligned text (also what ``gtrig demo`` prints)."""
    out = ["stop  x (m)      y (m)      theta (deg)  sd xy (mm)  sd th (deg)  verdict"
           + ("   vs survey (mm, deg)" if res.survey_rel is not None else "")]
    for row in res.rows():
        s = (f"{row['pose']:>4}  {row['x']:+.4f}   {row['y']:+.4f}   {np.degrees(row['theta']):+9.3f}   "
             f"{1000 * max(row['sd_x'], row['sd_y']):8.2f}   {np.degrees(row['sd_theta']):9.4f}   {row['verdict']}")
        if "diff_xy_m" in row:
            s += f"   {1000 * row['diff_xy_m']:.2f}, {np.degrees(row['diff_theta_rad']):+.3f}"
        out.append(s)
    acc = sum(1 for r in res.rows() if r["verdict"] == "accepted")
    out.append(f"{acc} of {len(res.matches)} stops matched without a manual step (the seeds: about 50 %)")
    return out


@app.command("map")
@handle_errors
def map_(
    map_file: Annotated[Path, typer.Option("--map", help="MAP.yaml (ROS map_server)")],
    recording: Annotated[Path, typer.Option("--recording", help="recording folder (validation/onboard)")],
    initial: Annotated[Path, typer.Option("--initial", help="INIT.csv: pose,x,y,theta rough poses in the map")],
    out: Annotated[Path, typer.Option("--out", help="poses.csv to write (and POSES_map_errors.csv)")],
    rig: Annotated[Path | None, typer.Option("--rig", help="rig.yaml (default: the recording's)")] = None,
) -> None:
    """Validation stops' onboard scans aligned on a map; the map's surfaces that disagree are named."""
    from gtrig.cli import checks
    from gtrig.errors import InputError
    from gtrig.io.atomic import atomic_group
    from gtrig.io.rosmap import read_map
    from gtrig.io.scanmatch import read_planar_poses, stop_poses_text
    from gtrig.scanmatch.mapmatch import map_points, match_to_map
    from gtrig.scanmatch.validate import ErrorModel, load_stop_scans, scanner_height_m

    checks.input_folder("--recording", recording)
    checks.outputs([map_file, initial, rig], [out, out.with_name(out.stem + "_map_errors.csv")])
    m = read_map(map_file)
    r = _rig(rig, recording)
    ids, init, _ = read_planar_poses(initial)
    stops = load_stop_scans(recording, r)
    index = {int(p): k for k, p in enumerate(stops.pose_ids)}
    missing = [int(i) for i in ids if int(i) not in index]
    if missing:
        raise InputError(f"{initial}: pose {missing[0]} is not a validation stop of {recording}")
    scans = [stops.merged[index[int(i)]] for i in ids]
    mp = map_points(m)
    res = match_to_map(mp, scans, init, tilt_shift_m=scanner_height_m(r) * ErrorModel().floor_tilt_sigma_rad)
    rows: list[dict[str, object]] = []
    for i, p, c, v in zip(ids, res.poses, res.covs, res.verdicts, strict=True):
        sd = np.sqrt(np.diag(c))
        rows.append({"pose": int(i), "x": p[0], "y": p[1], "theta": p[2], "sd_x": sd[0], "sd_y": sd[1],
                     "sd_theta": sd[2], "verdict": "accepted" if v.accepted else "rejected", "reason": v.reason})
    frows: list[dict[str, object]] = [
        {"surface": f.name(), "offset_m": f.offset_m, "se_m": f.se_m, "scans": f.n_scans, "points": f.n_points,
         "map_error": "yes" if f.flagged else "no"} for f in res.features]
    ferr = out.with_name(out.stem + "_map_errors.csv")
    with atomic_group(out, ferr) as (a, b):
        a.write_text(stop_poses_text(rows), encoding="utf-8")
        b.write_text(stop_poses_text(frows), encoding="utf-8")
    acc = sum(1 for v in res.verdicts if v.accepted)
    console.print(f"{acc} of {len(rows)} stops aligned on {map_file}")
    for f in res.flagged:
        console.print(f"map error: {f.name()} is off by {1000 * f.offset_m:+.1f} mm (+- {1000 * f.se_m:.1f}, "
                      f"{f.n_scans} scans); excluded from the poses", highlight=False)
    if not res.flagged:
        console.print("no map surface disagrees with the scans")
    console.print(f"wrote {out} and {ferr}")


@app.command("mounting")
@handle_errors
def mounting(
    recording: Annotated[Path, typer.Option("--recording", help="recording folder (validation/onboard)")],
    survey: Annotated[Path, typer.Option("--survey", help="survey poses (pose,x,y,theta and covariance)")],
    out: Annotated[Path, typer.Option("--out", help="rig.yaml to write with the estimated mountings")],
    rig: Annotated[Path | None, typer.Option("--rig", help="rig.yaml (default: the recording's)")] = None,
) -> None:
    """The onboard scanners' mountings from matched validation stops against the survey (planar hand-eye)."""
    from gtrig.cli import checks
    from gtrig.errors import InputError
    from gtrig.geometry import rpy_from_T
    from gtrig.io.scanmatch import read_planar_poses
    from gtrig.rig.load import dump_rig
    from gtrig.rig.models import Pose
    from gtrig.scanmatch.mounting import calibrate_mounting
    from gtrig.scanmatch.validate import ErrorModel, load_stop_scans, scanner_height_m, scanner_pose_xyth

    checks.input_folder("--recording", recording)
    checks.outputs([rig, survey, recording / "rig.yaml"], [out])
    r = _rig(rig, recording)
    ids, sv, cov = read_planar_poses(survey)
    stops = load_stop_scans(recording, r)
    if list(ids) != [int(i) for i in stops.pose_ids]:
        raise InputError(f"{survey}: its poses {list(ids)[:3]}... are not the recording's stops")
    if cov is None:
        cov = np.tile(np.diag([0.001**2, 0.001**2, np.radians(0.05) ** 2]), (len(ids), 1, 1))
    model = ErrorModel()
    tilt = scanner_height_m(r) * model.floor_tilt_sigma_rad
    new_sc = []
    for sc in r.robot.onboard_scanners:
        res, n_try, n_acc = calibrate_mounting(stops.per_scanner[sc.name], sv, cov, scanner_pose_xyth(sc),
                                               model.range_sigma_m, tilt)
        sd = np.sqrt(np.diag(res.cov))
        x, y, th = res.mounting
        console.print(f"{sc.name}: x {x:+.4f} m, y {y:+.4f} m, yaw {np.degrees(th):+.3f} deg "
                      f"(sd {1000 * sd[0]:.2f} mm, {1000 * sd[1]:.2f} mm, {np.degrees(sd[2]):.3f} deg; "
                      f"{n_acc} of {n_try} stop pairs; chi2/dof {res.chi2_dof:.2f})", highlight=False)
        T = sc.T_robot_scanner.matrix()
        roll, pitch = (float(v) for v in np.degrees(rpy_from_T(T))[:2])
        new_sc.append(sc.model_copy(update={"T_robot_scanner": Pose(
            xyz=(float(x), float(y), float(T[2, 3])), rpy_deg=(roll, pitch, float(np.degrees(th))))}))
    robot = r.robot.model_copy(update={"onboard_scanners": tuple(new_sc)})
    dump_rig(r.model_copy(update={"robot": robot}), out)
    console.print(f"wrote {out}")
