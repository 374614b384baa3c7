"""``gtrig calib intrinsics | network | recording | check | steady | video | compare-lenses``: camera calibration."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import typer

from gtrig.cli.common import console, err_console, handle_errors, styled

if TYPE_CHECKING:
    from gtrig.calib.idboards import IdBoard

app = typer.Typer(help="Camera calibration: intrinsics, the camera network, checks.", no_args_is_help=True)

BOARD_HELP = ("Chessboard as COLSxROWSxSQUARE (inner corners, square side in metres, e.g. 9x5x0.100), or a board "
              "file: Kalibr's checkerboard or aprilgrid target YAML, a ChArUco board (gtrig's or caliscope's).")


@app.command("intrinsics")
@handle_errors
def intrinsics(
    images: Path = typer.Option(
        ..., "--images", help="Folder of one camera's chessboard images (JPEG, PNG...)."
    ),
    board: str = typer.Option(..., "--board", help=BOARD_HELP),
    out: Path = typer.Option(..., "--out", help="cam.yaml to write."),
    k3: bool = typer.Option(False, "--k3", help="Also estimate the 6th-order radial term k3."),
    figure: Path = typer.Option(None, "--figure", help="Coverage figure (PNG); default: next to --out."),
) -> None:
    """Calibrate one camera from board images (chessboard, ChArUco, AprilGrid); write cam.yaml and a
    coverage figure."""
    from gtrig.calib.chessboard import Board, parse_board
    from gtrig.calib.intrinsics import calibrate_intrinsics
    from gtrig.calib.plots import plot_coverage
    from gtrig.calib.targets import read_target_file
    from gtrig.cli import checks
    from gtrig.io.camfile import write_cam_yaml

    b = read_target_file(board) if Path(board).suffix.lower() in (".yaml", ".yml", ".toml") else parse_board(board)
    checks.input_folder("--images", images)
    checks.outputs([], [out, figure])
    if not isinstance(b, Board):
        _id_board_intrinsics(images, b, out, figure, k3)
        return
    res = calibrate_intrinsics(images, b, estimate_k3=k3)
    write_cam_yaml(out, res.camera)
    fig = figure or out.with_name(out.stem + "_coverage.png")
    plot_coverage(
        [v.corners_px for v in res.views],
        res.camera.image_size,
        fig,
        res.per_image_rms_px,
        [v.file for v in res.views],
        title=f"{images.name}: coverage {100 * res.coverage:.0f} %",
    )
    K, d, std = res.camera.camera_matrix, res.camera.dist_coeffs, res.std
    console.print(styled(out, "bold"), f": {len(res.views)} views, RMS {res.camera.rms_px:.3f} px", sep="")
    console.print(
        f"  fx {K[0, 0]:.2f} ± {std.get('fx', 0):.2f}  fy {K[1, 1]:.2f} ± {std.get('fy', 0):.2f}  "
        f"cx {K[0, 2]:.2f} ± {std.get('cx', 0):.2f}  cy {K[1, 2]:.2f} ± {std.get('cy', 0):.2f} px"
    )
    console.print(
        f"  dist {', '.join(f'{v:.5f}' for v in d)}; coverage {100 * res.coverage:.0f} %; figure {fig}"
    )
    for w in res.warnings:
        err_console.print(styled("warning:", "yellow"), w)


def _id_board_intrinsics(images: Path, board: IdBoard, out: Path, figure: Path | None, k3: bool) -> None:
    """``gtrig calib intrinsics`` with a ChArUco board or an AprilGrid: partial views, corners by ID."""
    from gtrig.calib.id_sweep import calibrate_id_folder
    from gtrig.calib.plots import plot_coverage
    from gtrig.io.camfile import write_cam_yaml

    res = calibrate_id_folder(images, board, camera=images.name, estimate_k3=k3)
    write_cam_yaml(out, res.camera)
    fig = figure or out.with_name(out.stem + "_coverage.png")
    rms = dict(zip(res.fit.names, res.fit.per_view_rms_px.tolist(), strict=True))
    plot_coverage([v.corners for v in res.views], res.camera.image_size, fig, rms, list(res.fit.names),
                  title=f"{images.name}: {board.spec()}")
    K, std = res.camera.camera_matrix, res.fit.std
    console.print(styled(out, "bold"), f": {len(res.views)} views of the {board.spec()}, RMS "
                  f"{res.camera.rms_px:.3f} px", sep="")
    console.print(
        f"  fx {K[0, 0]:.2f} ± {std.get('fx', 0):.2f}  fy {K[1, 1]:.2f} ± {std.get('fy', 0):.2f}  "
        f"cx {K[0, 2]:.2f} ± {std.get('cx', 0):.2f}  cy {K[1, 2]:.2f} ± {std.get('cy', 0):.2f} px; figure {fig}"
    )
    for w in res.camera.extra.get("warnings", []):
        err_console.print(styled("warning:", "yellow"), w)


def _report_paths(out: Path) -> list[Path]:
    """The calibration report's files written beside the calibrated rig ``out``."""
    return [out.parent / "calibration_report.md", out.parent / "calibration_report.yaml"]


