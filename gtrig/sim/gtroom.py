"""The GT room of the seeds (deliverable AD2.3; journal paper, section 7.1), as simulated truth.

The world frame is the seeds' validation frame "GTV": the reference points O, A, B, C are at
(0, 0), (0, 2.5), (2.5, 0), (2.5, 2.5) m, z up, floor at z = 0 on average. The 16 world points are at
the coordinates the deliverable published; the walls are fitted through them, so the room is the
quadrilateral of about 8 x 6 m whose two short walls are not parallel. The 26 validation poses are the
published ones (``../shared/reference/validation_poses.csv``, columns ``val_*``), copied below.

:func:`make_scene` draws one installation from a seed: the truth (``rig_true``) and what the operator
believes (``rig_nominal``: nominal intrinsics, tape-measured camera poses, hand-placed markers and the
design value of the double-board transform).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.interpolate import CubicSpline

from gtrig import geometry as geo
from gtrig.rig.models import (
    Camera,
    Hull,
    LaserScanner,
    Marker,
    MarkerFamily,
    Odometry,
    OnboardScanner,
    Pose,
    ReferencePoint,
    Rig,
    Robot,
    Survey,
    World,
)
from gtrig.sim.floor import Floor

# Published world points (AD2.3), metres, in GTV.
WORLD_POINTS_XY = np.array([
    [0.746335, -2.636647], [1.487105, -2.251523], [2.440868, -1.755774], [3.349824, -1.279703],
    [4.101903, -0.889099], [3.287522, 1.088277], [3.010098, 2.106208], [2.165534, 3.728941],
    [1.420934, 4.660137], [0.234251, 6.367675], [-0.889505, 5.798842], [-2.188851, 5.134402],
    [-3.622194, 3.993617], [-2.760034, 1.212409], [-2.226985, 0.209837], [-1.160521, -0.637959],
])
WORLD_POINT_NAMES = tuple(str(i + 1) for i in range(16))
# A DISTO-class hand laser: +-1.5 mm at 2 sigma; reference points marked with a steel tape to 0.5 mm.
# (The seeds assumed 8 mm and 2 mm; at those levels nothing reaches millimetres: see docs/simulator.md.)
HAND_LASER_SIGMA_M = 0.00075
REFERENCE_SIGMA_M = 0.0005
REFERENCE_POINTS_XY = {"O": (0.0, 0.0), "A": (0.0, 2.5), "B": (2.5, 0.0), "C": (2.5, 2.5)}

# Published validation poses (AD2.3, val_x, val_y, val_th), metres and radians, in GTV.
VALIDATION_POSES = np.array([
    [1.2653, -1.174, 3.4456], [1.8838, -0.6341, 4.00131], [2.2171, 0.0456, 4.4645],
    [1.9801, 0.7345, 5.16], [1.3285, 1.3213, 5.5105], [0.8781, 1.9556, 5.1869],
    [0.5397, 2.6828, 5.1143], [0.229, 3.357, 5.1503], [-0.0079, 4.1598, 4.9086],
    [-0.2102, 4.4968, 5.488], [-0.7092, 4.7668, 6.068], [-0.9756, 4.2708, 1.7449],
    [-0.7689, 3.5655, 1.9824], [-0.1228, 3.1824, 2.7651], [0.039, 2.4743, 1.4604],
    [-0.0228, 1.5651, 1.515], [0.1349, 0.694, 2.074], [1.1491, 0.47468, 2.6219],
    [1.841, -0.3749, 1.9983], [1.207, -0.8692, 6.06], [0.49296, -0.18139, 5.1983],
    [0.5174, 1.1805, 4.4479], [-0.0333, 2.1745, 5.5533], [-0.9847, 3.0299, 5.3534],
    [-1.5081, 4.2249, 4.9689], [-0.9872, 4.8136, 3.5275],
])

# The robot (seeds: 570 x 780 mm footprint); robot frame origin on the floor under its centre.
ROBOT_LENGTH_M = 0.78
ROBOT_WIDTH_M = 0.57
ROBOT_TOP_M = 0.62  # the plate the markers lie on
GOWN_Z = (0.05, 0.55)
# (id, side, x, y, yaw_deg) on the top plate; marker 14 as published: +90 deg about z, (-143, 98) mm.
MARKER_LAYOUT = (
    (3, 0.156, 0.235, 0.140, 0.0),
    (6, 0.156, 0.235, -0.140, 0.0),
    (14, 0.160, -0.143, 0.098, 90.0),
    (30, 0.156, 0.040, -0.125, 0.0),
    (89, 0.156, -0.200, -0.125, 180.0),
    (200, 0.156, 0.045, 0.125, -90.0),
)
DIMA_MARKER_ID = 14  # the marker all others are referred to (AD2.3, "Robot-frame")
MARKER_LIFT_M = 0.018  # marker 14 sits 18 mm above the robot frame's published origin plane

# Camera chain along the band of validation poses (see docs/simulator.md for the design).
BAND_CENTRE = np.array([0.36, 2.0])
BAND_DIR_RAD = np.radians(117.67)  # direction of the east wall and of the band
CAM_U = (-2.78, -0.93, 0.93, 2.78)  # positions along the band
CAM_POLE_V = 2.45  # poles on the west side of the band
CAM_HEIGHT = (2.80, 2.65, 2.90, 2.75)
CAM_TARGET_V = -0.6
CAM_RES = (1024, 768)
CAM_F = 1500.0
CAM_RATE_HZ = 10.0

SCANNER_UV = ((-3.7, 1.75), (-3.7, -1.75), (3.7, -1.75), (3.7, 1.75))  # the band's corners
LASER_HEIGHT_M = 0.25
LASER_RATE_HZ = 75.0
LASER_BEAMS = 180

CHESSBOARD_SQUARES = (10, 6)  # columns x rows of squares; inner corners 9 x 5
CHESSBOARD_SQUARE_M = 0.100
DOUBLE_BOARD_GAP_M = 0.5


def _band_xy(u: float, v: float) -> np.ndarray:
    a = BAND_DIR_RAD
    eu = np.array([np.cos(a), np.sin(a)])
    ev = np.array([-np.sin(a), np.cos(a)])
    return BAND_CENTRE + u * eu + v * ev


def room_walls() -> np.ndarray:
    """Wall segments (4, 2, 2) in world xy: lines fitted through the world points on each wall,
    pushed out so that every world point lies inside the room (points mark the wall feet)."""
    groups = ((0, 1, 2, 3, 4), (5, 6, 7, 8), (9, 10, 11, 12), (13, 14, 15))
    lines = []
    for g in groups:
        q = WORLD_POINTS_XY[list(g)]
        c = q.mean(axis=0)
        _, _, vt = np.linalg.svd(q - c)
        n = vt[1]
        if n @ (c - WORLD_POINTS_XY.mean(axis=0)) < 0:
            n = -n  # outward normal
        offset = np.max((q - c) @ n) + 0.05
        lines.append((c + offset * n, n))
    corners = []
    for i in range(4):
        (c1, n1), (c2, n2) = lines[i - 1], lines[i]
        corners.append(np.linalg.solve(np.array([n1, n2]), [n1 @ c1, n2 @ c2]))
    corners_a = np.array(corners)
    return np.stack([corners_a, np.roll(corners_a, -1, axis=0)], axis=1)


@dataclass(frozen=True)
class Box:
    """An upright box of clutter: centre xy, size (lx, ly, h), yaw; ``reflectivity`` for the lasers."""

    name: str
    centre_xy: tuple[float, float]
    size: tuple[float, float, float]
    yaw_rad: float
    reflectivity: float = 0.5

    def corners_xy(self) -> np.ndarray:
        lx, ly = self.size[0] / 2, self.size[1] / 2
        c, s = np.cos(self.yaw_rad), np.sin(self.yaw_rad)
        local = np.array([[-lx, -ly], [lx, -ly], [lx, ly], [-lx, ly]])
        return local @ np.array([[c, s], [-s, c]]) + self.centre_xy


def clutter() -> tuple[Box, ...]:
    """Desk, boxes and heaters along the walls, out of the robot's band (seeds, Fig. 6)."""
    boxes = []
    for name, u, v, size, yaw_off, refl in (
        ("desk", 1.85, 2.95, (1.6, 0.8, 0.75), 0.0, 0.4),
        ("cabinet", -1.75, 2.45, (0.9, 0.45, 1.9), 0.0, 0.6),
        ("box_a", -2.4, -2.0, (0.5, 0.4, 0.45), 0.3, 0.5),
        ("box_b", 2.4, -2.0, (0.6, 0.6, 0.6), -0.2, 0.3),
        ("heater_e", 0.5, -2.15, (1.2, 0.12, 0.6), 0.0, 0.9),
        ("heater_w", 0.0, 2.85, (1.0, 0.12, 0.6), 0.0, 0.9),
        ("calib_object", -0.8, -1.9, (1.2, 0.6, 0.5), 0.0, 0.7),
        # a second object of known shape and surveyed pose across the band: the two scanners at the far
        # corners see each object 4-5 m away, so one object alone fixes the world's yaw to only about
        # 0.05 deg; two objects 3.9 m apart fix it by their positions as well as their faces
        ("calib_object_b", 0.6, 1.95, (1.2, 0.6, 0.5), 0.0, 0.7),
    ):
        c = _band_xy(u, v)
        boxes.append(Box(name, (float(c[0]), float(c[1])), size, BAND_DIR_RAD + yaw_off, refl))
    return tuple(boxes)


