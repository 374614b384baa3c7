"""Every camera image set of a simulated recording: run and validation sequences, calibration sets
(chessboard sweeps, double-chessboard pairs, the world board) and the hand-held marker survey.

Images are formed by :mod:`gtrig.sim.render` (supersampled projection of planar textured faces through
the true lens). Each function is deterministic for its seed: frame ``k`` of camera ``c`` draws its
random numbers from ``default_rng([seed, c, k, ...])``, so the output does not depend on the number of
worker processes (``cfg.workers``; 0 = one per core).
"""

from __future__ import annotations

import logging
import math
import os
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from gtrig import geometry as geo
from gtrig.calib.charuco import charuco_board_document
from gtrig.io.atomic import atomic_write_bytes, atomic_write_text
from gtrig.io.frames import write_frame_index
from gtrig.io.tum import Trajectory, write_tum
from gtrig.parallel import process_pool
from gtrig.rig.models import Camera, Pose
from gtrig.sim import gtroom
from gtrig.sim.config import CameraSimConfig, SimConfig, noise_stream
from gtrig.sim.gtroom import Scene
from gtrig.sim.motion import RobotMotion
from gtrig.sim.render import (
    Face,
    Layer,
    PinholeCamera,
    add_sensor_noise,
    blur_by_depth,
    composite,
    defocus_sigma_px,
    encode_png,
    noise_sd,
    render_layer,
    vignetting_map,
)
from gtrig.sim.textures import (
    MARKER_MARGIN_M,
    board_face,
    board_object_points,
    board_outline_board,
    charuco_face,
    floor_illumination,
    marker_corners_local,
    robot_faces,
    room_faces,
    sim_charuco_board,
)

log = logging.getLogger(__name__)

LEVELS_PER_RADIANCE = 210.0  # grey level of a perfect white under the room's average light
BACKGROUND_SUPERSAMPLE = 2  # the static background is rendered once per camera
HANDHELD_SIZE = (1600, 1200)
ROI_MARGIN_PX = 4


# ----------------------------------------------------------------------------------------- contexts
@dataclass(frozen=True)
class CameraView:
    """A camera at a pose with its precomputed background (grey levels, vignetted and defocused)."""

    cam: PinholeCamera
    T_world_cam: np.ndarray
    background: np.ndarray  # (h, w) float32 grey levels
    gain: np.ndarray  # (h, w) float32: grey levels per unit radiance (vignetting included)
    noise_sd: np.ndarray  # (h, w) float32: sensor noise sd of the background, grey levels


def _scene_order(faces: Sequence[Face], T_world_cam: np.ndarray) -> list[Face]:
    """Floor and walls first (they bound the room), then the clutter far to near by box."""
    eye = T_world_cam[:3, 3]
    is_fixed = [f.name == "floor" or f.name.startswith("wall") for f in faces]
    fixed = [f for f, x in zip(faces, is_fixed, strict=True) if x]
    rest = [f for f, x in zip(faces, is_fixed, strict=True) if not x]
    boxes: dict[str, list[Face]] = {}
    for f in rest:
        boxes.setdefault(f.name.rsplit("_", 1)[0], []).append(f)

    def dist(group: list[Face]) -> float:
        c = np.mean([geo.transform_points(g.T_world_face, np.c_[g.outline_xy, np.zeros(len(g.outline_xy))])
                     .mean(axis=0) for g in group], axis=0)
        return float(np.linalg.norm(c - eye))

    ordered = sorted(boxes.values(), key=dist, reverse=True)
    return fixed + [f for g in ordered for f in g]


def make_view(scene: Scene, cam: PinholeCamera, T_world_cam: np.ndarray, ccfg: CameraSimConfig,
              s: int = BACKGROUND_SUPERSAMPLE, focus_inv_depth: float | None = None) -> CameraView:
    """Render the static room seen by ``cam`` at ``T_world_cam``: the background of every frame.

    ``focus_inv_depth`` (1/m) moves the focus (hand-held camera); default: focused on 2-5 m.
    """
    faces = _scene_order(room_faces(scene, ccfg.sunlight), T_world_cam)
    lay = render_layer(cam, T_world_cam, faces, None, s=s, with_depth=True)
    gain = vignetting_map(cam, ccfg.vignetting) * np.float32(LEVELS_PER_RADIANCE)
    img = lay.colour * gain
    if ccfg.defocus_sigma_px > 0:
        assert lay.inv_depth is not None
        inv_d = lay.inv_depth / np.maximum(lay.alpha, 1e-6)
        img = blur_by_depth(img, _sigma(inv_d, ccfg, focus_inv_depth).astype(np.float32))
    img = img.astype(np.float32)
    return CameraView(cam, T_world_cam, img, gain, noise_sd(img, ccfg.noise_sigma))


