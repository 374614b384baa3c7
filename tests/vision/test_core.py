"""GTvision's estimation core on synthetic corners: Jacobians, IPPE, flips, accuracy and NEES."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from gtrig import geometry as geo
from gtrig.rig.models import Pose
from gtrig.sim.gtroom import VALIDATION_POSES, make_scene
from gtrig.vision.covariance import PLANAR_INDEX, RigUncertainty, nees, planar_covariance, pose_error_xi
from gtrig.vision.estimate import Status, VisionOptions, estimate_frame
from gtrig.vision.init import PreviousPose, ippe_view
from gtrig.vision.observations import FrameObservations, MarkerView, VisionModel, stack_corners
from gtrig.vision.projection import camera_pose_jacobian, lens_jacobian, marker_pose_jacobian, project_pose, skew
from gtrig.vision.refine import apply_step
from gtrig.vision.synthetic import CornerNoise, synthetic_observations, visible_views


@pytest.fixture(scope="module")
def scene():
    return make_scene(0)


def _obs(scene, k, rng, **kw):
    T = scene.T_world_robot(*VALIDATION_POSES[k])
    return T, synthetic_observations(scene.rig_true, T, float(k), rng, **kw)


def test_jacobians_match_finite_differences(scene):
    rng = np.random.default_rng(0)
    T, obs = _obs(scene, 3, rng)
    model = VisionModel.from_rig(scene.rig_true)
    sc = stack_corners(model, obs.views)
    uv0, _, J = project_pose(sc, T)
    h = 1e-6
    for i in range(6):
        d = np.zeros(6)
        d[i] = h
        uv1, _, _ = project_pose(sc, apply_step(T, d), jacobian=False)
        np.testing.assert_allclose((uv1 - uv0) / h, J[:, :, i], rtol=1e-4, atol=1e-2)
    # camera perturbation: moving the camera by xi is the same as moving the world by its inverse
    Jc = camera_pose_jacobian(sc, T)
    assert Jc.shape == J.shape and np.all(np.isfinite(Jc))
    np.testing.assert_allclose(Jc[:, :, :3], -J[:, :, :3], rtol=1e-9, atol=1e-9)
    Jm = marker_pose_jacobian(sc, T)
    # a marker translation in robot axes equals a robot translation rotated into the world
    np.testing.assert_allclose(Jm[:, :, :3], J[:, :, :3] @ T[:3, :3], rtol=1e-9, atol=1e-9)
    # the lens: every parameter of the distortion model, with a strong lens
    sc = replace(sc, dist=np.tile([-0.3, 0.12, 1e-3, -2e-3, -0.02, 0.0, 0.0, 0.0], (sc.uv.shape[0], 1)))
    Jl = lens_jacobian(sc, T)
    uv0, _, _ = project_pose(sc, T, jacobian=False)
    for i, name in enumerate(("fx", "fy", "cx", "cy")):
        uv1, _, _ = project_pose(replace(sc, **{name: getattr(sc, name) + 1e-3}), T, jacobian=False)
        np.testing.assert_allclose((uv1 - uv0) / 1e-3, Jl[:, :, i], rtol=1e-6, atol=1e-6)
    for i, col in enumerate((0, 1, 2, 3, 4)):  # k1, k2, p1, p2, k3
        d = sc.dist.copy()
        d[:, col] += 1e-7
        uv1, _, _ = project_pose(replace(sc, dist=d), T, jacobian=False)
        np.testing.assert_allclose((uv1 - uv0) / 1e-7, Jl[:, :, 4 + i], rtol=1e-4, atol=1e-3)


def test_ippe_returns_both_solutions_and_the_true_one(scene):
    rng = np.random.default_rng(1)
    T, obs = _obs(scene, 0, rng, noise=CornerNoise(sigma_px=0.0))
    model = VisionModel.from_rig(scene.rig_true)
    for v in obs.views:
        s = ippe_view(model, v)
        assert s.T_world_robot.shape == (2, 4, 4)
        errs = [geo.pose_error(Tc, T) for Tc in s.T_world_robot]
        best = min(errs)
        assert best[0] < 1e-6 and best[1] < 1e-6


@pytest.mark.parametrize("planar", [False, True])
def test_accuracy_and_nees_on_synthetic_corners(scene, planar):
    rng = np.random.default_rng(2)
    model = VisionModel.from_rig(scene.rig_true)
    opts = VisionOptions(planar=planar, corner_floor_px=0.0, rig_uncertainty=RigUncertainty.none())
    pos, n6, n3 = [], [], []
    for _rep in range(3):
        for k in range(0, 26, 2):
            T, obs = _obs(scene, k, rng)
            est = estimate_frame(model, obs, opts)
            assert est.ok, est.reason
            e = pose_error_xi(est.T_world_robot, T)
            pos.append(np.linalg.norm(e[:2]))
            n6.append(nees(e, est.cov_6x6))
            n3.append(nees(e[[0, 1, 5]], planar_covariance(est.cov_6x6)))
    assert np.mean(pos) < 0.002 and np.max(pos) < 0.006
    # 117 draws: the mean of a chi-square(6) has sd 0.32 here
    assert 6 * 0.75 < np.mean(n6) < 6 * 1.3
    assert 3 * 0.7 < np.mean(n3) < 3 * 1.35


def test_rig_uncertainty_keeps_covariances_consistent(scene):
    """Cameras and markers off by their stated sigmas: the covariance must grow to cover the error."""
    rng = np.random.default_rng(3)
    ru = RigUncertainty()
    n_all, n_naive = [], []
    for trial in range(4):
        rig = scene.rig_true
        cams = tuple(c.model_copy(update={"T_world_cam": Pose.from_matrix(
            geo.T_from_xyz_rpy(rng.normal(0, ru.camera_xyz_m, 3), np.zeros(3)) @ c.T_world_cam.matrix()
            @ geo.T_from_xyz_rpy(np.zeros(3), rng.normal(0, ru.camera_rot_rad, 3)))}) for c in rig.cameras)
        mks = tuple(m.model_copy(update={"T_robot_marker": Pose.from_matrix(
            m.T_robot_marker.matrix() @ geo.T_from_xyz_rpy(rng.normal(0, ru.marker_xyz_m, 3),
                                                           rng.normal(0, ru.marker_rot_rad, 3)))})
            for m in rig.robot.markers)
        robot = rig.robot.model_copy(update={"markers": mks})
        rig_est = rig.model_copy(update={"cameras": cams, "robot": robot})
        model = VisionModel.from_rig(rig_est)
        for k in range(trial, 26, 4):
            T, obs = _obs(scene, k, rng)
            e1 = estimate_frame(model, obs, VisionOptions(planar=False, corner_floor_px=0.0, rig_uncertainty=ru))
            assert e1.ok, e1.reason
            n_all.append(nees(pose_error_xi(e1.T_world_robot, T), e1.cov_6x6))
            e0 = estimate_frame(model, obs, VisionOptions(planar=False, corner_floor_px=0.0,
                                                          rig_uncertainty=RigUncertainty.none(),
                                                          max_variance_factor=math.inf))
            # corner noise alone: the fit's covariance before the frame's own variance factor
            n_naive.append(nees(pose_error_xi(e0.T_world_robot, T), e0.cov_6x6 / max(1.0, e0.variance_factor)))
    assert 0.5 * 6 < np.mean(n_all) < 2 * 6
    assert np.mean(n_naive) > 3 * np.mean(n_all)  # corner noise alone would be far too confident


def test_full_camera_covariances_are_used_not_just_their_sigmas(scene):
    """Cameras calibrated on boards near the robot: their centre and rotation errors are strongly
    correlated, so points in the working volume barely move. With each camera's full covariance the
    pose covariance stays consistent; the same sigmas taken as independent overstate it."""
    from scipy.spatial.transform import Rotation

    rng = np.random.default_rng(5)
    rig = scene.rig_true
    P = np.array([0.0, 0.0, 0.4])  # the middle of the working volume
    covs = {}
    for c in rig.cameras:
        r = P - c.T_world_cam.matrix()[:3, 3]
        A = np.vstack([skew(r), np.eye(3)])  # centre move r x deps keeps P's image still
        covs[c.name] = (A @ A.T) * math.radians(0.03) ** 2 + np.diag([1e-4] * 3 + [1e-5] * 3) ** 2
    full = RigUncertainty(0.0, 0.0, 0.0, 0.0, camera_cov=covs)
    sd = max(float(np.sqrt(np.max(np.diag(C)[:3]))) for C in covs.values())
    sr = max(float(np.sqrt(np.max(np.diag(C)[3:]))) for C in covs.values())
    iso = RigUncertainty(sd, sr, 0.0, 0.0)
    n_full, n_iso, sig_full, sig_iso = [], [], [], []
    for trial in range(4):
        cams = []
        for c in rig.cameras:
            x = rng.multivariate_normal(np.zeros(6), covs[c.name])
            T = c.T_world_cam.matrix().copy()
            T[:3, :3] = Rotation.from_rotvec(x[3:]).as_matrix() @ T[:3, :3]
            T[:3, 3] += x[:3]
            cams.append(c.model_copy(update={"T_world_cam": Pose.from_matrix(T)}))
        model = VisionModel.from_rig(rig.model_copy(update={"cameras": tuple(cams)}))
        for k in range(trial, 26, 4):
            T, obs = _obs(scene, k, rng, noise=CornerNoise(sigma_px=0.05))
            for ru, out, sig in ((full, n_full, sig_full), (iso, n_iso, sig_iso)):
                e = estimate_frame(model, obs, VisionOptions(planar=False, corner_floor_px=0.0, rig_uncertainty=ru,
                                                             max_variance_factor=math.inf))
                assert e.ok, e.reason
                out.append(nees(pose_error_xi(e.T_world_robot, T), e.cov_6x6))
                sig.append(math.sqrt(np.trace(e.cov_6x6[:3, :3])))
    assert 0.5 * 6 < np.mean(n_full) < 2 * 6
    # the correlations are what the full covariance adds: position sigma 2.0 mm against 4.8 mm
    assert np.mean(sig_full) < 0.6 * np.mean(sig_iso)


def _frontal_rig(scene):
    """One camera looking straight down from 4 m at a single marker: the classic flip case."""
    cam = scene.rig_true.cameras[0]
    T_wc = geo.look_at([0.0, 0.0, 4.0], [0.0, 0.0, 0.0], up=(0.0, 1.0, 0.0))
    cam = cam.model_copy(update={"T_world_cam": Pose.from_matrix(T_wc), "dist_coeffs": (0.0,) * 5})
    m = scene.rig_true.robot.markers[0].model_copy(update={
        "T_robot_marker": Pose(xyz=(0.0, 0.0, 0.62), rpy_deg=(0, 0, 0))})
    return scene.rig_true.model_copy(update={
        "cameras": (cam,), "robot": scene.rig_true.robot.model_copy(update={"markers": (m,)})})


def test_flip_reported_ambiguous_then_broken_by_floor_prior_or_previous_pose(scene):
    rig = _frontal_rig(scene)
    model = VisionModel.from_rig(rig)
    rng = np.random.default_rng(4)
    T = geo.T_from_xyz_rpy([0.4, -0.02, 0.0], np.radians([0.3, -0.2, 30.0]))
    free = VisionOptions(planar=False, corner_floor_px=0.0, rig_uncertainty=RigUncertainty.none())
    planar = VisionOptions(planar=True, corner_floor_px=0.0, rig_uncertainty=RigUncertainty.none())
    n_amb = n_prev_ok = n_planar_ok = 0
    for _ in range(12):
        obs = synthetic_observations(rig, T, 0.0, rng, noise=CornerNoise(sigma_px=0.2))
        assert len(obs.views) == 1
        e = estimate_frame(model, obs, free)
        if e.status is Status.AMBIGUOUS:
            n_amb += 1
            rot_err = sorted(geo.pose_error(a, T)[1] for a in e.alternatives)
            assert len(rot_err) >= 2 and rot_err[-1] > math.radians(8)  # a real flip, not noise
            e2 = estimate_frame(model, obs, free, PreviousPose(T, 0.05, math.radians(3.0)))
            picked = geo.pose_error(e2.T_world_robot, T)[1]
            n_prev_ok += e2.ok and picked == pytest.approx(rot_err[0], abs=1e-3)
        e3 = estimate_frame(model, obs, planar)
        n_planar_ok += e3.ok and geo.pose_error(e3.T_world_robot, T)[1] < math.radians(1.0)
    assert n_amb >= 6  # without the floor, a lone near-frontal marker is ambiguous, and gtrig says so
    assert n_prev_ok == n_amb
    assert n_planar_ok == 12


def test_outlier_view_rejected_and_failures_have_reasons(scene):
    rng = np.random.default_rng(5)
    model = VisionModel.from_rig(scene.rig_true)
    opts = VisionOptions(planar=True, corner_floor_px=0.0, rig_uncertainty=RigUncertainty.none())
    T, obs = _obs(scene, 3, rng)
    assert len(obs.views) >= 3
    bad = obs.views[1]
    views = list(obs.views)
    views[1] = MarkerView(bad.camera, bad.marker_id, bad.corners_px + [[4.0, -3.0], [0, 0], [0, 0], [0, 0]],
                          bad.corner_cov)
    est = estimate_frame(model, FrameObservations(obs.stamp_s, tuple(views)), opts)
    assert est.ok
    assert est.rejected == ((bad.camera, bad.marker_id),)
    assert geo.pose_error(est.T_world_robot, T)[0] < 0.005

    none = estimate_frame(model, FrameObservations(1.0, ()), opts)
    assert none.status is Status.NO_MARKER and none.T_world_robot is None and "no marker" in none.reason

    # every corner several times noisier than its covariance says: kept, its covariance scaled by the
    # frame's variance factor; far beyond the limit: refused, not silently kept
    def noisier(sd: float) -> FrameObservations:
        return FrameObservations(2.0, tuple(MarkerView(v.camera, v.marker_id, v.corners_px + rng.normal(0, sd, (4, 2)),
                                                       v.corner_cov) for v in obs.views))

    est = estimate_frame(model, noisier(1.0), opts)
    assert est.ok and 4 < est.variance_factor < opts.max_variance_factor
    est = estimate_frame(model, noisier(6.0), opts)
    assert est.status is Status.INCONSISTENT and "variance factor" in est.reason
    assert est.variance_factor > opts.max_variance_factor


def test_anchor_frame_covariance_matches_sampled_robot_frame_errors() -> None:
    """The robot frame's error from the anchor's measured pose: sampled against the first-order covariance."""
    from scipy.spatial.transform import Rotation

    from gtrig.vision.covariance import add_robot_frame_covariance, anchor_frame_covariance, pose_error_xi

    rng = np.random.default_rng(4)
    T_ra = np.eye(4)
    T_ra[:3, :3] = Rotation.from_euler("z", 90, degrees=True).as_matrix()
    T_ra[:3, 3] = [-0.143, 0.098, 0.62]
    sig = np.r_[0.0003, 0.0003, 0.0001, np.radians([0.05, 0.05, 0.2])]
    T_wr = np.eye(4)
    T_wr[:3, :3] = Rotation.from_euler("z", 40, degrees=True).as_matrix()
    T_wr[:3, 3] = [1.0, 2.0, 0.0]
    xs = []
    for _ in range(4000):
        eps = rng.normal(0, sig)
        E = np.eye(4)
        E[:3, :3] = Rotation.from_rotvec(eps[3:]).as_matrix()
        E[:3, 3] = eps[:3]
        F = T_ra @ np.linalg.inv(E) @ np.linalg.inv(T_ra)
        xs.append(pose_error_xi(T_wr @ F, T_wr))
    C_mc = np.cov(np.array(xs).T)
    C = add_robot_frame_covariance(T_wr, np.zeros((6, 6)), anchor_frame_covariance(T_ra, np.diag(sig**2)))
    d = np.sqrt(np.diag(C))
    assert np.allclose(C_mc / np.outer(d, d), C / np.outer(d, d), atol=0.08)
    assert np.allclose(np.sqrt(np.diag(C_mc)), d, rtol=0.08)


def test_cameras_exposed_at_different_times_are_compensated(scene):
    """A robot at 0.3 m/s seen by two cameras 4 ms apart: fitted as one instant the views disagree
    by 1.2 mm; moved by the neighbours' velocity (compensate_motion) they agree again."""
    from gtrig.vision.sequence import compensate_motion

    rng = np.random.default_rng(11)
    model = VisionModel.from_rig(scene.rig_true)
    opts = VisionOptions(planar=True, corner_floor_px=0.0, rig_uncertainty=RigUncertainty.none())
    x0, y0, th0 = VALIDATION_POSES[3]
    v, w = 0.3, 0.2  # m/s along the heading, rad/s

    def pose(t: float) -> np.ndarray:
        th = th0 + w * t
        return scene.T_world_robot(x0 + v * t * math.cos(th0), y0 + v * t * math.sin(th0), th)

    seen = sorted({c for c, _, _ in visible_views(scene.rig_true, pose(0.0))})
    assert len(seen) >= 2
    cams, dt = seen[:2], (-0.002, 0.002)
    noise = CornerNoise(sigma_px=0.01)
    obs, offsets, truth = [], [], []
    for k in range(5):
        t = 0.1 * k
        views = []
        for c, d in zip(cams, dt, strict=True):
            views += synthetic_observations(scene.rig_true, pose(t + d), t, rng, noise, cameras=(c,)).views
        obs.append(FrameObservations(t, tuple(views), tuple(cams)))
        offsets.append(dict(zip(cams, dt, strict=True)))
        truth.append(pose(t))
    first = [estimate_frame(model, o, opts) for o in obs]
    assert all(e.ok for e in first)
    after, timed = compensate_motion(model, obs, first, offsets, {}, opts)
    assert timed == set(range(len(obs)))
    err0 = [np.linalg.norm(pose_error_xi(e.T_world_robot, T)[:3]) for e, T in zip(first, truth, strict=True)]
    err1 = [np.linalg.norm(pose_error_xi(e.T_world_robot, T)[:3]) for e, T in zip(after, truth, strict=True)]
    print("error mm, one instant / compensated:", 1e3 * np.mean(err0), 1e3 * np.mean(err1))
    assert np.mean(err0) > 0.4e-3
    assert np.mean(err1) < 0.25 * np.mean(err0) and np.max(err1) < 0.2e-3
    # a single camera, or cameras exposed together, need nothing: the same estimate comes back
    same, timed = compensate_motion(model, obs, first, [{c: 0.0 for c in cams}] * len(obs), {}, opts)
    assert all(a is b for a, b in zip(same, first, strict=True)) and not timed


