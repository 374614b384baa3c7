"""Consecutive instants started from the last localized pose, and the compiled projection they rely on."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from gtrig import geometry as geo
from gtrig.sim.gtroom import VALIDATION_POSES, continuous_path, make_scene
from gtrig.vision import estimate as estimate_module
from gtrig.vision.covariance import RigUncertainty
from gtrig.vision.estimate import FrameEstimate, Status, VisionOptions, estimate_consecutive, estimate_frame
from gtrig.vision.observations import FrameObservations, VisionModel, stack_corners
from gtrig.vision.projection import project_pose, project_pose_numpy
from gtrig.vision.synthetic import CornerNoise, synthetic_observations

OPTS = VisionOptions(planar=True, rig_uncertainty=RigUncertainty())


@pytest.fixture(scope="module")
def scene():
    return make_scene(1)


def _run(scene, n: int, rate_hz: float = 10.0) -> tuple[list[np.ndarray], list[FrameObservations]]:
    """``n`` instants of the continuous run with a marker in view: every camera at ``rate_hz``, each a
    quarter period after the one before (unsynchronised cameras: one instant per image), noisy corners."""
    rng = np.random.default_rng(7)
    stamps, xyth = continuous_path(rate_hz=4 * rate_hz)
    cams = [c.name for c in scene.rig_true.cameras]
    Ts, obs = [], []
    for k in range(len(stamps)):
        T = scene.T_world_robot(*xyth[k])
        o = synthetic_observations(scene.rig_true, T, float(stamps[k]), rng, CornerNoise(sigma_px=0.15),
                                   cameras=(cams[k % len(cams)],))
        if o.views:
            Ts.append(T)
            obs.append(o)
        if len(obs) == n:
            break
    return Ts, obs


def test_compiled_projection_matches_its_numpy_form(scene):
    rng = np.random.default_rng(3)
    model = VisionModel.from_rig(scene.rig_true)
    T = scene.T_world_robot(*VALIDATION_POSES[5])
    obs = synthetic_observations(scene.rig_true, T, 0.0, rng)
    sc = stack_corners(model, obs.views)
    n = sc.uv.shape[0]
    # a strong rational lens with tangential terms and skew, so that every term of the model counts
    sc = replace(sc, dist=np.tile([-0.3, 0.12, 1e-3, -2e-3, -0.02, 0.05, -0.01, 0.002], (n, 1)),
                 skew=np.full(n, 0.7))
    for _ in range(5):
        Tx = T @ geo.T_from_xyz_rpy(rng.normal(0, 0.05, 3), rng.normal(0, 0.05, 3))
        for jac in (True, False):
            got, ref = project_pose(sc, Tx, jac), project_pose_numpy(sc, Tx, jac)
            np.testing.assert_allclose(got[0], ref[0], rtol=1e-12, atol=1e-9)
            np.testing.assert_allclose(got[1], ref[1], rtol=1e-12, atol=1e-12)
            if jac:
                np.testing.assert_allclose(got[2], ref[2], rtol=1e-10, atol=1e-9)
            else:
                assert got[2] is None


def test_consecutive_instants_follow_and_agree_with_the_full_search(scene, monkeypatch):
    model = VisionModel.from_rig(scene.rig_true)
    Ts, obs = _run(scene, 24)
    searched = [estimate_frame(model, o, OPTS) for o in obs]
    calls = []
    real = estimate_module.initial_pose
    monkeypatch.setattr(estimate_module, "initial_pose", lambda *a, **k: calls.append(1) or real(*a, **k))
    followed = estimate_consecutive(model, obs, OPTS)
    assert len(calls) <= len(obs) // 3  # most instants start from the one before, not from a search
    assert [e.status for e in followed] == [e.status for e in searched]
    n_ok = 0
    for a, b, T in zip(searched, followed, Ts, strict=True):
        if not b.ok:
            continue
        n_ok += 1
        dt, dr = geo.pose_error(a.T_world_robot, b.T_world_robot)
        assert dt < 5e-5 and dr < 5e-5  # the same minimum (its nuisances linearised elsewhere: 0.01 mm)
        # the rig's nuisances are linearised at the fit's start pose (the instant before, 25 ms away, or
        # the refined candidate): the covariances differ by about a per cent, never more than a few
        sd_a, sd_b = np.sqrt(np.diag(a.cov_6x6)), np.sqrt(np.diag(b.cov_6x6))
        np.testing.assert_allclose(sd_b, sd_a, rtol=0.03)
        assert geo.pose_error(b.T_world_robot, T)[0] < 0.01
    assert n_ok >= len(obs) - 2
    # the first instant of a list is searched whatever came before it: a list's estimates are its own
    again = estimate_consecutive(model, obs[5:], OPTS)
    assert np.array_equal(again[0].T_world_robot, searched[5].T_world_robot)


def test_a_follow_that_does_not_hold_gives_way_to_the_search(scene):
    model = VisionModel.from_rig(scene.rig_true)
    _, obs = _run(scene, 3)
    o = obs[1]
    ref = estimate_frame(model, o, OPTS)
    assert ref.ok
    # a pose half a metre and 40 degrees away (an instant long before, a gap in the stamps) and the
    # marker's mirrored flip: both end in the searched pose, exactly
    far = ref.T_world_robot @ geo.T_from_xyz_rpy([0.5, 0.0, 0.0], [0.0, 0.0, math.radians(40.0)])
    tilted = ref.T_world_robot @ geo.T_from_xyz_rpy([0.0, 0.0, 0.0], [math.radians(35.0), 0.0, 0.0])
    for T_bad in (far, tilted):
        e = estimate_frame(model, o, OPTS, follow=FrameEstimate(o.stamp_s - 0.1, Status.OK, T_world_robot=T_bad,
                                                                 flip_margin=50.0))
        assert e.status is ref.status
        np.testing.assert_array_equal(e.T_world_robot, ref.T_world_robot)
        assert e.flip_margin == ref.flip_margin
    # instants further apart than follow_max_gap_s are searched each
    spread = [replace(x, stamp_s=10.0 * i) for i, x in enumerate(obs)]
    for a, b in zip(estimate_consecutive(model, spread, OPTS), [estimate_frame(model, x, OPTS) for x in spread],
                    strict=True):
        np.testing.assert_array_equal(a.T_world_robot, b.T_world_robot)
