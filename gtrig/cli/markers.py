"""``gtrig markers make | detect``."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from gtrig.cli.common import console, handle_errors
from gtrig.rig.models import MarkerFamily

app = typer.Typer(help="Square ID markers: printable sheets and high-accuracy detection.",
                  no_args_is_help=True)


@app.command("make")
@handle_errors
def make(
    family: Annotated[MarkerFamily, typer.Option("--family", help="Marker family.")],
    marker_id: Annotated[int, typer.Option("--id", help="Marker ID.")],
    size_mm: Annotated[float, typer.Option("--size-mm", help="Black square side (border included), mm.")],
    out: Annotated[Path, typer.Option("--out", help="Output file: .pdf, .svg or .png.")],
    dpi: Annotated[float, typer.Option("--dpi", help="Minimum resolution of a PNG (dots per inch).")] = 600.0,
) -> None:
    """Write a printable marker at exact physical size, with cut marks and its ID outside the marker."""
    from gtrig.markers.generate import png_resolution, write_marker

    lay = write_marker(family, marker_id, size_mm, out, dpi)
    msg = f"{out}: {family.value} id {marker_id}, black square {size_mm:g} mm"
    if out.suffix.lower() == ".png":
        k, ppm = png_resolution(size_mm, lay.cells.shape[0], dpi)
        msg += (f", {k} px per cell at {ppm * 0.0254:.2f} dpi "
                f"(printed side {lay.cells.shape[0] * k / ppm * 1000:.3f} mm)")
    console.print(msg, highlight=False)


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
    family: Annotated[MarkerFamily, typer.Option("--family", help="Marker family.")],
    out: Annotated[Path, typer.Option("--out", help="Output JSON (det.json).")],
    camera: Annotated[Path | None, typer.Option("--camera", help="cam.yaml: fit edges undistorted.")] = None,
) -> None:
    """Detect markers with sub-pixel corners and their covariances; write det.json."""
    import json

    import cv2

    from gtrig.cli.common import track
    from gtrig.errors import FormatError, InputError
    from gtrig.io.atomic import atomic_write_text
    from gtrig.markers.detect import MarkerDetector

    K = dist = None
    size = None
    if camera is not None:
        from gtrig.calib.camfile import read_cam_yaml

        cam = read_cam_yaml(camera)
        K, dist, size = cam.camera_matrix, cam.dist_coeffs, cam.image_size
    det = MarkerDetector(family, K, dist)
    files = _image_files(inputs)
    images = []
    n_det = 0
    for f in track(files, "detecting", total=len(files)):
        img = cv2.imread(str(f), cv2.IMREAD_GRAYSCALE)
        if img is None:
            raise FormatError(f"{f}: not a readable image")
        if size is not None and (img.shape[1], img.shape[0]) != tuple(size):
            raise InputError(f"{f}: {img.shape[1]} x {img.shape[0]} px but {camera} is for "
                             f"{size[0]} x {size[1]}")
        dets = det.detect(img)
        n_det += len(dets)
        images.append({"file": str(f), "detections": [d.to_json() for d in dets]})
    doc = {"family": family.value, "camera": None if camera is None else str(camera), "images": images}
    atomic_write_text(out, json.dumps(doc, indent=1) + "\n")
    console.print(f"{out}: {n_det} detection(s) in {len(files)} image(s)", highlight=False)
