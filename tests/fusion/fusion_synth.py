"""A synthetic run for fusion tests: the simulator's path and odometry, fixes drawn around the truth."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pytest

from gtrig.io.odometry import OdometryLog
from gtrig.sim.floor import Floor
from gtrig.sim.gtroom import continuous_path
from gtrig.sim.motion import RobotMotion
from gtrig.sim.odometry import OdometryErrors, simulate_odometry
from gtrig.trajectory import PoseTrack


@dataclass(frozen=True)
class Run:
    motion: RobotMotion
    odometry: OdometryLog
    vision: PoseTrack
    laser: PoseTrack


def draw_fixes(motion: RobotMotion, stamps: np.ndarray, sig: tuple[float, float, float], rng: np.random.Generator,
               source: str) -> PoseTrack:
    truth = motion.planar(stamps)
    cov = np.diag(np.square(sig))
    z = truth + rng.multivariate_normal(np.zeros(3), cov, stamps.size)
    return PoseTrack.from_xytheta(stamps, z, cov=np.tile(cov, (stamps.size, 1, 1)), source=source)


@pytest.fixture(scope="session")
def run() -> Run:
    rng = np.random.default_rng(5)
    st, xyth = continuous_path(duration_s=30.0)
    motion = RobotMotion(st + 100.0, xyth, Floor.flat())
    t0, t1 = motion.stamps_s[0], motion.stamps_s[-1]
    errors = OdometryErrors(scale=0.007, differential=-0.002, wheelbase=0.007, slip_sigma_m=0.002, ticks_per_rev=4096)
    odo = simulate_odometry(motion, t0, t1, 50.0, errors, rng)
    vis_t = np.arange(t0 + 0.013, t1 - 0.01, 0.1) + rng.normal(0, 0.001, int(np.ceil((t1 - t0 - 0.023) / 0.1)))
    las_t = np.arange(t0 + 0.007, t1 - 0.01, 1 / 75)
    vision = draw_fixes(motion, np.sort(vis_t), (0.002, 0.002, 0.0007), rng, "vision")
    laser = draw_fixes(motion, las_t, (0.0012, 0.0012, 0.0025), rng, "laser")
    return Run(motion, odo, vision, laser)


def planar_errors(track: PoseTrack, motion: RobotMotion) -> np.ndarray:
    """(N, 3) estimate - truth, yaw wrapped."""
    e = track.xytheta() - motion.planar(track.stamps_s)
    e[:, 2] = (e[:, 2] + np.pi) % (2 * np.pi) - np.pi
    return e


def nees(track: PoseTrack, motion: RobotMotion) -> np.ndarray:
    e = planar_errors(track, motion)
    assert track.cov is not None
    return np.einsum("ni,nij,nj->n", e, np.linalg.inv(track.cov), e)
