"""GTlaser on a recording folder (docs/formats.md): read scans, calibrate, track, write the results.

The public entry points for the CLI and the demo are :func:`calibrate_recording` and
:func:`track_recording`.
"""

from __future__ import annotations

import contextlib
import logging
import os
import tempfile
from collections.abc import Callable, Iterator, Mapping
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any, Literal, TypeVar

import numpy as np
import yaml

from gtrig.errors import ConfigError, FormatError, InputError
from gtrig.io.atomic import atomic_open
from gtrig.io.posetrack import write_pose_track
from gtrig.io.scans import ScanLog, ScanRows, index_scans, read_scans
from gtrig.io.text import read_text
from gtrig.io.yamlfile import safe_load
from gtrig.laser.background import BackgroundModel, build_background
from gtrig.laser.beam_timing import TimingFit, check_beam_timing
from gtrig.laser.calibrate import CalibrationReport, calibrate_scanners, calibrated_rig, object_outlines
from gtrig.laser.clock import ScannerClock, on_clock
from gtrig.laser.foreground import foreground_mask, foreground_threshold
from gtrig.laser.fuse import FramedPoints, FrameLayout, frame_layout, window_points
from gtrig.laser.hull_icp import HullModel
from gtrig.laser.track import OK, TrackResult, TrackSettings, to_pose_track, track_frames
from gtrig.rig.load import load_rig
from gtrig.rig.models import LaserScanner, Rig

log = logging.getLogger(__name__)
_T = TypeVar("_T")

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
    return _scanner_files(folder, rig, what, read_scans)


def _scanner_files(folder: str | os.PathLike[str], rig: Rig, what: str,
                   reader: Callable[[Path, LaserScanner], _T]) -> dict[str, _T]:
    """``reader(<folder>/<scanner>.csv, scanner)`` of every scanner of ``rig`` (read or indexed)."""
    folder = Path(folder)
    out = {}
    for s in rig.laser_scanners:
        p = folder / f"{s.name}.csv"
        if not p.is_file():
            raise InputError(f"scanner {s.name}: no {what} scans ({p} is missing)")
        out[s.name] = reader(p, s)
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


def load_object_outline(path: str | os.PathLike[str]) -> list[np.ndarray]:
    """The world-defining objects' outlines from YAML, world frame, metres, corners in order around each
    object: ``corners_xy: [[x, y], ...]`` for one object, or ``objects: [{corners_xy: ...}, ...]`` for
    several (their poses surveyed in the world). Returned counter-clockwise, each (K_j, 2)."""
    p = Path(path)
    try:
        doc = safe_load(read_text(p, "YAML file"))
        entries = doc["objects"] if "objects" in doc else [doc]
        outlines = [np.asarray(e["corners_xy"], dtype=float) for e in entries]
    except FileNotFoundError:
        raise InputError(f"{p}: no such file") from None
    except (yaml.YAMLError, KeyError, TypeError, ValueError):
        raise FormatError(
            f"{p}: expected 'corners_xy: [[x, y], ...]' or 'objects: [{{corners_xy: ...}}, ...]' "
            "(world frame, metres)"
        ) from None
    for c in outlines:
        if c.ndim != 2 or c.shape[1] != 2 or c.shape[0] < 3:
            raise FormatError(f"{p}: corners_xy needs at least 3 [x, y] pairs")
    if not outlines:
        raise FormatError(f"{p}: no object")
    return object_outlines(outlines)


def _object_for_recording(rec: Path) -> list[np.ndarray]:
    p = rec / OBJECT_FILE
    if p.is_file():
        return load_object_outline(p)
    raise InputError(f"{rec}: no {OBJECT_FILE} (the outline of the object that defines the world frame; "
                     "docs/formats.md; a recording simulated before it was written: simulate it again)")


