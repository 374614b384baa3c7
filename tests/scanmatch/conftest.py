"""A small recording of validation stops with onboard scans (the simulator's scanners, no cameras)."""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np
import pytest

from gtrig.io.scans import write_scans
from gtrig.rig.load import dump_rig
from gtrig.sim.config import SimConfig
from gtrig.sim.gtroom import VALIDATION_POSES, make_scene
from gtrig.sim.lasers import simulate_onboard_scans
from gtrig.sim.motion import static_motion

STOPS = (0, 2, 4, 6, 14, 16, 18, 19, 20, 21, 22)  # indices into the published validation poses


@pytest.fixture(scope="session")
def stop_rec(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, np.ndarray, object]:
    """(recording folder, true stop poses (K, 3), scene)."""
    rec = tmp_path_factory.mktemp("smrec")
    scene = make_scene(5)
    poses = VALIDATION_POSES[list(STOPS)]
    motion, iv = static_motion(poses, scene.floor, 0.4)
    cfg = SimConfig(seed=5, laser={"people": 1})
    scans, _ = simulate_onboard_scans(scene, motion, iv, cfg, seed=51)
    dump_rig(scene.rig_nominal, rec / "rig.yaml")
    (rec / "validation" / "onboard").mkdir(parents=True)
    for name, log in scans.items():
        write_scans(rec / "validation" / "onboard" / f"{name}.csv", log)
    with open(rec / "validation" / "poses.csv", "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["pose", "start_s", "end_s"])
        for k, (a, b) in enumerate(iv):
            w.writerow([k + 1, f"{a:.6f}", f"{b:.6f}"])
    return rec, poses, scene
