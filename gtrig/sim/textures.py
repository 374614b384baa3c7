"""Procedural textures and the planar faces of the simulated scene (room, clutter, robot, markers,
chessboards) for :mod:`gtrig.sim.render`.

Texture values are linear radiance relative to a white sheet under the room's average light (0..~2;
the camera maps 1.0 to about grey level 200). Illumination is baked into the static textures: ceiling
lights give a smooth gradient and the sun through the window a bright, soft-edged patch on the floor
(see ``docs/simulator.md``).
"""

from __future__ import annotations

import functools
import math

import numpy as np

from gtrig import geometry as geo
from gtrig.calib.charuco import CharucoBoard
from gtrig.markers.families import marker_cells
from gtrig.rig.models import Marker
from gtrig.sim import gtroom
from gtrig.sim.gtroom import Box, Scene
from gtrig.sim.render import Face, PinholeCamera, texture_affine

PAPER = 0.90  # white paper
INK = 0.06  # black toner (matte prints reflect a few percent)
PLATE = 0.45  # the robot's top plate (anodised grey)
GOWN = 0.18  # the dark fabric gown
MARKER_MARGIN_M = 0.012  # white paper around each marker's black square
BOARD_MARGIN_M = 0.05  # white margin around the chessboard's squares
ROOM_HEIGHT_M = 3.2
WINDOW_WALL = 2  # index of the wall with the window (room_walls order)
WINDOW_SPAN = (0.35, 0.65)  # along the wall, fraction of its length
WINDOW_Z = (0.9, 2.3)
SUN_GAIN = 1.6  # direct sun on top of the ambient light
SUN_SOFT_M = 0.06  # penumbra (sun disc 0.5 deg over ~4 m, plus the diffusing window frame)


