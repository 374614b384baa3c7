"""The renderer: lens model, edge accuracy of projected markers and chessboards, determinism."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from gtrig import geometry as geo
from gtrig.markers.families import marker_cells
from gtrig.sim import gtroom
from gtrig.sim.render import Face, PinholeCamera, add_sensor_noise, render_layer, undistort_pixels
from gtrig.sim.textures import (
    board_face,
    board_object_points,
    cells_face,
    marker_corners_local,
    texels_for,
)

BLACK, WHITE = 0.06, 0.90


@pytest.fixture(scope="module")
def cam_and_pose() -> tuple[PinholeCamera, np.ndarray]:
    c = gtroom.make_scene(0).rig_true.cameras[1]
    return PinholeCamera.from_rig(c), c.T_world_cam.matrix()


def test_undistort_inverts_the_distortion_model(cam_and_pose):
    cam, _ = cam_and_pose
    rng = np.random.default_rng(0)
    uv = rng.uniform([0, 0], cam.size, (500, 2))
    ideal = undistort_pixels(uv, cam.K, cam.dist)
    ray = np.column_stack([ideal, np.ones(len(ideal))]) @ np.linalg.inv(cam.K).T
    back = geo.project_points(ray, cam.K, cam.dist)
    assert np.max(np.abs(back - uv)) < 1e-8
    assert np.max(np.abs(ideal - uv)) > 5  # the lens does distort


def _edge_points(img: np.ndarray, P0: np.ndarray, P1: np.ndarray, half: int = 3) -> np.ndarray:
    """Sub-pixel crossings of a dark/bright edge along rows (or columns) by the area method: for a
    normalised profile n_k over [a, b], the edge sits at b + 0.5 - sum(n_k), exact for any symmetric
    pixel response."""
    d = P1 - P0
    along_rows = abs(d[1]) > abs(d[0])
    pts = []
    for t in np.linspace(0.15, 0.85, 40):
        p = P0 + t * d
        if along_rows:
            r = round(p[1])
            x = P0[0] + (r - P0[1]) * d[0] / d[1]
            c0 = round(x) - half
            prof = (img[r, c0: c0 + 2 * half + 1] - BLACK) / (WHITE - BLACK)
        else:
            r = round(p[0])
            x = P0[1] + (r - P0[0]) * d[1] / d[0]
            c0 = round(x) - half
            prof = (img[c0: c0 + 2 * half + 1, r] - BLACK) / (WHITE - BLACK)
        if prof[-1] < prof[0]:
            prof = 1 - prof
        e = c0 + 2 * half + 0.5 - prof.sum()
        pts.append((e, r) if along_rows else (r, e))
    return np.array(pts, float)


def _fit_line(pts: np.ndarray) -> tuple[np.ndarray, float]:
    c = pts.mean(axis=0)
    n = np.linalg.svd(pts - c)[2][1]
    return n, float(n @ c)


def test_marker_corners_match_projection(cam_and_pose):
    """Blur- and noise-free markers: corners from lines fitted to the rendered edges (in ideal
    coordinates, so the lens' curvature does not bend them) agree with the projected truth."""
    cam, Twc = cam_and_pose
    rng = np.random.default_rng(1)
    cells = marker_cells("artoolkitplus_simple", 14)
    side = 0.156
    errs = []
    for _ in range(5):
        px = [rng.uniform(250, 770), rng.uniform(200, 560), 1.0]
        ray = np.linalg.inv(cam.K) @ px
        p = Twc[:3, :3] @ (ray / np.linalg.norm(ray)) * rng.uniform(2.5, 4.0) + Twc[:3, 3]
        T = geo.look_at(p, Twc[:3, 3] + rng.normal(0, 1.2, 3)) @ geo.T_from_xyz_rpy(
            [0, 0, 0], [0, 0, rng.uniform(-np.pi, np.pi)])
        corners = geo.transform_points(T, marker_corners_local(side))
        # a wide white margin so that the profiles see only the black square's edge
        face = cells_face(T, cells, (side, side), 0.05, texels_for(cam, Twc, corners, 12, 4), "m")
        uv = cam.project(Twc, corners)
        x0, y0 = np.floor(uv.min(axis=0)).astype(int) - 20
        x1, y1 = np.ceil(uv.max(axis=0)).astype(int) + 20
        lay = render_layer(cam, Twc, [face], (x0, y0, x1, y1), s=4)
        img = np.zeros(cam.size[::-1], np.float32)
        img[y0:y1, x0:x1] = lay.colour
        lines = [_fit_line(undistort_pixels(_edge_points(img, uv[i], uv[(i + 1) % 4]), cam.K, cam.dist))
                 for i in range(4)]
        est = np.array([np.linalg.solve([lines[i - 1][0], lines[i][0]], [lines[i - 1][1], lines[i][1]])
                        for i in range(4)])
        ideal = geo.project_points(geo.transform_points(geo.inv_T(Twc), corners), cam.K, np.zeros(5))
        errs.append(np.linalg.norm(est - ideal, axis=1))
    assert np.max(errs) < 0.05, np.max(errs)


def test_chessboard_found_where_projected(cam_and_pose):
    cam, Twc = cam_and_pose
    rng = np.random.default_rng(2)
    for _ in range(2):
        R = geo.T_from_xyz_rpy([0, 0, 0], np.radians([rng.uniform(-30, 30), rng.uniform(-30, 30),
                                                      rng.uniform(-15, 15)]))[:3, :3]
        T_cam_board = geo.make_T(R, np.array([0, 0, rng.uniform(2.3, 3.0)]) - R @ [0.4, 0.2, 0.0])
        T_world_board = Twc @ T_cam_board
        bg = Face(np.eye(4), np.array([[-20, -20], [20, -20], [20, 20], [-20, 20]], float),
                  np.full((2, 2), 0.5, np.float32), np.eye(3), name="floor")
        faces = [bg, board_face(T_world_board, cam, Twc, 4)]
        img = render_layer(cam, Twc, faces, None, s=4).colour
        g = np.clip(np.rint(img * 255), 0, 255).astype(np.uint8)
        ok, found = cv2.findChessboardCorners(g, (9, 5))
        assert ok
        found = cv2.cornerSubPix(g, found, (5, 5), (-1, -1),
                                 (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_COUNT, 100, 1e-4)).reshape(-1, 2)
        truth = cam.project(Twc, geo.transform_points(T_world_board, board_object_points()))
        if np.linalg.norm(found[0] - truth[0]) > np.linalg.norm(found[0] - truth[-1]):
            found = found[::-1]  # the 9 x 5 board is symmetric under a half turn
        err = np.linalg.norm(found - truth, axis=1)
        assert np.max(err) < 0.1, np.max(err)


def test_noise_is_deterministic_and_shot_limited():
    img = np.full((200, 300), 128.0, np.float32)
    img[:, 150:] = 20.0
    a = add_sensor_noise(img, 2.0, np.random.default_rng([1, 2, 3]))
    b = add_sensor_noise(img, 2.0, np.random.default_rng([1, 2, 3]))
    c = add_sensor_noise(img, 2.0, np.random.default_rng([1, 2, 4]))
    assert a.tobytes() == b.tobytes() and a.tobytes() != c.tobytes()
    bright, dark = a[:, :150].astype(float), a[:, 150:].astype(float)
    assert abs(bright.mean() - 128) < 0.1 and 1.8 < bright.std() < 2.2
    assert dark.std() < bright.std() - 0.5  # shot noise grows with the signal
