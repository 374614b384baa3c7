"""A planned rig installed in the simulated GT room: the truth drawn from the plan, and what the operator
then writes down (``gtrig sim --rig``).

The plan (a rig file as ``gtrig plan`` reads it: cameras' nominal poses and intrinsics, fixed scanners,
the robot's markers and hull, the survey's reference points) is what the lab designed. Installing it
draws, from the seed, the errors :func:`gtrig.sim.gtroom.make_scene` draws for the GT room, in the same
order, so that the GT room's own design (:func:`gtrig.sim.gtroom.design_rig`) gives the built-in scene:

- each camera's aim point on the floor moves by 5 cm across and along its view, the mount rolls by
  0.5 deg, the focal length is off by 1 % (and the aspect by 0.1 %), the principal point by 4 px; a lens
  planned without distortion gets a typical wide lens's (k1 -0.12, k2 0.10) with its spread, a planned
  one that spread about it;
- each scanner's heading is off by 1 deg;
- each marker is placed by hand (1.5 mm, 0.5 deg; the anchor marker a fifth of that);
- each reference point is marked within its own sigma (the one named ``O``, the origin, exactly);
- the operator's nominal rig: the true camera and scanner poses taped to 3 cm, 1 deg (scanners 2 deg in
  heading), the planned intrinsics and markers.

The room is the GT room (walls, clutter, world points, calibration objects and boards, the validation
poses) unless the plan gives its own outline (``world.outline_xy``): then the walls stand on that
outline, the 16 world points mark its wall feet (spread evenly along it, 5 cm inside), and of the GT
room's clutter and calibration objects only those standing inside it are kept. The plan's sensors must
fit in the room. What the simulator cannot simulate is refused with one line naming the rig's field
(:func:`check_plan`).
"""

from __future__ import annotations

import numpy as np

from gtrig import geometry as geo
from gtrig.errors import InputError
from gtrig.markers.families import marker_cells
from gtrig.rig.models import Camera, LaserScanner, Marker, Pose, Rig
from gtrig.sim.floor import Floor
from gtrig.sim.gtroom import (
    CHESSBOARD_SQUARE_M,
    CHESSBOARD_SQUARES,
    DIMA_MARKER_ID,
    DOUBLE_BOARD_GAP_M,
    ROBOT_TOP_M,
    WORLD_POINTS_XY,
    Scene,
    clutter,
    room_walls,
)

#: how far inside the walls the world points mark their feet, metres (the GT room's are pushed out by this)
WORLD_POINT_INSET_M = 0.05
#: the farthest a camera's optical axis may meet the floor, metres (farther: it looks at the walls)
MAX_AIM_DISTANCE_M = 30.0
#: how far a marker may lie from the robot's top plate (height, metres; tilt, degrees)
MARKER_PLATE_TOL_M = 0.01
MARKER_TILT_TOL_DEG = 5.0
#: a scanner's plane may tilt this much (roll, pitch, degrees): the simulator casts horizontal beams
SCANNER_TILT_TOL_DEG = 0.01


def inside_polygon(xy: np.ndarray, polygon_xy: np.ndarray) -> bool:
    """Whether the point (2,) lies inside the polygon (V, 2) (even-odd rule)."""
    x, y = float(xy[0]), float(xy[1])
    inside = False
    for (x0, y0), (x1, y1) in zip(polygon_xy, np.roll(polygon_xy, -1, axis=0), strict=True):
        if (y0 > y) != (y1 > y) and x < x0 + (y - y0) * (x1 - x0) / (y1 - y0):
            inside = not inside
    return inside


def room_outline(plan: Rig) -> np.ndarray:
    """The room's outline (V, 2), world xy, metres: the plan's ``world.outline_xy``, else the GT room's."""
    if plan.world.outline_xy is not None:
        return np.asarray(plan.world.outline_xy, dtype=float)
    return room_walls()[:, 0]


def outline_walls(outline_xy: np.ndarray) -> np.ndarray:
    """Wall segments (V, 2, 2) along an outline (V, 2): corner i to corner i + 1, the last back to the first."""
    P = np.asarray(outline_xy, dtype=float)
    return np.stack([P, np.roll(P, -1, axis=0)], axis=1)