# ------------------------------------------------------------------------------------------ helpers
def _frame_on_wall(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Face frame of a vertical wall from floor point a to b (world xy): x along the wall, y up,
    z = x cross y, which points into the room when the room is on the right of a->b."""
    ex = np.r_[b - a, 0.0]
    ex /= np.linalg.norm(ex)
    ey = np.array([0.0, 0.0, 1.0])
    ez = np.cross(ex, ey)
    return geo.make_T(np.column_stack([ex, ey, ez]), np.r_[a, 0.0])


def _smooth_noise(rng: np.random.Generator, shape: tuple[int, int], scale_px: float,
                  amp: float) -> np.ndarray:
    import cv2

    n = rng.standard_normal(shape).astype(np.float32)
    n = np.asarray(cv2.GaussianBlur(n, (0, 0), scale_px), dtype=np.float32)
    sd = float(n.std()) or 1.0
    return (n / sd * amp).astype(np.float32)


def sun_geometry(scene: Scene) -> tuple[np.ndarray, np.ndarray]:
    """Window corners (4, 3) in the world and the unit direction (3,) of sunlight (downwards, into the
    room), drawn from the scene seed."""
    walls = scene.walls
    centroid = walls[:, 0].mean(axis=0)
    a, b = walls[WINDOW_WALL]
    inward = np.array([-(b - a)[1], (b - a)[0]])
    inward /= np.linalg.norm(inward)
    if inward @ (centroid - a) < 0:
        inward = -inward
    rng = np.random.default_rng([scene.seed, 31])
    elev = math.radians(rng.uniform(25, 40))
    azim = math.atan2(inward[1], inward[0]) + math.radians(rng.uniform(-30, 30))
    d = np.array([math.cos(elev) * math.cos(azim), math.cos(elev) * math.sin(azim), -math.sin(elev)])
    corners = []
    for f, z in ((WINDOW_SPAN[0], WINDOW_Z[0]), (WINDOW_SPAN[1], WINDOW_Z[0]),
                 (WINDOW_SPAN[1], WINDOW_Z[1]), (WINDOW_SPAN[0], WINDOW_Z[1])):
        p = a + f * (b - a)
        corners.append([p[0], p[1], z])
    return np.array(corners), d


def floor_illumination(scene: Scene, xy: np.ndarray, sunlight: bool = True) -> np.ndarray:
    """Relative illumination of floor points ``xy`` (..., 2): ceiling lights plus the sun patch."""
    xy = np.asarray(xy, float)
    c = scene.walls[:, 0].mean(axis=0)
    # two rows of ceiling lights: a broad bump over the room's middle, darker towards the walls
    r2 = np.sum((xy - c) ** 2, axis=-1)
    light = 0.75 + 0.35 * np.exp(-r2 / (2 * 3.0 ** 2))
    if sunlight:
        win, d = sun_geometry(scene)
        # the window's shadow outline on the floor: corners moved along d to z = 0
        poly = win[:, :2] + (-win[:, 2:3] / d[2]) * d[:2]
        sd = _signed_dist_convex(xy, poly)
        light = light + SUN_GAIN * np.clip(0.5 + sd / SUN_SOFT_M, 0, 1)
    return light


def _signed_dist_convex(xy: np.ndarray, poly: np.ndarray) -> np.ndarray:
    """Signed distance (positive inside) of points to a convex polygon's edges (min over edges)."""
    ctr = poly.mean(axis=0)
    out = np.full(xy.shape[:-1], np.inf)
    for i in range(len(poly)):
        a, b = poly[i], poly[(i + 1) % len(poly)]
        e = b - a
        n = np.array([-e[1], e[0]]) / np.linalg.norm(e)
        if n @ (ctr - a) < 0:
            n = -n
        out = np.minimum(out, (xy - a) @ n)
    return out


# ---------------------------------------------------------------------------------------- room faces
_ROOM_CACHE: dict[tuple[int, bool], tuple[Face, ...]] = {}


def room_faces(scene: Scene, sunlight: bool = True) -> tuple[Face, ...]:
    """Static faces: floor, walls and clutter boxes (with baked illumination). Cached per scene seed."""
    key = (scene.seed, sunlight)
    if key in _ROOM_CACHE:
        return _ROOM_CACHE[key]
    rng = np.random.default_rng([scene.seed, 32])
    faces: list[Face] = []
    walls = scene.walls
    lo = walls[:, 0].min(axis=0) - 0.2
    hi = walls[:, 0].max(axis=0) + 0.2
    texel = 0.01
    nx, ny = int(math.ceil((hi[0] - lo[0]) / texel)), int(math.ceil((hi[1] - lo[1]) / texel))
    A = texture_affine(lo[0], hi[1], texel, texel)
    cols, rows = np.meshgrid(np.arange(nx), np.arange(ny))
    xy = (A[:2, :2] @ np.stack([cols.ravel(), rows.ravel()]) + A[:2, 2:3]).T.reshape(ny, nx, 2)
    # 40 cm tiles with dark grout and slightly varying shades, plus stains
    tile = 0.40
    ti = np.floor(xy / tile).astype(int)
    shade = np.random.default_rng([scene.seed, 33]).uniform(-0.04, 0.04, (64, 64))
    alb = 0.42 + shade[ti[..., 0] % 64, ti[..., 1] % 64]
    frac = xy / tile - np.floor(xy / tile)
    grout = (np.minimum(frac, 1 - frac) * tile < 0.003).any(axis=-1)
    alb = np.where(grout, 0.22, alb) + _smooth_noise(rng, (ny, nx), 6, 0.02)
    # reference point marks: small crosses of tape
    for px, py in scene.reference_true_xy.values():
        cross = ((np.abs(xy[..., 0] - px) < 0.06) & (np.abs(xy[..., 1] - py) < 0.008)) | (
            (np.abs(xy[..., 1] - py) < 0.06) & (np.abs(xy[..., 0] - px) < 0.008))
        alb = np.where(cross, 0.85, alb)
    tex = (alb * floor_illumination(scene, xy, sunlight)).astype(np.float32)
    outline = walls[:, 0]
    if _poly_area(outline) < 0:
        outline = outline[::-1]
    faces.append(Face(np.eye(4), outline.copy(), tex, A, name="floor"))

    ccw = _poly_area(walls[:, 0]) > 0
    win, _ = sun_geometry(scene)
    for k, (a, b) in enumerate(walls):
        if ccw:
            a, b = b, a  # walk clockwise so that the frame's z (x cross up) points into the room
        T = _frame_on_wall(a, b)
        length = float(np.linalg.norm(b - a))
        wt = 0.02
        nxw, nyw = int(math.ceil(length / wt)), int(math.ceil(ROOM_HEIGHT_M / wt))
        Aw = texture_affine(0.0, ROOM_HEIGHT_M, wt, wt)
        xw = Aw[0, 0] * np.arange(nxw) + Aw[0, 2]
        yw = Aw[1, 1] * np.arange(nyw) + Aw[1, 2]
        X, Y = np.meshgrid(xw, yw)
        # plaster lit from the ceiling: brighter high up
        alb = 0.70 + 0.08 * (Y / ROOM_HEIGHT_M) + _smooth_noise(rng, (nyw, nxw), 3, 0.015)
        alb = np.where(Y < 0.10, 0.25, alb)  # skirting board
        if k == WINDOW_WALL:
            f = 1 - X / length if ccw else X / length
            inwin = (f > WINDOW_SPAN[0]) & (f < WINDOW_SPAN[1]) & (Y > WINDOW_Z[0]) & (Y < WINDOW_Z[1])
            alb = np.where(inwin, 1.6, alb)  # the bright sky through the glass
        if k == (WINDOW_WALL + 2) % 4:
            door = (np.abs(X - 0.5 * length) < 0.45) & (Y < 2.1)
            alb = np.where(door, 0.50, alb)
        outline = np.array([[0, 0], [length, 0], [length, ROOM_HEIGHT_M], [0, ROOM_HEIGHT_M]], float)
        faces.append(Face(T, outline, alb.astype(np.float32), Aw, name=f"wall{k}"))
    for box in scene.boxes:
        faces.extend(box_faces(box, rng))
    out = tuple(faces)
    _ROOM_CACHE[key] = out
    return out


def _poly_area(p: np.ndarray) -> float:
    x, y = p[:, 0], p[:, 1]
    return 0.5 * float(np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y))


