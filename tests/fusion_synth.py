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


def long_run(minutes: float, vision_hz: float = 10.0, laser_hz: float = 75.0, odometry_hz: float = 50.0,
             seed: int = 0, t0_s: float = 1000.0) -> tuple[OdometryLog, PoseTrack, PoseTrack]:
    """A run of any length at a recording's rates, cheap to make (no simulator): a smooth closed path
    (two incommensurate sines in a 4 m x 3 m room, heading along the motion, about 0.3 m/s), wheel
    odometry with a 0.7 % distance scale and 0.2 % turn scale error plus increment noise, GTvision and
    GTlaser fixes drawn around the truth (vision stamps jittered by 1 ms).

    Returns
    -------
    odometry : at ``odometry_hz`` from ``t0_s`` for ``minutes``; vision, laser : ``PoseTrack`` (planar,
    ``xyyaw`` covariances) inside that span, metres and radians.
    """
    rng = np.random.default_rng(seed)
    t = t0_s + np.arange(0.0, 60.0 * minutes, 1.0 / odometry_hz)

    def truth(s: np.ndarray) -> np.ndarray:
        u = s - t0_s
        x, y = 1.8 * np.sin(0.11 * u), 1.3 * np.sin(0.17 * u + 0.4)
        dx, dy = 1.8 * 0.11 * np.cos(0.11 * u), 1.3 * 0.17 * np.cos(0.17 * u + 0.4)
        return np.column_stack([x, y, np.unwrap(np.arctan2(dy, dx))])

    xyt = truth(t)
    # the robot-frame increments, then dead reckoning with the scale errors and increment noise
    d = np.diff(xyt, axis=0)
    c, s = np.cos(xyt[:-1, 2]), np.sin(xyt[:-1, 2])
    u = np.column_stack([c * d[:, 0] + s * d[:, 1], -s * d[:, 0] + c * d[:, 1], d[:, 2]])
    u *= np.array([1.007, 1.007, 0.998])
    u += rng.normal(0.0, 1.0, u.shape) * np.array([2e-5, 2e-5, 5e-5])
    odo = np.zeros_like(xyt)
    odo[1:, 2] = np.cumsum(u[:, 2])
    ch, sh = np.cos(odo[:-1, 2]), np.sin(odo[:-1, 2])
    odo[1:, 0] = np.cumsum(ch * u[:, 0] - sh * u[:, 1])
    odo[1:, 1] = np.cumsum(sh * u[:, 0] + ch * u[:, 1])
    dt = 1.0 / odometry_hz
    odometry = OdometryLog(t, odo, np.r_[0.0, np.hypot(u[:, 0], u[:, 1]) / dt], np.r_[0.0, u[:, 2] / dt])

    def fixes(rate: float, first: float, sig: tuple[float, float, float], jitter: float) -> PoseTrack:
        st = np.arange(t[0] + first, t[-1] - 0.01, 1.0 / rate)
        st = np.sort(st + rng.normal(0.0, jitter, st.size)) if jitter else st
        cov = np.diag(np.square(sig))
        z = truth(st) + rng.normal(0.0, 1.0, (st.size, 3)) * np.asarray(sig)
        return PoseTrack.from_xytheta(st, z, cov=np.broadcast_to(cov, (st.size, 3, 3)).copy())

    vision = fixes(vision_hz, 0.013, (0.002, 0.002, 0.0007), 0.001)
    laser = fixes(laser_hz, 0.007, (0.0012, 0.0012, 0.0025), 0.0)
    return odometry, vision, laser
