"""Reading GTvision's checkpoint of detections (``gt_vision_<sequence>.checkpoint``, JSON lines) outside
GTvision: the time sync's camera fits and the report's coverage read its records in order."""

from __future__ import annotations

import json
import os
from collections.abc import Iterator
from typing import Any


def checkpoint_records(path: str | os.PathLike[str]) -> Iterator[Any]:
    """The records after the header line (the detections' key), parsed, in order; the reading stops at a
    line an interruption cut (not JSON)."""
    with open(path, encoding="utf-8") as f:
        f.readline()
        for line in f:
            try:
                yield json.loads(line)
            except json.JSONDecodeError:
                return
