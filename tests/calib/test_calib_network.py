"""Network calibration on projected corners of the simulated GT room: the joint BA recovers the truth."""

from __future__ import annotations

import numpy as np
import pytest

from gtrig import geometry as geo
from gtrig.calib import synth
from gtrig.calib.chessboard import Board
from gtrig.calib.network import calibrate_network
from gtrig.errors import InputError
from gtrig.sim.gtroom import make_scene

BOARD = Board(9, 5, 0.1)
PAIRS = [("cam0", "cam1"), ("cam1", "cam2"), ("cam2", "cam3")]


def _network(sc, n_pair_views: int, noise_px: float, rng: np.random.Generator, **kw):
    """The simulated room's network: true and nominal rig and boards, PAIRS, anchored on cam1."""
    return synth.synthetic_network(sc.rig_true, sc.rig_nominal, BOARD, sc.T_board1_board2_true,
                                   sc.T_board1_board2_nominal, sc.T_world_board, PAIRS, ["cam1"], n_pair_views,
                                   noise_px, rng, **kw)


@pytest.fixture(scope="module")
def solved():
    sc = make_scene(3)
    prob = _network(sc, 5, 0.05, np.random.default_rng(3))
    return sc, prob, calibrate_network(prob)


def test_joint_recovers_truth_and_beats_the_chain(solved) -> None:
    sc, _, res = solved
    for c in sc.rig_true.cameras:
        dt, dr = geo.pose_error(res.joint[c.name].T_world_cam, c.T_world_cam.matrix())
        assert dt < 0.003 and np.degrees(dr) < 0.03, c.name
    T3 = sc.rig_true.camera("cam3").T_world_cam.matrix()
    joint3 = geo.pose_error(res.joint["cam3"].T_world_cam, T3)[0]
    chain3 = geo.pose_error(res.chain["cam3"], T3)[0]
    assert res.chain_path["cam3"] == ["cam1", "cam2", "cam3"]
    assert chain3 > 2 * joint3
    # the double board's transform is estimated, not taken at its nominal value
    assert geo.pose_error(res.T_board1_board2, sc.T_board1_board2_true)[0] < 0.5e-3


def test_uncertainty_is_consistent(solved) -> None:
    sc, _, res = solved
    assert 0.03 < res.sigma_px < 0.08  # the 0.05 px of noise put in
    for c in sc.rig_true.cameras:
        e = res.joint[c.name].T_world_cam[:3, 3] - c.T_world_cam.matrix()[:3, 3]
        s = res.joint[c.name].sigma_pos_m
        assert np.all(s > 0) and np.all(np.abs(e) < 5 * s + 1e-4), c.name
    assert set(res.rms_px_pair) == {"cam0-cam1", "cam1-cam2", "cam2-cam3"}
    assert all(v < 0.15 for v in res.rms_px_pair.values())


def test_no_world_board_is_a_one_line_error(solved) -> None:
    _, prob, _ = solved
    from dataclasses import replace

    with pytest.raises(InputError, match="world board"):
        calibrate_network(replace(prob, world_views=[]))


def test_intrinsics_jacobian_matches_finite_differences() -> None:
    from gtrig.calib.network import _apply_intrinsics, _intrinsics_jacobian, _intrinsics_vector

    c = make_scene(0).rig_true.cameras[0]
    from gtrig.io.camfile import CameraIntrinsics

    ci = CameraIntrinsics(c.resolution, c.K, np.r_[c.dist[:4], 0.01])
    rng = np.random.default_rng(0)
    Xc = np.column_stack([rng.uniform(-0.8, 0.8, (20, 2)), rng.uniform(2, 3, 20)])
    q = _intrinsics_vector(ci, 9)
    J = _intrinsics_jacobian(Xc, *_apply_intrinsics(ci, q), 9)
    for k in range(9):
        h = 1e-6 * max(abs(q[k]), 1e-3)
        dq = np.zeros(9)
        dq[k] = h
        up = geo.project_points(Xc, *_apply_intrinsics(ci, q + dq))
        dn = geo.project_points(Xc, *_apply_intrinsics(ci, q - dq))
        np.testing.assert_allclose(J[:, :, k], (up - dn) / (2 * h), rtol=1e-5, atol=1e-6 * np.abs(J).max())


@pytest.fixture(scope="module")
def solved_with_sweeps():
    """The GT room's cameras with wrong lenses (2 px off in f and c) and 8-view sweeps of projected
    corners: the bundle adjustment must refine the lenses from the sweeps, pairs and world board."""
    from dataclasses import replace

    from gtrig.calib.network import SweepView
    from gtrig.io.camfile import CameraIntrinsics

    sc = make_scene(1)
    rng = np.random.default_rng(5)
    noise = 0.03
    wrong, sweeps = {}, []
    for i, c in enumerate(sc.rig_true.cameras):
        K = c.K.copy()
        K[0, 0] += 2.0 * (-1) ** i
        K[1, 1] -= 1.5
        K[0, 2] += 2.0
        K[1, 2] -= 2.0 * (-1) ** i
        wrong[c.name] = CameraIntrinsics(c.resolution, K, np.r_[c.dist[:4] * 0.9, 0.0])
        for k, T in enumerate(
            synth.random_intrinsic_views(rng, c.K, c.dist, c.resolution, BOARD, 8, depth_m=(1.8, 3.6))
        ):
            u = synth.project_board(c.K, c.dist, T, BOARD) + rng.normal(0, noise, (BOARD.n_corners, 2))
            sweeps.append(SweepView(c.name, f"{k:06d}.png", u))
    prob = _network(sc, 6, noise, rng, intrinsics=wrong)
    prob = replace(prob, sweep_views=sweeps)
    return sc, prob, calibrate_network(prob), calibrate_network(prob, refine_intrinsics=False)


