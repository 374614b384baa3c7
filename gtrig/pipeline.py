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


def _stages() -> list[tuple[str, Stage]]:
    return []


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
