"""``gtrig markers make | detect | calibrate-robot``."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from gtrig.cli.common import console, handle_errors
from gtrig.rig.models import MarkerFamily

app = typer.Typer(help="Square ID markers: printable sheets, high-accuracy detection, calibration on the robot.",
                  no_args_is_help=True)


@app.command("make")
@handle_errors
def make(
    out: Annotated[Path, typer.Option("--out", help="Output file: .pdf (one page per sheet), or .svg / .png "
                                      "(one sheet).")],
    family: Annotated[MarkerFamily | None, typer.Option("--family", help="Marker family (with --id).")] = None,
    marker_ids: Annotated[str | None, typer.Option(
        "--id", help="Marker IDs: 14, 3,6,14 or 0-11 (with --family and --size-mm).")] = None,
    size_mm: Annotated[float | None, typer.Option(
        "--size-mm", help="Black square side (border included), mm (with --id).")] = None,
    rig: Annotated[Path | None, typer.Option(
        "--rig", help="rig.yaml: print every marker of robot.markers (family and side from the rig).")] = None,
    boards: Annotated[Path | None, typer.Option(
        "--boards", help="calib/boards.yaml: print the double board's two boards and the world board.")] = None,
    board: Annotated[str | None, typer.Option(
        "--board", help="One chessboard COLSxROWSxSQUARE (inner corners, metres), e.g. 9x5x0.03.")] = None,
    paper: Annotated[str, typer.Option(
        "--paper", help="a4, letter, a3 or WIDTHxHEIGHT in mm; portrait or landscape is chosen to fit.")] = "a4",
    dpi: Annotated[float, typer.Option("--dpi", help="Minimum resolution of a PNG (dots per inch).")] = 600.0,
) -> None:
    """Lay markers and chessboards out on printable sheets at exact size, each with a 100 mm scale ruler.

    Several markers share a sheet when they fit; each has a white quiet zone, cut marks and its family,
    ID and side printed outside the quiet zone. Print at 100 % (no fit-to-page) and check the ruler.
    """
    from gtrig.cli import checks
    from gtrig.errors import InputError
    from gtrig.markers.sheetfiles import write_sheets
    from gtrig.markers.sheets import lay_out, marker_tile, parse_paper
    from gtrig.markers.sheetsources import board_tile, boards_tiles, parse_ids, rig_marker_tiles

    the_paper = parse_paper(paper)
    checks.outputs([rig, boards], [out])
    tiles = []
    if marker_ids is not None or family is not None or size_mm is not None:
        if marker_ids is None or family is None or size_mm is None:
            raise InputError("--family, --id and --size-mm go together (or print a rig's markers with --rig)")
        checks.number("--size-mm", size_mm, lo=5.0, hi=2000.0, unit="mm", lo_hint="metres given for millimetres")
        tiles += [marker_tile(family, i, size_mm) for i in parse_ids(marker_ids, family)]
    if rig is not None:
        from gtrig.rig import load_rig

        tiles += rig_marker_tiles(load_rig(rig), str(rig))
    if boards is not None:
        from gtrig.calib.chessboard import read_boards_yaml

        tiles += boards_tiles(read_boards_yaml(boards))
    if board is not None:
        from gtrig.calib.chessboard import parse_board

        tiles.append(board_tile(parse_board(board), "chessboard"))
    if not tiles:
        raise InputError("nothing to print: give --family, --id and --size-mm, --rig, --boards or --board")
    pages = lay_out(tiles, the_paper)
    write_sheets(pages, out, dpi)
    for i, page in enumerate(pages, start=1):
        w, h = page.size_mm
        console.print(f"{out}: sheet {i} of {len(pages)}, {page.paper.name} {page.orientation} "
                      f"({w:g} x {h:g} mm): {'; '.join(page.contents)}", highlight=False)
    console.print("print at 100 % (no fit-to-page) and check that each sheet's ruler measures 100 mm",
                  highlight=False)


_IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff", ".pgm", ".ppm")


def _image_files(inputs: list[Path]) -> list[Path]:
    from gtrig.errors import InputError

    files: list[Path] = []
    for p in inputs:
        if p.is_dir():
            found = sorted(f for f in p.iterdir() if f.suffix.lower() in _IMAGE_SUFFIXES)
            if not found:
                raise InputError(f"{p}: no images ({', '.join(_IMAGE_SUFFIXES)}) in this folder")
            files.extend(found)
        elif p.is_file():
            files.append(p)
        else:
            raise InputError(f"{p}: no such file or folder")
    return files


@app.command("detect")
@handle_errors
def detect(
    inputs: Annotated[list[Path], typer.Argument(help="Images or folders of images.")],
    family: Annotated[MarkerFamily, typer.Option("--family", help="Marker family: ArUco, AprilTag or "
                                                 "ARToolKitPlus (docs/markers.md lists them).")],
    out: Annotated[Path, typer.Option("--out", help="Output JSON (det.json).")],
    camera: Annotated[Path | None, typer.Option("--camera", help="cam.yaml: fit edges undistorted.")] = None,
    debug: Annotated[Path | None, typer.Option(
        "--debug", help="Folder for one PNG per image: the detections and every rejected candidate with the "
        "stage and reason it was dropped.")] = None,
    tone: Annotated[str, typer.Option(
        "--tone", help="How the images store light: auto (as each file declares: JPEG and PNGs with an sRGB "
        "chunk sRGB, others linear), linear (machine-vision cameras) or srgb (phones, webcams).")] = "auto",
) -> None:
    """Detect markers with sub-pixel corners and their covariances; write det.json."""
    import dataclasses
    import json
    from typing import cast

    import cv2

    from gtrig.cli import checks
    from gtrig.cli.common import track
    from gtrig.errors import FormatError, InputError
    from gtrig.io.atomic import atomic_write_text
    from gtrig.io.frames import check_image_size
    from gtrig.io.imagetone import DeclaredTone, declared_tone
    from gtrig.markers.detect import DetectorParams, MarkerDetector

    if tone not in ("auto", "linear", "srgb"):
        raise InputError(f"--tone {tone!r}: choose auto, linear or srgb")
    files = _image_files(inputs)
    checks.outputs([*files, camera], [out])
    if debug is not None:
        checks.output_folder("--debug", debug)

    K = dist = None
    size = None
    if camera is not None:
        from gtrig.io.camfile import read_cam_yaml

        cam = read_cam_yaml(camera)
        K, dist, size = cam.camera_matrix, cam.dist_coeffs, cam.image_size
    base = DetectorParams()
    detectors: dict[DeclaredTone, MarkerDetector] = {}  # one per tone: the undistortion maps are set up once
    images = []
    debug_files: list[tuple[Path, bytes]] = []
    n_det = 0
    for f in track(files, "detecting", total=len(files)):
        img = cv2.imread(str(f), cv2.IMREAD_GRAYSCALE | cv2.IMREAD_ANYDEPTH)  # 16-bit kept: to_gray scales it
        if img is None:
            raise FormatError(f"{f}: not a readable image")
        check_image_size(img, f)
        if size is not None and (img.shape[1], img.shape[0]) != tuple(size):
            raise InputError(f"{f}: {img.shape[1]} x {img.shape[0]} px but {camera} is for "
                             f"{size[0]} x {size[1]}")
        trace: list | None = [] if debug is not None else None
        t: DeclaredTone = declared_tone(f) if tone == "auto" else cast(DeclaredTone, tone)  # checked above
        if t not in detectors:
            detectors[t] = MarkerDetector(family, K, dist, dataclasses.replace(base, tone=t))
        dets = detectors[t].detect(img, trace)
        if debug is not None:
            from gtrig.markers.detect import to_gray
            from gtrig.markers.detect.debug import debug_image

            ok, buf = cv2.imencode(".png", debug_image(to_gray(img), dets, trace or []))
            if ok:
                debug_files.append((debug / f"{f.stem}.debug.png", buf.tobytes()))
        n_det += len(dets)
        images.append({"file": str(f), "tone": t, "detections": [d.to_json() for d in dets]})
    doc = {"family": family.value, "camera": None if camera is None else str(camera), "images": images}
    atomic_write_text(out, json.dumps(doc, indent=1) + "\n")
    if debug is not None:
        from gtrig.io.atomic import atomic_open

        for path, data in debug_files:
            with atomic_open(path, "wb") as fh:
                fh.write(data)
        console.print(f"{debug}: {len(debug_files)} debug picture(s)", highlight=False)
    console.print(f"{out}: {n_det} detection(s) in {len(files)} image(s)", highlight=False)


def _parse_sides(items: list[str], family: MarkerFamily) -> list:
    """``--side-mm ID=MM[,ID=MM...]`` (repeatable) as calibration targets."""
    from gtrig.cli import checks
    from gtrig.errors import InputError
    from gtrig.markers.robotcal import MarkerSpec

    specs = {}
    for item in items:
        for tok in item.split(","):
            tok = tok.strip()
            if not tok:
                continue
            try:
                mid, mm = tok.split("=")
                side_mm = float(mm)
                checks.number(f"--side-mm {tok!r}", side_mm, lo=5.0, hi=2000.0, unit="mm",
                              lo_hint="metres given for millimetres")
                specs[int(mid)] = MarkerSpec(int(mid), side_mm / 1000.0, family)
            except ValueError:
                raise InputError(f"--side-mm {tok!r}: expected ID=MM, e.g. 14=160") from None
    return list(specs.values())


@app.command("calibrate-robot")
@handle_errors
def calibrate_robot(
    images: Annotated[Path, typer.Option("--images", help="Folder of hand-held images of the standing robot.")],
    camera: Annotated[Path, typer.Option("--camera", help="cam.yaml of the hand-held camera.")],
    out: Annotated[Path, typer.Option("--out", help="Output markers.yaml (poses and 6 x 6 covariances).")],
    anchor: Annotated[int, typer.Option("--anchor", help="ID of the marker whose pose on the robot is measured.")]
    = 14,
    anchor_pose: Annotated[str | None, typer.Option(
        "--anchor-pose", help="Its measured T_robot_marker: 'x,y,z,roll,pitch,yaw' (m, deg; R = Rz Ry Rx) or a "
        "YAML file with xyz and quat_xyzw or rpy_deg. Default: the pose in --rig.")] = None,
    rig: Annotated[Path | None, typer.Option(
        "--rig", help="rig.yaml: the markers to calibrate (family, ID, side) and the default anchor pose.")] = None,
    rig_out: Annotated[Path | None, typer.Option(
        "--rig-out", help="Write --rig with the calibrated marker poses to this file.")] = None,
    side_mm: Annotated[list[str] | None, typer.Option(
        "--side-mm", help="Without --rig: the markers to calibrate, ID=MM[,ID=MM...] (black-square side).")] = None,
    family: Annotated[MarkerFamily, typer.Option("--family", help="Without --rig: the markers' family.")]
    = MarkerFamily.ARTOOLKITPLUS_SIMPLE,
    anchor_sigma_mm: Annotated[float, typer.Option(
        "--anchor-sigma-mm", help="One-sigma error of the anchor's measured position, per axis, mm.")] = 0.0,
    anchor_sigma_deg: Annotated[float, typer.Option(
        "--anchor-sigma-deg", help="One-sigma error of the anchor's measured orientation, per axis, deg.")] = 0.0,
) -> None:
    """Calibrate the markers' poses on the robot from hand-held images, anchored on one measured marker."""
    import math

    import numpy as np

    from gtrig.cli import checks
    from gtrig.errors import InputError
    from gtrig.io.camfile import read_cam_yaml
    from gtrig.markers import robotcal as rc
    from gtrig.rig import dump_rig, load_rig

    if rig_out is not None and rig is None:
        raise InputError("--rig-out needs --rig (the rig to update)")
    checks.number("--anchor-sigma-mm", anchor_sigma_mm, lo=0.0, hi=100.0, unit="mm")
    checks.number("--anchor-sigma-deg", anchor_sigma_deg, lo=0.0, hi=45.0, unit="deg")
    checks.input_folder("--images", images)
    checks.outputs([camera, rig], [out, rig_out])
    the_rig = load_rig(rig) if rig is not None else None
    if the_rig is not None:
        if side_mm:
            raise InputError("give either --rig or --side-mm, not both (the rig has the markers' sides)")
        specs = rc.specs_from_rig(the_rig)
    elif side_mm:
        specs = _parse_sides(side_mm, family)
    else:
        raise InputError("which markers? give --rig rig.yaml or --side-mm ID=MM,...")
    if anchor_pose is not None:
        T_anchor = rc.parse_anchor_pose(anchor_pose)
    elif the_rig is not None:
        try:
            T_anchor = the_rig.marker(anchor).T_robot_marker.matrix()
        except KeyError:
            raise InputError(f"{rig}: marker {anchor} (the anchor) is not in robot.markers") from None
    else:
        raise InputError("--anchor-pose is needed without --rig")
    cam = read_cam_yaml(camera)
    cov = None
    if anchor_sigma_mm > 0 or anchor_sigma_deg > 0:
        cov = np.diag([(anchor_sigma_mm / 1000) ** 2] * 3 + [math.radians(anchor_sigma_deg) ** 2] * 3)
    cal = rc.calibrate_robot_markers(images, cam, specs, anchor, T_anchor, cov)
    from gtrig.io.atomic import atomic_group

    # both or neither: the markers file and the rig carry one calibration
    with atomic_group(*([out] if rig_out is None else [out, rig_out])) as tmps:
        rc.write_markers_yaml(tmps[0], cal, specs)
        if the_rig is not None and rig_out is not None:
            dump_rig(rc.apply_to_rig(the_rig, cal), tmps[1])
    _print_calibration(cal)
    console.print(f"{out}: {len(cal.T_robot_marker)} marker(s), anchor {anchor}"
                  + (f"; {rig_out}: rig with the calibrated markers" if rig_out is not None else ""),
                  highlight=False)