def test_timing_camera_covariance_is_the_robot_motion_seen_from_the_camera(scene):
    from gtrig.vision.covariance import timing_camera_covariance
    from gtrig.vision.projection import project_pose

    rng = np.random.default_rng(12)
    T, obs = _obs(scene, 3, rng)
    model = VisionModel.from_rig(scene.rig_true)
    sc = stack_corners(model, obs.views)
    vel = np.array([0.2, -0.25, 0.0, 0.0, 0.0, 0.4])
    dt = 1e-4
    T_moved = T.copy()
    T_moved[:3, :3] = geo.T_from_xyz_rpy([0, 0, 0], vel[3:] * dt)[:3, :3] @ T[:3, :3]
    T_moved[:3, 3] += vel[:3] * dt
    uv_moved, _, _ = project_pose(sc, T_moved, jacobian=False)
    uv0, _, _ = project_pose(sc, T, jacobian=False)
    Jc = camera_pose_jacobian(sc, T)
    for i, name in enumerate(sc.camera_names):
        C = timing_camera_covariance(vel, T, model.cameras[name].T_world_cam[:3, 3], 1.0)
        w, U = np.linalg.eigh(C)
        g = U[:, -1] * np.sqrt(w[-1])  # +-(v + omega x lever, omega)
        m = sc.cam == i
        pred = np.einsum("nij,j->ni", Jc[m], g * dt)
        np.testing.assert_allclose(np.abs(pred), np.abs(uv_moved[m] - uv0[m]), rtol=1e-3, atol=1e-6)


