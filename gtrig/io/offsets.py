"""``sync.yaml``: clock offsets per source, as ``gtrig sync`` writes them and ``gtrig fuse --sync`` reads them.

::

    reference: odometry
    convention: offset_s = source stamp - reference stamp of the same instant
    sources:
      vision: {verdict: ok, offset_s: 0.0012, ci95_s: [0.0001, 0.0023], ...}
      laser: {verdict: unobservable, offset_s: null, ...}
"""

from __future__ import annotations

import math
import os
from pathlib import Path

import yaml

from gtrig.errors import FormatError
from gtrig.io.atomic import atomic_write_text
from gtrig.io.text import read_text
from gtrig.io.yamlfile import safe_load

CONVENTION = "offset_s = source stamp - reference stamp of the same instant"

#: scipy.stats.norm.ppf(0.975): a 95 % interval's half-width in standard deviations
Z95 = 1.959963984540054


def sigma_from_ci95(ci95_s: object) -> float | None:
    """The standard deviation (s) of an offset whose 95 % interval is ``ci95_s = (low, high)``: its
    half-width / :data:`Z95`; None when the interval is missing, not two finite numbers, or reversed."""
    try:
        lo, hi = float(ci95_s[0]), float(ci95_s[1])  # type: ignore[index]
    except (TypeError, ValueError, IndexError, KeyError):
        return None
    if not (math.isfinite(lo) and math.isfinite(hi) and hi >= lo):
        return None
    return (hi - lo) / 2 / Z95


def write_offsets(path: str | os.PathLike[str], reference: str, sources: dict[str, dict[str, object]]) -> None:
    doc = {"reference": reference, "convention": CONVENTION, "sources": sources}
    atomic_write_text(path, yaml.safe_dump(doc, sort_keys=False))


def read_offsets(path: str | os.PathLike[str]) -> dict[str, float]:
    """Offsets (seconds) of the sources whose verdict is ``ok``; the others are left out (no number)."""
    p = Path(path)
    try:
        doc = safe_load(read_text(p, "YAML file"))
    except FileNotFoundError:
        raise FormatError(f"{p}: no such file") from None
    except yaml.YAMLError as e:
        raise FormatError(f"{p}: not YAML ({str(e).splitlines()[0]})") from None
    if not isinstance(doc, dict) or not isinstance(doc.get("sources"), dict):
        raise FormatError(f"{p}: no 'sources' mapping")
    out: dict[str, float] = {}
    for name, v in doc["sources"].items():
        if not isinstance(v, dict) or "verdict" not in v:
            raise FormatError(f"{p}: sources.{name}: needs a verdict")
        if v["verdict"] == "ok" and not (v.get("offset_s") is None and "offset_to_vision_s" in v):
            # (a camera's or scanner's entry without an offset to the reference is no source's offset)
            try:
                out[str(name)] = float(v["offset_s"])
            except (TypeError, ValueError, KeyError):
                raise FormatError(f"{p}: sources.{name}.offset_s: not a number") from None
            if not abs(out[str(name)]) <= 86400.0:  # NaN fails too
                raise FormatError(f"{p}: sources.{name}.offset_s: {v['offset_s']} is not a finite offset within a day")
    return out