def _print_calibration(cal) -> None:  # noqa: ANN001 (RobotCalibration, imported lazily)
    import math

    from gtrig import geometry as geo

    console.print(f"markers on the robot, anchor {cal.anchor}: {cal.images_used} of {cal.images_total} images "
                  f"used, corner RMS {cal.rms_px:.3f} px", highlight=False)
    console.print(f"{'id':>5} {'x mm':>9} {'y mm':>9} {'z mm':>9} {'roll':>8} {'pitch':>8} {'yaw':>8} "
                  f"{'sd mm':>7} {'sd deg':>7} {'views':>5}  path", highlight=False)
    for mid, T in cal.T_robot_marker.items():
        rpy = [math.degrees(a) for a in geo.rpy_from_T(T)]
        s_m, s_r = cal.sigma(mid)
        path = "anchor" if mid == cal.anchor else " > ".join(str(x) for x in cal.paths.get(mid, ()))
        x, y, z = (1000 * v for v in T[:3, 3])
        console.print(f"{mid:>5} {x:9.2f} {y:9.2f} {z:9.2f} {rpy[0]:8.3f} {rpy[1]:8.3f} {rpy[2]:8.3f} "
                      f"{1000 * s_m:7.3f} {math.degrees(s_r):7.4f} {cal.n_views.get(mid, 0):5d}  {path}",
                      highlight=False)
    for im, why in cal.rejected_images.items():
        console.print(f"rejected image {im}: {why}", highlight=False)
    for (im, mid), why in cal.rejected_views.items():
        console.print(f"rejected marker {mid} in {im}: {why}", highlight=False)
    for a, b in cal.rejected_pairs:
        console.print(f"rejected pair {a}-{b}: its relative pose disagrees with the other pairs", highlight=False)
    for mid, why in cal.uncalibrated.items():
        console.print(f"not calibrated: marker {mid}: {why}", highlight=False)
    if cal.bridged_pairs:
        console.print("never seen together (bridged): "
                      + ", ".join(f"{a}-{b}" for a, b in cal.bridged_pairs), highlight=False)
