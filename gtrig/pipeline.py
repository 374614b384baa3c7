"""The whole job on one recording, as a table of contents: each stage that exists runs in turn.

``run(rec, out)`` reads a recording, runs the stages and, when the recording carries its truth
(simulated), measures every result against it. Each stage writes its outputs under ``out`` and
returns rows of the accuracy table.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

from gtrig.io.recording import recording_dir

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class AccuracyRow:
    """One measured figure: ``stage``, what was measured, the value with its unit, and our target."""

    stage: str
    metric: str
    value: float
    unit: str
    target: str = ""
    ok: bool | None = None


@dataclass
class StageContext:
    """What stages hand on to later ones (the calibrated rig, trajectories...)."""

    rec: Path
    out: Path
    products: dict[str, object] = field(default_factory=dict)


Stage = Callable[[StageContext], list[AccuracyRow]]


def _has_truth(ctx: StageContext) -> bool:
    return (ctx.rec / "truth").is_dir()


def survey(ctx: StageContext) -> list[AccuracyRow]:
    """World points and validation poses from the hand-laser distances (issue 3)."""
    from gtrig.survey import compare_to_truth, run_recording_survey

    res = run_recording_survey(ctx.rec, ctx.out / "survey")
    ctx.products["survey"] = res
    if not _has_truth(ctx):
        return []
    s = compare_to_truth(res, ctx.rec).summary()
    return [
        AccuracyRow("survey", "world points, max error", s["world_points_max_mm"], "mm", "<= 2",
                    s["world_points_max_mm"] <= 2.0),
        AccuracyRow("survey", "world points, RMS error", s["world_points_rms_mm"], "mm"),
        AccuracyRow("survey", "validation poses, max position error", s["poses_max_pos_mm"], "mm", "<= 3",
                    s["poses_max_pos_mm"] <= 3.0),
        AccuracyRow("survey", "validation poses, max heading error", s["poses_max_theta_deg"], "deg", "<= 0.1",
                    s["poses_max_theta_deg"] <= 0.1),
        AccuracyRow("survey", "validation poses, mean NEES / dof", s["poses_mean_nees"] / 3, "", "0.7-1.4"),
    ]


def _stages() -> list[tuple[str, Stage]]:
    return [
        ("survey", survey),
    ]


@dataclass(frozen=True)
class PipelineResult:
    rows: tuple[AccuracyRow, ...]
    seconds: dict[str, float]
    skipped: dict[str, str]


def run(rec: str | Path, out: str | Path, on_stage: Callable[[str], None] | None = None) -> PipelineResult:
    """Run every available stage on the recording ``rec``, writing under ``out``."""
    ctx = StageContext(recording_dir(rec), Path(out))
    ctx.out.mkdir(parents=True, exist_ok=True)
    rows: list[AccuracyRow] = []
    seconds: dict[str, float] = {}
    skipped: dict[str, str] = {}
    for name, stage in _stages():
        if on_stage:
            on_stage(name)
        t = time.perf_counter()
        rows.extend(stage(ctx))
        seconds[name] = time.perf_counter() - t
    return PipelineResult(tuple(rows), seconds, skipped)