def _sigma(inv_depth: np.ndarray | float, ccfg: CameraSimConfig, focus_inv_depth: float | None) -> np.ndarray:
    if focus_inv_depth is None:
        return defocus_sigma_px(inv_depth, ccfg.defocus_sigma_px)
    # a hand-held camera focused at 1/focus_inv_depth, sharp within sigma over +-30 % in depth
    half = 0.3 * focus_inv_depth
    return ccfg.defocus_sigma_px * np.abs(np.asarray(inv_depth, float) - focus_inv_depth) / half


_VIEWS: dict[tuple[Any, ...], CameraView] = {}


def _cached_view(scene: Scene, cam_rig: Camera, ccfg: CameraSimConfig) -> CameraView:
    key = (scene.seed, cam_rig.name, cam_rig.model_dump_json(), ccfg.model_dump_json())
    if key not in _VIEWS:
        if len(_VIEWS) > 8:
            _VIEWS.clear()
        _VIEWS[key] = make_view(scene, PinholeCamera.from_rig(cam_rig), cam_rig.T_world_cam.matrix(), ccfg)
    return _VIEWS[key]


# ------------------------------------------------------------------------------------------- frames
def _roi_of(view: CameraView, pts_world: np.ndarray, margin: float) -> tuple[int, int, int, int] | None:
    uv = view.cam.project(view.T_world_cam, pts_world)
    if np.any(~np.isfinite(uv)):
        return None
    w, h = view.cam.size
    x0 = max(0, math.floor(float(uv[:, 0].min()) - margin))
    y0 = max(0, math.floor(float(uv[:, 1].min()) - margin))
    x1 = min(w, math.ceil(float(uv[:, 0].max()) + margin) + 1)
    y1 = min(h, math.ceil(float(uv[:, 1].max()) + margin) + 1)
    if x1 - x0 < 2 or y1 - y0 < 2:
        return None
    return x0, y0, x1, y1


def _robot_box_points(scene: Scene, T_world_robot: np.ndarray) -> np.ndarray:
    hull = scene.rig_true.robot.hull
    assert hull is not None, "the simulated robot has a hull"
    c = hull.corners_xy()
    z = (0.0, gtroom.ROBOT_TOP_M + 0.01)
    pts = np.array([[x, y, zz] for zz in z for x, y in c])
    return geo.transform_points(T_world_robot, pts)


def _occluders(scene: Scene, view: CameraView, ccfg: CameraSimConfig, robot_centre: np.ndarray,
               roi: tuple[int, int, int, int]) -> list[Face]:
    """Clutter faces nearer to the camera than the robot and overlapping ``roi``: painted over it."""
    eye = view.T_world_cam[:3, 3]
    d_robot = float(np.linalg.norm(robot_centre - eye))
    out = []
    for f in room_faces(scene, ccfg.sunlight):
        if f.name == "floor" or f.name.startswith("wall"):
            continue
        outline = geo.transform_points(f.T_world_face, np.c_[f.outline_xy, np.zeros(len(f.outline_xy))])
        if np.linalg.norm(outline.mean(axis=0) - eye) >= d_robot - 0.3:
            continue
        uv = view.cam.project(view.T_world_cam, outline)
        if np.all(np.isfinite(uv)) and (uv[:, 0].max() < roi[0] or uv[:, 0].min() > roi[2]
                                        or uv[:, 1].max() < roi[1] or uv[:, 1].min() > roi[3]):
            continue
        out.append(f)
    return out


def robot_layer(scene: Scene, view: CameraView, T_world_robot: np.ndarray, roi: tuple[int, int, int, int],
                s_body: int, s_marker: int, light: float = 1.0, occluders: Sequence[Face] = ()) -> Layer:
    """The robot (and nearer clutter) over ``roi``: the body at supersampling ``s_body``; the markers,
    whose edges are measured, at ``s_marker`` in their own small regions, composited on top (they lie
    on the plate, the topmost part of the body)."""
    faces = robot_faces(scene, T_world_robot, view.cam, view.T_world_cam, s_marker, light)
    markers = [f for f in faces if f.name.startswith("marker")]
    if s_marker == s_body or occluders:
        return render_layer(view.cam, view.T_world_cam, faces + list(occluders), roi, s=max(s_body, s_marker)
                            if occluders else s_body)
    body = [f for f in faces if not f.name.startswith("marker")]
    lay = render_layer(view.cam, view.T_world_cam, body, roi, s=s_body)
    rx0, ry0, rx1, ry1 = roi
    for m, face in zip(scene.rig_true.robot.markers, markers, strict=True):
        T = face.T_world_face
        a = m.side_m / 2 + MARKER_MARGIN_M
        pts = geo.transform_points(T, np.array([[-a, -a, 0], [a, -a, 0], [a, a, 0], [-a, a, 0]], float))
        r = _roi_of(view, pts, 2.0)
        if r is None:
            continue
        r = (max(r[0], rx0), max(r[1], ry0), min(r[2], rx1), min(r[3], ry1))
        if r[2] - r[0] < 2 or r[3] - r[1] < 2:
            continue
        sub = render_layer(view.cam, view.T_world_cam, [face], r, s=s_marker)
        sl = np.s_[r[1] - ry0: r[3] - ry0, r[0] - rx0: r[2] - rx0]
        keep = 1.0 - sub.alpha
        lay.colour[sl] = lay.colour[sl] * keep + sub.colour
        lay.alpha[sl] = lay.alpha[sl] * keep + sub.alpha
    return lay


