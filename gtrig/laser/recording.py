"""GTlaser on a recording folder (docs/formats.md): read scans, calibrate, track, write the results.

The public entry points for the CLI and the demo are :func:`calibrate_recording` and
:func:`track_recording`.
"""

from __future__ import annotations

import logging
import os
from pathlib import Path

import numpy as np
import yaml

from gtrig import geometry as geo
from gtrig.errors import FormatError, InputError
from gtrig.io.atomic import atomic_open
from gtrig.io.scans import ScanLog, read_scans
from gtrig.io.tum import Trajectory, write_tum
from gtrig.laser.background import BackgroundModel, build_background
from gtrig.laser.calibrate import CalibrationReport, calibrate_scanners, calibrated_rig
from gtrig.laser.foreground import foreground_mask, foreground_threshold
from gtrig.laser.fuse import frame_points
from gtrig.laser.hull_icp import HullModel
from gtrig.laser.track import OK, STATUS_NAMES, TrackResult, TrackSettings, track_frames
from gtrig.rig.load import load_rig
from gtrig.rig.models import Rig

log = logging.getLogger(__name__)

OBJECT_FILE = "calib/laser_object.yaml"


def read_scanner_logs(folder: str | os.PathLike[str], rig: Rig, what: str = "sequence") -> dict[str, ScanLog]:
    """Scans ``<folder>/<scanner>.csv`` of every scanner of ``rig``.

    Raises
    ------
    InputError
        A scanner of the rig without its CSV (one line naming the scanner and the folder).
    FormatError
        From :func:`gtrig.io.scans.read_scans`: wrong beam count, time stamps not increasing...
    """
    folder = Path(folder)
    out = {}
    for s in rig.laser_scanners:
        p = folder / f"{s.name}.csv"
        if not p.is_file():
            raise InputError(f"scanner {s.name}: no {what} scans ({p} is missing)")
        out[s.name] = read_scans(p, s)
    return out


def load_backgrounds(static_dir: str | os.PathLike[str], rig: Rig) -> list[BackgroundModel]:
    """Background models of every scanner of ``rig`` from ``<static_dir>/lasers/<scanner>.csv``
    (or ``<static_dir>/<scanner>.csv``)."""
    d = Path(static_dir)
    folder = d / "lasers" if (d / "lasers").is_dir() else d
    if not folder.is_dir():
        raise InputError(f"{d}: no static (background) sequence folder")
    logs = read_scanner_logs(folder, rig, "background")
    return [build_background(logs[s.name].ranges_m, s) for s in rig.laser_scanners]


def load_object_outline(path: str | os.PathLike[str]) -> np.ndarray:
    """The world-defining object's outline from YAML ``corners_xy: [[x, y], ...]`` (world, metres, in
    order around the object); returned counter-clockwise, (K, 2)."""
    p = Path(path)
    try:
        doc = yaml.safe_load(p.read_text(encoding="utf-8"))
        c = np.asarray(doc["corners_xy"], dtype=float)
    except FileNotFoundError:
        raise InputError(f"{p}: no such file") from None
    except (yaml.YAMLError, KeyError, TypeError, ValueError):
        raise FormatError(f"{p}: expected 'corners_xy: [[x, y], ...]' (world frame, metres)") from None
    if c.ndim != 2 or c.shape[1] != 2 or c.shape[0] < 3:
        raise FormatError(f"{p}: corners_xy needs at least 3 [x, y] pairs")
    area = 0.5 * np.sum(c[:, 0] * np.roll(c[:, 1], -1) - np.roll(c[:, 0], -1) * c[:, 1])
    return c if area > 0 else c[::-1].copy()


def _object_for_recording(rec: Path) -> np.ndarray:
    p = rec / OBJECT_FILE
    if p.is_file():
        return load_object_outline(p)
    cfg = rec / "sim_config.yaml"
    if cfg.is_file():
        scenario = (yaml.safe_load(cfg.read_text(encoding="utf-8")) or {}).get("scenario", "gtroom")
        if scenario == "gtroom":
            # the simulated GT room's calibration object stands at a fixed, known place (seed-independent)
            from gtrig.sim.gtroom import clutter

            for b in clutter():
                if b.name == "calib_object":
                    return b.corners_xy()
    raise InputError(f"{rec}: no {OBJECT_FILE} (the outline of the object that defines the world frame)")


