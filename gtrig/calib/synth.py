"""Synthetic chessboard data for tests and for measuring the calibration: projected corners with noise,
and rendered images (a ray-cast of textured planes through the OpenCV distortion model, supersampled).

Rendering: for every sub-pixel the distorted normalised coordinates are undistorted (OpenCV,
iterative), the ray is cut with each plane, and the nearest hit's texture is sampled; the supersamples are
box-averaged, then Gaussian blur (defocus) and Gaussian noise are added. Not a physical camera model
(no vignetting, no motion blur): the simulator's ``gtrig.sim`` images are the realistic ones.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import cv2
import numpy as np

from gtrig import geometry as geo
from gtrig.calib.chessboard import Board

Texture = Callable[[np.ndarray, np.ndarray], np.ndarray]


def project_board(K: np.ndarray, dist: np.ndarray, T_cam_board: np.ndarray, board: Board) -> np.ndarray:
    """Pixel positions (N, 2) of the board's inner corners (board order)."""
    return geo.project_points(geo.transform_points(T_cam_board, board.object_points()), K, dist)


def in_image(uv: np.ndarray, size: tuple[int, int], margin_px: float = 20.0) -> bool:
    """True if all points are at least ``margin_px`` inside the image."""
    w, h = size
    return bool(
        np.all(
            (uv[:, 0] > margin_px)
            & (uv[:, 0] < w - 1 - margin_px)
            & (uv[:, 1] > margin_px)
            & (uv[:, 1] < h - 1 - margin_px)
        )
    )


def board_outline_points(board: Board, margin_squares: float = 1.5) -> np.ndarray:
    """The corners (4, 3) of the printed sheet (squares plus white margin) in the board frame."""
    s = board.square_m
    P = board.object_points()
    lo = P[:, :2].min(axis=0) - s * margin_squares
    hi = P[:, :2].max(axis=0) + s * margin_squares
    return np.array([[lo[0], lo[1], 0], [hi[0], lo[1], 0], [hi[0], hi[1], 0], [lo[0], hi[1], 0]])


def random_intrinsic_views(
    rng: np.random.Generator,
    K: np.ndarray,
    dist: np.ndarray,
    size: tuple[int, int],
    board: Board,
    n: int,
    depth_m: tuple[float, float] = (1.5, 3.5),
    max_tilt_deg: float = 40.0,
) -> list[np.ndarray]:
    """``n`` board poses ``T_cam_board`` spread over the image, tilted up to ``max_tilt_deg``, all
    corners and the sheet's outline inside the image."""
    out: list[np.ndarray] = []
    w, h = size
    Kinv = np.linalg.inv(K)
    P = board.object_points()
    centre = P.mean(axis=0)
    tries = 0
    while len(out) < n:
        tries += 1
        if tries > 200 * n:
            raise RuntimeError("could not place the board in view; image too small for the board?")
        z = rng.uniform(*depth_m)
        uv = np.array([rng.uniform(0.15, 0.85) * w, rng.uniform(0.15, 0.85) * h, 1.0])
        c = Kinv @ uv * z
        tilt = np.radians(rng.uniform(-max_tilt_deg, max_tilt_deg, 2))
        R = geo.T_from_xyz_rpy([0, 0, 0], [tilt[0], tilt[1], rng.uniform(-0.4, 0.4)])[:3, :3]
        T = geo.make_T(R, c - R @ centre)
        corners = project_board(K, dist, T, board)
        sheet = geo.project_points(geo.transform_points(T, board_outline_points(board, 0.7)), K, dist)
        if in_image(corners, size, 10) and in_image(sheet, size, 2):
            out.append(T)
    return out