def _flat_face(T: np.ndarray, w: float, h: float, value: float, rng: np.random.Generator | None,
               name: str, texel: float = 0.02) -> Face:
    """A w x h rectangle spanning [0, w] x [0, h] of the face frame with a mildly noisy texture."""
    nx, ny = max(2, int(math.ceil(w / texel))), max(2, int(math.ceil(h / texel)))
    tex = np.full((ny, nx), value, np.float32)
    if rng is not None:
        tex += _smooth_noise(rng, (ny, nx), 1.5, 0.02 * value)
    A = texture_affine(0.0, h, w / nx, h / ny)
    return Face(T, np.array([[0, 0], [w, 0], [w, h], [0, h]], float), tex, A, name=name)


def _box_side_faces(T_world_box: np.ndarray, lx: float, ly: float, z0: float, z1: float,
                    value: float, rng: np.random.Generator | None, name: str,
                    top: float | None = None) -> list[Face]:
    """The four vertical sides (outward normals) of a box centred on the frame's z axis, and its top."""
    out = []
    hx, hy = lx / 2, ly / 2
    corners = [(-hx, -hy), (hx, -hy), (hx, hy), (-hx, hy)]
    for i in range(4):
        a, b = np.array(corners[i]), np.array(corners[(i + 1) % 4])
        ex = np.r_[b - a, 0.0]
        length = float(np.linalg.norm(ex))
        ex /= length
        ey = np.array([0.0, 0.0, 1.0])
        ez = np.cross(ex, ey)  # outward for counter-clockwise corners
        T = T_world_box @ geo.make_T(np.column_stack([ex, ey, ez]), [a[0], a[1], z0])
        out.append(_flat_face(T, length, z1 - z0, value * (0.8 + 0.1 * (i % 3)), rng, f"{name}_side{i}"))
    if top is not None:
        T = T_world_box @ geo.make_T(np.eye(3), [-hx, -hy, z1])
        out.append(_flat_face(T, lx, ly, top, rng, f"{name}_top"))
    return out


def box_faces(box: Box, rng: np.random.Generator | None) -> list[Face]:
    T = geo.se2_to_T(box.centre_xy[0], box.centre_xy[1], box.yaw_rad)
    v = 0.25 + 0.5 * box.reflectivity
    return _box_side_faces(T, box.size[0], box.size[1], 0.0, box.size[2], v, rng, box.name, top=v * 1.15)


# --------------------------------------------------------------------------------------- robot faces
@functools.lru_cache(maxsize=64)
def _cells(family: str, marker_id: int) -> np.ndarray:
    return marker_cells(family, marker_id)


def cells_face(T_world_face: np.ndarray, cells: np.ndarray, side_m: tuple[float, float],
               margin_m: float, texels_per_cell: int, name: str,
               white: float = PAPER, black: float = INK) -> Face:
    """A printed grid of cells (rows top to bottom as printed, 1 = white) spanning ``side_m`` (w, h)
    centred on the face origin (x right, y up as printed), with a white margin. Cell edges fall on
    texel boundaries so that bilinear sampling puts each printed edge exactly where it is."""
    rows, cols = cells.shape
    k = int(texels_per_cell)
    tx, ty = side_m[0] / (cols * k), side_m[1] / (rows * k)
    pad = int(math.ceil(margin_m / min(tx, ty))) + 1
    img = np.kron(cells.astype(np.float32), np.ones((k, k), np.float32))
    img = np.pad(img, pad, constant_values=1.0)
    tex = (black + (white - black) * img).astype(np.float32)
    A = texture_affine(-side_m[0] / 2 - pad * tx, side_m[1] / 2 + pad * ty, tx, ty)
    hw, hh = side_m[0] / 2 + margin_m, side_m[1] / 2 + margin_m
    outline = np.array([[-hw, -hh], [hw, -hh], [hw, hh], [-hw, hh]])
    return Face(T_world_face, outline, tex, A, name=name)


