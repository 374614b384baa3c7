"""A rigid body of identified points tracked from fixed cameras (gtrig.vision.body): accuracy against simulated
truth, the covariance's NEES, an outlier camera dropped, the shape checks on exact data."""

from __future__ import annotations

import cv2
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from gtrig import geometry as geo
from gtrig.vision.body import BodyOptions, BodyView, PointBody, camera_geometry, estimate_body_pose
from gtrig.vision.body_check import edge_errors, plane_rms, shape_from_poses, split_pose_nees, triangulate_points
from gtrig.vision.covariance import nees, pose_error_xi

K = np.array([[900.0, 0, 640], [0, 900.0, 360], [0, 0, 1]])
DIST = np.array([-0.1, 0.05, 0.0, 0.0, 0.0])
SQUARE = 0.054
BOARD = PointBody("board", np.array([[(c + 1) * SQUARE, (r + 1) * SQUARE, 0.0] for r in range(4) for c in range(3)]))



CAMS = {f"cam_{i}": camera_geometry(f"cam_{i}", K, DIST, geo.look_at(c, np.zeros(3)), (1280, 720))
        for i, c in enumerate(np.array([[1.2, 0.0, 0.4], [0.0, 1.1, 0.5], [-0.9, -0.8, 0.3]]))}


def _pose(rng: np.random.Generator) -> np.ndarray:
    R = Rotation.from_rotvec(rng.normal(0, 0.3, 3)).as_matrix()
    # the board faces roughly upwards, its centre near the origin
    return geo.make_T(R, rng.normal(0, 0.05, 3) - R @ np.array([2 * SQUARE, 2.5 * SQUARE, 0.0]))


def _views(T_world_body: np.ndarray, rng: np.random.Generator, sigma_px: float) -> list[BodyView]:
    out = []
    for name, cam in CAMS.items():
        p_cam = geo.transform_points(cam.T_cam_world @ T_world_body, BOARD.points_body)
        if np.any(p_cam[:, 2] <= 0.1):
            continue
        uv = cv2.projectPoints(p_cam, np.zeros(3), np.zeros(3), K, DIST)[0].reshape(-1, 2)
        out.append(BodyView(name, np.arange(len(uv)), uv + rng.normal(0, sigma_px, uv.shape)))
    return out


def test_pose_accurate_and_covariance_consistent() -> None:
    rng = np.random.default_rng(5)
    opts = BodyOptions(sigma_px=0.3)
    n, err_mm = [], []
    for _ in range(60):
        T = _pose(rng)
        p = estimate_body_pose(CAMS, BOARD, _views(T, rng, 0.3), 0.0, opts)
        assert p.ok and p.T_world_body is not None and p.cov_6x6 is not None
        e = pose_error_xi(p.T_world_body, T)
        n.append(nees(e, p.cov_6x6))
        err_mm.append(1000 * np.linalg.norm(e[:3]))
    assert np.median(err_mm) < 1.0  # three cameras at about 1.2 m, 0.3 px corners
    # NEES over 6 dof: mean 6 for a right covariance (60 draws: 5 % band about 4.9-7.2); frames whose factor
    # is significantly above 1 are scaled up, so slightly below 6 is expected
    assert 4.5 < np.mean(n) < 7.5


def test_outlier_camera_dropped() -> None:
    rng = np.random.default_rng(6)
    T = _pose(rng)
    views = _views(T, rng, 0.3)
    bad = views[1]
    views[1] = BodyView(bad.camera, bad.ids, bad.points_px + np.array([12.0, -8.0]))  # that camera's image is off
    p = estimate_body_pose(CAMS, BOARD, views, 0.0, BodyOptions(sigma_px=0.3))
    assert p.ok and p.rejected == (bad.camera,) and p.T_world_body is not None
    assert 1000 * np.linalg.norm(p.T_world_body[:3, 3] - T[:3, 3]) < 3.0


