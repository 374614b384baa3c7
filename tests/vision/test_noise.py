"""The corner-noise model: variance factors estimated from residuals, repeated images averaged."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from gtrig.sim.gtroom import VALIDATION_POSES, make_scene
from gtrig.vision.covariance import RigUncertainty, nees, pose_error_xi
from gtrig.vision.estimate import VisionOptions, estimate_frame, merge_repeated
from gtrig.vision.noise import estimate_corner_scale, scale_change
from gtrig.vision.observations import FrameObservations, VisionModel
from gtrig.vision.sequence import calibrate_noise
from gtrig.vision.synthetic import CornerNoise, synthetic_observations


def _optimistic(obs: FrameObservations, factor: float) -> FrameObservations:
    """The same corners, but covariances ``factor`` times too small (a detector's optimism)."""
    return replace(obs, views=tuple(replace(v, corner_cov=v.corner_cov / factor) for v in obs.views))


def test_variance_factor_recovers_an_optimistic_detector_and_makes_frames_consistent():
    scene = make_scene(0)
    model = VisionModel.from_rig(scene.rig_true)
    rng = np.random.default_rng(11)
    truth, obs = [], []
    for rep in range(1):
        for k in range(26):
            T = scene.T_world_robot(*VALIDATION_POSES[k])
            for cam in scene.rig_true.cameras:  # one camera per instant, as in the run
                o = synthetic_observations(scene.rig_true, T, 100.0 * rep + k, rng, CornerNoise(0.15),
                                           cameras=(cam.name,))
                if o.views:
                    truth.append(T)
                    obs.append(_optimistic(o, 6.0))
    opts = VisionOptions(planar=True, corner_floor_px=0.0, rig_uncertainty=RigUncertainty.none())
    first = [estimate_frame(model, o, opts) for o in obs]
    # taken at its word, the optimistic detector leaves frames whose residuals say it: variance factors
    # near 6, each frame's covariance scaled by its own noisy factor
    vf = [e.variance_factor for e in first if e.ok]
    assert len(vf) >= len(obs) - 1 and 4.5 < np.mean(vf) < 7.5
    cams = sorted({c.name for c in scene.rig_true.cameras})
    opts2, history = calibrate_noise(obs, opts, cams, lambda o, x: [estimate_frame(model, v, o) for v in x],
                                     max_rounds=4)
    factors = dict(opts2.corner_scale)
    assert set(factors) == set(cams)
    assert all(4.8 < f < 7.2 for f in factors.values()), factors  # the true factor is 6
    assert len(history) == 1 or scale_change(history[-2], history[-1]) <= 0.05
    ests = [estimate_frame(model, o, opts2) for o in obs]
    ok = [e.ok for e in ests]
    assert sum(ok) >= len(obs) - 1
    ne = [nees(pose_error_xi(e.T_world_robot, T)[[0, 1, 5]], e.cov_6x6[np.ix_([0, 1, 5], [0, 1, 5])])
          for e, T in zip(ests, truth, strict=True) if e.ok]
    assert 0.7 * 3 < np.mean(ne) < 1.4 * 3


def test_scale_estimate_pools_cameras_with_little_data_caps_and_ignores_bad_entries():
    noise = [(("a", 500.0, 250.0), ("b", 3.0, 1.0)), (("a", float("nan"), 3.0),), (("a", 90.0, 10.0),)]
    s = dict(estimate_corner_scale(noise, ["a", "b", "c"], {"a": 0.5}))
    # a: (500 + 30 (the 90 capped at 3 x 10 dof)) / 260, times the factor the fits were made with
    assert s["a"] == 0.5 * 530.0 / 260.0
    assert s["b"] == s["c"] == (0.5 * 530.0 + 3.0) / 261.0  # too little data: the pooled factor
    assert estimate_corner_scale([(("a", 5.0, 2.0),)], ["a"]) == ()  # nothing to estimate from


def test_repeated_images_of_a_static_robot_are_averaged_once():
    scene = make_scene(0)
    rng = np.random.default_rng(12)
    T = scene.T_world_robot(*VALIDATION_POSES[3])
    views = []
    for f in range(10):
        o = synthetic_observations(scene.rig_true, T, 0.0, rng)
        views.extend(replace(v, frame=f) for v in o.views)
    merged = merge_repeated(views)
    keys = [(v.camera, v.marker_id) for v in merged]
    assert len(keys) == len(set(keys)) == len(views) // 10
    one = next(v for v in merged if v.camera == views[0].camera and v.marker_id == views[0].marker_id)
    same = [v.corners_px for v in views if (v.camera, v.marker_id) == (one.camera, one.marker_id)]
    np.testing.assert_allclose(one.corners_px, np.mean(same, axis=0))
    first = [v for v in views if v.frame == 0]
    assert merge_repeated(first) == first  # one image per camera: nothing to average
