"""What fusion's smoother makes of GTvision's and GTlaser's fixes: a steady-state smoother over odometry.

Fusion (:mod:`gtrig.fusion`) smooths the two sources' fixes with odometry between them. It counts a
source's fixes within ``FusionOptions.correlation_s`` as one independent fix (each fix's covariance times
their number), so per step of that length each source brings the information of one fix, ``inv(C)``
(a source slower than one fix per step brings its share). Between steps the robot moves by an odometry
increment whose noise is the fusion's own slip model (:func:`gtrig.fusion.process.odometry_increments`)
for the step's travel at the robot's speed and turn rate, turned into the world frame by its heading.

Far from a track's ends and at a steady speed this is a random walk observed at every step; its
Rauch-Tung-Striebel smoother has a steady state in closed form. With the step's fix covariance ``R`` and
the increment's covariance ``Q`` (both 3 x 3, x, y, yaw), the coordinates ``z = L^-1 x`` (``R = L L^T``)
that also diagonalise ``L^-1 Q L^-T`` (eigenvalues ``lam``) make three independent scalar walks of
measurement variance 1 and step variance ``lam``; each one's smoothed variance is :func:`walk_share`.

What the smoother cannot average is added after it, as fusion adds a source's run-constant error (its
considered bias): each source's persistent part (GTvision's: the markers' pose errors on the robot,
:func:`gtrig.plan.vision.marker_part`, fusion's "robot frame" bias) with the weight that source has in a
step's fix.

The clock. Fusion stamps its poses on the odometry's clock after subtracting each source's offset that
``gtrig sync`` estimated; an offset wrong by ``dt`` puts every pose ``v dt`` off along the motion, and
fusion adds ``sigma_t^2 v v^T`` to each node's covariance (``FusionOptions.offsets_sigma_s``). The plan
adds the same with ``sigma_t`` the offset's standard error :attr:`FusionPlanSettings.clock_sigma_s`. On
the GT room's runs the clock's share is most of the fused yaw's where the robot turns: the fused yaw
errors of seeds 0-2 follow the yaw rate with slopes of -0.28, -1.42 and +1.58 ms, as ``gtrig sync``'s
stated sigmas (1.52, 1.24, 1.12 ms) allow.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from gtrig.fusion.fuse import FusionOptions
from gtrig.fusion.process import OdometryNoise, odometry_increments

#: the plan's robot speed on an area grid when none is given (the GT room's runs drive at 0.3 m/s)
DEFAULT_SPEED_MPS = 0.3

#: the standard error of the clock offsets ``gtrig sync`` applies, seconds: the RMS of its stated sigmas
#: (the better-timed source's, as fusion takes it) on the GT room's 75 s runs of seeds 0-2 (1.52, 1.24,
#: 1.12 ms)
SYNC_SIGMA_S = 0.0013


@dataclass(frozen=True)
class FusionPlanSettings:
    """Fusion's model the prediction uses.

    Attributes
    ----------
    smooth : False: the two sources' information at one instant (no odometry, no neighbouring fixes).
    speed_mps : the robot's speed on an area grid, driving forward along each pose's heading, m/s (a path
        with time stamps moves at its own velocity).
    step_s : the span whose fixes count as one (fusion's ``correlation_s``), seconds.
    odometry : the odometry's noise model (fusion's).
    clock_sigma_s : the standard error of the sources' clock offsets to the odometry after ``gtrig sync``
        (fusion's ``offsets_sigma_s``, the better-timed source's), seconds; 0: clocks known exactly.
    """

    smooth: bool = True
    speed_mps: float = DEFAULT_SPEED_MPS
    step_s: float = FusionOptions().correlation_s
    odometry: OdometryNoise = field(default_factory=OdometryNoise)
    clock_sigma_s: float = SYNC_SIGMA_S


@dataclass(frozen=True)
class SourceRates:
    """Fixes per second of GTvision (None: a camera without a rate, taken as faster than one per step)
    and of GTlaser."""

    vision_hz: float | None
    laser_hz: float | None


def walk_share(lam: np.ndarray) -> np.ndarray:
    """Steady-state smoothed variance of a random walk observed at every step with variance 1, for step
    variances ``lam`` (any shape, > 0): ``P / (1 + P / (P + lam))`` with the filter's ``P`` the positive
    root of ``P^2 + lam P - lam = 0``."""
    lam = np.asarray(lam, dtype=float)
    P = 2.0 * lam / (lam + np.sqrt(lam * lam + 4.0 * lam))  # (-lam + sqrt(lam^2 + 4 lam)) / 2, without cancellation
    return P / (1.0 + P / (P + lam))


def odometry_step_covariance(heading_rad: np.ndarray, velocity_xytheta: np.ndarray, dt_s: float,
                             noise: OdometryNoise) -> np.ndarray:
    """(K, 3, 3) covariance of the odometry increment over ``dt_s`` at K poses, world frame (x, y in m, yaw in
    rad): the fusion's slip model for the travel ``|v| dt`` and turn ``omega dt`` (``velocity_xytheta``
    (K, 3), world frame, m/s and rad/s), its robot-frame axes turned by ``heading_rad`` (K,)."""
    v = np.asarray(velocity_xytheta, dtype=float)
    K = v.shape[0]
    # each pose's increment as a two-pose odometry log from the origin: the even rows of the increments
    ends = np.zeros((2 * K, 3))
    ends[1::2, 0] = np.hypot(v[:, 0], v[:, 1]) * dt_s
    ends[1::2, 2] = v[:, 2] * dt_s
    stamps = np.tile([0.0, dt_s], K)
    _, cov_robot = odometry_increments(ends, stamps, noise)
    cov_robot = cov_robot[0::2]
    c, s = np.cos(heading_rad), np.sin(heading_rad)
    R = np.zeros((K, 3, 3))
    R[:, 0, 0], R[:, 0, 1], R[:, 1, 0], R[:, 1, 1], R[:, 2, 2] = c, -s, s, c, 1.0
    return R @ cov_robot @ np.swapaxes(R, 1, 2)


def smoothed_walk_covariance(R_fix: np.ndarray, Q_step: np.ndarray) -> np.ndarray:
    """(K, 3, 3) steady-state smoothed covariance of a random walk with step covariance ``Q_step`` observed
    at every step with covariance ``R_fix`` (both (K, 3, 3), positive definite; module docstring)."""
    L = np.linalg.cholesky(R_fix)
    Li = np.linalg.inv(L)
    M = Li @ Q_step @ np.swapaxes(Li, 1, 2)
    lam, U = np.linalg.eigh(0.5 * (M + np.swapaxes(M, 1, 2)))
    LU = L @ U
    return (LU * walk_share(np.maximum(lam, 1e-300))[:, None, :]) @ np.swapaxes(LU, 1, 2)


def _information(C: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The inverse of covariances (K, 3, 3) where finite (zero elsewhere) and where they are finite (K,)."""
    ok = np.all(np.isfinite(C), axis=(1, 2))
    info = np.zeros(C.shape)
    if ok.any():
        info[ok] = np.linalg.inv(C[ok])
    return info, ok