def test_shape_checks_recover_the_board() -> None:
    """Triangulated and pose-based reconstructions of a noiseless board give its edges and flatness exactly;
    with 0.3 px noise the triangulated corners' errors agree with their covariance (NEES near 3)."""
    rng = np.random.default_rng(7)
    poses, views = [], []
    for _ in range(8):
        T = _pose(rng)
        vs = _views(T, rng, 0.0)
        poses.append(estimate_body_pose(CAMS, BOARD, vs, 0.0, BodyOptions(sigma_px=0.3)))
        views.append(vs)
        tri = triangulate_points(CAMS, vs, 0.3)
        assert len(tri.ids) == 12
        np.testing.assert_allclose(tri.X_world, geo.transform_points(T, BOARD.points_body), atol=1e-6)
    shape = shape_from_poses(CAMS, poses, views)
    assert np.max(np.abs(edge_errors(shape, BOARD, SQUARE))) < 1e-6 and len(edge_errors(shape, BOARD, SQUARE)) == 17
    assert plane_rms(np.array(list(shape.values()))) < 1e-6
    d = []
    for _ in range(40):
        T = _pose(rng)
        tri = triangulate_points(CAMS, _views(T, rng, 0.3), 0.3)
        d += [nees(x - y, C) for x, y, C in zip(tri.X_world, geo.transform_points(T, BOARD.points_body[tri.ids]),
                                                 tri.cov, strict=True)]
    assert 2.6 < np.mean(d) < 3.4  # 480 points, 3 dof each
    s = split_pose_nees(CAMS, BOARD, _views(_pose(rng), rng, 0.3), BodyOptions(sigma_px=0.3))
    assert len(s) == 3 and all(np.isfinite(s))


@pytest.mark.parametrize("n_points", [3])
def test_too_few_points_is_no_pose(n_points: int) -> None:
    v = BodyView("cam_0", np.arange(n_points), np.zeros((n_points, 2)) + 600)
    p = estimate_body_pose(CAMS, BOARD, [v], 1.5)
    assert not p.ok and p.T_world_body is None and p.stamp_s == 1.5


# --- cameras' time offsets and line delays (gtrig.vision.body_timing) --------------------------------------

OFFSET_S = {"cam_0": 0.0, "cam_1": 0.020, "cam_2": -0.012}


def _T_moving(t: float) -> np.ndarray:
    """A board swept through the cameras' shared view: up to about 0.25 m/s and 0.6 rad/s."""
    R = Rotation.from_rotvec([0.4 * np.sin(1.3 * t), 0.3 * np.cos(0.9 * t), 0.5 * np.sin(0.7 * t)]).as_matrix()
    c = np.array([0.12 * np.sin(1.5 * t), 0.1 * np.cos(1.1 * t), 0.05 * np.sin(0.8 * t)])
    return geo.make_T(R, c - R @ np.array([2 * SQUARE, 2.5 * SQUARE, 0.0]))


def _image(name: str, t_exposure: float, line_delay_s: float) -> np.ndarray:
    """Pixels (12, 2) of the moving board in camera ``name``, each row exposed ``line_delay_s`` per row later."""
    cam = CAMS[name]
    t = np.full(len(BOARD.points_body), t_exposure)
    for _ in range(3):  # each point's row depends on its time: a fixed point
        uv = np.array([cv2.projectPoints(geo.transform_points(cam.T_cam_world @ _T_moving(tk), p[None]), np.zeros(3),
                                         np.zeros(3), K, DIST)[0].reshape(2) for tk, p in zip(t, BOARD.points_body,
                                                                                                strict=True)])
        t = t_exposure + line_delay_s * (uv[:, 1] - 360.0)
    return uv