def test_each_cameras_jitter_is_a_nuisance_of_its_own(scene):
    """Two cameras per instant, each exposed with its own 3 ms jitter, the robot at 0.3 m/s: after the
    motion pass the covariance holds the cameras' disagreement (NEES about its dof)."""
    from gtrig.vision.sequence import compensate_motion

    rng = np.random.default_rng(13)
    model = VisionModel.from_rig(scene.rig_true)
    opts = VisionOptions(planar=True, corner_floor_px=0.0, rig_uncertainty=RigUncertainty.none())
    x0, y0, th0 = VALIDATION_POSES[3]
    sig_t = 0.003

    def pose(t: float) -> np.ndarray:
        return scene.T_world_robot(x0 + 0.3 * t * math.cos(th0), y0 + 0.3 * t * math.sin(th0), th0 + 0.2 * t)

    cams = sorted({c for c, _, _ in visible_views(scene.rig_true, pose(0.0))})[:2]
    obs, truth = [], []
    for k in range(60):
        t = 0.02 * k
        views = []
        for c in cams:
            views += synthetic_observations(scene.rig_true, pose(t + rng.normal(0, sig_t)), t, rng,
                                            CornerNoise(sigma_px=0.02), cameras=(c,)).views
        obs.append(FrameObservations(t, tuple(views), tuple(cams)))
        truth.append(pose(t))
    first = [estimate_frame(model, o, opts) for o in obs]
    after, timed = compensate_motion(model, obs, first, [{c: 0.0 for c in cams}] * len(obs),
                                     {c: sig_t for c in cams}, opts)
    assert len(timed) == len(obs)
    i = np.array(PLANAR_INDEX)
    def mean_nees(ests: list) -> float:
        return float(np.mean([nees(pose_error_xi(e.T_world_robot, T)[i], planar_covariance(e.cov_6x6))
                              for e, T in zip(ests, truth, strict=True)]))

    n0, n1 = mean_nees(first), mean_nees(after)
    print("NEES / dof, first / after:", n0 / 3, n1 / 3)
    assert n0 > 10 * 3  # corners alone: the jitter is not in the covariance
    assert 0.5 * 3 < n1 < 1.6 * 3