def _per_step(rate_hz: float | None, step_s: float) -> float:
    """A source's fixes per step as fusion weighs them: one at most (those within a step count as one)."""
    return 1.0 if rate_hz is None else min(1.0, rate_hz * step_s)


def fused_covariance(cov_vision: np.ndarray, cov_laser: np.ndarray, persistent_vision: np.ndarray | None,
                     persistent_laser: np.ndarray | None, heading_rad: np.ndarray, velocity_xytheta: np.ndarray,
                     rates: SourceRates, settings: FusionPlanSettings = FusionPlanSettings()) -> np.ndarray:
    """Fusion's covariance (K, 3, 3) of x, y (m) and yaw (rad) at K poses (module docstring).

    Parameters
    ----------
    cov_vision, cov_laser : (K, 3, 3) each source's covariance at one instant, world frame; nan where it
        does not cover the pose.
    persistent_vision, persistent_laser : (K, 3, 3) the part of each source's covariance that no averaging
        removes, or None (all of it averages).
    heading_rad : (K,) the robot's headings.
    velocity_xytheta : (K, 3) the robot's velocity, world frame (m/s, rad/s).
    rates : the sources' fix rates.
    settings : fusion's model.

    Returns
    -------
    (K, 3, 3), nan where neither source covers the pose; with ``settings.smooth`` False, the inverse of
    the sum of the two informations; either with the clock's share ``clock_sigma_s^2 v v^T``.
    """
    info_v, ok_v = _information(np.asarray(cov_vision, dtype=float))
    info_l, ok_l = _information(np.asarray(cov_laser, dtype=float))
    have = ok_v | ok_l
    out = np.full(info_v.shape, np.nan)
    if not have.any():
        return out
    v = np.asarray(velocity_xytheta, dtype=float)[have]
    clock = settings.clock_sigma_s**2 * v[:, :, None] * v[:, None, :]
    if not settings.smooth:
        out[have] = np.linalg.inv(info_v[have] + info_l[have]) + clock
        return out
    w_v, w_l = _per_step(rates.vision_hz, settings.step_s), _per_step(rates.laser_hz, settings.step_s)
    R = np.linalg.inv(w_v * info_v[have] + w_l * info_l[have])
    kept = np.zeros(R.shape)
    for P_src, info, ok, w in ((persistent_vision, info_v, ok_v, w_v), (persistent_laser, info_l, ok_l, w_l)):
        if P_src is not None:
            P = np.where(ok[have, None, None], np.asarray(P_src, dtype=float)[have], 0.0)
            A = w * R @ info[have]  # the source's weight in a step's fix
            kept += A @ P @ np.swapaxes(A, 1, 2)
    Q = odometry_step_covariance(np.asarray(heading_rad, dtype=float)[have], v, settings.step_s, settings.odometry)
    out[have] = smoothed_walk_covariance(R - kept, Q) + kept + clock
    return out


def plan_velocity(heading_rad: np.ndarray, path_velocity: np.ndarray | None, speed_mps: float) -> np.ndarray:
    """(K, 3) the robot's velocity at K poses, world frame (m/s, rad/s): a path's own, or driving forward
    along each heading at ``speed_mps`` without turning."""
    if path_velocity is not None:
        return np.asarray(path_velocity, dtype=float)
    th = np.asarray(heading_rad, dtype=float)
    return np.column_stack([speed_mps * np.cos(th), speed_mps * np.sin(th), np.zeros(th.shape[0])])
