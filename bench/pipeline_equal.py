"""Whether two `gtrig run` output folders hold the same results (a refactor changes no number).

Compares, between a reference folder (e.g. the pipeline's outputs at a branch point) and a new one: the
bytes of the pose tracks' TUM files, the calibrated rig, the markers file and the survey's tables; the
covariance CSVs' stamps and values (any layout gtrig.io.posetrack reads: the old GTvision layout wrote
``repr`` floats, compared bit for bit; the old GTlaser one ``%.6e``, compared to that precision); and
``accuracy.csv`` line by line when both have it.

    python bench/pipeline_equal.py REFERENCE_DIR NEW_DIR

Exit code 0 when everything agrees, 1 otherwise.
"""

from __future__ import annotations

import argparse
import logging
import sys
from pathlib import Path

import numpy as np

from gtrig.io.posetrack import read_covariance_csv

FILES = ("gt_vision_validation.tum", "gt_vision_run.tum", "gt_laser.tum", "rig.calibrated.yaml", "markers.yaml",
         "survey/world_points.csv", "survey/validation_poses.csv")
COVARIANCES = ("gt_vision_validation_cov.csv", "gt_vision_run_cov.csv", "gt_laser_cov.csv")


def _old_laser_layout(path: Path) -> bool:
    return path.read_text(encoding="utf-8").startswith("timestamp,x,y,theta,cov_xx")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("reference", type=Path)
    ap.add_argument("new", type=Path)
    a = ap.parse_args()
    logging.basicConfig(level=logging.ERROR)  # the old layouts' deprecation warnings
    same = True
    for n in FILES:
        x, y = (a.reference / n).read_bytes(), (a.new / n).read_bytes()
        same &= x == y
        print(f"{n}: {'identical bytes' if x == y else 'DIFFERENT'} ({len(x)} bytes)")
    for n in COVARIANCES:
        sa, ca, ka, *_ = read_covariance_csv(a.reference / n)
        sb, cb, kb, status, *_ = read_covariance_csv(a.new / n)
        stamps = bool(np.array_equal(sa, sb))
        if _old_laser_layout(a.reference / n) and not _old_laser_layout(a.new / n):
            rel = float(np.max(np.abs(ca - cb) / np.maximum(np.abs(cb), 1e-300)))
            ok = stamps and rel < 5e-7 + 1e-12
            print(f"{n}: {len(sa)} rows, stamps equal {stamps}, {ka} -> {kb}, max relative difference {rel:.2e} "
                  f"(the old layout's %.6e), statuses {sorted(set(status.tolist()))}")
        else:
            ok = stamps and bool(np.array_equal(ca, cb))
            print(f"{n}: {len(sa)} rows, stamps equal {stamps}, {ka} -> {kb}, values bit-identical {ok}")
        same &= ok
    ra, rb = a.reference / "accuracy.csv", a.new / "accuracy.csv"
    if ra.exists() and rb.exists():
        x, y = ra.read_text().splitlines(), rb.read_text().splitlines()
        same &= x == y
        print(f"accuracy.csv: {'identical' if x == y else 'DIFFERENT'} ({len(x) - 1} rows)")
        for lx, ly in zip(x, y, strict=False):
            if lx != ly:
                print(f"  reference: {lx}\n  new:       {ly}")
    else:
        print(f"accuracy.csv: in reference {ra.exists()}, in new {rb.exists()}")
    return 0 if same else 1


if __name__ == "__main__":
    sys.exit(main())
