"""Wheel odometry of a differential-drive robot, with the drift real odometry has.

Physical sources (docs/simulator.md, "Odometry and onboard scans"): the software's wheel radii and
wheelbase differ from the real ones (tyre wear and load, the contact patch's width; Borenstein and Feng's
UMBmark calls these the systematic errors: a common scale error, a right/left difference and a wheelbase
error), the wheels slip randomly on the floor (non-systematic errors, variance growing with the
distance rolled), and the encoders count whole ticks. The wheel travel is integrated in the robot's own
start frame at the odometry rate.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass

import numpy as np

from gtrig.errors import InputError
from gtrig.io.odometry import OdometryLog, write_odometry_csv
from gtrig.sim.config import SimConfig, noise_stream
from gtrig.sim.gtroom import Scene
from gtrig.sim.motion import RobotMotion

WHEEL_RADIUS_M = 0.10
WHEELBASE_M = 0.50  # the robot is 0.57 m wide
ENCODER_TICKS_PER_REV = 4096  # 1024-line quadrature encoder on the wheel axle (after the gearbox)


@dataclass(frozen=True)
class OdometryErrors:
    """How the robot's odometry is wrong. Relative errors are (believed - true) / true.

    Attributes
    ----------
    scale : common error of both wheel radii (distance scale error).
    differential : right minus left wheel radius error (makes straight lines curve).
    wheelbase : wheelbase error (scales every turn).
    slip_sigma_m : random slip of each wheel: its travel error has variance ``slip_sigma_m**2`` per
        metre rolled (units m per sqrt(m)).
    ticks_per_rev : encoder resolution; 0 for no quantisation.
    """

    scale: float = 0.0
    differential: float = 0.0
    wheelbase: float = 0.0
    slip_sigma_m: float = 0.0
    ticks_per_rev: int = 0

    @staticmethod
    def draw(rng: np.random.Generator) -> OdometryErrors:
        """A plausible robot: 0.5-1 % scale and wheelbase errors, 0.1-0.3 % right/left difference (a
        calibrated robot; uncalibrated ones reach 1 %), 2 mm per sqrt(m) of slip per wheel."""
        def signed(lo: float, hi: float) -> float:
            return float(rng.choice([-1.0, 1.0]) * rng.uniform(lo, hi))

        return OdometryErrors(scale=signed(0.005, 0.01), differential=signed(0.001, 0.003),
                              wheelbase=signed(0.005, 0.01), slip_sigma_m=0.002,
                              ticks_per_rev=ENCODER_TICKS_PER_REV)


def simulate_odometry(
    motion: RobotMotion, t0: float, t1: float, rate_hz: float, errors: OdometryErrors,
    rng: np.random.Generator,
) -> OdometryLog:
    """Dead-reckoned odometry from ``t0`` to ``t1`` at ``rate_hz``.

    Parameters
    ----------
    motion : the true motion (its planar part; the floor's tilt changes distances by < 1e-4).
    t0, t1 : seconds, recording clock.
    rate_hz : odometry rate.
    errors : the robot's odometry errors (:meth:`OdometryErrors.draw`, or ``OdometryErrors()`` for
        perfect odometry).
    rng : random slip.

    Returns
    -------
    The odometry: pose in its start frame (identity at ``t0``), and speeds over the last step
    (0 in the first row).
    """
    if not t1 > t0:
        raise InputError(f"odometry interval must have t1 > t0, got {t0}, {t1}")
    n = int(math.floor((t1 - t0) * rate_hz + 1e-9)) + 1
    stamps = t0 + np.arange(n) / rate_hz
    true = motion.planar(stamps)
    # true wheel travel per step: the chord in the robot's frame and the heading change
    dp = np.diff(true[:, :2], axis=0)
    th = true[:-1, 2]
    fwd = np.cos(th) * dp[:, 0] + np.sin(th) * dp[:, 1]
    ds_true = np.hypot(dp[:, 0], dp[:, 1]) * np.where(fwd < 0, -1.0, 1.0)
    dth_true = np.diff(true[:, 2])
    half_b = WHEELBASE_M / 2
    wheel = np.column_stack([ds_true + dth_true * half_b, ds_true - dth_true * half_b])  # right, left
    if errors.slip_sigma_m > 0:
        wheel = wheel + rng.normal(0.0, 1.0, wheel.shape) * errors.slip_sigma_m * np.sqrt(np.abs(wheel))
    if errors.ticks_per_rev > 0:
        per_tick = 2 * math.pi * WHEEL_RADIUS_M / errors.ticks_per_rev
        ticks = np.floor(np.cumsum(wheel, axis=0) / per_tick)
        wheel = np.diff(np.vstack([np.zeros((1, 2)), ticks]), axis=0) * per_tick
    # what the software believes each tick is worth, and its wheelbase
    wheel = wheel * np.array([1 + errors.scale + errors.differential / 2,
                              1 + errors.scale - errors.differential / 2])
    b_believed = WHEELBASE_M * (1 + errors.wheelbase)
    ds = wheel.mean(axis=1)
    dth = (wheel[:, 0] - wheel[:, 1]) / b_believed
    theta = np.r_[0.0, np.cumsum(dth)]
    mid = theta[:-1] + dth / 2
    x = np.r_[0.0, np.cumsum(ds * np.cos(mid))]
    y = np.r_[0.0, np.cumsum(ds * np.sin(mid))]
    v = np.r_[0.0, ds * rate_hz]
    omega = np.r_[0.0, dth * rate_hz]
    return OdometryLog(stamps, np.column_stack([x, y, theta]), v, omega)


def write_odometry(
    scene: Scene, motion: RobotMotion, t0: float, t1: float, path: str | os.PathLike[str], cfg: SimConfig,
    seed: int,
) -> OdometryErrors:
    """Write the run's odometry CSV (``stamp_s,x,y,theta,v,omega``) at ``rig.robot.odometry.rate_hz``.

    The stamps are on the robot's clock: the GT clock plus ``cfg.odometry_clock_offset_s`` (the samples
    themselves are taken at the same true instants). Returns the errors drawn from ``seed`` (the same seed
    gives the same file); ``cfg.noise_draw`` redraws the slip, never the errors.
    """
    rng = np.random.default_rng([seed, 0x0D0])
    errors = OdometryErrors.draw(rng)
    rate = scene.rig_true.robot.odometry.rate_hz
    slip = noise_stream(rng, [seed, 0x0D0], cfg.noise_draw_of("sensors"))
    log = simulate_odometry(motion, t0, t1, rate, errors, slip)
    if cfg.odometry_clock_offset_s:
        log = OdometryLog(log.stamps_s + cfg.odometry_clock_offset_s, log.xytheta, log.v_mps, log.omega_radps)
    write_odometry_csv(path, log)
    return errors
