"""The accuracy table (``accuracy.csv``, against truth) and the checks (``summary.csv``, without it)."""

from __future__ import annotations

import csv
import math
from collections.abc import Sequence
from pathlib import Path

from gtrig.pipeline.context import AccuracyRow


def write_accuracy_csv(path: Path, rows: Sequence[AccuracyRow]) -> None:
    """``stage,metric,value,unit,target,ok``: one measured figure a row (6 significant digits)."""
    from gtrig.io.atomic import atomic_write_text

    def cell(v: object) -> str:
        return f'"{v}"' if "," in str(v) else str(v)

    lines = ["stage,metric,value,unit,target,ok"]
    lines += [",".join(cell(v) for v in (r.stage, r.metric, f"{r.value:.6g}", r.unit, r.target,
                                         "" if r.ok is None else int(r.ok))) for r in rows]
    atomic_write_text(path, "\n".join(lines) + "\n")


def read_accuracy_csv(path: Path) -> dict[tuple[str, str], float]:
    """{(stage, metric): value} from :func:`write_accuracy_csv`."""
    with open(path, newline="") as f:
        return {(r["stage"], r["metric"]): float(r["value"]) for r in csv.DictReader(f)}


def value_text(row: AccuracyRow) -> str:
    """The row's value with its unit (4 significant digits); ``-`` when it could not be measured."""
    return "-" if math.isnan(row.value) else f"{row.value:.4g} {row.unit}".rstrip()


def check_line(row: AccuracyRow) -> str:
    """One check as a sentence: ``stage: metric is value unit (expected target)``; a figure that could not
    be measured (NaN) says so, and an empty target is left out."""
    value = "not measured" if math.isnan(row.value) else value_text(row)
    expected = f" (expected {row.target})" if row.target else ""
    return f"{row.stage}: {row.metric} is {value}{expected}"


def in_range(value: float, lo: float, hi: float) -> bool:
    return bool(lo <= value <= hi)
