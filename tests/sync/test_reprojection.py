"""Per-camera clock offsets by reprojection: ceiling cameras whose clocks are off by known amounts see
the robot's markers along the simulated path; each camera's offset comes back from its own corners against
a GTlaser-like reference (1.2 mm, 2.5 mrad at 75 Hz, smoothed), within what that reference allows."""

import json

import numpy as np
import pytest

from gtrig import geometry as geo
from gtrig.fusion.measurements import fixes_from_track
from gtrig.sync.reference import reference_track
from gtrig.sync.reprojection import (
    CameraCorners,
    camera_offsets_reprojection,
    image_corrections,
    read_camera_corners,
)
from gtrig.trajectory import PoseTrack
from gtrig.vision.observations import CameraGeometry, MarkerView, VisionModel, marker_corners_marker, stack_corners

K = np.array([[700.0, 0.0, 640.0], [0.0, 700.0, 480.0], [0.0, 0.0, 1.0]])
SIZE = (1280, 960)
CAMS = {"c0": (0.0, 0.0), "c1": (1.5, 2.0), "c2": (0.5, 4.0)}  # ceiling cameras' (x, y), 3.2 m up
TAUS = {"c0": 0.002, "c1": 0.0, "c2": -0.0015}  # each camera's stamps minus its true exposure times
MARKERS = {1: (0.12, 0.0), 2: (-0.12, 0.1), 3: (-0.12, -0.1)}  # on the robot's top, 0.4 m up


def _down_looking(x: float, y: float, tilt: tuple[float, float] = (0.0, 0.0)) -> np.ndarray:
    """T_world_cam of a camera at (x, y, 3.2) looking straight down (optical axis -z), tilted by small
    rotations about the world x and y axes (radians)."""
    R = np.diag([1.0, -1.0, -1.0])  # camera x = world x, camera y = -world y, camera z = down
    R = _rxy(*tilt) @ R
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = R, [x, y, 3.2]
    return T


def _rxy(a: float, b: float) -> np.ndarray:
    ca, sa, cb, sb = np.cos(a), np.sin(a), np.cos(b), np.sin(b)
    return np.array([[1, 0, 0], [0, ca, -sa], [0, sa, ca]]) @ np.array([[cb, 0, sb], [0, 1, 0], [-sb, 0, cb]])


def _model(tilts: dict[str, tuple[float, float]] | None = None) -> VisionModel:
    cams = {}
    for name, (x, y) in CAMS.items():
        T = _down_looking(x, y, (tilts or {}).get(name, (0.0, 0.0)))
        cams[name] = CameraGeometry(name, K, np.zeros(8), T, geo.inv_T(T), SIZE)
    Trm = {}
    for m, (x, y) in MARKERS.items():
        T = np.eye(4)
        T[:3, 3] = [x, y, 0.4]
        Trm[m] = T
    corners = {m: geo.transform_points(T, marker_corners_marker(0.1)) for m, T in Trm.items()}
    return VisionModel(cams, dict.fromkeys(MARKERS, 0.1), Trm, corners)


def _images(run, truth_model: VisionModel, model: VisionModel, rng: np.random.Generator,  # noqa: ANN001
            sigma_px: float = 0.1, static: bool = False) -> dict[str, CameraCorners]:
    """Each camera's images at 20 Hz (own phase, 0.5 ms stamp jitter): the markers fully inside the image,
    projected through ``truth_model`` at the true exposure time, ``sigma_px`` noise; the corners stacked
    against ``model`` (what the estimator believes)."""
    t0, t1 = run.motion.stamps_s[0] + 0.5, run.motion.stamps_s[-1] - 0.5
    out = {}
    for j, name in enumerate(CAMS):
        expo = np.arange(t0 + 0.017 * j, t1, 0.05)
        stamps = expo + TAUS[name] + rng.normal(0, 0.0005, expo.size)
        P = np.tile([0.7, 1.5, 0.3], (expo.size, 1)) if static else run.motion.planar(expo)
        views, rows = [], []
        for i, p in enumerate(P):
            T_wr = geo.se2_to_T(*p)
            for m, c_r in truth_model.corners_robot.items():
                g = truth_model.cameras[name]
                p_c = geo.transform_points(g.T_cam_world, geo.transform_points(T_wr, c_r))
                uv = (p_c[:, :2] / p_c[:, 2:]) @ K[:2, :2].T + K[:2, 2]
                if np.all(p_c[:, 2] > 0) and np.all((uv >= 0) & (uv < SIZE)):
                    uv = uv + rng.normal(0, sigma_px, uv.shape)
                    views.append(MarkerView(name, m, uv, np.tile(np.eye(2) * sigma_px**2, (4, 1, 1)), i))
                    rows.append(i)
        if not views:
            continue
        uniq, img = np.unique(rows, return_inverse=True)
        out[name] = CameraCorners(name, stamps[uniq], stack_corners(model, views), np.repeat(img, 4))
    return out