def outline_world_points(outline_xy: np.ndarray, n: int = len(WORLD_POINTS_XY)) -> np.ndarray:
    """``n`` world points (n, 2) marking the walls' feet of an outline (V, 2): evenly spread along its
    perimeter (half a spacing from the first corner), :data:`WORLD_POINT_INSET_M` inside it."""
    walls = outline_walls(outline_xy)
    d = walls[:, 1] - walls[:, 0]
    length = np.hypot(d[:, 0], d[:, 1])
    P = walls[:, 0]
    ccw = np.sum(P[:, 0] * np.roll(P[:, 1], -1) - np.roll(P[:, 0], -1) * P[:, 1]) > 0
    inward = np.column_stack([-d[:, 1], d[:, 0]]) / length[:, None] * (1.0 if ccw else -1.0)
    s = (np.arange(n) + 0.5) * length.sum() / n
    k = np.minimum(np.searchsorted(np.cumsum(length), s, side="right"), len(length) - 1)
    u = (s - (np.cumsum(length) - length)[k]) / length[k]
    return walls[k, 0] + u[:, None] * d[k] + WORLD_POINT_INSET_M * inward[k]


def floor_aim(T_world_cam: np.ndarray) -> np.ndarray | None:
    """Where the camera's optical axis meets the floor (z = 0), world xy (2,), or None when it looks up or
    level, or meets it farther than :data:`MAX_AIM_DISTANCE_M`."""
    eye, axis = T_world_cam[:3, 3], T_world_cam[:3, 2]
    if axis[2] >= -1e-6 or eye[2] <= 0:
        return None
    s = -eye[2] / axis[2]
    if s > MAX_AIM_DISTANCE_M:
        return None
    return (eye + s * axis)[:2]


def _check_cameras(plan: Rig, room_xy: np.ndarray) -> None:
    if not plan.cameras:
        raise InputError("cameras: the simulator needs at least one camera (it records the robot's markers)")
    for i, c in enumerate(plan.cameras):
        where = f"cameras[{i}] ({c.name})"
        if c.rate_hz is None:
            raise InputError(f"{where}.rate_hz: the simulator records video; give the camera's frame rate")
        T = c.T_world_cam.matrix()
        if not inside_polygon(T[:2, 3], room_xy) or not 0.0 < T[2, 3] < 10.0:
            raise InputError(f"{where}.T_world_cam: the camera is outside the simulated room "
                             "(inside its walls, 0-10 m high)")
        if floor_aim(T) is None:
            raise InputError(f"{where}.T_world_cam: the optical axis does not meet the floor within "
                             f"{MAX_AIM_DISTANCE_M:g} m; the simulator's cameras look down at the floor")
        if len(c.dist_coeffs) < 4:
            raise InputError(f"{where}.dist_coeffs: the simulator needs at least k1, k2, p1, p2")


def _check_scanners(plan: Rig, room_xy: np.ndarray) -> None:
    for i, s in enumerate(plan.laser_scanners):
        where = f"laser_scanners[{i}] ({s.name})"
        T = s.T_world_scanner.matrix()
        if not inside_polygon(T[:2, 3], room_xy):
            raise InputError(f"{where}.T_world_scanner: the scanner is outside the simulated room's walls")
        if np.degrees(np.arccos(np.clip(T[2, 2], -1.0, 1.0))) > SCANNER_TILT_TOL_DEG:
            raise InputError(f"{where}.T_world_scanner: the simulator's scanners scan a horizontal plane "
                             "(roll and pitch 0)")


def _check_robot(plan: Rig) -> None:
    hull = plan.robot.hull
    if hull is None:
        raise InputError("robot.hull: the simulator draws the robot's body; give its hull")
    if not plan.robot.markers:
        raise InputError("robot.markers: the simulator's cameras track markers; give at least one")
    if hull.z_max_m >= ROBOT_TOP_M:
        raise InputError(f"robot.hull.z_max_m: the simulated robot's top plate is at {ROBOT_TOP_M:g} m; "
                         "the hull must end below it")
    for i, m in enumerate(plan.robot.markers):
        where = f"robot.markers[{i}] (id {m.id})"
        marker_cells(m.family, m.id)  # an unknown family or id: one line from the marker families
        T = m.T_robot_marker.matrix()
        if abs(T[2, 3] - ROBOT_TOP_M) > MARKER_PLATE_TOL_M or \
                np.degrees(np.arccos(np.clip(T[2, 2], -1.0, 1.0))) > MARKER_TILT_TOL_DEG:
            raise InputError(f"{where}.T_robot_marker: the simulator lays markers flat on the robot's top "
                             f"plate (z {ROBOT_TOP_M:g} m, face up)")
    if plan.robot.onboard_scanners and any(abs(o.T_robot_scanner.matrix()[2, 2] - 1.0) > 1e-6
                                           for o in plan.robot.onboard_scanners):
        raise InputError("robot.onboard_scanners: the simulator's onboard scanners scan a horizontal plane")