def _true_cameras(rng: np.random.Generator) -> tuple[Camera, ...]:
    cams = []
    w, h = CAM_RES
    for i, (u, z) in enumerate(zip(CAM_U, CAM_HEIGHT, strict=True)):
        eye = np.r_[_band_xy(u, CAM_POLE_V), z]
        target = np.r_[_band_xy(u + rng.normal(0, 0.05), CAM_TARGET_V + rng.normal(0, 0.05)), 0.0]
        T = geo.look_at(eye, target)
        # a slight roll: poles and mounts are never perfectly level
        T = T @ geo.T_from_xyz_rpy([0, 0, 0], [0, 0, np.radians(rng.normal(0, 0.5))])
        f = CAM_F * (1 + rng.normal(0, 0.01))
        K = ((f, 0.0, w / 2 - 0.5 + rng.normal(0, 4)), (0.0, f * (1 + rng.normal(0, 0.001)),
             h / 2 - 0.5 + rng.normal(0, 4)), (0.0, 0.0, 1.0))
        dist = (-0.12 + rng.normal(0, 0.01), 0.10 + rng.normal(0, 0.02),
                rng.normal(0, 2e-4), rng.normal(0, 2e-4), 0.0)
        cams.append(Camera(name=f"cam{i}", resolution=CAM_RES, camera_matrix=K, dist_coeffs=dist,
                           T_world_cam=Pose.from_matrix(T), rate_hz=CAM_RATE_HZ))
    return tuple(cams)


