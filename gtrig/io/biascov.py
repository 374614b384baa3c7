"""``*_bias.yaml``: the covariance of the error a GT source's poses share over a whole run (its calibration),
as the GTlaser and GTvision stages write it beside their tracks and fusion reads it (docs/fusion.md)::

    format: gtrig run-constant error v1
    source: GTlaser
    frame_id: world
    axes: [x, y, yaw]                 # m, m, rad (a position source: [x, y])
    cov: [[1.2e-06, ...], ...]        # the sum of the terms
    terms:                            # what it is made of, each over the same axes
      scanners' calibration: [[...], ...]
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from pathlib import Path

import numpy as np
import yaml

from gtrig.errors import FormatError
from gtrig.io.atomic import atomic_write_text
from gtrig.io.yamlfile import load_yaml

FORMAT = "gtrig run-constant error v1"
AXES = {3: ["x", "y", "yaw"], 2: ["x", "y"]}


def bias_cov_text(source: str, terms: Mapping[str, np.ndarray]) -> str:
    """The file's text: ``terms`` (name: (k, k) covariance, k = 3 or 2, world axes) and their sum."""
    mats = {k: np.asarray(v, float) for k, v in terms.items()}
    k = next(iter(mats.values())).shape[0] if mats else 3
    total = sum(mats.values(), np.zeros((k, k)))
    doc = {"format": FORMAT, "source": source, "frame_id": "world", "axes": AXES[k],
           "cov": total.tolist(), "terms": {n: m.tolist() for n, m in mats.items()}}
    return yaml.safe_dump(doc, sort_keys=False)


def write_bias_cov(path: str | os.PathLike[str], source: str, terms: Mapping[str, np.ndarray]) -> None:
    atomic_write_text(path, bias_cov_text(source, terms))


def read_bias_cov(path: str | os.PathLike[str]) -> np.ndarray:
    """The covariance (k, k) of ``path``, checked: the format line, axes x, y[, yaw], finite, symmetric,
    positive semi-definite."""
    p = Path(path)
    doc = load_yaml(p)
    if not isinstance(doc, dict) or doc.get("format") != FORMAT:
        raise FormatError(f"{p}: not a '{FORMAT}' file (its 'format' line)")
    axes = doc.get("axes")
    if not isinstance(axes, list) or axes not in AXES.values():
        raise FormatError(f"{p}: axes must be [x, y, yaw] or [x, y], got {axes!r}")
    if doc.get("frame_id", "world") != "world":
        raise FormatError(f"{p}: frame_id must be world, got {doc.get('frame_id')!r}")
    try:
        cov = np.array(doc.get("cov"), dtype=float)
    except (TypeError, ValueError):
        raise FormatError(f"{p}: cov: not a matrix of numbers") from None
    k = len(axes)
    if cov.shape != (k, k) or not np.all(np.isfinite(cov)):
        raise FormatError(f"{p}: cov must be {k} x {k} finite numbers")
    scale = max(float(np.abs(cov).max()), 1e-300)
    if not np.allclose(cov, cov.T, rtol=1e-9, atol=1e-12 * scale) or np.linalg.eigvalsh(cov).min() < -1e-9 * scale:
        raise FormatError(f"{p}: cov is not symmetric positive semi-definite")
    return 0.5 * (cov + cov.T)
