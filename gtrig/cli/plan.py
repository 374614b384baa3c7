# ruff: noqa: B008  (typer.Option in defaults is the Typer idiom, as in the other CLI modules)
"""``gtrig plan``: the ground truth's predicted accuracy and coverage over the floor for a planned rig."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import typer

from gtrig.cli.common import console, handle_errors

if TYPE_CHECKING:
    from gtrig.plan.grid import PlanGrid
    from gtrig.plan.maps import CellMaps, TargetSummary
    from gtrig.plan.predict import PlanResult, PlanSettings
    from gtrig.rig.models import Rig


def parse_polygon(text: str, option: str = "--area") -> list[tuple[float, float]]:
    """``--area`` (or ``option``): ``X,Y;X,Y;...`` in metres, or a file of ``x,y`` lines (``#`` comments)."""
    from gtrig.errors import InputError

    p = Path(text)
    source, rows = option, [r for r in text.split(";") if r.strip()]
    if ";" not in text and p.is_file():
        source = str(p)
        rows = [r for r in p.read_text(encoding="utf-8").splitlines() if r.strip() and not r.lstrip().startswith("#")]
    out = []
    for i, r in enumerate(rows):
        f = r.replace(" ", "").split(",")
        try:
            if len(f) != 2:
                raise ValueError
            out.append((float(f[0]), float(f[1])))
        except ValueError:
            where = f"{source}:{i + 1}" if source != option else f"{option} vertex {i + 1}"
            raise InputError(f"{where}: expected x,y in metres, got {r.strip()!r}") from None
    return out


def parse_suggest(text: str | None) -> tuple[int, int]:
    """``--suggest cameras:N,scanners:M`` (either or both): the cameras and fixed scanners to add (0, 0
    without the option)."""
    from gtrig.errors import InputError

    if text is None:
        return 0, 0
    n = {"cameras": 0, "scanners": 0}
    for part in text.split(","):
        kind, _, count = part.strip().partition(":")
        if kind not in n or n[kind] or not count.isdigit() or not 1 <= int(count) <= 10:
            raise InputError(f"--suggest: expected cameras:N, scanners:M or cameras:N,scanners:M with N and M from "
                             f"1 to 10, got {text!r}")
        n[kind] = int(count)
    return n["cameras"], n["scanners"]


@handle_errors
def command(
    rig: Path = typer.Argument(..., help="The planned rig.yaml (nominal poses and intrinsics)."),
    out: Path = typer.Option(..., "--out", help="Folder for the maps, plan_grid.csv and plan.html."),
    area: str | None = typer.Option(None, "--area", help="Floor polygon X,Y;X,Y;... (m) or a file of x,y lines "
                                    "[default: the hull of the scanners and reference points]."),
    path: Path | None = typer.Option(None, "--path", help="A TUM trajectory: plan at its poses instead of a grid."),
    sunlit: str | None = typer.Option(None, "--sunlit", help="Floor polygon X,Y;X,Y;... (m) or a file of x,y lines "
                                      "where the robot's markers are in the sun and their white clips: their "
                                      "corners get the detector's scatter of clipped markers."),
    grid_m: float = typer.Option(0.05, "--grid-m", help="Cell size (m)."),
    headings: int = typer.Option(16, "--headings", help="Headings per cell."),
    target_mm: float = typer.Option(1.0, "--target-mm", help="Target one-sigma position accuracy (mm)."),
    target_deg: float = typer.Option(0.05, "--target-deg", help="Target one-sigma yaw accuracy (deg)."),
    camera_sigma_mm: float = typer.Option(0.33, "--camera-sigma-mm", help="Camera position sigma after calibration "
                                          "(cameras without pose_cov)."),
    camera_sigma_deg: float = typer.Option(0.0072, "--camera-sigma-deg", help="Camera orientation sigma."),
    marker_sigma_mm: float = typer.Option(0.12, "--marker-sigma-mm", help="Marker position sigma on the robot after "
                                          "calibration (markers without pose_cov)."),
    marker_sigma_deg: float = typer.Option(0.0097, "--marker-sigma-deg", help="Marker orientation sigma."),
    speed_mps: float = typer.Option(0.3, "--speed-mps", help="The robot's speed over an area (m/s): fusion's "
                                    "odometry noise between fixes grows with it (a --path with stamps moves at "
                                    "its own)."),
    clock_sigma_ms: float = typer.Option(1.3, "--clock-sigma-ms", help="Standard error of the sources' clock "
                                         "offsets after gtrig sync (ms): the fused pose is off by the robot's "
                                         "velocity times it."),
    workers: int = typer.Option(2, "--workers", help="Processes."),
    suggest: str | None = typer.Option(None, "--suggest", help="cameras:N,scanners:M (either or both): add N cameras "
                                       "and M fixed scanners, each where it most increases the share meeting the "
                                       "target (greedy over candidate poses)."),
    suggest_height: float = typer.Option(2.8, "--suggest-height", help="Height of the suggested cameras (m)."),
    suggest_positions: int = typer.Option(24, "--suggest-positions", help="Candidate positions along the outline "
                                          "(each aimed at the area's centre and at the failing cells' centre)."),
    suggest_scanner_height: float | None = typer.Option(None, "--suggest-scanner-height", help="Height of the "
                                                        "suggested scanners (m; by default the rig's first "
                                                        "scanner's)."),
) -> None:
    """Predict GTvision's, GTlaser's and the fused pose accuracy over the floor for a planned rig."""
    import math

    from gtrig.cli import checks
    from gtrig.errors import InputError
    from gtrig.rig.load import load_rig

    checks.number("--grid-m", grid_m, lo=0.0, lo_open=True, hi=5.0, unit="m")
    checks.count("--headings", headings, 1, 360)
    checks.workers(workers)
    checks.number("--speed-mps", speed_mps, lo=0.0, hi=10.0, unit="m/s")
    checks.number("--clock-sigma-ms", clock_sigma_ms, lo=0.0, hi=1000.0, unit="ms")
    checks.number("--target-mm", target_mm, lo=0.0, lo_open=True, hi=1000.0, unit="mm")
    checks.number("--target-deg", target_deg, lo=0.0, lo_open=True, hi=180.0, unit="deg")
    for name, v in (("--camera-sigma-mm", camera_sigma_mm), ("--marker-sigma-mm", marker_sigma_mm)):
        checks.number(name, v, lo=0.0, hi=100.0, unit="mm")
    for name, v in (("--camera-sigma-deg", camera_sigma_deg), ("--marker-sigma-deg", marker_sigma_deg)):
        checks.number(name, v, lo=0.0, hi=10.0, unit="deg")
    n_suggest = parse_suggest(suggest)
    checks.number("--suggest-height", suggest_height, lo=0.1, hi=20.0, unit="m")
    checks.count("--suggest-positions", suggest_positions, 1, 1000)
    if suggest_scanner_height is not None:
        checks.number("--suggest-scanner-height", suggest_scanner_height, lo=0.0, hi=20.0, unit="m")
    if area is not None and path is not None:
        raise InputError("--area and --path exclude each other: give one")
    checks.output_folder("--out", out)
    if not rig.is_file():
        raise InputError(f"{rig}: no such rig file")
    r = load_rig(rig)
    if n_suggest != (0, 0):
        from gtrig.plan.suggest import check_suggestion

        check_suggestion(r, *n_suggest, suggest_scanner_height)
    grid = _plan_grid(r, area, path, grid_m, headings)
    settings = _plan_settings(camera_sigma_mm, camera_sigma_deg, marker_sigma_mm, marker_sigma_deg, speed_mps,
                              clock_sigma_ms, sunlit)
    if workers == 0:
        import os

        workers = os.cpu_count() or 1
    _run(r, grid, settings, out, target_mm / 1000, math.radians(target_deg), rig.stem, workers,
         Suggest(*n_suggest, suggest_height, suggest_positions, suggest_scanner_height))


def _plan_grid(r: Rig, area: str | None, path: Path | None, grid_m: float, headings: int) -> PlanGrid:
    """The poses to plan at: those of the TUM trajectory ``path``, else a grid of ``grid_m`` cells and
    ``headings`` headings over ``--area`` (by default the rig's)."""
    import numpy as np

    from gtrig import geometry as geo
    from gtrig.plan.grid import area_grid, default_area, path_grid

    if path is not None:
        from gtrig.io.tum import read_tum

        traj = read_tum(path)
        return path_grid(traj.xyz[:, :2], geo.yaw_of_quats(traj.quat_xyzw), traj.stamps_s)
    poly = np.asarray(parse_polygon(area), dtype=float) if area is not None else default_area(r)
    return area_grid(poly, grid_m, headings)


def _plan_settings(camera_sigma_mm: float, camera_sigma_deg: float, marker_sigma_mm: float, marker_sigma_deg: float,
                   speed_mps: float, clock_sigma_ms: float, sunlit: str | None = None) -> PlanSettings:
    """The prediction's settings from the options: the rig's uncertainty after calibration, the robot's speed,
    the clock offsets' standard error and the floor polygon where the markers' white clips (``--sunlit``)."""
    import math
    from dataclasses import replace

    import numpy as np

    from gtrig.plan.fused import FusionPlanSettings
    from gtrig.plan.grid import check_polygon
    from gtrig.plan.predict import PlanSettings
    from gtrig.plan.vision import after_calibration
    from gtrig.vision.covariance import RigUncertainty

    ru = RigUncertainty(camera_sigma_mm / 1000, math.radians(camera_sigma_deg), marker_sigma_mm / 1000,
                        math.radians(marker_sigma_deg))
    vision = after_calibration(ru)
    if sunlit is not None:
        lit = check_polygon(np.asarray(parse_polygon(sunlit, "--sunlit"), dtype=float), "--sunlit")
        vision = replace(vision, sunlit_xy=tuple((float(x), float(y)) for x, y in lit))
    return PlanSettings(vision=vision,
                        fusion=FusionPlanSettings(speed_mps=speed_mps, clock_sigma_s=clock_sigma_ms / 1000))


@dataclass(frozen=True)
class Suggest:
    """What ``--suggest`` asks for: cameras and scanners to add, the cameras' height (m), the candidate
    positions along the outline, the scanners' height (m; None: the rig's first scanner's)."""

    cameras: int = 0
    scanners: int = 0
    height_m: float = 2.8
    positions: int = 24
    scanner_height_m: float | None = None


def _run(rig: Rig, grid: PlanGrid, settings: PlanSettings, out: Path, target_m: float, target_rad: float,
         name: str, workers: int, suggest: Suggest = Suggest()) -> None:
    """Predict, then write every output (nothing is written when the prediction fails)."""
    import time

    from gtrig.io.atomic import atomic_write_bytes, atomic_write_text
    from gtrig.io.plan import write_plan_csv, write_plan_html
    from gtrig.plan.maps import cell_maps, summarize_target
    from gtrig.plan.predict import predict_plan
    from gtrig.plan.report import plan_table, summary_lines

    t0 = time.perf_counter()
    plan = predict_plan(rig, grid, settings, workers)
    elapsed = time.perf_counter() - t0
    maps = cell_maps(plan)
    summary = summarize_target(plan, target_m, target_rad)
    lines = summary_lines(plan, maps, summary, elapsed)
    figs = _figures(plan, maps, summary, target_m, target_rad)
    suggested = None
    if suggest.cameras or suggest.scanners:
        from gtrig.plan import plots
        from gtrig.plan.suggest import suggest_sensors

        found = suggest_sensors(rig, plan, suggest.cameras, suggest.scanners, target_m, target_rad, settings,
                                suggest.height_m, suggest.positions, suggest.scanner_height_m, workers)
        for sg in found:
            x, y, z = sg.position_m
            lines.append(f"suggested {sg.kind} {sg.sensor.name} at x {x:.2f}, y {y:.2f}, z {z:.2f} m "
                         f"({sg.n_candidates} candidates): target met on {100 * sg.share_before:.1f} % -> "
                         f"{100 * sg.share_after:.1f} % of the {'area' if grid.kind == 'area' else 'path'}")
        suggested = found[-1]
        maps2 = cell_maps(suggested.plan)
        summary2 = summarize_target(suggested.plan, target_m, target_rad)
        figs += [("target_suggested.png", "With the suggested sensor(s): where the target is met",
                  plots.target_map(suggested.plan, summary2)),
                 ("sigma_fused_suggested.png", "With the suggested sensor(s): fused sigma",
                  plots.sigma_maps(suggested.plan, maps2, "fused", target_m, target_rad))]
    out.mkdir(parents=True, exist_ok=True)
    if suggested is not None:
        from gtrig.rig.load import dump_rig

        dump_rig(suggested.rig, out / "rig_suggested.yaml")
    write_plan_csv(out / "plan_grid.csv", plan_table(plan))
    for fname, _, png in figs:
        atomic_write_bytes(out / fname, png)
    atomic_write_text(out / "summary.txt", "\n".join(lines) + "\n")
    write_plan_html(out / "plan.html", f"gtrig plan: {name}", lines, [(cap, png) for _, cap, png in figs])
    for line in lines:
        console.print(line, highlight=False, soft_wrap=True)


def _figures(plan: PlanResult, maps: CellMaps, summary: TargetSummary, target_m: float, target_rad: float
             ) -> list[tuple[str, str, bytes]]:
    from gtrig.plan import plots

    out = [("target.png", "Where the fused pose meets the target at every heading", plots.target_map(plan, summary))]
    for src in ("fused", "vision", "laser"):
        out.append((f"sigma_{src}.png", f"{src}: position and yaw sigma, worst and median heading",
                    plots.sigma_maps(plan, maps, src, target_m, target_rad)))
    out.append(("coverage.png", "Coverage: cameras seeing a marker whole, scanners with beams on the hull",
                plots.coverage_maps(plan, maps)))
    return out
