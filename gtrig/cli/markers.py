"""``gtrig markers make | detect``."""

from __future__ import annotations

from pathlib import Path

import typer

from gtrig.cli.common import console, handle_errors
from gtrig.rig.models import MarkerFamily

app = typer.Typer(help="Square ID markers: printable sheets and high-accuracy detection.",
                  no_args_is_help=True)


@app.command("make")
@handle_errors
def make(
    family: MarkerFamily = typer.Option(..., "--family", help="Marker family."),
    marker_id: int = typer.Option(..., "--id", help="Marker ID."),
    size_mm: float = typer.Option(..., "--size-mm", help="Side of the black square (border included), mm."),
    out: Path = typer.Option(..., "--out", help="Output file: .pdf, .svg or .png."),
    dpi: float = typer.Option(600.0, "--dpi", help="Minimum resolution of a PNG (dots per inch)."),
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