def _scanners(rng: np.random.Generator) -> tuple[LaserScanner, ...]:
    """Four 180-degree scanners at the band's corners, looking inwards (seeds: SICK LMS, 180 beams)."""
    out = []
    for i, (u, v) in enumerate(SCANNER_UV):
        p = _band_xy(u, v)
        to_centre = BAND_CENTRE - p
        yaw = float(np.arctan2(to_centre[1], to_centre[0]) + rng.normal(0, np.radians(1)))
        T = geo.T_from_xyz_rpy([p[0], p[1], LASER_HEIGHT_M], [0, 0, yaw])
        inc = np.pi / LASER_BEAMS
        out.append(LaserScanner(name=f"laser{i}", T_world_scanner=Pose.from_matrix(T),
                                angle_min_rad=-np.pi / 2 + inc / 2, angle_increment_rad=inc,
                                beams=LASER_BEAMS, range_max_m=30.0, rate_hz=LASER_RATE_HZ,
                                range_sigma_m=0.01))
    return tuple(out)


def _markers(rng: np.random.Generator | None) -> tuple[Marker, ...]:
    out = []
    for mid, side, x, y, yaw in MARKER_LAYOUT:
        T = geo.T_from_xyz_rpy([x, y, ROBOT_TOP_M], [0, 0, np.radians(yaw)])
        if rng is not None:
            # hand placement: about 1.5 mm and 0.5 deg in the plate, a sheet's warp out of it; the
            # dima-marker is set square against the dima's edge and its offset measured with a caliper
            # ("a marker in a simple-to-measure pose with respect to the robot-frame", AD2.3), so its
            # placement error is a fifth of that (0.3 mm, 0.1 deg)
            k = 0.2 if mid == DIMA_MARKER_ID else 1.0
            T = T @ geo.T_from_xyz_rpy(
                k * np.array([rng.normal(0, 0.0015), rng.normal(0, 0.0015), rng.normal(0, 0.0003)]),
                k * np.radians([rng.normal(0, 0.1), rng.normal(0, 0.1), rng.normal(0, 0.5)]),
            )
        out.append(Marker(family=MarkerFamily.ARTOOLKITPLUS_SIMPLE, id=mid, side_m=side,
                          T_robot_marker=Pose.from_matrix(T)))
    return tuple(out)


