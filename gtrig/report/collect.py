"""What a pipeline output folder holds: the report shows what is present and names what is not."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path


@dataclass(frozen=True)
class ResultsInventory:
    """Files of one results folder (None or empty when absent).

    Attributes
    ----------
    root : the results folder.
    truth : the recording's ``truth/`` folder (simulated recordings), found beside the results.
    tracks : name -> (TUM path, covariance CSV or None), every pose track of the folder.
    accuracy : ``accuracy.csv`` (the pipeline's accuracy against truth).
    summaries : every stage's Markdown summary (``*.md``).
    calibration_yaml : ``calibration/calibration_report.yaml``.
    vision_checkpoints : GTvision's detection logs (``gt_vision_*.checkpoint``, NDJSON).
    world_points, validation_poses : the survey's outputs.
    sync : CSVs of time-sync correlation curves (a ``sync`` folder or ``*sync*.csv``).
    gps_reports : ``gtrig gps --report`` JSONs (``*gps*.json``: a name holding "gps").
    summary_csv : ``summary.csv`` (the run's checks).
    sync_yaml : ``sync.yaml`` (the clock offsets the sync stage measured).
    fusion_json : ``fusion_report.json``.
    rig_yaml : the rig the run used (``rig.calibrated.yaml``, else ``rig.yaml``).
    """

    root: Path
    truth: Path | None
    tracks: dict[str, tuple[Path, Path | None]]
    accuracy: Path | None
    summaries: list[Path]
    calibration_yaml: Path | None
    vision_checkpoints: list[Path]
    world_points: Path | None
    validation_poses: Path | None
    sync: list[Path] = field(default_factory=list)
    gps_reports: list[Path] = field(default_factory=list)
    summary_csv: Path | None = None
    sync_yaml: Path | None = None
    fusion_json: Path | None = None
    rig_yaml: Path | None = None


def _opt(p: Path) -> Path | None:
    return p if p.is_file() else None


def inventory(root: str | Path, truth: str | Path | None = None) -> ResultsInventory:
    """Scan ``root`` (and its sub-folders, one level deep) for the files the report knows."""
    r = Path(root)
    t = Path(truth) if truth is not None else None
    if t is None:
        for cand in (r / "truth", r.parent / "recording" / "truth", r.parent / "truth"):
            if cand.is_dir():
                t = cand
                break
    tums = sorted(list(r.glob("*.tum")) + list(r.glob("*/*.tum")))
    tracks = {}
    for p in tums:
        cov = p.with_name(p.stem + "_cov.csv")
        tracks[str(p.relative_to(r).with_suffix(""))] = (p, cov if cov.is_file() else None)
    sync = sorted(set(r.glob("sync/*.csv")) | set(r.glob("*sync*.csv")) | set(r.glob("*/*sync*.csv")))
    return ResultsInventory(
        r, t, tracks, _opt(r / "accuracy.csv"), sorted(list(r.glob("*.md")) + list(r.glob("*/*.md"))),
        _opt(r / "calibration" / "calibration_report.yaml"), sorted(r.glob("gt_vision_*.checkpoint")),
        _opt(r / "survey" / "world_points.csv"), _opt(r / "survey" / "validation_poses.csv"), sync,
        sorted(set(r.glob("*gps*.json")) | set(r.glob("*/*gps*.json"))), _opt(r / "summary.csv"),
        _opt(r / "sync.yaml"), _opt(r / "fusion_report.json"),
        _opt(r / "rig.calibrated.yaml") or _opt(r / "rig.yaml"))