def _check_world_board(plan: Rig) -> None:
    """A planned camera must see the world board whole: the simulated calibration anchors the cameras to
    the world with it."""
    from gtrig.sim.cameras import board_fully_visible
    from gtrig.sim.render import PinholeCamera

    T_world_board = world_board_pose()
    if not any(board_fully_visible(PinholeCamera.from_rig(c), c.T_world_cam.matrix(), T_world_board,
                                   margin_px=5.0, max_angle_deg=80.0) for c in plan.cameras):
        x, y = T_world_board[:2, 3]
        raise InputError(f"cameras: none sees the simulated world board whole (on the floor at x {x:g}, y {y:g} m, "
                         "x along world x); the simulated calibration anchors the cameras to it")


def world_board_pose() -> np.ndarray:
    """T_world_board (4, 4) of the GT room's world-anchoring chessboard: flat on the floor, printed side
    down (the board's z into the floor), x along world x."""
    return geo.T_from_xyz_rpy([1.1, 1.65, 0.0], [np.pi, 0, 0])


def check_plan(plan: Rig) -> None:
    """Refuse, with one line naming the field, a planned rig the simulator cannot simulate."""
    room_xy = room_outline(plan)
    _check_cameras(plan, room_xy)
    _check_world_board(plan)
    _check_scanners(plan, room_xy)
    _check_robot(plan)
    names = [p.name for p in plan.survey.reference_points]
    if len(names) < 2:
        raise InputError("survey.reference_points: the simulated survey needs at least two reference points")


def _true_camera(c: Camera, rng: np.random.Generator) -> Camera:
    T = c.T_world_cam.matrix()
    eye = T[:3, 3]
    aim = floor_aim(T)
    assert aim is not None, "checked by check_plan"
    fwd = T[:2, 2] / np.linalg.norm(T[:2, 2])  # the view's direction on the floor
    side = np.array([-fwd[1], fwd[0]])
    d_side, d_back = rng.normal(0, 0.05), rng.normal(0, 0.05)
    target = np.r_[aim + d_side * side - d_back * fwd, 0.0]
    T_true = geo.look_at(eye, target) @ geo.T_from_xyz_rpy([0, 0, 0], [0, 0, np.radians(rng.normal(0, 0.5))])
    K = np.asarray(c.camera_matrix, dtype=float)
    f = K[0, 0] * (1 + rng.normal(0, 0.01))
    fy = K[1, 1] / K[0, 0] * f
    K_true = ((f, K[0, 1], K[0, 2] + rng.normal(0, 4)), (0.0, fy * (1 + rng.normal(0, 0.001)),
              K[1, 2] + rng.normal(0, 4)), (0.0, 0.0, 1.0))
    d = np.asarray(c.dist_coeffs, dtype=float)
    base = np.r_[-0.12, 0.10, 0.0, 0.0] if not np.any(d) else d[:4]
    k1, k2 = base[0] + rng.normal(0, 0.01), base[1] + rng.normal(0, 0.02)
    p1, p2 = base[2] + rng.normal(0, 2e-4), base[3] + rng.normal(0, 2e-4)
    rest = tuple(float(x) for x in d[4:]) if d.size > 4 else (0.0,)
    return c.model_copy(update={"camera_matrix": K_true, "dist_coeffs": (k1, k2, p1, p2, *rest),
                                "T_world_cam": Pose.from_matrix(T_true), "pose_cov": None})


def _true_scanner(s: LaserScanner, rng: np.random.Generator) -> LaserScanner:
    T = s.T_world_scanner.matrix()
    yaw = float(np.arctan2(T[1, 0], T[0, 0]) + rng.normal(0, np.radians(1)))
    T_true = geo.T_from_xyz_rpy([T[0, 3], T[1, 3], T[2, 3]], [0, 0, yaw])
    return s.model_copy(update={"T_world_scanner": Pose.from_matrix(T_true)})