def _report(rig_cal: object, report: object, out: Path) -> None:
    """Write the calibrated rig ``out`` and its report beside it, all or none, and print the report."""
    from gtrig.calib.recording import CalibrationReport
    from gtrig.io.atomic import atomic_group
    from gtrig.rig.load import rig_text
    from gtrig.rig.models import Rig

    assert isinstance(report, CalibrationReport) and isinstance(rig_cal, Rig)
    report_texts = report.texts()
    texts = {out: rig_text(rig_cal), **{out.parent / n: t for n, t in report_texts.items()}}
    with atomic_group(*texts) as tmps:  # the rig and its report: all or none
        for tmp, text in zip(tmps, texts.values(), strict=True):
            tmp.write_text(text, encoding="utf-8")
    console.print(report_texts["calibration_report.md"], markup=False, highlight=False)
    console.print(f"wrote {out}, {out.parent / 'calibration_report.md'} and .yaml")


@app.command("network")
@handle_errors
def network(
    rig: Path = typer.Option(..., "--rig", help="The nominal rig.yaml (camera names, believed poses)."),
    pairs: Path = typer.Option(..., "--pairs", help="Folder of <camA>-<camB>/<camA|camB>/<n>.png."),
    world_board: Path = typer.Option(
        ..., "--world-board", help="Folder of <cam>/<n>.png of the world board."
    ),
    boards: Path = typer.Option(..., "--boards", help="boards.yaml: board, T_board1_board2, T_world_board."),
    intrinsics_dir: Path = typer.Option(
        None,
        "--intrinsics",
        help="Folder of <cam>.yaml, or of <cam>/ image sweeps to calibrate; default: the rig's intrinsics.",
    ),
    out: Path = typer.Option(..., "--out", help="Calibrated rig.yaml to write (report next to it)."),
) -> None:
    """Calibrate the camera network: pairs chained from the world board, then a joint bundle adjustment."""
    from gtrig.calib.chessboard import read_boards_yaml
    from gtrig.calib.network import NetworkProblem, calibrate_network
    from gtrig.calib.recording import (
        CalibrationReport,
        as_intrinsics,
        calibrated_rig,
        load_intrinsics,
        load_pair_views,
        load_world_views,
        sweep_views,
    )
    from gtrig.cli import checks
    from gtrig.errors import InputError
    from gtrig.io.camfile import CameraIntrinsics
    from gtrig.rig import load_rig

    for opt, folder in (("--pairs", pairs), ("--world-board", world_board)):
        checks.input_folder(opt, folder)
    checks.outputs([rig, boards], [out, *_report_paths(out)])
    r = load_rig(rig)
    spec = read_boards_yaml(boards)
    if spec.T_world_board is None:
        raise InputError(f"{boards}: T_world_board: missing field")
    names = [c.name for c in r.cameras]
    intr = load_intrinsics(intrinsics_dir, names, spec.board) if intrinsics_dir else {}
    for c in r.cameras:
        intr.setdefault(c.name, CameraIntrinsics(c.resolution, c.K, c.dist))
    cams = {n: as_intrinsics(x) for n, x in intr.items()}
    pv = load_pair_views(pairs, spec.board, names, {n: c.image_size for n, c in cams.items()})
    wv = load_world_views(world_board, spec.board, names, spec.T_world_board)
    prob = NetworkProblem(
        spec.board,
        spec.T_board1_board2,
        cams,
        {c.name: c.T_world_cam.matrix() for c in r.cameras},
        pv,
        wv,
        sweep_views(intr),  # image sweeps given: the bundle adjustment refines the lenses from them
    )
    net = calibrate_network(prob)
    _report(calibrated_rig(r, intr, net), CalibrationReport(intr, net), out)