def motion_kernel(dx: float, dy: float, samples: int = 64) -> np.ndarray | None:
    """Normalised line kernel for a uniform image motion ``(dx, dy)`` px during the exposure,
    centred (the average position is the mid-exposure one); None below 0.3 px."""
    length = math.hypot(dx, dy)
    if length < 0.3:
        return None
    r = int(math.ceil(max(abs(dx), abs(dy)) / 2)) + 1
    k = np.zeros((2 * r + 1, 2 * r + 1), np.float32)
    t = (np.arange(samples) + 0.5) / samples - 0.5
    x, y = r + t * dx, r + t * dy
    ix, iy = np.floor(x).astype(int), np.floor(y).astype(int)
    fx, fy = x - ix, y - iy
    for ox, oy, wgt in ((0, 0, (1 - fx) * (1 - fy)), (1, 0, fx * (1 - fy)), (0, 1, (1 - fx) * fy),
                        (1, 1, fx * fy)):
        np.add.at(k, (iy + oy, ix + ox), wgt)
    return k / k.sum()


def render_robot_frame(scene: Scene, view: CameraView, motion: RobotMotion, t_s: float,
                       ccfg: CameraSimConfig, rng: np.random.Generator,
                       focus_inv_depth: float | None = None) -> np.ndarray:
    """One 8-bit image of the robot moving along ``motion``, exposed around ``t_s`` (mid-exposure).

    Motion blur: the robot layer rendered at mid-exposure is smeared along the image motion of the
    robot's top centre over ``ccfg.exposure_s`` (a line kernel; rotation during the 8 ms exposure moves
    the plate's corners by at most a pixel more than its centre, so one kernel is a fair model).
    """
    img = view.background.copy()
    T_mid = motion.T_world_robot(t_s)
    pts = _robot_box_points(scene, T_mid)
    if not np.all(np.isfinite(view.cam.project(view.T_world_cam, pts))):
        return add_sensor_noise(img, ccfg.noise_sigma, rng, view.noise_sd)
    kernel = None
    if ccfg.motion_blur:
        half = 0.5 * ccfg.exposure_s
        top = np.array([[0.0, 0.0, gtroom.ROBOT_TOP_M]])
        ends = [geo.transform_points(motion.T_world_robot(t_s + d), top)[0] for d in (-half, half)]
        uv = view.cam.project(view.T_world_cam, np.array(ends))
        if np.all(np.isfinite(uv)):
            kernel = motion_kernel(*(uv[1] - uv[0]))
    centre = pts.mean(axis=0)
    depth = float((geo.inv_T(view.T_world_cam) @ np.r_[centre, 1.0])[2])
    sigma = float(_sigma(1.0 / depth, ccfg, focus_inv_depth)) if ccfg.defocus_sigma_px > 0 else 0.0
    extra = 0 if kernel is None else kernel.shape[0] // 2
    roi = _roi_of(view, pts, ROI_MARGIN_PX + 3 * sigma + extra)
    if roi is None:
        return add_sensor_noise(img, ccfg.noise_sigma, rng, view.noise_sd)
    light = float(floor_illumination(scene, centre[None, :2], ccfg.sunlight)[0])
    occ = _occluders(scene, view, ccfg, centre, roi)
    s_mark = ccfg.supersample
    layer = robot_layer(scene, view, T_mid, roi, min(2, s_mark), s_mark, light, occ)
    if kernel is not None:
        import cv2

        layer = Layer(cv2.filter2D(layer.colour, -1, kernel, borderType=cv2.BORDER_CONSTANT),
                      cv2.filter2D(layer.alpha, -1, kernel, borderType=cv2.BORDER_CONSTANT), roi)
    composite(img, layer, sigma, view.gain)
    sd = view.noise_sd.copy()
    x0, y0, x1, y1 = roi
    sd[y0:y1, x0:x1] = noise_sd(img[y0:y1, x0:x1], ccfg.noise_sigma)
    return add_sensor_noise(img, ccfg.noise_sigma, rng, sd)