def calibrate_recording(
    rec_dir: str | os.PathLike[str],
    rig: Rig | None = None,
    static_dir: str | os.PathLike[str] | None = None,
    object_corners_world_xy: np.ndarray | list[np.ndarray] | None = None,
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
        (K, 2) the world object's outline, or a list of outlines (default
        ``rec_dir/calib/laser_object.yaml``, or the simulated GT room's ``calib_object*`` boxes).

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


def calibration_cov_path(rig_path: str | os.PathLike[str]) -> Path:
    """Where ``gtrig laser calibrate`` writes the scanners' calibration covariance: next to the calibrated
    rig file, ``<stem>.laser_cov.yaml``."""
    p = Path(rig_path)
    return p.with_name(p.stem + ".laser_cov.yaml")


def write_calibration_cov(path: str | os.PathLike[str], rig: Rig, report: CalibrationReport) -> None:
    """Write ``scanners: [names]`` and ``cov_xytheta`` (3 S x 3 S rows; x, y m, theta rad, world frame)."""
    doc = {
        "scanners": [s.name for s in rig.laser_scanners],
        "units": "x, y in m, theta in rad per scanner, world frame",
        "cov_xytheta": [[float(v) for v in row] for row in report.cov_xytheta],
    }
    with atomic_open(path, "w") as f:
        yaml.safe_dump(doc, f, sort_keys=False)


def read_calibration_cov(path: str | os.PathLike[str], rig: Rig) -> np.ndarray:
    """The (3 S, 3 S) calibration covariance written by :func:`write_calibration_cov`, checked against the
    rig's scanners (same names, same order).

    Raises
    ------
    FormatError
        Unreadable file, scanners that differ from the rig's, or a matrix of the wrong shape.
    """
    p = Path(path)
    try:
        doc = safe_load(read_text(p, "YAML file"))
        names = [str(n) for n in doc["scanners"]]
        cov = np.asarray(doc["cov_xytheta"], dtype=float)
    except FileNotFoundError:
        raise InputError(f"{p}: no such file") from None
    except (yaml.YAMLError, KeyError, TypeError, ValueError):
        raise FormatError(f"{p}: expected 'scanners: [...]' and 'cov_xytheta: [[...], ...]'") from None
    want = [s.name for s in rig.laser_scanners]
    if names != want:
        raise FormatError(f"{p}: scanners {names} differ from the rig's {want}")
    if cov.shape != (3 * len(want), 3 * len(want)):
        raise FormatError(f"{p}: cov_xytheta is {cov.shape}, expected {(3 * len(want), 3 * len(want))}")
    return cov


@dataclass(frozen=True)
class LoggedFrames:
    """The frames of a sequence read from its scan logs on disk a time window at a time
    (:class:`gtrig.laser.fuse.FrameSource`): in memory only the scans' stamps and places
    (:class:`gtrig.io.scans.ScanRows`) and which frame each joins (:class:`gtrig.laser.fuse.FrameLayout`),
    about 40 bytes per scan; a window's ranges are read, masked and turned into world points when it
    is asked for, by the client or by the worker a part of it is sent to (the recording on a path both
    see, as the cameras' images, docs/scale.md). The points are those of
    :func:`gtrig.laser.fuse.frame_points` over the whole logs, bit for bit.

    Attributes
    ----------
    scanners : the scanners (calibrated poses, on the frames' clock).
    rows : per scanner, where its scans are (the part of its log this source covers).
    thresholds : per scanner, (B_s,) its foreground threshold, metres (:func:`foreground_threshold`).
    layout : the frames and the frame each scan joins.
    """

    scanners: tuple[LaserScanner, ...]
    rows: tuple[ScanRows, ...]
    thresholds: tuple[np.ndarray, ...]
    layout: FrameLayout

    @property
    def frame_stamps_s(self) -> np.ndarray:
        return self.layout.frame_stamps_s

    @property
    def n_frames(self) -> int:
        return self.layout.n_frames

    @property
    def scanner_xy_world(self) -> np.ndarray:
        return np.array([s.T_world_scanner.matrix()[:2, 3] for s in self.scanners])

    @property
    def sigma_m(self) -> np.ndarray:
        return np.array([s.range_sigma_m for s in self.scanners])

    @property
    def stamp_sigma_s(self) -> np.ndarray:
        return np.array([s.stamp_sigma_s for s in self.scanners])

    def window(self, a: int, b: int, scans: bool = True) -> FramedPoints:
        """Frames ``[a, b)`` read from the logs (:class:`gtrig.laser.fuse.FrameSource`)."""
        ranges, masks = [], []
        for i, (r, th) in enumerate(zip(self.rows, self.thresholds, strict=True)):
            lo, hi = self.layout.scans(i, a, b)
            ranges.append(r.read(lo, hi))
            masks.append(foreground_mask(ranges[-1], th))
        fp = window_points(self.scanners, self.layout, a, b, ranges, masks)
        return fp if scans else replace(fp, ranges_m=(), masks=(), beam_dirs=())

    def part(self, a: int, b: int) -> LoggedFrames:
        """Frames ``[a, b)``: the places of their scans only, a few kB to send to a worker."""
        lohi = [self.layout.scans(i, a, b) for i in range(len(self.scanners))]
        return replace(self, rows=tuple(r.part(lo, hi) for r, (lo, hi) in zip(self.rows, lohi, strict=True)),
                       layout=self.layout.part(a, b))


def logged_frames(
    rig: Rig, seq_dir: str | os.PathLike[str], backgrounds: list[BackgroundModel],
    clocks: Mapping[str, ScannerClock] | None = None, scan_cache: str | os.PathLike[str] | None = None,
) -> tuple[Rig, LoggedFrames]:
    """The frames of ``seq_dir/lasers/<scanner>.csv`` as :class:`LoggedFrames` (each log indexed, not
    read: :func:`gtrig.io.scans.index_scans`), and the rig, moved onto the reference clock of
    ``clocks`` (:func:`gtrig.laser.clock.on_clock`) when given. ``scan_cache``: the folder where the
    logs' parsed ranges are kept (``index_scans(cache=)``): the windows are then read from it, not
    parsed again; None: from the text."""
    rows = _scanner_files(Path(seq_dir) / "lasers", rig, "sequence",
                          lambda p, s: index_scans(p, s, cache=scan_cache))
    if clocks:
        rig, _ = on_clock(rig, {}, clocks)
        rows = {k: v.shifted(clocks[k].offset_s) if k in clocks else v for k, v in rows.items()}
    scs = tuple(rig.laser_scanners)
    layout = frame_layout(scs, [rows[s.name].stamps_s for s in scs])
    return rig, LoggedFrames(scs, tuple(rows[s.name] for s in scs),
                             tuple(foreground_threshold(b) for b in backgrounds), layout)


@contextlib.contextmanager
def scan_cache_folder(scan_cache: str | os.PathLike[str] | Literal[False] | None) -> Iterator[Path | None]:
    """The folder :func:`track_sequence` keeps the logs' parsed ranges in: ``scan_cache`` itself; for None
    a temporary folder (``$TMPDIR``) removed at the end of the block, so that one call parses each log
    once; for False none (every window parsed from the text)."""
    if scan_cache is False:
        yield None
        return
    if scan_cache is not None:
        yield Path(scan_cache)
        return
    try:
        tmp = tempfile.TemporaryDirectory(prefix="gtrig-scans-")
    except OSError:  # no writable temporary folder: the text is parsed as it is read
        yield None
        return
    with tmp:
        yield Path(tmp.name)


def track_sequence(
    rig: Rig,
    seq_dir: str | os.PathLike[str],
    backgrounds: list[BackgroundModel],
    settings: TrackSettings | None = None,
    scanner_cov: np.ndarray | None = None,
    clocks: Mapping[str, ScannerClock] | None = None,
    scan_cache: str | os.PathLike[str] | Literal[False] | None = None,
    **parallel: Any,
) -> TrackResult:
    """Track the hull through ``seq_dir/lasers/<scanner>.csv`` with the given background models;
    ``scanner_cov`` (3 S, 3 S) is the scanners' calibration covariance, propagated into each pose;
    ``clocks``: per scanner, its offset to a reference clock (:mod:`gtrig.laser.clock`): the scans are
    moved onto that clock first and the track is on it; ``parallel``: ``executor``, ``workers``,
    ``progress`` of :func:`gtrig.laser.track.track_frames`. The logs are read a time window at a time
    (:class:`LoggedFrames`), by the workers too: the client's memory grows by per-frame results only.
    ``scan_cache``: where the logs' parsed ranges are kept (:func:`scan_cache_folder`; default a temporary
    folder for the call): each log's text is parsed once, by its indexing, and the tracking passes and the
    workers read the binary copy (a worker that does not see the folder parses its windows' text)."""
    if not rig.laser_scanners:
        raise InputError("the rig has no laser scanners")
    if rig.robot.hull is None:
        raise ConfigError("rig: robot.hull: missing field: GTlaser tracks the robot's hull (length_m, width_m, "
                          "z_min_m, z_max_m)")
    with scan_cache_folder(scan_cache) as cache:
        _, frames = logged_frames(rig, seq_dir, backgrounds, clocks, cache)
        return track_frames(frames, HullModel.from_hull(rig.robot.hull), settings or TrackSettings(), scanner_cov,
                            **parallel)


def track_recording(
    rec_dir: str | os.PathLike[str],
    sequence: str = "run",
    rig: Rig | None = None,
    out_tum: str | os.PathLike[str] | None = None,
    out_cov: str | os.PathLike[str] | None = None,
    settings: TrackSettings | None = None,
    scanner_cov: np.ndarray | None = None,
    clocks: Mapping[str, ScannerClock] | None = None,
    scan_cache: str | os.PathLike[str] | Literal[False] | None = None,
    **parallel: Any,
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
    scanner_cov
        (3 S, 3 S) the scanners' calibration covariance (``CalibrationReport.cov_xytheta``), propagated into
        each pose's covariance; when ``rig`` is ``None`` the recording's own calibration provides it.
    clocks
        Per scanner, its clock offset to a reference clock (:func:`gtrig.laser.clock.clocks_from_sync`):
        the track is then on that clock (:func:`track_sequence`); default: the scanners' own stamps.
    scan_cache
        Where the logs' parsed ranges are kept (:func:`track_sequence`): ``gtrig run`` passes
        ``RESULTS/.gtrig/scans``, so its later stages and a resumed run parse no log again.
    parallel
        ``executor``, ``workers`` and ``progress`` of :func:`gtrig.laser.track.track_frames` (where the
        per-frame covariance terms run; the output does not depend on them).
    """
    rec = Path(rec_dir)
    if sequence not in ("run", "validation"):
        raise InputError(f"sequence must be 'run' or 'validation', got {sequence!r}")
    if rig is None:
        rig, report = calibrate_recording(rec)
        scanner_cov = report.cov_xytheta if scanner_cov is None else scanner_cov
    bgs = load_backgrounds(rec / "background", rig)
    res = track_sequence(rig, rec / sequence, bgs, settings, scanner_cov, clocks, scan_cache, **parallel)
    if out_tum is not None:
        write_track(res, out_tum, out_cov)
    return res


def write_track(
    result: TrackResult,
    tum_path: str | os.PathLike[str],
    cov_path: str | os.PathLike[str] | None = None,
    include_flagged: bool = False,
) -> int:
    """Write ``OK`` poses (and, with ``include_flagged``, the degenerate and ambiguous ones, status
    ``rejected`` with their reason) as TUM and, with ``cov_path``, the one covariance CSV layout of
    :mod:`gtrig.io.posetrack` (same rows), both or neither. Returns the number of poses written."""
    track = to_pose_track(result)
    if not include_flagged:
        track = track.usable()
    if len(track) == 0:
        raise InputError("no pose to write: the hull was never localized")
    write_pose_track(track, tum_path, cov_path)
    return len(track)


__all__ = [
    "OK",
    "calibrate_recording",
    "calibration_cov_path",
    "read_calibration_cov",
    "write_calibration_cov",
    "load_backgrounds",
    "track_recording",
    "track_sequence",
    "write_track",
]


def check_recording_timing(
    rec_dir: str | os.PathLike[str],
    result: TrackResult,
    rig: Rig,
    sequence: str = "run",
    scan_cache: str | os.PathLike[str] | Literal[False] | None = None,
) -> tuple[TimingFit, ...]:
    """Each fixed scanner's declared beam timing checked against the residuals of the track ``result``
    made by :func:`track_recording` on ``sequence`` with ``rig`` (:mod:`gtrig.laser.beam_timing`);
    ``scan_cache``: as :func:`track_recording`'s (the logs are read again from it)."""
    rec = Path(rec_dir)
    if rig.robot.hull is None:
        raise ConfigError("rig: robot.hull: missing field: GTlaser tracks the robot's hull")
    bgs = load_backgrounds(rec / "background", rig)
    with scan_cache_folder(scan_cache) as cache:
        rig_c, frames = logged_frames(rig, rec / sequence, bgs, None, cache)
        return check_beam_timing(frames, result.xytheta, result.ok, result.track_id, rig_c.laser_scanners,
                                 HullModel.from_hull(rig.robot.hull))