@app.command("recording")
@handle_errors
def recording(
    rec: Path = typer.Argument(..., help="Recording folder (rig.yaml, calib/)."),
    out: Path = typer.Option(None, "--out", help="Calibrated rig to write; default REC/rig.calibrated.yaml."),
    k3: bool = typer.Option(False, "--k3", help="Also estimate k3."),
) -> None:
    """Calibrate every camera of a recording (intrinsics, then the network); compare with truth if present."""
    from gtrig.calib.recording import calibrate_recording
    from gtrig.cli import checks

    checks.input_folder("REC", rec)
    out = out or rec / "rig.calibrated.yaml"
    checks.outputs([rec / "rig.yaml"], [out, *_report_paths(out)])
    rig_cal, report = calibrate_recording(rec, estimate_k3=k3)
    _report(rig_cal, report, out)


@app.command("check")
@handle_errors
def check(
    rig: Path = typer.Option(..., "--rig", help="Calibrated rig.yaml."),
    images: Path = typer.Option(
        ..., "--images", help="Folder of <camera>/<image> of the board on the table."
    ),
    truth: Path = typer.Option(..., "--truth", help="CSV camera,image,x,y,z[,yaw_deg] of the board origin."),
    board: str = typer.Option("9x5x0.100", "--board", help=BOARD_HELP),
    tol_mm: float = typer.Option(10.0, "--tol-mm", help="Flag errors larger than this (mm)."),
) -> None:
    """Locate a board at surveyed poses with the calibrated rig and compare (the seeds' table check)."""
    import numpy as np
    from rich.table import Table

    from gtrig.calib.check import check_rig
    from gtrig.calib.chessboard import parse_board
    from gtrig.cli import checks
    from gtrig.rig import load_rig

    checks.number("--tol-mm", tol_mm, lo=0.0, lo_open=True, hi=10000.0, unit="mm")
    checks.input_folder("--images", images)
    rows = check_rig(load_rig(rig), images, truth, parse_board(board))
    t = Table(
        "camera", "image", "x, y, z est (m)", "dx, dy, dz (mm)", "|d| (mm)", "yaw err (deg)", "RMS (px)"
    )
    bad = 0
    for r in rows:
        n = float(np.linalg.norm(r.err_mm))
        bad += n > tol_mm
        t.add_row(
            r.camera,
            r.image,
            ", ".join(f"{v:.4f}" for v in r.xyz_est),
            ", ".join(f"{v:+.1f}" for v in r.err_mm),
            f"[{'red' if n > tol_mm else 'green'}]{n:.1f}",
            f"{r.yaw_err_deg:+.3f}",
            f"{r.reproj_px:.3f}",
        )
    console.print(t)
    e = np.array([r.err_mm for r in rows])
    console.print(
        f"{len(rows)} board(s): RMS error {np.sqrt(np.mean(np.sum(e**2, axis=1))):.1f} mm, max "
        f"{np.max(np.linalg.norm(e, axis=1)):.1f} mm; {bad} above {tol_mm:g} mm"
    )
    if bad:
        raise typer.Exit(1)