def _robot(markers: tuple[Marker, ...]) -> Robot:
    hull = Hull(length_m=ROBOT_LENGTH_M, width_m=ROBOT_WIDTH_M, z_min_m=GOWN_Z[0], z_max_m=GOWN_Z[1])
    onboard = (
        OnboardScanner(name="sick_front", T_robot_scanner=Pose(xyz=(0.30, 0.0, 0.35), rpy_deg=(0, 0, 0)),
                       angle_min_rad=-np.pi / 2, angle_increment_rad=np.pi / 180, beams=181,
                       range_max_m=30.0, rate_hz=25.0),
        OnboardScanner(name="sick_rear", T_robot_scanner=Pose(xyz=(-0.30, 0.0, 0.35), rpy_deg=(0, 0, 180)),
                       angle_min_rad=-np.pi / 2, angle_increment_rad=np.pi / 180, beams=181,
                       range_max_m=30.0, rate_hz=25.0),
    )
    return Robot(hull=hull, markers=markers, odometry=Odometry(rate_hz=50.0), onboard_scanners=onboard)


@dataclass(frozen=True)
class Scene:
    """One simulated installation: truth and belief.

    Attributes
    ----------
    rig_true, rig_nominal : Rig
        The real installation and the one the operator writes down before calibrating.
    walls : (4, 2, 2) wall segments, world xy, metres.
    boxes : clutter.
    floor : the uneven floor.
    world_points_xy : (16, 2) true world points.
    reference_true_xy : true positions of O, A, B, C (the nominal ones are in ``rig_nominal.survey``).
    T_board1_board2_true, T_board1_board2_nominal : the double chessboard's rigid transform.
    T_world_board : pose of the world-anchoring chessboard (true).
    """

    seed: int
    rig_true: Rig
    rig_nominal: Rig
    walls: np.ndarray
    boxes: tuple[Box, ...]
    floor: Floor
    world_points_xy: np.ndarray
    reference_true_xy: dict[str, tuple[float, float]]
    T_board1_board2_true: np.ndarray
    T_board1_board2_nominal: np.ndarray
    T_world_board: np.ndarray
    notes: dict[str, float] = field(default_factory=dict)

    def T_world_robot(self, x: float, y: float, theta: float) -> np.ndarray:
        """The robot's 6-DoF pose at planar pose (x, y, theta) on this scene's floor."""
        return self.floor.robot_pose(x, y, theta)