def render_faces_frame(view: CameraView, faces: list[Face], ccfg: CameraSimConfig, rng: np.random.Generator,
                       extent_world: np.ndarray) -> np.ndarray:
    """One 8-bit image of static foreground ``faces`` (chessboards) over the room; ``extent_world``
    (N, 3) bounds the faces (for the region of interest and the defocus depth)."""
    img = view.background.copy()
    centre = extent_world.mean(axis=0)
    depth = float((geo.inv_T(view.T_world_cam) @ np.r_[centre, 1.0])[2])
    sigma = float(_sigma(1.0 / depth, ccfg, None)) if ccfg.defocus_sigma_px > 0 else 0.0
    roi = _roi_of(view, extent_world, ROI_MARGIN_PX + 3 * sigma)
    if roi is not None:
        lay = render_layer(view.cam, view.T_world_cam, faces, roi, s=ccfg.supersample)
        composite(img, lay, sigma, view.gain)
    return add_sensor_noise(img, ccfg.noise_sigma, rng)


# ------------------------------------------------------------------------------------- parallel map
_WORKER_STATE: dict[str, Any] = {}


def _init_worker(fn: Callable[..., Any], shared: Any) -> None:
    import cv2

    cv2.setNumThreads(1)  # one process per core already
    _WORKER_STATE["fn"] = fn
    _WORKER_STATE["shared"] = shared


def _call(job: Any) -> Any:
    return _WORKER_STATE["fn"](_WORKER_STATE["shared"], job)