def _true_marker(m: Marker, rng: np.random.Generator, anchor_id: int) -> Marker:
    # hand placement in the plate and a sheet's warp out of it; the anchor is set square against the
    # robot's edge and its offset measured with a caliper: a fifth of the error
    k = 0.2 if m.id == anchor_id else 1.0
    T = m.T_robot_marker.matrix() @ geo.T_from_xyz_rpy(
        k * np.array([rng.normal(0, 0.0015), rng.normal(0, 0.0015), rng.normal(0, 0.0003)]),
        k * np.radians([rng.normal(0, 0.1), rng.normal(0, 0.1), rng.normal(0, 0.5)]),
    )
    return m.model_copy(update={"T_robot_marker": Pose.from_matrix(T), "pose_cov": None})


def _nominal(rig_true: Rig, plan: Rig, rng: np.random.Generator) -> Rig:
    """What the operator writes down: tape-measured poses of the true sensors, the planned intrinsics
    and markers."""
    cams = []
    for c, p in zip(rig_true.cameras, plan.cameras, strict=True):
        T = c.T_world_cam.matrix() @ geo.T_from_xyz_rpy(rng.normal(0, 0.03, 3), np.radians(rng.normal(0, 1.0, 3)))
        cams.append(c.model_copy(update={"camera_matrix": p.camera_matrix, "dist_coeffs": p.dist_coeffs,
                                         "T_world_cam": Pose.from_matrix(T)}))
    scanners = []
    for s in rig_true.laser_scanners:
        T = s.T_world_scanner.matrix() @ geo.T_from_xyz_rpy(
            [rng.normal(0, 0.03), rng.normal(0, 0.03), 0.0], [0, 0, np.radians(rng.normal(0, 2.0))])
        scanners.append(s.model_copy(update={"T_world_scanner": Pose.from_matrix(T)}))
    return rig_true.model_copy(update={"cameras": tuple(cams), "laser_scanners": tuple(scanners),
                                       "robot": plan.robot})


def install(plan: Rig, seed: int = 0, anchor_id: int = DIMA_MARKER_ID) -> Scene:
    """The planned rig installed in the simulated GT room, drawn from ``seed`` (module docstring).

    Parameters
    ----------
    plan : the planned rig (checked with :func:`check_plan`).
    seed : the installation's random seed.
    anchor_id : the marker placed with a caliper (the robot frame's reference, GTvision's anchor).
    """
    check_plan(plan)
    rng = np.random.default_rng(seed)
    cams = tuple(_true_camera(c, rng) for c in plan.cameras)
    scanners = tuple(_true_scanner(s, rng) for s in plan.laser_scanners)
    markers = tuple(_true_marker(m, rng, anchor_id) for m in plan.robot.markers)
    ref_true = {}
    for p in plan.survey.reference_points:
        ref_true[p.name] = (p.xy[0] + rng.normal(0, p.sigma_m), p.xy[1] + rng.normal(0, p.sigma_m))
    if "O" in ref_true:  # the origin is where it is planned, by definition
        ref_true["O"] = next(p.xy for p in plan.survey.reference_points if p.name == "O")
    rig_true = plan.model_copy(update={"cameras": cams, "laser_scanners": scanners,
                                       "robot": plan.robot.model_copy(update={"markers": markers})})
    rig_nominal = _nominal(rig_true, plan, rng)
    T12_nom = geo.make_T(np.eye(3), [CHESSBOARD_SQUARES[0] * CHESSBOARD_SQUARE_M + DOUBLE_BOARD_GAP_M, 0, 0])
    T12_true = T12_nom @ geo.T_from_xyz_rpy(rng.normal(0, 0.002, 3), np.radians(rng.normal(0, 0.2, 3)))
    T_world_board = world_board_pose()
    outline = room_outline(plan)
    own = plan.world.outline_xy is not None
    boxes = tuple(b for b in clutter() if inside_polygon(np.asarray(b.centre_xy), outline)) if own else clutter()
    world_points = outline_world_points(outline) if own else WORLD_POINTS_XY.copy()
    return Scene(
        seed=seed, rig_true=rig_true, rig_nominal=rig_nominal, walls=outline_walls(outline), boxes=boxes,
        floor=Floor.random(rng), world_points_xy=world_points, reference_true_xy=ref_true,
        T_board1_board2_true=T12_true, T_board1_board2_nominal=T12_nom, T_world_board=T_world_board,
    )
