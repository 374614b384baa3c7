from __future__ import annotations

import numpy as np
import pytest

from gtrig import geometry as geo
from gtrig.laser import synth
from gtrig.rig.models import Hull, LaserScanner, Pose


def make_scanner(name: str, x: float, y: float, yaw: float, beams: int = 180) -> LaserScanner:
    inc = np.pi / beams
    return LaserScanner(
        name=name,
        T_world_scanner=Pose.from_matrix(geo.T_from_xyz_rpy([x, y, 0.25], [0, 0, yaw])),
        angle_min_rad=-np.pi / 2 + inc / 2,
        angle_increment_rad=inc,
        beams=beams,
        range_max_m=30.0,
        rate_hz=75.0,
        range_sigma_m=0.01,
    )


@pytest.fixture(scope="session")
def scanner_factory():
    return make_scanner


@pytest.fixture(scope="session")
def room():
    """A 8 x 6 m room, four scanners in its corners looking in, one box, the seeds' robot hull."""
    walls = synth.rectangle_segments([[-4, -3], [4, -3], [4, 3], [-4, 3]])
    box = synth.rectangle_segments([[2.6, -2.6], [3.4, -2.6], [3.4, -2.0], [2.6, -2.0]])
    scanners = (
        make_scanner("a", -3.6, -2.6, np.radians(35)),
        make_scanner("b", 3.6, -2.2, np.radians(150)),
        make_scanner("c", 3.6, 2.6, np.radians(-145)),
        make_scanner("d", -3.6, 2.6, np.radians(-35)),
    )
    hull = Hull(length_m=0.78, width_m=0.57, z_min_m=0.05, z_max_m=0.55)
    return {"static": np.concatenate([walls, box]), "scanners": scanners, "hull": hull, "box": box}


def agile_fixed_scans(cfg, seed: int, draw_seeds: tuple[int, int], duration_s: float = 8.0):  # noqa: ANN001, ANN201
    """The GT room configured by ``cfg`` (scene ``seed``), an agile drive at 1 m/s of ``duration_s`` through
    its validation poses, and its fixed scanners' scans of it: ``(scene, motion, runs, masks)``, the masks
    the foreground against each scanner's background second (-10 to -9 s). ``draw_seeds``: the noise draws
    of the background and of the drive."""
    from gtrig.laser.background import build_background
    from gtrig.laser.foreground import foreground_mask, foreground_threshold
    from gtrig.sim.gtroom import VALIDATION_POSES, make_scene
    from gtrig.sim.lasers import configure_scene, simulate_fixed_scans
    from gtrig.sim.motion import RobotMotion, agile_path

    sc = configure_scene(make_scene(seed), cfg)
    ts, xyth = agile_path(VALIDATION_POSES, 1.0, duration_s=duration_s)
    mot = RobotMotion(ts, xyth, sc.floor)
    bgs, _ = simulate_fixed_scans(sc, None, np.array([[-10.0, -9.0]]), cfg, draw_seeds[0])
    runs, _ = simulate_fixed_scans(sc, mot, np.array([[0.0, ts[-1]]]), cfg, draw_seeds[1])
    masks = [foreground_mask(runs[s.name].ranges_m, foreground_threshold(build_background(bgs[s.name].ranges_m, s)))
             for s in sc.rig_true.laser_scanners]
    return sc, mot, runs, masks