def _parallel_map(fn: Callable[[Any, Any], Any], shared: Any, jobs: list[Any], workers: int) -> list[Any]:
    """``[fn(shared, job) for job in jobs]`` over a process pool (``workers`` 0 = one per core)."""
    n = workers or (os.cpu_count() or 1)
    n = max(1, min(n, len(jobs)))
    if n == 1:
        return [fn(shared, j) for j in jobs]
    chunk = max(1, len(jobs) // (n * 8))
    with process_pool(n, _init_worker, (fn, shared)) as ex:
        return list(ex.map(_call, jobs, chunksize=chunk))


def _frame_rng(seed: int, cam_index: int, frame: int, salt: int = 0, draw: int = 0) -> np.random.Generator:
    # an image's own stream: its noise does not depend on the order or the process it is rendered in
    key = [int(seed) & 0x7FFFFFFF, cam_index + 1, frame, salt]
    return noise_stream(np.random.default_rng(key), key, draw)


def _write_png(path: Path, img: np.ndarray, ccfg: CameraSimConfig) -> None:
    atomic_write_bytes(path, encode_png(img, ccfg.png_compression))


def _cam_index(scene: Scene, name: str) -> int:
    names = [c.name for c in scene.rig_true.cameras]
    return names.index(name) if name in names else len(names)


# ------------------------------------------------------------------------------------------ sequence
@dataclass(frozen=True)
class _SeqShared:
    scene: Scene
    cam: Camera
    motion: RobotMotion
    folder: Path
    ccfg: CameraSimConfig
    seed: int
    cam_index: int
    noise_draw: int = 0


def _seq_frame(sh: _SeqShared, job: tuple[int, float]) -> None:
    k, t = job
    view = _cached_view(sh.scene, sh.cam, sh.ccfg)
    rng = _frame_rng(sh.seed, sh.cam_index, k, 0, sh.noise_draw)
    img = render_robot_frame(sh.scene, view, sh.motion, t, sh.ccfg, rng)
    _write_png(sh.folder / f"{k:06d}.png", img, sh.ccfg)


def jittered_stamps(stamps_s: np.ndarray, jitter_s: float, seed: int, cam_index: int,
                    noise_draw: int = 0) -> np.ndarray:
    """Written time stamps: the true mid-exposure times plus Gaussian jitter (trigger and transfer
    latency, drawn from ``noise_draw``: :func:`gtrig.sim.config.noise_stream`), clipped to 0.45 of the
    smallest frame spacing so that they still increase."""
    stamps_s = np.asarray(stamps_s, float)
    if jitter_s <= 0 or stamps_s.size == 0:
        return stamps_s.copy()
    j = np.array([_frame_rng(seed, cam_index, k, 1, noise_draw).normal(0.0, jitter_s) for k in range(stamps_s.size)])
    if stamps_s.size > 1:
        lim = 0.45 * float(np.min(np.diff(stamps_s)))
        j = np.clip(j, -lim, lim)
    return stamps_s + j


def render_sequence(scene: Scene, rig_true_camera: Camera, motion: RobotMotion, stamps_s: np.ndarray,
                    folder: str | os.PathLike[str], cfg: SimConfig, seed: int) -> np.ndarray:
    """Render one camera's image sequence: ``folder/NNNNNN.png`` and ``folder/timestamps.csv``.

    Parameters
    ----------
    scene : the installation (truth).
    rig_true_camera : the true camera (intrinsics, distortion, ``T_world_cam``).
    motion : the robot's true motion.
    stamps_s : (N,) true mid-exposure times, strictly increasing, seconds.
    folder : output folder (``.../cameras/<cam>``), created if needed.
    cfg : simulator settings (``cfg.camera`` and ``cfg.workers`` are used).
    seed : random seed of this sequence.

    Returns
    -------
    numpy.ndarray, (N,)
        The written time stamps (true stamps plus ``cfg.camera.stamp_jitter_s`` jitter).
    """
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    ci = _cam_index(scene, rig_true_camera.name)
    stamps_s = np.asarray(stamps_s, float)
    draw = cfg.noise_draw_of("sensors")
    shared = _SeqShared(scene, rig_true_camera, motion, folder, cfg.camera, int(seed), ci, draw)
    _cached_view(scene, rig_true_camera, cfg.camera)  # once, before forking: workers inherit it
    _parallel_map(_seq_frame, shared, list(enumerate(stamps_s.tolist())), cfg.workers)
    written = jittered_stamps(stamps_s, cfg.camera.stamp_jitter_s, int(seed), ci, draw)
    write_frame_index(folder, written, [f"{k:06d}.png" for k in range(stamps_s.size)])
    log.debug("%s: %d frames", folder, stamps_s.size)
    return written


# ---------------------------------------------------------------------------------- board poses
def _pose_dict(T: np.ndarray) -> dict[str, list[float]]:
    p = Pose.from_matrix(T)
    assert p.quat_xyzw is not None
    return {"xyz": [float(x) for x in p.xyz], "quat_xyzw": [float(x) for x in p.quat_xyzw]}


def _board_world_points(T_world_board: np.ndarray) -> np.ndarray:
    return geo.transform_points(T_world_board, np.vstack([board_object_points(), board_outline_board()]))


def board_fully_visible(cam: PinholeCamera, T_world_cam: np.ndarray, T_world_board: np.ndarray,
                        margin_px: float = 12.0, max_angle_deg: float = 65.0) -> bool:
    """All inner corners and the paper outline inside the image, the printed side facing the camera."""
    pts = _board_world_points(T_world_board)
    uv = cam.project(T_world_cam, pts)
    w, h = cam.size
    if not np.all(np.isfinite(uv)):
        return False
    if np.any(uv < margin_px) or np.any(uv[:, 0] > w - 1 - margin_px) or np.any(uv[:, 1] > h - 1 - margin_px):
        return False
    # the printed side faces -z of the board frame
    to_cam = T_world_cam[:3, 3] - T_world_board[:3, 3]
    to_cam /= np.linalg.norm(to_cam)
    return bool(-T_world_board[:3, 2] @ to_cam > math.cos(math.radians(max_angle_deg)))


def _board_centre_local() -> np.ndarray:
    cols, rows = gtroom.CHESSBOARD_SQUARES
    sq = gtroom.CHESSBOARD_SQUARE_M
    return np.array([(cols / 2 - 1) * sq, (rows / 2 - 1) * sq, 0.0])


def sample_intrinsic_poses(cam: PinholeCamera, T_world_cam: np.ndarray, n: int,
                           rng: np.random.Generator) -> list[np.ndarray]:
    """``n`` hand-held board poses ``T_world_board`` filling the image with varied tilt; the board
    stays above the floor and wholly in view."""
    out: list[np.ndarray] = []
    w, h = cam.size
    Kinv = np.linalg.inv(cam.K)
    cell = 0
    for _ in range(200000):
        if len(out) == n:
            break
        # stratify the board centre over a 3 x 3 grid of the image so that the sweep fills it
        gx, gy = cell % 3, (cell // 3) % 3
        px = np.array([w * (0.2 + 0.3 * gx + rng.uniform(-0.12, 0.12)),
                       h * (0.2 + 0.3 * gy + rng.uniform(-0.12, 0.12)), 1.0])
        ray = Kinv @ px
        ray /= np.linalg.norm(ray)
        d = rng.uniform(1.8, 3.6)
        tilt = np.radians([rng.uniform(-40, 40), rng.uniform(-40, 40), rng.uniform(-20, 20)])
        R = geo.T_from_xyz_rpy([0, 0, 0], tilt)[:3, :3]  # board axes in the camera frame (facing it)
        c_cam = ray * d
        T_cam_board = geo.make_T(R, c_cam - R @ _board_centre_local())
        T = T_world_cam @ T_cam_board
        pts = _board_world_points(T)
        if np.min(pts[:, 2]) < 0.05:
            continue
        if board_fully_visible(cam, T_world_cam, T):
            out.append(T)
            cell += 1
    if len(out) < n:
        raise RuntimeError(f"could only place {len(out)} of {n} calibration boards in view")
    return out


def sample_pair_poses(camA: PinholeCamera, T_world_camA: np.ndarray, camB: PinholeCamera,
                      T_world_camB: np.ndarray, T_board1_board2: np.ndarray, n: int,
                      rng: np.random.Generator) -> list[np.ndarray]:
    """``n`` poses ``T_world_board1`` of the rigid double board with board 1 wholly in camera A and
    board 2 wholly in camera B."""
    out: list[np.ndarray] = []
    cA, cB = T_world_camA[:3, 3], T_world_camB[:3, 3]
    zA, zB = T_world_camA[:3, 2], T_world_camB[:3, 2]
    off12 = T_board1_board2[:3, 3]
    for _ in range(200000):
        if len(out) == n:
            break
        hgt = rng.uniform(0.2, 1.4)
        # where each optical axis meets the horizontal plane at that height
        fa = cA + zA * (hgt - cA[2]) / zA[2]
        fb = cB + zB * (hgt - cB[2]) / zB[2]
        ex = np.r_[(fb - fa)[:2], 0.0]
        ex /= np.linalg.norm(ex)
        yaw = math.atan2(ex[1], ex[0]) + rng.normal(0, 0.12)
        # printed side up towards the cameras: board z points down, then tilt
        R = (geo.T_from_xyz_rpy([0, 0, 0], [math.pi + rng.normal(0, 0.25), rng.normal(0, 0.2), yaw]))[:3, :3]
        mid = 0.5 * (fa + fb) + np.r_[rng.normal(0, 0.25, 2), 0.0]
        centre_local = _board_centre_local() + 0.5 * off12
        T = geo.make_T(R, mid - R @ centre_local)
        T2 = T @ T_board1_board2
        if min(_board_world_points(T)[:, 2].min(), _board_world_points(T2)[:, 2].min()) < 0.05:
            continue
        if board_fully_visible(camA, T_world_camA, T) and board_fully_visible(camB, T_world_camB, T2):
            out.append(T)
    if len(out) < n:
        raise RuntimeError(f"could only place {len(out)} of {n} double boards in view")
    return out


# ------------------------------------------------------------------------------------ calibration
@dataclass(frozen=True)
class _StillShared:
    scene: Scene
    ccfg: CameraSimConfig
    seed: int
    noise_draw: int = 0


#: one still image: the camera, the boards' poses ``T_world_board``, the file, the camera's index, the
#: image's serial number (its noise stream) and whether the boards are ChArUco boards (else chessboards)
_StillJob = tuple[Camera, list[np.ndarray], str, int, int, bool]


def _still_frame(sh: _StillShared, job: _StillJob) -> None:
    cam_rig, boards, path, cam_index, k, charuco = job
    view = _cached_view(sh.scene, cam_rig, sh.ccfg)
    make_face = charuco_face if charuco else board_face
    faces = [make_face(T, view.cam, view.T_world_cam, sh.ccfg.supersample, f"board{i}")
             for i, T in enumerate(boards)]
    # painter's order: farther board first
    eye = view.T_world_cam[:3, 3]
    order = np.argsort([-np.linalg.norm(T[:3, 3] - eye) for T in boards])
    faces = [faces[i] for i in order]
    extent = np.vstack([_board_world_points(T) for T in boards])
    img = render_faces_frame(view, faces, sh.ccfg, _frame_rng(sh.seed, cam_index, k, 2, sh.noise_draw), extent)
    _write_png(Path(path), img, sh.ccfg)


def write_calibration_sets(scene: Scene, rec_dir: str | os.PathLike[str], cfg: SimConfig) -> dict[str, Any]:
    """Write ``calib/`` (intrinsic sweeps, double-board pairs, world-board views, ``boards.yaml``) and
    ``truth/boards.yaml`` of a recording.

    Returns the truth document written to ``truth/boards.yaml``.
    """
    rec = Path(rec_dir)
    cams = scene.rig_true.cameras
    rng = np.random.default_rng([cfg.seed, 4242])
    jobs: list[_StillJob] = []
    sweep_charuco = cfg.calib_board == "charuco"
    truth: dict[str, Any] = {
        "T_board1_board2": _pose_dict(scene.T_board1_board2_true),
        "T_world_board": _pose_dict(scene.T_world_board),
        "intrinsics": {}, "pairs": {}, "world_board": {},
    }
    serial = 0
    for ci, c in enumerate(cams):
        pc, Twc = PinholeCamera.from_rig(c), c.T_world_cam.matrix()
        poses = sample_intrinsic_poses(pc, Twc, cfg.n_intrinsic_views, rng)
        entries = []
        for k, T in enumerate(poses):
            name = f"{k:06d}.png"
            jobs.append((c, [T], str(rec / "calib" / "intrinsics" / c.name / name), ci, serial, sweep_charuco))
            serial += 1
            entries.append({"image": name, "T_cam_board": _pose_dict(geo.inv_T(Twc) @ T)})
        truth["intrinsics"][c.name] = entries
    for ca, cb in zip(cams[:-1], cams[1:], strict=True):
        ia, ib = _cam_index(scene, ca.name), _cam_index(scene, cb.name)
        pa, pb = PinholeCamera.from_rig(ca), PinholeCamera.from_rig(cb)
        Ta, Tb = ca.T_world_cam.matrix(), cb.T_world_cam.matrix()
        poses = sample_pair_poses(pa, Ta, pb, Tb, scene.T_board1_board2_true, cfg.n_pair_views, rng)
        pair = f"{ca.name}-{cb.name}"
        entries = []
        for k, T1 in enumerate(poses):
            T2 = T1 @ scene.T_board1_board2_true
            name = f"{k:06d}.png"
            for c, ci in ((ca, ia), (cb, ib)):
                jobs.append((c, [T1, T2], str(rec / "calib" / "pairs" / pair / c.name / name), ci, serial, False))
                serial += 1
            entries.append({"image": name, "T_world_board1": _pose_dict(T1),
                            f"T_{ca.name}_board1": _pose_dict(geo.inv_T(Ta) @ T1),
                            f"T_{cb.name}_board2": _pose_dict(geo.inv_T(Tb) @ T2)})
        truth["pairs"][pair] = entries
    for ci, c in enumerate(cams):
        pc, Twc = PinholeCamera.from_rig(c), c.T_world_cam.matrix()
        if not board_fully_visible(pc, Twc, scene.T_world_board, margin_px=5.0, max_angle_deg=80.0):
            continue
        names = []
        for k in range(cfg.n_world_board_views):
            name = f"{k:06d}.png"
            path = rec / "calib" / "world_board" / c.name / name
            jobs.append((c, [scene.T_world_board], str(path), ci, serial, False))
            serial += 1
            names.append(name)
        truth["world_board"][c.name] = {"images": names,
                                        "T_cam_board": _pose_dict(geo.inv_T(Twc) @ scene.T_world_board)}
    if not truth["world_board"]:
        log.warning("no camera sees the whole world board")
    for c in cams:
        _cached_view(scene, c, cfg.camera)  # once, before forking: workers inherit them
    shared = _StillShared(scene, cfg.camera, cfg.seed, cfg.noise_draw_of("calibration"))
    _parallel_map(_still_frame, shared, jobs, cfg.workers)

    cols, rows = gtroom.CHESSBOARD_SQUARES
    nominal = {
        "squares": [cols, rows],
        "inner_corners": [cols - 1, rows - 1],
        "square_m": gtroom.CHESSBOARD_SQUARE_M,
        "margin_m": 0.05,
        "object_points": "(i * square_m, j * square_m, 0), i along the 9 corners of a row, row-major; "
                         "board z points into the board (away from a camera seeing the print)",
        "T_board1_board2": _pose_dict(scene.T_board1_board2_nominal),
        "T_world_board": _pose_dict(scene.T_world_board),
    }
    if sweep_charuco:
        # the intrinsic sweeps show a ChArUco board in its own frame (origin at the outer corner)
        nominal["sweep_board"] = charuco_board_document(sim_charuco_board())
    atomic_write_text(rec / "calib" / "boards.yaml", yaml.safe_dump(nominal, sort_keys=False))
    atomic_write_text(rec / "truth" / "boards.yaml", yaml.safe_dump(truth, sort_keys=False))
    return truth


# --------------------------------------------------------------------------------------- hand-held
def handheld_camera() -> PinholeCamera:
    """The hand-held survey camera: 1600 x 1200, known (calibrated) intrinsics."""
    w, h = HANDHELD_SIZE
    K = np.array([[1320.0, 0.0, 801.3], [0.0, 1320.0, 597.8], [0.0, 0.0, 1.0]])
    return PinholeCamera(K, np.array([-0.085, 0.06, 0.0004, -0.0002, 0.0]), (w, h))


HANDHELD_ROBOT_XYTHETA = (0.36, 2.0, 0.4)


def _markers_in_view(scene: Scene, cam: PinholeCamera, T_world_cam: np.ndarray, T_world_robot: np.ndarray,
                     margin: float = 15.0) -> list[int]:
    seen = []
    w, h = cam.size
    for m in scene.rig_true.robot.markers:
        T = T_world_robot @ m.T_robot_marker.matrix()
        uv = cam.project(T_world_cam, geo.transform_points(T, marker_corners_local(m.side_m)))
        if not np.all(np.isfinite(uv)):
            continue
        if np.any(uv < margin) or np.any(uv[:, 0] > w - 1 - margin) or np.any(uv[:, 1] > h - 1 - margin):
            continue
        to_cam = T_world_cam[:3, 3] - T[:3, 3]
        if T[:3, 2] @ to_cam / np.linalg.norm(to_cam) < math.cos(math.radians(70)):
            continue
        seen.append(m.id)
    return seen


def sample_handheld_poses(scene: Scene, T_world_robot: np.ndarray, cam: PinholeCamera, n: int,
                          rng: np.random.Generator) -> tuple[list[np.ndarray], list[list[int]]]:
    """``n`` hand-held camera poses ``T_world_cam`` around the robot, each seeing at least two markers
    whole, and every marker seen together with another in at least two images."""
    top = geo.transform_points(T_world_robot, np.array([[0.0, 0.0, gtroom.ROBOT_TOP_M]]))[0]
    ids = [m.id for m in scene.rig_true.robot.markers]
    for _attempt in range(50):
        poses: list[np.ndarray] = []
        seen_all: list[list[int]] = []
        tries = 0
        while len(poses) < n and tries < 20000:
            tries += 1
            az = 2 * math.pi * (len(poses) + rng.uniform(0, 1)) / n
            el = math.radians(rng.uniform(35, 72))
            dist = rng.uniform(1.0, 2.0)
            eye = top + dist * np.array([math.cos(el) * math.cos(az), math.cos(el) * math.sin(az),
                                         math.sin(el)])
            target = top + np.r_[rng.normal(0, 0.12, 2), 0.0]
            roll = geo.T_from_xyz_rpy([0, 0, 0], [0, 0, math.radians(rng.normal(0, 12))])
            T = geo.look_at(eye, target) @ roll
            seen = _markers_in_view(scene, cam, T, T_world_robot)
            if len(seen) >= 2:
                poses.append(T)
                seen_all.append(seen)
        if len(poses) < n:
            continue
        together = {i: sum(1 for s in seen_all if i in s and len(s) >= 2) for i in ids}
        if min(together.values()) >= 2:
            return poses, seen_all
    raise RuntimeError("could not place the hand-held views")


@dataclass(frozen=True)
class _HandShared:
    scene: Scene
    ccfg: CameraSimConfig
    motion: RobotMotion
    seed: int
    folder: Path
    noise_draw: int = 0


def _hand_frame(sh: _HandShared, job: tuple[int, np.ndarray]) -> None:
    k, T_world_cam = job
    cam = handheld_camera()
    T_world_robot = sh.motion.T_world_robot(0.0)
    centre = geo.transform_points(T_world_robot, np.array([[0.0, 0.0, gtroom.ROBOT_TOP_M]]))[0]
    inv_focus = 1.0 / float((geo.inv_T(T_world_cam) @ np.r_[centre, 1.0])[2])
    view = make_view(sh.scene, cam, T_world_cam, sh.ccfg, s=1, focus_inv_depth=inv_focus)
    img = render_robot_frame(sh.scene, view, sh.motion, 0.0, sh.ccfg, _frame_rng(sh.seed, 99, k, 3, sh.noise_draw),
                             focus_inv_depth=inv_focus)
    _write_png(sh.folder / f"{k:06d}.png", img, sh.ccfg)


def write_handheld_set(scene: Scene, rec_dir: str | os.PathLike[str], cfg: SimConfig) -> list[np.ndarray]:
    """Write ``handheld/camera.yaml``, ``handheld/images/NNNNNN.png`` and ``truth/handheld.tum``.

    A hand-held camera shoots the static robot (at :data:`HANDHELD_ROBOT_XYTHETA`) from
    ``cfg.n_handheld_views`` angles. Returns the true poses ``T_world_cam`` (4, 4) of the images.
    """
    rec = Path(rec_dir)
    cam = handheld_camera()
    x, y, th = HANDHELD_ROBOT_XYTHETA
    motion = RobotMotion(np.array([0.0, 1.0]), np.array([[x, y, th], [x, y, th]]), scene.floor)
    T_world_robot = motion.T_world_robot(0.0)
    rng = np.random.default_rng([cfg.seed, 4343])
    poses, _ = sample_handheld_poses(scene, T_world_robot, cam, cfg.n_handheld_views, rng)
    folder = rec / "handheld" / "images"
    folder.mkdir(parents=True, exist_ok=True)
    # the hand is steady and the exposure short: no motion blur in the survey images
    ccfg = cfg.camera.model_copy(update={"motion_blur": False})
    shared = _HandShared(scene, ccfg, motion, cfg.seed, folder, cfg.noise_draw_of("calibration"))
    _parallel_map(_hand_frame, shared, list(enumerate(poses)), cfg.workers)
    doc = {
        "image_size": [cam.size[0], cam.size[1]],
        "camera_matrix": cam.K.tolist(),
        "dist_coeffs": cam.dist.tolist(),
        "rms_px": 0.15,
    }
    atomic_write_text(rec / "handheld" / "camera.yaml", yaml.safe_dump(doc, sort_keys=False))
    write_tum(rec / "truth" / "handheld.tum",
              Trajectory.from_matrices(np.arange(len(poses), dtype=float), np.stack(poses)))
    rp = _pose_dict(T_world_robot)
    text = (rec / "truth" / "handheld.tum").read_text()
    atomic_write_text(rec / "truth" / "handheld.tum",
                      f"# robot during the hand-held survey, T_world_robot: xyz {rp['xyz']} quat_xyzw "
                      f"{rp['quat_xyzw']}\n" + text)
    return poses
