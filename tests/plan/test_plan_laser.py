"""GTlaser's predicted beams and covariance against the scan simulator and the hull ICP."""

from __future__ import annotations

import numpy as np

from gtrig.laser.hull_icp import HullModel, fit_hull
from gtrig.laser.synth import cast_rays, hull_segments_world
from gtrig.plan.laser import cast_beams, predict_laser
from gtrig.sim.gtroom import VALIDATION_POSES, make_scene


def test_beams_and_scan_covariance_match_the_icp():
    rig = make_scene(0).rig_true
    poses = VALIDATION_POSES[::3]
    pred = predict_laser(rig, poses)
    model = HullModel.from_hull(rig.robot.hull)
    hits = cast_beams(rig, model, poses)
    S_xy = np.array([s.T_world_scanner.xyz[:2] for s in rig.laser_scanners])
    sigma = np.array([s.range_sigma_m for s in rig.laser_scanners])
    for k, pose in enumerate(poses):
        seg = hull_segments_world(rig.robot.hull, pose)
        xy, sid, dirs = [], [], []
        for si, s in enumerate(rig.laser_scanners):
            T = s.T_world_scanner.matrix()
            a = np.arctan2(T[1, 0], T[0, 0]) + s.angles_rad
            u = np.column_stack([np.cos(a), np.sin(a)])
            r = cast_rays(T[:2, 3], u, seg, s.range_max_m)
            ok = np.isfinite(r)
            assert pred.beams[k, si] == ok.sum()
            xy.append(T[:2, 3] + r[ok, None] * u[ok])
            sid.append(np.full(ok.sum(), si))
            dirs.append(u[ok])
        p = np.concatenate(xy)
        m = hits.pose == k
        assert np.allclose(np.sort(hits.xy[m], axis=0), np.sort(p, axis=0), atol=1e-9)
        fit = fit_hull(model, p, np.concatenate(sid), S_xy, np.concatenate(dirs), sigma, pose)
        assert np.allclose(fit.xytheta, pose, atol=1e-6)
        assert np.allclose(pred.cov_scan_xytheta[k], fit.cov_xytheta, rtol=1e-4, atol=1e-14)
        assert pred.covered[k] == (not fit.degenerate)
    assert pred.covered.all()


def test_compiled_blocks_equal_the_icps_normal_equations():
    from gtrig.laser.hull_icp import BeamPoints, side_bias_normal_equations
    from gtrig.laser.track import TrackSettings
    from gtrig.plan.laser import laser_information

    rig = make_scene(0).rig_true
    rng = np.random.default_rng(5)
    poses = np.column_stack([rng.uniform(-3, 3, 300), rng.uniform(-2, 6, 300), rng.uniform(-np.pi, np.pi, 300)])
    model = HullModel.from_hull(rig.robot.hull)
    hits = cast_beams(rig, model, poses)
    S_xy = np.array([s.T_world_scanner.xyz[:2] for s in rig.laser_scanners])
    sigma = np.array([s.range_sigma_m for s in rig.laser_scanners])
    icp = TrackSettings().icp
    hit_points = BeamPoints(hits.xy, hits.pose, hits.scanner, S_xy, hits.dir, sigma)
    H, H_pb, *_ = side_bias_normal_equations(model, hit_points, poses, icp)
    got = laser_information(rig, poses)
    prior = np.diag([1 / icp.prior_std_m**2, 1 / icp.prior_std_m**2, 1 / icp.prior_std_rad**2])
    assert hits.pose.size > 3000
    assert np.allclose(got.H_pp + prior, H, rtol=1e-10, atol=1e-9)
    assert np.allclose(got.H_pb, H_pb, rtol=1e-10, atol=1e-9)