def _moving_instants(line_delay_s: float, rng: np.random.Generator, n: int = 36, exposure_jitter_s: float = 0.0,
                     drift_s_per_s: dict[str, float] | None = None):
    """The board's views at 6 frames/s; ``exposure_jitter_s``: each image exposed up to that much (uniform)
    before or after its camera's offset, not in its stamp; ``drift_s_per_s``: each camera's offset changes
    at that rate about the recording's midpoint."""
    from gtrig.vision.body_track import group_instants

    pairs = []
    mid_s = (n - 1) / 6.0 / 2
    for i in range(n):
        for name in CAMS:
            t_img = i / 6.0 + rng.uniform(-0.005, 0.005)  # the stamps of one instant differ a little
            slide = (drift_s_per_s or {}).get(name, 0.0) * (t_img - mid_s)
            t_exp = t_img + OFFSET_S[name] + slide + rng.uniform(-exposure_jitter_s, exposure_jitter_s)
            uv = _image(name, t_exp, line_delay_s) + rng.normal(0, 0.2, (12, 2))
            pairs.append((i, BodyView(name, np.arange(12), uv, t_img)))
    return group_instants(pairs)


def test_local_motion_follows_a_one_hertz_sway() -> None:
    """The speed at an instant from the polynomial through its neighbours' poses (6 frames/s), against the
    exact derivative of a 1 Hz sway: five poses err by about (omega h)^4 / 30 = 4 %, seven by
    (omega h)^6 / 140 = 0.9 %; near the track's end the window is one-sided and still follows."""
    from gtrig.vision.body import BodyPose
    from gtrig.vision.body_timing import local_motion
    from gtrig.vision.estimate import Status

    w = 2 * np.pi * 1.0
    amp_m, amp_rad = np.array([0.05, 0.03, 0.02]), np.array([0.3, 0.2, 0.1])

    def T(t: float) -> np.ndarray:
        return geo.make_T(Rotation.from_rotvec(amp_rad * np.sin(w * t)).as_matrix(), amp_m * np.sin(w * t))

    stamps = np.arange(12) / 6.0
    poses = [BodyPose(float(t), Status.OK, T(t)) for t in stamps]
    # at the sway's fastest (t = 1 s) measured 3.5 % and 0.76 % of the peak speed; one-sided (1 pose
    # before, 3 after) 1.8 %
    for i, reach, lo, hi in ((6, 2, 0.03, 0.045), (6, 3, 0.0, 0.01), (1, 3, 0.0, 0.025)):
        m = local_motion(poses, i, 0.5, reach)
        assert m is not None
        true = np.r_[amp_m, amp_rad] * w * np.cos(w * stamps[i])
        rel = np.abs(m.twist(np.zeros(1))[0] - true) / np.abs(np.r_[amp_m, amp_rad] * w)
        assert lo <= np.max(rel) < hi, (i, reach, rel)
    assert local_motion(poses, 0, 0.5) is None  # no pose before the first


@pytest.mark.parametrize("line_delay_s", [0.0, 40e-6])  # 40 us per row: 720 rows read out in 29 ms
def test_camera_offsets_and_line_delay_recovered(line_delay_s: float) -> None:
    from gtrig.vision.body_timing import estimate_timing
    from gtrig.vision.body_track import track_body

    rng = np.random.default_rng(3)
    opts = BodyOptions(sigma_px=0.2)
    track = track_body(CAMS, BOARD, _moving_instants(line_delay_s, rng), opts)
    tm = estimate_timing(CAMS, BOARD, track.instants, track.poses, "cam_0", line_delay=line_delay_s > 0,
                         options=opts)
    assert tm.instants >= 30 and tm.cameras == ("cam_0", "cam_1", "cam_2")
    for c, d, s in zip(tm.cameras, tm.offset_s, tm.sigma_offset_s, strict=True):
        # a margin of a tenth of the offset beyond the interval: the local motions' speed error (under 1 %)
        assert abs(d - OFFSET_S[c]) < 3 * s + 0.1 * abs(OFFSET_S[c]) + 1e-4, (c, d, s)
    assert tm.rms_px["model"] < 0.7 * tm.rms_px["stamps"]
    if line_delay_s:
        assert np.all(np.abs(tm.line_delay_s - line_delay_s) < 3 * tm.sigma_line_delay_s + 6e-6), tm.line_delay_s