def calibrate_recording(
    rec_dir: str | os.PathLike[str],
    rig: Rig | None = None,
    static_dir: str | os.PathLike[str] | None = None,
    object_corners_world_xy: np.ndarray | None = None,
) -> tuple[Rig, CalibrationReport]:
    """Calibrate the fixed scanners of a recording.

    Parameters
    ----------
    rec_dir
        The recording (``rig.yaml``, ``background/lasers/*.csv``).
    rig
        The nominal rig (default ``rec_dir/rig.yaml``).
    static_dir
        The static sequence (default ``rec_dir/background``).
    object_corners_world_xy
        (K, 2) the world object's outline (default ``rec_dir/calib/laser_object.yaml``, or the simulated
        GT room's ``calib_object``).

    Returns
    -------
    rig : the rig with calibrated scanner poses.
    report : residuals and standard deviations.
    """
    rec = Path(rec_dir)
    rig = load_rig(rec / "rig.yaml") if rig is None else rig
    bgs = load_backgrounds(rec / "background" if static_dir is None else static_dir, rig)
    obj = _object_for_recording(rec) if object_corners_world_xy is None else object_corners_world_xy
    scanners, report = calibrate_scanners(rig.laser_scanners, bgs, obj)
    return calibrated_rig(rig, scanners), report


def track_sequence(
    rig: Rig,
    seq_dir: str | os.PathLike[str],
    backgrounds: list[BackgroundModel],
    settings: TrackSettings | None = None,
) -> TrackResult:
    """Track the hull through ``seq_dir/lasers/<scanner>.csv`` with the given background models."""
    if not rig.laser_scanners:
        raise InputError("the rig has no laser scanners")
    logs = read_scanner_logs(Path(seq_dir) / "lasers", rig, "sequence")
    scs = rig.laser_scanners
    masks = [
        foreground_mask(logs[s.name].ranges_m, foreground_threshold(b))
        for s, b in zip(scs, backgrounds, strict=True)
    ]
    fp = frame_points(scs, [logs[s.name].stamps_s for s in scs], [logs[s.name].ranges_m for s in scs], masks)
    return track_frames(fp, HullModel.from_hull(rig.robot.hull), settings or TrackSettings())


def track_recording(
    rec_dir: str | os.PathLike[str],
    sequence: str = "run",
    rig: Rig | None = None,
    out_tum: str | os.PathLike[str] | None = None,
    out_cov: str | os.PathLike[str] | None = None,
    settings: TrackSettings | None = None,
) -> TrackResult:
    """Run GTlaser on one sequence of a recording.

    Parameters
    ----------
    rec_dir
        The recording.
    sequence
        ``"run"`` or ``"validation"``.
    rig
        The rig with calibrated scanners (default: calibrate from the recording's background sequence).
    out_tum, out_cov
        Where to write the poses (TUM, ``OK`` frames only) and their covariances (CSV, same rows).
    settings
        Tracking settings.
    """
    rec = Path(rec_dir)
    if sequence not in ("run", "validation"):
        raise InputError(f"sequence must be 'run' or 'validation', got {sequence!r}")
    if rig is None:
        rig, _ = calibrate_recording(rec)
    bgs = load_backgrounds(rec / "background", rig)
    res = track_sequence(rig, rec / sequence, bgs, settings)
    if out_tum is not None:
        write_track(res, out_tum, out_cov)
    return res


def write_track(
    result: TrackResult,
    tum_path: str | os.PathLike[str],
    cov_path: str | os.PathLike[str] | None = None,
    include_flagged: bool = False,
) -> int:
    """Write ``OK`` poses (and, with ``include_flagged``, degenerate and ambiguous ones) as TUM, and a
    covariance CSV with the same rows: ``timestamp,x,y,theta,cov_xx,cov_xy,cov_xtheta,cov_yy,cov_ytheta,
    cov_thetatheta,status,n_points,n_sides,rms_m``. Returns the number of poses written."""
    keep = result.ok if not include_flagged else np.isfinite(result.xytheta[:, 0])
    idx = np.flatnonzero(keep)
    T = np.stack([geo.se2_to_T(*result.xytheta[k]) for k in idx]) if idx.size else np.zeros((0, 4, 4))
    if idx.size == 0:
        raise InputError("no pose to write: the hull was never localized")
    write_tum(tum_path, Trajectory.from_matrices(result.stamps_s[idx], T))
    if cov_path is not None:
        with atomic_open(cov_path, "w", newline="\n") as f:
            f.write(
                "timestamp,x,y,theta,cov_xx,cov_xy,cov_xtheta,cov_yy,cov_ytheta,cov_thetatheta,"
                "status,n_points,n_sides,rms_m\n"
            )
            for k in idx:
                c = result.cov_xytheta[k]
                x, y, th = result.xytheta[k]
                f.write(
                    f"{result.stamps_s[k]:.6f},{x:.6f},{y:.6f},{th:.8f},{c[0, 0]:.6e},{c[0, 1]:.6e},"
                    f"{c[0, 2]:.6e},{c[1, 1]:.6e},{c[1, 2]:.6e},{c[2, 2]:.6e},"
                    f"{STATUS_NAMES[int(result.status[k])]},{result.n_points[k]},{result.n_sides[k]},"
                    f"{result.rms_m[k]:.5f}\n"
                )
    return int(idx.size)


__all__ = [
    "OK",
    "calibrate_recording",
    "load_backgrounds",
    "track_recording",
    "track_sequence",
    "write_track",
]
