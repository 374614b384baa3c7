from __future__ import annotations

import numpy as np

from gtrig import geometry as geo
from gtrig.laser import synth
from gtrig.laser.background import build_background
from gtrig.laser.calibrate import calibrate_scanners
from gtrig.rig.models import Pose


def test_recovers_scanner_poses_from_static_scans(room):
    rng = np.random.default_rng(5)
    scs = room["scanners"]
    # clutter of unknown pose helps the overlap; the box at a known place defines the world
    clutter = np.concatenate(
        [
            synth.rectangle_segments([[-1.2, 1.8], [-0.6, 1.8], [-0.6, 2.2], [-1.2, 2.2]]),
            synth.rectangle_segments([[0.5, -1.8], [1.1, -1.8], [1.1, -1.5], [0.5, -1.5]]),
        ]
    )
    static = np.concatenate([room["static"], clutter])
    bgs = [build_background(np.array([synth.scan(s, static, rng) for _ in range(100)]), s) for s in scs]
    nominal = []
    for s in scs:
        T = s.T_world_scanner.matrix() @ geo.T_from_xyz_rpy(
            [rng.normal(0, 0.03), rng.normal(0, 0.03), 0], [0, 0, np.radians(rng.normal(0, 2.0))]
        )
        nominal.append(s.model_copy(update={"T_world_scanner": Pose.from_matrix(T)}))
    obj = room["box"][:, 0]
    cal, rep = calibrate_scanners(nominal, bgs, obj)
    for c, t, r in zip(cal, scs, rep.scanners, strict=True):
        a, b = geo.T_to_se2(c.T_world_scanner.matrix()), geo.T_to_se2(t.T_world_scanner.matrix())
        assert np.hypot(*(a[:2] - b[:2])) < 0.003
        assert abs(geo.wrap_angle(a[2] - b[2])) < np.radians(0.05)
        assert r.n_overlap > 50
    assert rep.rms_overlap_m < 0.003
    assert sum(r.n_object for r in rep.scanners) > 10


def test_two_objects_and_covariance(room):
    """Several known objects are accepted; the joint covariance is symmetric, (3 S, 3 S), and matches the
    reported standard deviations."""
    rng = np.random.default_rng(7)
    scs = room["scanners"]
    second = synth.rectangle_segments([[-3.0, 1.9], [-2.4, 1.9], [-2.4, 2.3], [-3.0, 2.3]])
    static = np.concatenate([room["static"], second])
    bgs = [build_background(np.array([synth.scan(s, static, rng) for _ in range(60)]), s) for s in scs]
    cal, rep = calibrate_scanners(scs, bgs, [room["box"][:, 0], second[:, 0]])
    S = len(scs)
    assert rep.cov_xytheta.shape == (3 * S, 3 * S)
    assert np.allclose(rep.cov_xytheta, rep.cov_xytheta.T)
    std = np.sqrt(np.diag(rep.cov_xytheta)).reshape(S, 3)
    assert np.allclose(std, np.array([r.std_xytheta for r in rep.scanners]))
    for c, t in zip(cal, scs, strict=True):
        a, b = geo.T_to_se2(c.T_world_scanner.matrix()), geo.T_to_se2(t.T_world_scanner.matrix())
        assert np.hypot(*(a[:2] - b[:2])) < 0.003