def make_scene(seed: int = 0) -> Scene:
    """Draw one GT-room installation from ``seed``."""
    rng = np.random.default_rng(seed)
    cams_true = _true_cameras(rng)
    scanners_true = _scanners(rng)
    markers_true = _markers(rng)
    ref_true = {k: (v[0] + rng.normal(0, REFERENCE_SIGMA_M), v[1] + rng.normal(0, REFERENCE_SIGMA_M))
                for k, v in REFERENCE_POINTS_XY.items()}
    ref_true["O"] = (0.0, 0.0)  # O defines the origin
    survey = Survey(
        reference_points=tuple(ReferencePoint(name=k, xy=v, sigma_m=REFERENCE_SIGMA_M)
                               for k, v in REFERENCE_POINTS_XY.items()),
        hand_laser_sigma_m=HAND_LASER_SIGMA_M,
    )
    world = World(name="gtroom", description="Simulated replica of the RAWSEEDS GT room (GTV frame)")
    rig_true = Rig(world=world, cameras=cams_true, laser_scanners=scanners_true,
                   robot=_robot(markers_true), survey=survey)

    # What the operator believes before calibration.
    cams_nom = []
    for c in cams_true:
        T = c.T_world_cam.matrix() @ geo.T_from_xyz_rpy(rng.normal(0, 0.03, 3), np.radians(rng.normal(0, 1.0, 3)))
        w, h = c.resolution
        cams_nom.append(c.model_copy(update={
            "camera_matrix": ((CAM_F, 0.0, w / 2 - 0.5), (0.0, CAM_F, h / 2 - 0.5), (0.0, 0.0, 1.0)),
            "dist_coeffs": (0.0, 0.0, 0.0, 0.0, 0.0),
            "T_world_cam": Pose.from_matrix(T),
        }))
    scanners_nom = []
    for s in scanners_true:
        T = s.T_world_scanner.matrix() @ geo.T_from_xyz_rpy(
            [rng.normal(0, 0.03), rng.normal(0, 0.03), 0.0], [0, 0, np.radians(rng.normal(0, 2.0))])
        scanners_nom.append(s.model_copy(update={"T_world_scanner": Pose.from_matrix(T)}))
    rig_nominal = rig_true.model_copy(update={
        "cameras": tuple(cams_nom),
        "laser_scanners": tuple(scanners_nom),
        "robot": _robot(_markers(None)),
    })

    T12_nom = geo.make_T(np.eye(3), [CHESSBOARD_SQUARES[0] * CHESSBOARD_SQUARE_M + DOUBLE_BOARD_GAP_M, 0, 0])
    T12_true = T12_nom @ geo.T_from_xyz_rpy(rng.normal(0, 0.002, 3), np.radians(rng.normal(0, 0.2, 3)))
    # The world board lies flat on the floor, whole in camera 1's view for any seed, x along world x.
    T_world_board = geo.T_from_xyz_rpy([1.1, 1.65, 0.0], [np.pi, 0, 0])

    return Scene(
        seed=seed, rig_true=rig_true, rig_nominal=rig_nominal, walls=room_walls(), boxes=clutter(),
        floor=Floor.random(rng), world_points_xy=WORLD_POINTS_XY.copy(), reference_true_xy=ref_true,
        T_board1_board2_true=T12_true, T_board1_board2_nominal=T12_nom, T_world_board=T_world_board,
    )