def test_offset_interval_covers_exposures_wandering_from_the_stamps() -> None:
    """Each image exposed up to 16 ms off its camera's offset (a webcam's frame picked from a 30 frames/s
    stream), not in its stamp: the residuals grow at every moving instant together, the interval with them,
    and it covers the truth where the variance factor's alone would not."""
    from gtrig.vision.body_timing import estimate_timing
    from gtrig.vision.body_track import track_body

    opts = BodyOptions(sigma_px=0.2)
    z, z_model = [], []
    for seed in (4, 5):
        rng = np.random.default_rng(seed)
        track = track_body(CAMS, BOARD, _moving_instants(0.0, rng, exposure_jitter_s=0.016), opts)
        tm = estimate_timing(CAMS, BOARD, track.instants, track.poses, "cam_0", line_delay=False, options=opts)
        err = np.array([tm.offset_s[k] - OFFSET_S[c] for k, c in enumerate(tm.cameras)])[1:]
        z.extend(np.abs(err) / tm.sigma_offset_s[1:])
        z_model.extend(np.abs(err) / tm.sigma_offset_model_s[1:])
        assert np.all(tm.sigma_offset_s >= tm.sigma_offset_model_s), seed
    # measured |error| / sigma 0.90, 0.83, 0.01, 0.99; with the variance factor's sigmas 4.0, 4.3, 0.05, 4.3
    assert max(z) < 2.5 and max(z_model) > 3.0


def test_offset_drift_recovered_and_the_halves_agree_only_with_it() -> None:
    """Offsets that slide against the stamps at a constant rate (a skewed clock, a stamping latency that
    changes: +6 and -4 ms per second, 21 and 14 ms over the recording): the drift model recovers the offsets
    at the midpoint and the drifts within their intervals; fitted apart, the recording's halves agree with
    each other under it, and disagree under constant offsets."""
    from gtrig.vision.body_timing import estimate_timing
    from gtrig.vision.body_timing_halves import timing_halves
    from gtrig.vision.body_track import track_body

    drift = {"cam_0": 0.0, "cam_1": 0.006, "cam_2": -0.004}
    opts = BodyOptions(sigma_px=0.2)
    track = track_body(CAMS, BOARD, _moving_instants(0.0, np.random.default_rng(6), drift_s_per_s=drift), opts)
    args = (CAMS, BOARD, track.instants, track.poses, "cam_0")
    tm = estimate_timing(*args, line_delay=False, drift=True, options=opts)
    assert tm.mid_s == pytest.approx(35 / 12, abs=0.01)  # the tracked instants' midpoint
    for k, c in enumerate(tm.cameras[1:], start=1):
        assert abs(tm.offset_s[k] - OFFSET_S[c]) < 3 * tm.sigma_offset_s[k] + 3e-4, (c, tm.offset_s[k])
        assert abs(tm.drift_s_per_s[k] - drift[c]) < 3 * tm.sigma_drift_s_per_s[k] + 3e-4, (c, tm.drift_s_per_s[k])
    assert tm.drift_s_per_s[0] == 0 and tm.sigma_drift_s_per_s[0] == 0
    with_drift = timing_halves(*args, drift=True, options=opts)
    constant = timing_halves(*args, drift=False, options=opts)
    assert with_drift.first.span_s[1] < tm.mid_s < with_drift.second.span_s[0]
    # measured (cam_1, cam_2): offsets at the midpoint 0.45, 0.06 and drifts 0.88, 0.72 of their combined 95 %
    # intervals with the drift; offsets 1.64, 1.14 without (the sandwich widens a misfit model's intervals, and
    # a half's 17 instants leave its middle few degrees of freedom)
    assert np.all(with_drift.offset_ratio < 1.5) and np.all(with_drift.drift_ratio < 1.5), with_drift
    assert np.all(constant.offset_ratio[1:] > 1.0), constant.offset_ratio