def checker_texture(
    board: Board, margin_squares: float = 1.0, dark: float = 25.0, light: float = 225.0
) -> Texture:
    """Texture of a printed chessboard in its board frame (NaN outside the sheet)."""
    s = board.square_m
    P = board.object_points()
    x0, y0 = P[0, 0], P[0, 1]  # first inner corner

    def tex(x: np.ndarray, y: np.ndarray) -> np.ndarray:
        i = np.floor((x - x0) / s)
        j = np.floor((y - y0) / s)
        inside = (i >= -1) & (i <= board.cols - 1) & (j >= -1) & (j <= board.rows - 1)
        v = np.where(((i + j) % 2 == 0) & inside, dark, light)
        sheet = (
            (x - x0 >= -s * (1 + margin_squares))
            & (x - x0 <= s * (board.cols + margin_squares))
            & (y - y0 >= -s * (1 + margin_squares))
            & (y - y0 <= s * (board.rows + margin_squares))
        )
        return np.where(sheet, v, np.nan)

    return tex


def noise_texture(
    rng: np.random.Generator,
    extent_m: float = 20.0,
    cell_m: float = 0.03,
    mean: float = 120.0,
    amp: float = 50.0,
) -> Texture:
    """A smooth random texture (bilinear value noise) over ``[-extent, extent]^2`` metres."""
    n = int(2 * extent_m / cell_m) + 2
    noise = cv2.GaussianBlur(rng.normal(0, 1, (n, n)).astype(np.float32), (0, 0), 1.0)
    grid = (noise / noise.std() * amp + mean).astype(np.float32)

    def tex(x: np.ndarray, y: np.ndarray) -> np.ndarray:
        gx = np.nan_to_num((x.ravel() + extent_m) / cell_m, posinf=0.0, neginf=0.0).astype(np.float32)
        gy = np.nan_to_num((y.ravel() + extent_m) / cell_m, posinf=0.0, neginf=0.0).astype(np.float32)
        n = gx.size
        width = 4096
        pad = (-n) % width
        gx = np.pad(gx, (0, pad)).reshape(-1, width)
        gy = np.pad(gy, (0, pad)).reshape(-1, width)
        out = cv2.remap(grid, gx, gy, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REFLECT)
        return out.ravel()[:n].reshape(x.shape).astype(np.float64)

    return tex


@dataclass(frozen=True)
class Plane:
    """A textured plane: its frame in the world (the plane is its z = 0) and a texture of (x, y)."""

    T_world_plane: np.ndarray
    texture: Texture


_RAY_CACHE: dict[tuple, np.ndarray] = {}


def _ray_grid(K: np.ndarray, dist: np.ndarray, size: tuple[int, int], ss: int) -> np.ndarray:
    """Undistorted normalised rays (h*ss, w*ss, 2) of every sub-pixel, cached per camera."""
    key = (tuple(np.round(K.ravel(), 9)), tuple(np.round(dist.ravel(), 12)), tuple(size), ss)
    if key not in _RAY_CACHE:
        w, h = size
        u = (np.arange(w * ss) + 0.5) / ss - 0.5
        v = (np.arange(h * ss) + 0.5) / ss - 0.5
        U, V = np.meshgrid(u, v)
        pts = np.stack([U, V], axis=-1).reshape(-1, 1, 2)
        crit = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 30, 1e-12)
        xy = cv2.undistortPoints(pts, K, dist, None, None, None, crit).reshape(h * ss, w * ss, 2)
        if len(_RAY_CACHE) > 6:
            _RAY_CACHE.clear()
        _RAY_CACHE[key] = xy
    return _RAY_CACHE[key]