@app.command("steady")
@handle_errors
def steady(
    before: Path = typer.Option(..., "--before", help="Folder of <cam>/<n>.png taken before."),
    after: Path = typer.Option(..., "--after", help="Folder of <cam>/<n>.png taken after (same names)."),
    rig: Path = typer.Option(..., "--rig", help="Calibrated rig.yaml (intrinsics for re-localisation)."),
    board: str = typer.Option(
        "9x5x0.100", "--board", help=BOARD_HELP + " Use 'none' for image comparison only."
    ),
    shift_px: float = typer.Option(0.3, "--shift-px", help="Image shift threshold (px)."),
    move_mm: float = typer.Option(0.8, "--move-mm", help="Board displacement threshold (mm)."),
    turn_deg: float = typer.Option(0.02, "--turn-deg", help="Board rotation threshold (deg)."),
    figures: Path = typer.Option(None, "--figures", help="Folder for before/after overlay figures."),
) -> None:
    """Detect cameras that moved between two recordings (image comparison and board re-localisation)."""
    from rich.table import Table

    from gtrig.calib.chessboard import parse_board
    from gtrig.calib.steady import check_steady
    from gtrig.cli import checks
    from gtrig.rig import load_rig

    # a NaN threshold would call every camera steady: every threshold is a positive finite number
    checks.number("--shift-px", shift_px, lo=0.0, lo_open=True, hi=1000.0, unit="px")
    checks.number("--move-mm", move_mm, lo=0.0, lo_open=True, hi=10000.0, unit="mm")
    checks.number("--turn-deg", turn_deg, lo=0.0, lo_open=True, hi=180.0, unit="deg")
    for opt, folder in (("--before", before), ("--after", after)):
        checks.input_folder(opt, folder)
    if figures is not None:
        checks.output_folder("--figures", figures)
    r = load_rig(rig)
    b = None if board.lower() == "none" else parse_board(board)
    res = check_steady(
        before,
        after,
        {c.name: (c.K, c.dist) for c in r.cameras},
        b,
        shift_px=shift_px,
        move_mm=move_mm,
        turn_deg=turn_deg,
    )
    t = Table("camera", "image", "image shift (px)", "board moved (mm)", "board turned (deg)", "verdict")
    for s in res:
        t.add_row(
            s.camera,
            s.image,
            f"{s.shift_px:.3f}",
            "-" if s.board is None else f"{s.board.move_mm:.2f}",
            "-" if s.board is None else f"{s.board.turn_deg:.4f}",
            styled("MOVED", "red") if s.moved else styled("steady", "green"),
        )
        if figures is not None:
            from gtrig.calib.chessboard import read_grey
            from gtrig.calib.plots import plot_overlay

            stem = Path(s.image).stem
            plot_overlay(
                read_grey(next((before / s.camera).glob(stem + ".*"))),
                read_grey(next((after / s.camera).glob(stem + ".*"))),
                figures / f"steady_{s.camera}_{stem}.png",
                f"{s.camera}: shift {s.shift_px:.2f} px",
            )
    console.print(t)
    moved = sorted({s.camera for s in res if s.moved})
    console.print(f"moved: {', '.join(moved)}" if moved else "all cameras steady")
    if moved:
        raise typer.Exit(1)


def _given_lenses(path: Path | None) -> dict:
    """Lenses to hold: a caliscope config.toml / camera_array.toml, or a folder of <cam>.yaml."""
    if path is None:
        return {}
    from gtrig.errors import InputError
    from gtrig.io.caliscope import read_caliscope_cameras
    from gtrig.io.camfile import read_cam_yaml

    if path.is_dir():
        return {p.stem: read_cam_yaml(p) for p in sorted(path.glob("*.yaml")) if p.stem != "network"}
    if path.suffix.lower() == ".toml":
        return {n: c.intrinsics for n, c in read_caliscope_cameras(path).items()}
    raise InputError(f"--lenses {path}: expected a folder of <cam>.yaml or a caliscope .toml")