def texels_for(cam: PinholeCamera, T_world_cam: np.ndarray, corners_world: np.ndarray, n_cells: int,
               s: int) -> int:
    """Texels per cell so that one texel spans at least one supersample where the printed grid is most
    foreshortened (bilinear ramps then antialias the edges)."""
    p = geo.transform_points(geo.inv_T(T_world_cam), corners_world)
    if np.any(p[:, 2] <= 0):
        return 1
    uv = (cam.K @ (p / p[:, 2:3]).T).T[:, :2] * s
    edges = np.linalg.norm(np.roll(uv, -1, axis=0) - uv, axis=1)
    return int(np.clip(math.floor(float(edges.min()) / n_cells), 1, 32))


def marker_corners_local(side_m: float) -> np.ndarray:
    """Black-square corners (4, 3) in the marker frame: top-left, top-right, bottom-right, bottom-left
    as printed (x right, y up)."""
    a = side_m / 2
    return np.array([[-a, a, 0.0], [a, a, 0.0], [a, -a, 0.0], [-a, -a, 0.0]])


def marker_face(marker: Marker, T_world_marker: np.ndarray, cam: PinholeCamera, T_world_cam: np.ndarray,
                s: int) -> Face:
    cells = _cells(marker.family.value, marker.id)
    corners = geo.transform_points(T_world_marker, marker_corners_local(marker.side_m))
    k = texels_for(cam, T_world_cam, corners, cells.shape[0], s)
    return cells_face(T_world_marker, cells, (marker.side_m, marker.side_m), MARKER_MARGIN_M, k,
                      f"marker{marker.id}")


def robot_faces(scene: Scene, T_world_robot: np.ndarray, cam: PinholeCamera, T_world_cam: np.ndarray,
                s: int, light: float = 1.0) -> list[Face]:
    """The robot (gown sides, plate edge, top plate, markers) in painter's order for a convex body:
    back faces are culled by the renderer, the plate comes after the sides and the markers last."""
    rig = scene.rig_true
    hull = rig.robot.hull
    assert hull is not None, "the simulated robot has a hull"
    top = gtroom.ROBOT_TOP_M
    T_box = T_world_robot @ geo.make_T(np.eye(3), [hull.offset_xy_m[0], hull.offset_xy_m[1], 0.0])
    faces = _box_side_faces(T_box, hull.length_m, hull.width_m, hull.z_min_m, hull.z_max_m,
                            GOWN * light, None, "gown")
    faces += _box_side_faces(T_box, hull.length_m, hull.width_m, hull.z_max_m, top, 0.35 * light, None, "rim")
    faces.append(_plate_face(T_box, hull.length_m, hull.width_m, top, light))
    for m in rig.robot.markers:
        T_wm = T_world_robot @ m.T_robot_marker.matrix()
        f = marker_face(m, T_wm, cam, T_world_cam, s)
        if light != 1.0:
            f = Face(f.T_world_face, f.outline_xy, f.texture * np.float32(light), f.A_face_tex, name=f.name)
        faces.append(f)
    return faces


@functools.lru_cache(maxsize=8)
def _plate_texture(lx: float, ly: float) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(77)
    texel = 0.005
    nx, ny = int(math.ceil(lx / texel)), int(math.ceil(ly / texel))
    tex = PLATE + _smooth_noise(rng, (ny, nx), 2.0, 0.015)
    return tex.astype(np.float32), texture_affine(0.0, ly, lx / nx, ly / ny)


def _plate_face(T_box: np.ndarray, lx: float, ly: float, top: float, light: float) -> Face:
    tex, A = _plate_texture(lx, ly)
    T = T_box @ geo.make_T(np.eye(3), [-lx / 2, -ly / 2, top])
    if light != 1.0:
        tex = tex * np.float32(light)
    return Face(T, np.array([[0, 0], [lx, 0], [lx, ly], [0, ly]], float), tex, A, name="plate")


# ----------------------------------------------------------------------------------------- chessboards
def board_object_points() -> np.ndarray:
    """Inner corners (45, 3) in the board frame, row-major (9 per row): ``(i * sq, j * sq, 0)``."""
    nx, ny = gtroom.CHESSBOARD_SQUARES[0] - 1, gtroom.CHESSBOARD_SQUARES[1] - 1
    sq = gtroom.CHESSBOARD_SQUARE_M
    j, i = np.mgrid[0:ny, 0:nx]
    return np.column_stack([i.ravel() * sq, j.ravel() * sq, np.zeros(i.size)])