def _laser_reference(run, rng: np.random.Generator):  # noqa: ANN001, ANN202
    t = np.arange(run.motion.stamps_s[0], run.motion.stamps_s[-1], 1 / 75)
    sig = np.array([0.0012, 0.0012, 0.0025])
    z = run.motion.planar(t) + rng.normal(0, 1, (t.size, 3)) * sig
    track = PoseTrack.from_xytheta(t, z, cov=np.tile(np.diag(sig**2), (t.size, 1, 1)), source="laser")
    return reference_track([fixes_from_track(track, "laser")])


def test_image_correction_is_the_pose_error() -> None:
    """One image's planar correction is what moves the assumed pose onto the true one."""
    model = _model()
    true = np.array([0.2, 0.3, 0.7])
    views = []
    for m, c_r in model.corners_robot.items():
        g = model.cameras["c0"]
        p_c = geo.transform_points(g.T_cam_world, geo.transform_points(geo.se2_to_T(*true), c_r))
        uv = (p_c[:, :2] / p_c[:, 2:]) @ K[:2, :2].T + K[:2, 2]
        views.append(MarkerView("c0", m, uv, np.tile(np.eye(2) * 0.01, (4, 1, 1)), 0))
    cc = CameraCorners("c0", np.array([0.0]), stack_corners(model, views), np.zeros(12, int))
    off = np.array([[0.001, -0.0015, 0.002]])
    y, Cy, rms = image_corrections(cc, true[None] - off, np.zeros(1), np.eye(3)[None])
    assert y[0] == pytest.approx(off[0], rel=2e-3, abs=1e-7)
    assert np.all(np.linalg.eigvalsh(Cy[0]) > 0) and rms[0] > 1.0


def test_camera_offsets_by_reprojection_recovered(run) -> None:  # noqa: ANN001
    """+2 / 0 / -1.5 ms cameras, each calibrated 0.3-0.5 mrad off (a 1-1.5 mm world bias at 3 m): every
    offset to the cameras' mean within 1 ms and inside its interval."""
    rng = np.random.default_rng(11)
    truth_model = _model({"c0": (4e-4, -3e-4), "c1": (-5e-4, 0.0), "c2": (0.0, 3e-4)})
    images = _images(run, truth_model, _model(), rng)
    ref = _laser_reference(run, rng)
    share = {"c0": 0.3, "c1": 0.3, "c2": 0.4}
    mean = sum(share[c] * TAUS[c] for c in CAMS)
    est = camera_offsets_reprojection(images, ref, run.vision, share, block_s=3.0)
    for e, c in zip(est, CAMS, strict=True):
        truth = TAUS[c] - mean
        assert e.verdict == "ok", e.reason
        assert abs(e.offset_s - truth) < 0.001, (c, e.offset_s, truth)
        assert e.ci95_s[0] <= truth <= e.ci95_s[1], (c, e.ci95_s, truth)
        assert e.ci95_s[1] - e.ci95_s[0] < 0.004
        assert np.nanmax(e.corr) == pytest.approx(1.0)
    assert abs(sum(share[c] * e.offset_s for e, c in zip(est, CAMS, strict=True))) < 1e-9
    # to the reference's clock (no shares): the offsets themselves
    absolute = camera_offsets_reprojection(images, ref, run.vision, None, block_s=3.0)
    assert all(abs(e.offset_s - TAUS[c]) < 0.001 for e, c in zip(absolute, CAMS, strict=True))


def test_camera_that_never_sees_motion_is_unobservable(run) -> None:  # noqa: ANN001
    rng = np.random.default_rng(12)
    images = _images(run, _model(), _model(), rng, static=True)
    assert images  # the robot stands in view
    est = camera_offsets_reprojection(images, _laser_reference(run, rng), run.vision, None, block_s=3.0)
    assert all(e.verdict != "ok" and np.isnan(e.offset_s) for e in est)


def test_read_camera_corners_from_the_checkpoint(tmp_path) -> None:  # noqa: ANN001
    model = _model()
    uv = [[600.0, 400.0], [650.0, 400.0], [650.0, 450.0], [600.0, 450.0]]
    cov = [np.eye(2).tolist()] * 4
    lines = [{"key": "k", "version": 5},
             {"camera": "c0", "frames": [[0, [[1, uv, cov], [2, uv, cov]]], [1, []], [2, [[9, uv, cov]]]]},
             {"camera": "c1", "frames": [[3, [[1, uv, cov], [1, uv, cov], [3, uv, cov]]]]}]
    p = tmp_path / "ck"
    p.write_text("\n".join(json.dumps(d) for d in lines) + "\n{\"camera\": \"c2\", \"fra")  # last line cut
    stamps = {c: np.arange(5) * 0.1 + j for j, c in enumerate(CAMS)}
    cc = read_camera_corners(p, model, stamps, floor_px=0.1)
    assert set(cc) == {"c0", "c1"}
    assert cc["c0"].stamps_s.tolist() == [0.0] and cc["c0"].corners.uv.shape == (8, 2)
    assert cc["c0"].corners.cov[0] == pytest.approx(np.eye(2) * 1.01)
    # a marker seen twice in one image is dropped (as GTvision does), the unknown marker 9 too
    assert cc["c1"].stamps_s.tolist() == [1.3] and cc["c1"].corners.marker.tolist() == [3] * 4