@app.command("video")
@handle_errors
def video(
    board: Path = typer.Option(
        ..., "--board", help="ChArUco board (gtrig's YAML/TOML, caliscope's charuco.toml) or AprilGrid "
        "(Kalibr's target YAML or gtrig's) file; a chessboard is refused."
    ),
    videos: Path = typer.Option(
        ..., "--videos", help="Folder of <cam>.mp4 with <cam>.timestamps.csv, or caliscope's timestamps.csv."
    ),
    out: Path = typer.Option(..., "--out", help="Folder to write <cam>.yaml and network.yaml into."),
    step: int = typer.Option(1, "--step", help="Read every n-th frame."),
    lenses: Path = typer.Option(
        None, "--lenses", help="Hold these lenses: a folder of <cam>.yaml or caliscope's camera_array.toml."
    ),
    reference: str = typer.Option(None, "--reference", help="The camera whose frame is the world."),
    k3: bool = typer.Option(False, "--k3", help="Also estimate the 6th-order radial term k3."),
    mirrored: list[str] = typer.Option(
        [], "--mirrored", help="A camera whose video is left-right mirrored (repeat for several)."
    ),
) -> None:
    """Calibrate fixed cameras from videos of a hand-held ChArUco board or AprilGrid: lenses, then relative poses."""
    from gtrig.calib.targets import read_id_board_file
    from gtrig.calib.video_calib import calibrate_from_videos, write_video_calibration
    from gtrig.cli import checks

    checks.input_folder("--videos", videos)
    checks.output_folder("--out", out)
    checks.not_inside("--out", out, videos, "the videos' folder")
    checks.count("--step", step, lo=1, hi=1000)
    b = read_id_board_file(board)
    given = _given_lenses(lenses)
    cal = calibrate_from_videos(videos, b, step=step, lenses=given, reference=reference, estimate_k3=k3,
                                mirrored=mirrored)
    write_video_calibration(out, cal)
    console.print(styled(out, "bold"), f": {b.spec()}; reference {cal.network.reference}", sep="")
    for c, lens in cal.lenses.items():
        v, det = cal.videos[c], cal.detections[c]
        src = f"lens RMS {lens.rms_px:.3f} px from {len(cal.fits[c].names)} views" if c in cal.fits else "lens held"
        console.print(f"  {c}: {v.timing.summary()}; board in {len(det.views)} of {det.n_frames_read} frames "
                      f"read; {src}; network RMS {cal.network.rms_px.get(c, float('nan')):.3f} px")
    console.print(f"  network: {cal.network.n_instants} instants, {cal.network.n_corners} corners, "
                  f"RMS {cal.network.rms_px_all:.3f} px")
    for p in cal.pairs:
        console.print(f"  {p.cam_a}-{p.cam_b}: baseline {1000 * p.baseline_m:.1f} ± "
                      f"{1000 * p.sigma_baseline_m:.1f} mm, angle {p.angle_deg:.2f} ± {p.sigma_angle_deg:.2f} deg")


@app.command("compare-lenses")
@handle_errors
def compare_lenses_cmd(
    a: Path = typer.Argument(..., help="First calibration: a folder of <cam>.yaml or caliscope's .toml."),
    b: Path = typer.Argument(..., help="Second calibration of the same cameras, the same forms."),
    limit: float = typer.Option(3.0, "--limit", help="Name the parameters differing by more combined sigmas."),
) -> None:
    """Compare two calibrations of the same cameras: fx, fy, cx, cy differences in combined sigmas."""
    from gtrig.calib.lens_compare import compare_lenses, differing
    from gtrig.cli import checks
    from gtrig.errors import InputError

    for name, p in (("A", a), ("B", b)):
        if not p.exists():
            raise InputError(f"{name} {p}: no such folder or file")
    checks.number("--limit", limit, lo=0, lo_open=True)
    la, lb = _given_lenses(a), _given_lenses(b)
    diffs = compare_lenses(la, lb)
    if not diffs:
        raise InputError(f"{a} and {b}: no camera in both")
    for d in diffs:
        console.print(f"  {d.camera} {d.parameter}: {d.value_a_px:.1f} ± {d.sigma_a_px:.1f} against "
                      f"{d.value_b_px:.1f} ± {d.sigma_b_px:.1f} px: {d.z:.2f} combined sigma")
    bad = differing(diffs, limit)
    for d in bad:
        console.print(styled(f"{d.camera} {d.parameter} differs by {d.z:.1f} combined sigma "
                             f"({d.value_a_px - d.value_b_px:+.1f} px)", "bold"))
    if not bad:
        worst = max((d for d in diffs if d.z == d.z), key=lambda d: d.z, default=None)
        tail = f" (largest {worst.camera} {worst.parameter}, {worst.z:.2f})" if worst else " (no sigmas stated)"
        console.print(f"every lens parameter within {limit:g} combined sigma{tail}")