def board_outline_board() -> np.ndarray:
    """The board's paper outline (4, 3) in the board frame, including the white margin."""
    cols, rows = gtroom.CHESSBOARD_SQUARES
    sq, m = gtroom.CHESSBOARD_SQUARE_M, BOARD_MARGIN_M
    x0, y0, x1, y1 = -sq - m, -sq - m, (cols - 1) * sq + m, (rows - 1) * sq + m
    return np.array([[x0, y0, 0], [x1, y0, 0], [x1, y1, 0], [x0, y1, 0]], float)


def board_face(T_world_board: np.ndarray, cam: PinholeCamera, T_world_cam: np.ndarray, s: int,
               name: str = "board") -> Face:
    """The chessboard: squares (col c, row r) with c + r even black; board frame origin at the first
    inner corner, x along the 9 corners of a row, y along the 5 rows, z into the board (the printed
    side faces -z, towards a camera for which ``(i * sq, j * sq, 0)`` are the object points)."""
    cols, rows = gtroom.CHESSBOARD_SQUARES
    sq = gtroom.CHESSBOARD_SQUARE_M
    cells = ((np.add.outer(np.arange(rows), np.arange(cols)) % 2) == 1).astype(np.uint8)
    # face frame: x = board x, y = -board y (up as printed), z = -board z (out of the print)
    T_face = T_world_board @ geo.make_T(np.diag([1.0, -1.0, -1.0]),
                                        [(cols / 2 - 1) * sq, (rows / 2 - 1) * sq, 0.0])
    outline = geo.transform_points(T_world_board, board_outline_board())
    k = texels_for(cam, T_world_cam, outline, max(cols, rows) + 1, s)
    return cells_face(T_face, cells, (cols * sq, rows * sq), BOARD_MARGIN_M, k, name)


# ------------------------------------------------------------------------------------------ ChArUco
#: modules (printed bits) per ChArUco square: a marker is 6 of them (4 x 4 bits and a black border)
#: centred in a white square of 8, so every printed edge falls on the module grid
CHARUCO_MODULES_PER_SQUARE = 8


def sim_charuco_board() -> CharucoBoard:
    """The simulator's ChArUco board: the chessboard's squares (``gtroom.CHESSBOARD_SQUARES`` of
    ``gtroom.CHESSBOARD_SQUARE_M``) with ``DICT_4X4_50`` markers of 3/4 of a square, OpenCV's layout.

    Its frame (:mod:`gtrig.calib.charuco`) has its origin at the board's outer corner: a point at
    ``p`` in the chessboard frame of :func:`board_object_points` is at ``p + (sq, sq, 0)`` in it.
    """
    cols, rows = gtroom.CHESSBOARD_SQUARES
    sq = gtroom.CHESSBOARD_SQUARE_M
    return CharucoBoard(cols, rows, sq, round(sq * 6 / CHARUCO_MODULES_PER_SQUARE, 9), "DICT_4X4_50")


@functools.lru_cache(maxsize=1)
def charuco_cells() -> np.ndarray:
    """The simulator's ChArUco board as printed modules (rows * 8, cols * 8), 1 = white, top row first."""
    b = sim_charuco_board()
    m = CHARUCO_MODULES_PER_SQUARE
    img = b.opencv_board().generateImage((b.squares_x * m, b.squares_y * m), marginSize=0, borderBits=1)
    return (np.asarray(img) > 127).astype(np.uint8)


def charuco_face(T_world_board: np.ndarray, cam: PinholeCamera, T_world_cam: np.ndarray, s: int,
                 name: str = "board") -> Face:
    """The simulator's ChArUco board (:func:`sim_charuco_board`) where :func:`board_face` puts the
    chessboard: same paper outline, same board frame (origin at the first inner corner)."""
    cols, rows = gtroom.CHESSBOARD_SQUARES
    sq = gtroom.CHESSBOARD_SQUARE_M
    cells = charuco_cells()
    T_face = T_world_board @ geo.make_T(np.diag([1.0, -1.0, -1.0]),
                                        [(cols / 2 - 1) * sq, (rows / 2 - 1) * sq, 0.0])
    outline = geo.transform_points(T_world_board, board_outline_board())
    k = texels_for(cam, T_world_cam, outline, (max(cols, rows) + 1) * CHARUCO_MODULES_PER_SQUARE, s)
    return cells_face(T_face, cells, (cols * sq, rows * sq), BOARD_MARGIN_M, k, name)