def test_lenses_are_refined_in_the_bundle_adjustment(solved_with_sweeps) -> None:
    sc, _, res, held = solved_with_sweeps
    for c in sc.rig_true.cameras:
        j = res.joint[c.name]
        assert j.n_sweep_views == 8 and j.rms_px_sweep < 0.06
        dK = j.intrinsics.camera_matrix - c.K
        std = j.intrinsics.extra["std"]
        # within 4 sigma of the truth, and far better than the 2 px the lenses started from
        for name, e in (("fx", dK[0, 0]), ("fy", dK[1, 1]), ("cx", dK[0, 2]), ("cy", dK[1, 2])):
            assert abs(e) < 4 * std[name] + 1e-3 and abs(e) < 1.0, (c.name, name, e, std[name])
        # the poses come out right with refined lenses, and far worse when the wrong lenses are held
        T = c.T_world_cam.matrix()
        assert geo.pose_error(j.T_world_cam, T)[0] < 0.003
    cams = sc.rig_true.cameras
    worst = max(geo.pose_error(res.joint[c.name].T_world_cam, c.T_world_cam.matrix())[1] for c in cams)
    worst_held = max(
        geo.pose_error(held.joint[c.name].T_world_cam, c.T_world_cam.matrix())[1] for c in cams
    )
    assert worst_held > 2 * worst


def test_pose_covariance_includes_the_lens_uncertainty(solved_with_sweeps) -> None:
    sc, _, res, held = solved_with_sweeps
    for c in sc.rig_true.cameras:
        j = res.joint[c.name]
        assert j.cov_pose_intrinsics.shape == (14, 14)
        np.testing.assert_allclose(j.cov_pose_intrinsics[:6, :6], j.cov)
        # marginal over the lens >= conditional on it, axis by axis, and clearly so for the rotation
        assert np.all(j.sigma_rot_rad >= j.sigma_rot_rad_fixed_intrinsics * (1 - 1e-9))
        assert np.all(j.sigma_pos_m >= j.sigma_pos_m_fixed_intrinsics * (1 - 1e-9))
        assert np.linalg.norm(j.sigma_rot_rad) > 1.5 * np.linalg.norm(j.sigma_rot_rad_fixed_intrinsics)
        # the orientation error is explained by the stated uncertainty
        dr = geo.pose_error(j.T_world_cam, c.T_world_cam.matrix())[1]
        assert dr < 4 * np.linalg.norm(j.sigma_rot_rad), c.name
        # held lenses: nothing to add
        h = held.joint[c.name]
        np.testing.assert_allclose(h.sigma_rot_rad, h.sigma_rot_rad_fixed_intrinsics)


def test_lens_without_sweep_uses_its_stated_sigmas_as_prior(solved) -> None:
    from dataclasses import replace

    from gtrig.io.camfile import CameraIntrinsics

    sc, prob, held = solved
    # no sweep views and no std: the lenses are held
    assert all(j.cov_pose_intrinsics.shape == (6, 6) for j in held.joint.values())
    names = ("fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2")
    std = dict(zip(names, [0.5, 0.5, 0.5, 0.5, 1e-3, 1e-3, 1e-4, 1e-4], strict=True))
    cams = {
        n: CameraIntrinsics(c.image_size, c.camera_matrix, c.dist_coeffs, 0.05, {"std": std})
        for n, c in prob.cameras.items()
    }
    res = calibrate_network(replace(prob, cameras=cams))
    for c in sc.rig_true.cameras:
        j = res.joint[c.name]
        assert j.intrinsics.extra["refined_in_network"] and j.n_sweep_views == 0
        # the prior caps the lens's sigma; the network can only tighten it
        assert all(j.intrinsics.extra["std"][k] <= std[k] * (1 + 1e-6) for k in names)
        assert np.all(j.sigma_rot_rad > j.sigma_rot_rad_fixed_intrinsics)
        assert geo.pose_error(j.T_world_cam, c.T_world_cam.matrix())[0] < 0.003


def test_sweeps_of_partial_corner_sets_refine_the_lenses_as_well(solved_with_sweeps) -> None:
    """Sweep views that carry their corners' board points (a board with corner IDs seen in part, as a
    ChArUco sweep) enter the bundle adjustment: with 60 % of each view's corners the lenses still come
    out within 4 sigma of the truth and the poses within 3 mm."""
    from dataclasses import replace

    from gtrig.calib.anchor import board_pose
    from gtrig.calib.network import SweepView

    sc, prob, _res, _held = solved_with_sweeps
    rng = np.random.default_rng(8)
    P = BOARD.object_points()
    partial = []
    for sv in prob.sweep_views:
        cam = prob.cameras[sv.camera]
        T, _ = board_pose(cam.camera_matrix, cam.dist_coeffs, sv.corners, BOARD)
        keep = np.sort(rng.choice(BOARD.n_corners, int(0.6 * BOARD.n_corners), replace=False))
        partial.append(SweepView(sv.camera, sv.name, sv.corners[keep], T, P[keep]))
    res = calibrate_network(replace(prob, sweep_views=partial))
    for c in sc.rig_true.cameras:
        j = res.joint[c.name]
        assert j.n_sweep_views == 8
        dK, std = j.intrinsics.camera_matrix - c.K, j.intrinsics.extra["std"]
        for name, e in (("fx", dK[0, 0]), ("fy", dK[1, 1]), ("cx", dK[0, 2]), ("cy", dK[1, 2])):
            assert abs(e) < 4 * std[name] + 1e-3 and abs(e) < 1.0, (c.name, name, e, std[name])
        assert geo.pose_error(j.T_world_cam, c.T_world_cam.matrix())[0] < 0.003