def design_rig() -> Rig:
    """The GT room's rig as planned, before it is installed: cameras on their poles aimed at the band's
    centre line with the nominal lens (no distortion), the scanners at the band's corners looking at its
    centre, the markers where the layout puts them, the survey's reference points. ``gtrig sim --rig`` on
    it (:func:`gtrig.sim.install.install`) draws the same installation as :func:`make_scene`."""
    w, h = CAM_RES
    K = ((CAM_F, 0.0, w / 2 - 0.5), (0.0, CAM_F, h / 2 - 0.5), (0.0, 0.0, 1.0))
    cams = tuple(
        Camera(name=f"cam{i}", resolution=CAM_RES, camera_matrix=K, dist_coeffs=(0.0, 0.0, 0.0, 0.0, 0.0),
               T_world_cam=Pose.from_matrix(geo.look_at(np.r_[_band_xy(u, CAM_POLE_V), z],
                                                        np.r_[_band_xy(u, CAM_TARGET_V), 0.0])),
               rate_hz=CAM_RATE_HZ)
        for i, (u, z) in enumerate(zip(CAM_U, CAM_HEIGHT, strict=True)))
    scanners = []
    for i, (u, v) in enumerate(SCANNER_UV):
        p = _band_xy(u, v)
        to_centre = BAND_CENTRE - p
        T = geo.T_from_xyz_rpy([p[0], p[1], LASER_HEIGHT_M], [0, 0, float(np.arctan2(to_centre[1], to_centre[0]))])
        inc = np.pi / LASER_BEAMS
        scanners.append(LaserScanner(name=f"laser{i}", T_world_scanner=Pose.from_matrix(T),
                                     angle_min_rad=-np.pi / 2 + inc / 2, angle_increment_rad=inc, beams=LASER_BEAMS,
                                     range_max_m=30.0, rate_hz=LASER_RATE_HZ, range_sigma_m=0.01))
    survey = Survey(reference_points=tuple(ReferencePoint(name=k, xy=v, sigma_m=REFERENCE_SIGMA_M)
                                           for k, v in REFERENCE_POINTS_XY.items()),
                    hand_laser_sigma_m=HAND_LASER_SIGMA_M)
    world = World(name="gtroom", description="Simulated replica of the RAWSEEDS GT room (GTV frame)")
    return Rig(world=world, cameras=cams, laser_scanners=tuple(scanners), robot=_robot(_markers(None)),
               survey=survey)


def continuous_path(
    speed_mps: float = 0.3, rate_hz: float = 200.0, duration_s: float | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """The continuous run: a smooth path through the validation positions, heading along the path.

    Returns
    -------
    stamps_s : (N,) seconds from the start of the run.
    xytheta : (N, 3) planar poses in the world (theta unwrapped, continuous).

    The speed ramps up and down over 1 s at either end. With ``duration_s`` the run is cut short
    (``--quick``).
    """
    p = VALIDATION_POSES[:, :2]
    chord = np.r_[0, np.cumsum(np.linalg.norm(np.diff(p, axis=0), axis=1))]
    spline = CubicSpline(chord, p, bc_type="natural")
    s_fine = np.linspace(0, chord[-1], 20000)
    xy_fine = spline(s_fine)
    arc = np.r_[0, np.cumsum(np.linalg.norm(np.diff(xy_fine, axis=0), axis=1))]
    length = arc[-1]
    ramp = 1.0
    total = length / speed_mps + ramp
    stamps = np.arange(0.0, total, 1.0 / rate_hz)
    # distance travelled with linear ramps of 1 s at both ends (trapezoidal speed profile)
    v = np.clip(np.minimum(stamps, total - stamps) / ramp, 0, 1) * speed_mps
    dist = np.r_[0, np.cumsum(0.5 * (v[1:] + v[:-1]) * np.diff(stamps))]
    dist *= length / dist[-1]
    s = np.interp(dist, arc, s_fine)
    xy = spline(s)
    dxy = spline(s, 1)
    theta = np.unwrap(np.arctan2(dxy[:, 1], dxy[:, 0]))
    out = np.column_stack([xy, theta])
    if duration_s is not None:
        keep = stamps <= duration_s
        stamps, out = stamps[keep], out[keep]
    return stamps, out