def render(
    K: np.ndarray,
    dist: np.ndarray,
    size: tuple[int, int],
    T_world_cam: np.ndarray,
    planes: Sequence[Plane],
    *,
    background: float = 90.0,
    supersample: int = 3,
    blur_sigma_px: float = 0.5,
    noise_sigma: float = 2.0,
    rng: np.random.Generator | None = None,
    roi: tuple[int, int, int, int] | None = None,
) -> np.ndarray:
    """Render an 8-bit grey image (h, w) of textured planes seen by a camera at ``T_world_cam``.

    ``roi = (x0, y0, x1, y1)`` (pixels) limits the ray casting to a window; the rest is ``background``.
    """
    w, h = size
    ss = supersample
    K = np.asarray(K, dtype=float)
    dist = np.asarray(dist, dtype=float).ravel()
    x0, y0, x1, y1 = roi if roi is not None else (0, 0, w, h)
    x0, y0, x1, y1 = max(0, x0), max(0, y0), min(w, x1), min(h, y1)
    full = np.full((h, w), background, dtype=float)
    if x1 > x0 and y1 > y0:
        xy = _ray_grid(K, dist, size, ss)[y0 * ss : y1 * ss, x0 * ss : x1 * ss]
        rays_c = np.concatenate([xy, np.ones(xy.shape[:2] + (1,))], axis=-1)
        sub = np.full(xy.shape[:2], background)
        depth = np.full(xy.shape[:2], np.inf)
        for pl in planes:
            T_plane_cam = geo.inv_T(pl.T_world_plane) @ T_world_cam
            Rp, tp = T_plane_cam[:3, :3], T_plane_cam[:3, 3]
            d = rays_c @ Rp.T  # ray directions in the plane frame
            with np.errstate(divide="ignore", invalid="ignore"):
                s = -tp[2] / d[..., 2]
                px = tp[0] + s * d[..., 0]
                py = tp[1] + s * d[..., 1]
                val = pl.texture(px, py)
            hit = (s > 0) & (s < depth) & np.isfinite(val)
            sub[hit] = val[hit]
            depth[hit] = s[hit]
        full[y0:y1, x0:x1] = sub.reshape(y1 - y0, ss, x1 - x0, ss).mean(axis=(1, 3))
    img = full
    if blur_sigma_px > 0:
        img = cv2.GaussianBlur(img, (0, 0), blur_sigma_px)
    if noise_sigma > 0:
        rng = rng or np.random.default_rng(0)
        img = img + rng.normal(0, noise_sigma, img.shape)
    return np.clip(np.round(img), 0, 255).astype(np.uint8)


def render_board_view(
    K: np.ndarray,
    dist: np.ndarray,
    size: tuple[int, int],
    T_cam_board: np.ndarray,
    board: Board,
    rng: np.random.Generator | None = None,
    **kw: Any,
) -> np.ndarray:
    """One chessboard on a plain background, the board at ``T_cam_board``."""
    sheet = geo.project_points(geo.transform_points(T_cam_board, board_outline_points(board, 1.1)), K, dist)
    lo = np.floor(sheet.min(axis=0)).astype(int) - 4
    hi = np.ceil(sheet.max(axis=0)).astype(int) + 5
    return render(
        K,
        dist,
        size,
        np.eye(4),
        [Plane(T_cam_board, checker_texture(board))],
        rng=rng,
        roi=(int(lo[0]), int(lo[1]), int(hi[0]), int(hi[1])),
        **kw,
    )


