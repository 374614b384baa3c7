"""Run-constant source biases considered in the fused covariance (Schmidt; gtrig.fusion.batch)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from fusion_synth import draw_fixes, nees

from gtrig.errors import InputError
from gtrig.fusion import FusionOptions, fixes_from_track, fuse
from gtrig.sim.floor import Floor
from gtrig.sim.gtroom import continuous_path
from gtrig.sim.motion import RobotMotion
from gtrig.sim.odometry import OdometryErrors, simulate_odometry
from gtrig.trajectory import PoseTrack

#: each source's run-constant error (its calibration), world x, y (m) and yaw (rad): larger than what
#: averaging a 20 s run of white fix noise leaves, as on the short-calibration recordings
BIAS = {"vision": np.diag([0.0008, 0.0008, 0.0003]) ** 2, "laser": np.diag([0.0010, 0.0010, 0.0005]) ** 2}


@pytest.fixture(scope="module")
def motion() -> RobotMotion:
    st, xyth = continuous_path(duration_s=20.0)
    return RobotMotion(st + 100.0, xyth, Floor.flat())


def _biased_run(motion: RobotMotion, seed: int) -> tuple[list, object]:  # noqa: ANN001
    """Odometry and two sources whose fixes carry white noise (as stated) plus one bias drawn from BIAS."""
    rng = np.random.default_rng(seed)
    t0, t1 = motion.stamps_s[0], motion.stamps_s[-1]
    errors = OdometryErrors(scale=0.007, differential=-0.002, wheelbase=0.007, slip_sigma_m=0.002, ticks_per_rev=4096)
    odo = simulate_odometry(motion, t0, t1, 50.0, errors, rng)
    fixes = []
    for name, rate, sig in (("vision", 10.0, (0.002, 0.002, 0.0007)), ("laser", 75.0, (0.0012, 0.0012, 0.0025))):
        t = draw_fixes(motion, np.arange(t0 + 0.01, t1 - 0.01, 1 / rate), sig, rng, name)
        b = rng.multivariate_normal(np.zeros(3), BIAS[name])
        fixes.append(fixes_from_track(PoseTrack.from_xytheta(t.stamps_s, t.xytheta() + b, cov=t.cov, source=name)))
    return fixes, odo


@pytest.mark.parametrize("estimator", ["batch", "ekf"])
def test_considered_bias_makes_the_fused_covariance_consistent(motion: RobotMotion, estimator: str) -> None:
    # the fixes' white noise is independent here (correlation_s = 0): the bias is the only error the
    # per-fix covariances leave out, so without its term the fused covariance shrinks far below the error
    with_term, without = [], []
    for seed in range(20):
        fixes, odo = _biased_run(motion, seed)
        plain, _ = fuse(fixes, odo, FusionOptions(estimator=estimator, correlation_s=0.0))
        cons, _ = fuse(fixes, odo, FusionOptions(estimator=estimator, correlation_s=0.0, bias_cov=BIAS))
        np.testing.assert_array_equal(cons.xytheta(), plain.xytheta())  # covariances only
        without.append(nees(plain, motion).mean() / 3)
        with_term.append(nees(cons, motion).mean() / 3)
    assert 0.5 <= np.mean(with_term) <= 2.0, with_term
    assert np.mean(without) > 2.0, without


def test_the_term_is_the_solutions_response_to_the_bias(motion: RobotMotion) -> None:
    # plain least squares (no robust loss, no innovation weighting): the solution is linear in the fixes,
    # so shifting every laser fix by delta moves each node by S delta, and B = delta delta^T gives
    # S B S^T = (that move)(that move)^T
    fixes, odo = _biased_run(motion, 99)
    # the odometry's noise as stated: fitted, it would follow the moved fixes and the solution would not
    # be linear in them
    opts = FusionOptions(huber_k=0.0, innovation_window_s=0.0, fit_odometry_noise=False)
    delta = np.array([0.0015, -0.001, 0.0008])
    base, _ = fuse(fixes, odo, opts)
    las = fixes[1]
    moved = [fixes[0], type(las)(las.source, las.stamps_s, las.model, las.value + delta, las.cov, las.lever_xy)]
    shifted, _ = fuse(moved, odo, opts)
    cons, _ = fuse(fixes, odo, replace(opts, bias_cov={"laser": np.outer(delta, delta)}))
    dx = shifted.xytheta() - base.xytheta()
    term = cons.cov_xytheta() - base.cov_xytheta()
    np.testing.assert_allclose(term, dx[:, :, None] * dx[:, None, :], atol=1e-3 * float(np.abs(dx).max()) ** 2)
    assert np.abs(dx[:, :2]).max() > 0.5e-3  # the laser moved the track: the check is not empty


def test_bad_bias_covariances_are_one_line_errors(motion: RobotMotion) -> None:
    fixes, odo = _biased_run(motion, 1)
    for bad, what in (({"gps": np.eye(3)}, "no source"), ({"laser": np.eye(2)}, "need 3 x 3"),
                      ({"laser": -np.eye(3)}, "positive semi-definite")):
        with pytest.raises(InputError, match=what):
            fuse(fixes, odo, FusionOptions(bias_cov=bad))
