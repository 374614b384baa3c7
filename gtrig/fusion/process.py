"""Process models: odometry increments with slip noise, or constant velocity when no odometry is given.

Odometry (Borenstein and Feng 1996, UMBmark): systematic errors are the parameters of the chain (a
distance scale, a turn-rate scale and a curvature per metre from unequal wheel radii; see
gtrig.fusion.kernels); non-systematic errors (wheel slip) are process noise whose variance grows with
the distance each wheel rolls. Wheel encoders count nothing while the robot stands and their
quantisation is bounded (a tick, never a random walk), so the stated floor per second is only what keeps
the increments' covariances positive definite. A robot that drifts with time shows it on a long run,
where fusion fits the slip and the floor (gtrig.fusion.odonoise).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from gtrig.io.odometry import OdometryLog


@dataclass(frozen=True)
class OdometryNoise:
    """Odometry's random errors and the prior on its systematic ones. Fusion fits the slip and the floors
    on the run (``FusionOptions.fit_odometry_noise``, gtrig.fusion.odonoise): these values are the fit's
    start and the model of a run too short to fit. The slip and the floors are what the GT room's
    simulated robot draws (gtrig.sim.odometry: 2 mm per sqrt(m) of each wheel's travel, 4096-tick
    encoders, nothing while standing): with floors of 0.5 mm and 0.5 mrad per sqrt(s), poses bridged
    through 3 s gaps on its 75 s runs had NEES/dof 0.51-0.73 (0.72-0.85 with these). The side slip is
    none in that robot's wheels, yet without it the bridged poses of a path turning at up to 0.9 rad/s
    are too confident (NEES/dof 3.1, 0.96 with it; tests/fusion/test_odometry_noise.py): it stands for
    what the increments' model misses in turns.

    Attributes
    ----------
    slip_m_per_sqrt_m : each wheel's travel error, metres per square root of metre rolled.
    wheelbase_m : distance between the wheels (turns the wheels' slip into heading noise).
    lateral_ratio : side slip as a fraction of the forward slip.
    floor_m_per_sqrt_s, floor_rad_per_sqrt_s : noise floor per square root of second, even standing
        (stated: the fit's smallest, :data:`gtrig.fusion.odonoise.FLOOR_SIGMA`; over a 3 s gap 0.17 mm and
        0.17 mrad, the size of the encoders' quantisation, 0.15 mm a tick).
    sigma_dist_scale, sigma_turn_scale : prior sigmas of the distance and turn-rate scales (around 1).
    sigma_curv_rad_per_m : prior sigma of the curvature bias (around 0).
    """

    slip_m_per_sqrt_m: float = 0.002
    wheelbase_m: float = 0.5
    lateral_ratio: float = 0.5
    floor_m_per_sqrt_s: float = 0.0001
    floor_rad_per_sqrt_s: float = 0.0001
    sigma_dist_scale: float = 0.05
    sigma_turn_scale: float = 0.05
    sigma_curv_rad_per_m: float = 0.02

    def prior(self) -> tuple[np.ndarray, np.ndarray]:
        """Mean (3,) and covariance (3, 3) of ``(k_dist, k_turn, k_curv)``."""
        s = np.array([self.sigma_dist_scale, self.sigma_turn_scale, self.sigma_curv_rad_per_m])
        return np.array([1.0, 1.0, 0.0]), np.diag(s**2)


@dataclass(frozen=True)
class ConstantVelocityNoise:
    """White-noise acceleration: spectral densities of the linear (m^2/s^3) and angular (rad^2/s^3)
    accelerations; a walking-pace robot accelerates by about 0.5 m/s^2 and 1 rad/s^2."""

    q_linear: float = 0.25
    q_angular: float = 1.0


def interpolate_odometry(log: OdometryLog, stamps_s: np.ndarray) -> np.ndarray:
    """(N, 3) odometry poses at ``stamps_s`` (linear in x, y and the unwrapped heading)."""
    th = np.unwrap(log.xytheta[:, 2])
    return np.column_stack([np.interp(stamps_s, log.stamps_s, log.xytheta[:, 0]),
                            np.interp(stamps_s, log.stamps_s, log.xytheta[:, 1]),
                            np.interp(stamps_s, log.stamps_s, th)])


def wheel_travel(u: np.ndarray, wheelbase_m: float) -> tuple[np.ndarray, np.ndarray]:
    """How far (m, >= 0) the right and the left wheel roll over each increment ``u`` (N-1, 3) (robot frame,
    m, m, rad) of a differential drive with that wheelbase: the two (N-1,) arrays."""
    ds = np.hypot(u[:, 0], u[:, 1])
    half_b = wheelbase_m / 2
    return np.abs(ds + u[:, 2] * half_b), np.abs(ds - u[:, 2] * half_b)


def odometry_increments(xytheta: np.ndarray, stamps_s: np.ndarray, noise: OdometryNoise,
                        ) -> tuple[np.ndarray, np.ndarray]:
    """Robot-frame increments between consecutive odometry poses and their noise.

    Parameters
    ----------
    xytheta : (N, 3) odometry poses (its own frame), heading unwrapped.
    stamps_s : (N,) their stamps.
    noise : the slip model.

    Returns
    -------
    u : (N-1, 3) increments ``(dx, dy, dyaw)`` in the frame of the earlier pose (m, m, rad).
    cov : (N-1, 3, 3) their covariance.
    """
    d = np.diff(xytheta, axis=0)
    c, s = np.cos(xytheta[:-1, 2]), np.sin(xytheta[:-1, 2])
    u = np.column_stack([c * d[:, 0] + s * d[:, 1], -s * d[:, 0] + c * d[:, 1], d[:, 2]])
    wr, wl = wheel_travel(u, noise.wheelbase_m)
    s2 = noise.slip_m_per_sqrt_m**2
    dt = np.diff(stamps_s)
    var_fwd = s2 * (wr + wl) / 4 + noise.floor_m_per_sqrt_s**2 * dt
    var_lat = noise.lateral_ratio**2 * s2 * (wr + wl) / 4 + noise.floor_m_per_sqrt_s**2 * dt
    var_th = s2 * (wr + wl) / noise.wheelbase_m**2 + noise.floor_rad_per_sqrt_s**2 * dt
    cov_fth = s2 * (wr - wl) / (2 * noise.wheelbase_m)
    cov = np.zeros((len(u), 3, 3))
    cov[:, 0, 0] = var_fwd
    cov[:, 1, 1] = var_lat
    cov[:, 2, 2] = var_th
    cov[:, 0, 2] = cov[:, 2, 0] = cov_fth
    return u, cov


@dataclass(frozen=True)
class OdometryJumps:
    """What odometry increment is no motion but a jump: an odometry reset (back to zero), a relocalised
    or restarted driver, a recording cut and joined (laps), a gross slip. An increment is a jump when
    its length exceeds ``max_speed_mps * dt + tol_m`` or its turn ``max_yaw_rate_radps * dt + tol_rad``:
    faster than the robot can move.

    Attributes
    ----------
    max_speed_mps, max_yaw_rate_radps : the fastest the robot moves and turns (m/s, rad/s).
    tol_m, tol_rad : what one increment may add to that (stamp jitter, quantisation).
    """

    max_speed_mps: float = 3.0
    max_yaw_rate_radps: float = 6.0
    tol_m: float = 0.02
    tol_rad: float = 0.05


def odometry_jumps(u: np.ndarray, dt_s: np.ndarray, jumps: OdometryJumps) -> np.ndarray:
    """(N-1,) which increments ``u`` (N-1, 3) (robot frame, m, m, rad) over ``dt_s`` (N-1,) are jumps."""
    dist = np.hypot(u[:, 0], u[:, 1])
    turn = np.abs(u[:, 2])
    return (dist > jumps.max_speed_mps * dt_s + jumps.tol_m) | (turn > jumps.max_yaw_rate_radps * dt_s + jumps.tol_rad)


#: an increment across a jump: no motion, with this standard deviation (m, rad): it ties nothing that the
#: fixes do not set (10 m against their millimetres: a pull of 1e-8 of the jump; a full turn in heading),
#: and the gate still lets the first fix after any jump within the room in (4.6 sigma: 46 m). Larger
#: sigmas leave the solvers with variances 1e12 times their fixes': at 100 m and 10 rad the filter and the
#: batch solve of a lapped 10 minutes lost positive definiteness (bench/fusion.py --recording)
JUMP_SIGMA = (10.0, 10.0, 2.0 * np.pi)


def cut_at_jumps(u: np.ndarray, cov: np.ndarray, jump: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Increments (N-1, 3) and covariances (N-1, 3, 3) with each jump's made a new odometry segment's
    start: zero motion, uninformative (:data:`JUMP_SIGMA`), so the poses on either side are tied by the
    fixes alone, not pulled towards the jump."""
    if not jump.any():
        return u, cov
    u, cov = u.copy(), cov.copy()
    u[jump] = 0.0
    cov[jump] = np.diag(np.square(JUMP_SIGMA))
    return u, cov


def constant_velocity_cov(dts: np.ndarray, noise: ConstantVelocityNoise) -> np.ndarray:
    """(N-1, 6, 6) covariance of the constant-velocity residual over steps ``dts`` (white-noise
    acceleration, Bar-Shalom's discretisation)."""
    q = np.array([noise.q_linear, noise.q_linear, noise.q_angular])
    dt = np.asarray(dts, float)[:, None]
    cov = np.zeros((dt.size, 6, 6))
    i = np.arange(3)
    cov[:, i, i] = q * dt**3 / 3
    cov[:, i, i + 3] = cov[:, i + 3, i] = q * dt**2 / 2
    cov[:, i + 3, i + 3] = q * dt
    return cov


#: matrices per slice in :func:`whitening` (and the filter's process covariances): their LAPACK temporaries
#: stay a slice's
CHUNK = 4096


def whitening(cov: np.ndarray) -> np.ndarray:
    """(N, k, k) upper factors W with W^T W = cov^-1 (so W r is standard normal), C-contiguous.

    Slice by slice (each matrix is factored on its own, so the values are those of one call on all): the
    inverse and its Cholesky factor are temporaries of a slice, not of all N."""
    cov = np.asarray(cov, float)
    out = np.empty(cov.shape)
    for a in range(0, cov.shape[0], CHUNK):
        L = np.linalg.cholesky(np.linalg.inv(cov[a:a + CHUNK]))  # info = L L^T
        out[a:a + CHUNK] = np.swapaxes(L, 1, 2)
    return out