def sample_double_board(
    rng: np.random.Generator,
    T_world_camA: np.ndarray,
    T_world_camB: np.ndarray,
    KA: np.ndarray,
    distA: np.ndarray,
    sizeA: tuple[int, int],
    KB: np.ndarray,
    distB: np.ndarray,
    sizeB: tuple[int, int],
    board: Board,
    T_board1_board2: np.ndarray,
    height_m: tuple[float, float] = (0.6, 1.4),
    max_tries: int = 20000,
) -> np.ndarray:
    """A pose ``T_world_board1`` of the double board, held so that board 1 is whole in camera A and
    board 2 whole in camera B, facing the cameras, tilted at random (rejection sampling)."""
    P = board.object_points()
    c1 = P.mean(axis=0)
    c12 = (c1 + geo.transform_points(T_board1_board2, c1)) / 2
    eyeA, eyeB = T_world_camA[:3, 3], T_world_camB[:3, 3]
    for _ in range(max_tries):
        zA = T_world_camA[:3, 2]
        zB = T_world_camB[:3, 2]
        # where each camera's axis meets a horizontal plane at the drawn height
        hgt = rng.uniform(*height_m)
        gA = eyeA + zA * (hgt - eyeA[2]) / zA[2]
        gB = eyeB + zB * (hgt - eyeB[2]) / zB[2]
        mid = (gA + gB) / 2 + np.r_[rng.normal(0, 0.25, 2), 0.0]
        xdir = gB - gA
        xdir[2] = 0
        xdir /= np.linalg.norm(xdir)
        look = (eyeA + eyeB) / 2 - mid
        look /= np.linalg.norm(look)
        zb = -look  # board z points away from the cameras
        xb = xdir - zb * (xdir @ zb)
        xb /= np.linalg.norm(xb)
        R = np.column_stack([xb, np.cross(zb, xb), zb])
        R = R @ geo.T_from_xyz_rpy([0, 0, 0], np.radians(rng.normal(0, [20, 20, 10])))[:3, :3]
        T = geo.make_T(R, mid - R @ c12)
        cA = project_board(KA, distA, geo.inv_T(T_world_camA) @ T, board)
        cB = project_board(KB, distB, geo.inv_T(T_world_camB) @ T @ T_board1_board2, board)
        okA = geo.transform_points(geo.inv_T(T_world_camA) @ T, P)[:, 2].min() > 0.3
        okB = geo.transform_points(geo.inv_T(T_world_camB) @ T @ T_board1_board2, P)[:, 2].min() > 0.3
        if okA and okB and in_image(cA, sizeA, 15) and in_image(cB, sizeB, 15):
            return T
    raise RuntimeError("no double-board pose found with board 1 in camera A and board 2 in camera B")


def synthetic_network(
    rig_true,
    rig_nominal,
    board: Board,
    T12_true: np.ndarray,
    T12_nominal: np.ndarray,
    T_world_board: np.ndarray,
    pairs: Sequence[tuple[str, str]],
    world_cams: Sequence[str],
    n_pair_views: int,
    noise_px: float,
    rng: np.random.Generator,
    n_world_views: int = 2,
    intrinsics=None,
):  # noqa: ANN001, ANN201
    """A :class:`gtrig.calib.network.NetworkProblem` of projected corners plus Gaussian noise.

    ``rig_true`` (cameras and their true poses) makes the observations; ``rig_nominal`` gives the
    believed poses; ``intrinsics`` ({name: CameraIntrinsics}) defaults to the true ones.
    """
    from gtrig.calib.network import NetworkProblem, PairView, WorldView
    from gtrig.io.camfile import CameraIntrinsics

    cams = {c.name: c for c in rig_true.cameras}
    intr = intrinsics or {n: CameraIntrinsics(c.resolution, c.K, c.dist) for n, c in cams.items()}
    pv = []
    for a, b in pairs:
        ca, cb = cams[a], cams[b]
        Ta, Tb = ca.T_world_cam.matrix(), cb.T_world_cam.matrix()
        for i in range(n_pair_views):
            T = sample_double_board(
                rng, Ta, Tb, ca.K, ca.dist, ca.resolution, cb.K, cb.dist, cb.resolution, board, T12_true
            )
            ua = project_board(ca.K, ca.dist, geo.inv_T(Ta) @ T, board) + rng.normal(
                0, noise_px, (board.n_corners, 2)
            )
            ub = project_board(cb.K, cb.dist, geo.inv_T(Tb) @ T @ T12_true, board) + rng.normal(
                0, noise_px, (board.n_corners, 2)
            )
            if rng.random() < 0.5:
                ua = ua[::-1].copy()  # the detector's half-turn ambiguity
            pv.append(PairView(a, b, f"{i:06d}.png", ua, ub))
    wv = []
    for n in world_cams:
        c = cams[n]
        for i in range(n_world_views):
            u = project_board(c.K, c.dist, geo.inv_T(c.T_world_cam.matrix()) @ T_world_board, board)
            wv.append(WorldView(n, f"{i:06d}.png", u + rng.normal(0, noise_px, u.shape), T_world_board))
    nominal = {c.name: c.T_world_cam.matrix() for c in rig_nominal.cameras}
    return NetworkProblem(board, T12_nominal, intr, nominal, pv, wv)
