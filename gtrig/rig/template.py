"""A commented ``rig.yaml`` to start from: every field with what it is, its unit, frame and a typical value.

:func:`template_rig` places ``n`` ceiling cameras looking down at the tracked area, ``m`` floor scanners
around it facing its centre, a robot with four markers and a hull, odometry and one onboard scanner,
and three survey reference points; ``odometry_only`` keeps only the robot's odometry and onboard
scanner (a recording or bag without the room's sensors). :func:`template_text` writes it as YAML with a
comment above every field (:data:`FIELD_NOTES`, keyed by the field's path with ``[]`` for list items)
and the fields a calibration writes later as commented-out notes (:data:`LATER_NOTES`).

The numbers are placeholders of the right size for a room of about 6 x 6 m: the user replaces the
poses by tape measurements and the lens by a datasheet's or calibration's values.
"""

from __future__ import annotations

import math
import textwrap
from typing import Any

import yaml

from gtrig import geometry as geo
from gtrig.rig.load import rig_to_dict
from gtrig.rig.models import (
    BeamTiming,
    Camera,
    Hull,
    LaserScanner,
    Marker,
    MarkerFamily,
    OnboardScanner,
    Pose,
    ReferencePoint,
    Rig,
    Robot,
    StampAt,
    Survey,
    World,
)

#: the tracked area's centre in the world frame (m): the survey's reference points O, A, B span it
AREA_CENTRE_XY_M = (1.5, 1.5)
CAMERA_HEIGHT_M = 2.8
SCANNER_HEIGHT_M = 0.25
MAX_SENSORS = 64

FIELD_NOTES: dict[str, str] = {
    "world": "The world frame: x, y on the floor, z up, origin at survey point O. Units: metres, "
             "radians unless a name ends in _deg; a pose is T_parent_child: xyz of the child's origin in the "
             "parent frame (m) and its rotation as rpy_deg (roll, pitch, yaw in degrees, R = Rz Ry Rx) or "
             "quat_xyzw (unit quaternion).",
    "world.name": "A short name of the room, printed by `gtrig rig check` and in reports.",
    "world.description": "Free text.",
    "cameras": "The fixed cameras that watch the robot's markers; one entry each.",
    "cameras[].name": "Folder name of its images: run/cameras/<name>/, calib/intrinsics/<name>/ (plain name), "
                      "e.g. cam0.",
    "cameras[].resolution": "Image width, height in pixels, as the files hold them.",
    "cameras[].camera_matrix": "OpenCV pinhole K = [[fx, 0, cx], [0, fy, cy], [0, 0, 1]] in pixels: fx = "
                               "focal length (mm) / pixel pitch (mm), e.g. 8 mm / 0.008 mm = 1000; cx, cy "
                               "near the image centre. `gtrig calib` replaces it with calibrated values.",
    "cameras[].dist_coeffs": "Lens distortion, OpenCV order k1, k2, p1, p2, k3 (4, 5, 8, 12 or 14 numbers, "
                             "unitless); zeros until calibrated.",
    "cameras[].T_world_cam": "The camera in the world, OpenCV camera frame (x right, y down in the image, "
                             "z along the optical axis). Tape-measure the position to a few cm; "
                             "`gtrig calib network` refines it.",
    "cameras[].T_world_cam.xyz": "Optical centre in the world (m); ceiling cameras are typically 2.5-3.5 m "
                                 "high.",
    "cameras[].T_world_cam.rpy_deg": "Orientation (deg). Roll 180 looks straight down; roll -90 "
                                     "horizontally along world +y, and between the two tilted down towards "
                                     "+y (typically -120 to -150); yaw then turns the view about the "
                                     "vertical: yaw 0 looks towards +y, 90 towards -x, -90 towards +x.",
    "cameras[].rate_hz": "Frame rate of the continuous run (Hz), typically 10-30; leave the line out for a "
                         "camera that only takes stills.",
    "cameras[].stamp_sigma_s": "Standard deviation of the image stamps about the true mid-exposure "
                               "instants (s): 0 with a hardware trigger, 0.001-0.005 with NTP-synced "
                               "software stamps.",
    "cameras[].tone": "How the image files store light: auto (as each file declares), linear "
                      "(machine-vision cameras) or srgb (phones, webcams).",
    "laser_scanners": "The fixed 2D laser scanners that see the robot's hull; one entry each.",
    "laser_scanners[].name": "File name of its scans: run/lasers/<name>.csv (plain name).",
    "laser_scanners[].T_world_scanner": "The scanner in the world: x along the beam at angle 0, z up "
                                        "(upside-down mounting: roll 180).",
    "laser_scanners[].T_world_scanner.xyz": "Centre of the mirror in the world (m); the height must cut the "
                                            "hull (robot.hull.z_min_m to z_max_m), typically 0.2-0.4 m.",
    "laser_scanners[].T_world_scanner.rpy_deg": "Orientation (deg): yaw = direction of the beam at angle 0, "
                                                "measured from world x; roll and pitch 0 for a level "
                                                "scanner.",
    "laser_scanners[].angle_min_rad": "Angle of the first beam in the scanner frame (rad), e.g. -1.5708 for "
                                      "a 180 deg scanner.",
    "laser_scanners[].angle_increment_rad": "Angle between beams (rad): 0.01745 = 1 deg, 0.00873 = 0.5 deg.",
    "laser_scanners[].beams": "Ranges per scan; must equal the columns r_0 ... r_{n-1} of its CSV "
                              "(181 for 180 deg at 1 deg).",
    "laser_scanners[].range_max_m": "Longest valid range (m); longer readings are no return. SICK LMS: 30-80.",
    "laser_scanners[].rate_hz": "Scans per second (Hz), typically 25-75.",
    "laser_scanners[].range_sigma_m": "Standard deviation of one range (m), datasheet value, typically "
                                      "0.005-0.03.",
    "laser_scanners[].beam_timing": "sweep (a rotating mirror fires the beams one after the other: SICK, "
                                    "Hokuyo) or simultaneous (every beam at the scan's stamp).",
    "laser_scanners[].stamp_at": "Which beam the scan's stamp refers to for a sweep: start, middle or end "
                                 "(see the driver).",
    "laser_scanners[].stamp_sigma_s": "Standard deviation of the scan stamps' offset from the recording "
                                      "clock (s): 0.001-0.005 for a PC-stamped scanner.",
    "robot": "The robot: its hull, markers, odometry and onboard scanners.",
    "robot.hull": "The box the fixed scanners see (the 'gown'), in the robot frame (x forward, y left, z "
                  "up, origin on the floor under the point whose pose the odometry reports; the simulator: "
                  "under the robot's centre); leave it out for a vision-only rig.",
    "robot.hull.length_m": "Length along robot x (m), e.g. 0.78.",
    "robot.hull.width_m": "Width along robot y (m), e.g. 0.57.",
    "robot.hull.z_min_m": "Height of its lower edge above the floor (m), e.g. 0.05.",
    "robot.hull.z_max_m": "Height of its upper edge (m), e.g. 0.55; the fixed scanners' plane lies between "
                          "the two.",
    "robot.hull.offset_xy_m": "Centre of the hull in the robot frame (m); 0, 0 when centred on the "
                              "odometry centre.",
    "robot.markers": "The square ID markers on the robot, seen by the fixed cameras. `gtrig markers make "
                     "--rig rig.yaml` prints them all; `gtrig markers calibrate-robot` measures their poses.",
    "robot.markers[].family": "Marker family: artoolkitplus_simple, artoolkitplus_bch, apriltag_36h11, "
                              "aruco_4x4_50, aruco_5x5_100, aruco_6x6_250, ... (`gtrig markers make "
                              "--help`).",
    "robot.markers[].id": "The marker's ID in its family; every (family, id) once.",
    "robot.markers[].side_m": "Side of the black square, border included (m), as printed and measured: "
                              "typically 0.10-0.20 for cameras 3-6 m away.",
    "robot.markers[].T_robot_marker": "The marker on the robot: origin at the square's centre, x right "
                                      "and y up as printed, z out of the paper.",
    "robot.markers[].T_robot_marker.xyz": "Centre of the square in the robot frame (m), tape-measured; "
                                          "markers flat on top of the robot have z = its top's height.",
    "robot.markers[].T_robot_marker.rpy_deg": "Orientation (deg): 0, 0, 0 lies flat facing up with the "
                                              "printed x along robot x.",
    "robot.odometry": "The robot's wheel odometry (run/odometry.csv).",
    "robot.odometry.rate_hz": "Odometry samples per second (Hz), typically 10-100.",
    "robot.onboard_scanners": "2D scanners on the robot (run/onboard/<name>.csv), for scan matching; an "
                              "empty list [] when there are none.",
    "robot.onboard_scanners[].name": "File name of its scans: run/onboard/<name>.csv (plain name).",
    "robot.onboard_scanners[].T_robot_scanner": "The scanner in the robot frame: x along the beam at "
                                                "angle 0, z up.",
    "robot.onboard_scanners[].T_robot_scanner.xyz": "Centre of the mirror in the robot frame (m).",
    "robot.onboard_scanners[].T_robot_scanner.rpy_deg": "Orientation (deg): 0, 0, 0 looks forward, yaw 180 "
                                                        "backward.",
    "robot.onboard_scanners[].angle_min_rad": "Angle of the first beam in the scanner frame (rad), e.g. "
                                              "-1.5708 for 180 deg.",
    "robot.onboard_scanners[].angle_increment_rad": "Angle between beams (rad), e.g. 0.017453 = 1 deg.",
    "robot.onboard_scanners[].beams": "Ranges per scan, the columns of its CSV (181 for 180 deg at 1 deg).",
    "robot.onboard_scanners[].range_max_m": "Longest valid range (m), e.g. 30 for a SICK LMS, 5.6 for a "
                                            "Hokuyo URG-04LX.",
    "robot.onboard_scanners[].rate_hz": "Scans per second (Hz), typically 10-75.",
    "survey": "The hand-laser survey that defines the world frame on the floor (docs/survey.md).",
    "survey.reference_points": "Floor points whose world coordinates are known by definition: O is the "
                               "origin, A lies on the world y axis, B on the x axis; at least 3, spread "
                               "over the tracked area.",
    "survey.reference_points[].name": "Name used in survey/*.csv, e.g. O, A, B.",
    "survey.reference_points[].xy": "World x, y (m), by definition: O (0, 0), A (0, d), B (d, 0) for a "
                                    "reference square of side d, e.g. 2.5.",
    "survey.reference_points[].sigma_m": "One-sigma accuracy of its marking on the floor (m), typically "
                                         "0.0005-0.002.",
    "survey.hand_laser_sigma_m": "One-sigma error of one hand-laser distance (m): the device's datasheet "
                                 "plus aiming, typically 0.001-0.002.",
}

#: fields the calibrations add, and optional ones; the template shows them as comments where they would go
LATER_NOTES: dict[str, str] = {
    "world": "outline_xy: the room's outline, its walls' feet as corners [[x, y], ...] (m) in order; "
             "`gtrig sim --rig` builds the simulated room's walls on it. Optional.",
    "cameras[]": "pose_cov: written by `gtrig calib network` (covariance of T_world_cam and the lens); "
                 "leave it out.",
    "robot.markers[]": "pose_cov: written by `gtrig markers calibrate-robot` (6 x 6, m and rad); leave "
                       "it out.",
    "robot": "markers_frame_cov: written by `gtrig robot-frame` (6 x 6, m and rad); leave it out.",
}


def _pose(T: geo.Array) -> Pose:
    """``T`` as xyz (mm-rounded) and rpy_deg (rounded to 0.1 deg)."""
    xyz = tuple(round(float(v), 3) for v in T[:3, 3])
    rpy = tuple(round(math.degrees(float(a)), 1) + 0.0 for a in geo.rpy_from_T(T))
    return Pose(xyz=(xyz[0], xyz[1], xyz[2]), rpy_deg=(rpy[0], rpy[1], rpy[2]))


def _cameras(n: int) -> tuple[Camera, ...]:
    """``n`` cameras in a row along world x, 2 m apart, 2.8 m high, each looking at the area 2.5 m ahead."""
    cx, cy = AREA_CENTRE_XY_M
    out = []
    for i in range(n):
        x = cx + 2.0 * (i - (n - 1) / 2)
        eye = (x, cy - 2.5, CAMERA_HEIGHT_M)
        T = geo.look_at(eye, (x, cy, 0.0))
        out.append(Camera(name=f"cam{i}", resolution=(1280, 960),
                          camera_matrix=((1000.0, 0.0, 639.5), (0.0, 1000.0, 479.5), (0.0, 0.0, 1.0)),
                          dist_coeffs=(0.0, 0.0, 0.0, 0.0, 0.0), T_world_cam=_pose(T), rate_hz=15.0,
                          stamp_sigma_s=0.002, tone="auto"))
    return tuple(out)


def _scanners(m: int) -> tuple[LaserScanner, ...]:
    """``m`` scanners on a 3 m circle around the area's centre, each facing it (its 180 deg fan)."""
    cx, cy = AREA_CENTRE_XY_M
    out = []
    for i in range(m):
        a = 2 * math.pi * i / m - 0.75 * math.pi
        x, y = cx + 3.0 * math.cos(a), cy + 3.0 * math.sin(a)
        yaw = math.atan2(cy - y, cx - x)
        T = geo.se2_to_T(x, y, yaw, SCANNER_HEIGHT_M)
        out.append(LaserScanner(name=f"laser{i}", T_world_scanner=_pose(T), angle_min_rad=-1.5708,
                                angle_increment_rad=0.017453, beams=181, range_max_m=30.0, rate_hz=75.0,
                                range_sigma_m=0.01, beam_timing=BeamTiming.SWEEP, stamp_at=StampAt.START,
                                stamp_sigma_s=0.002))
    return tuple(out)


def _markers() -> tuple[Marker, ...]:
    """Four markers flat on the robot's top, at 0.62 m, in a 2 x 2 grid."""
    ids = (3, 6, 14, 30)
    xy = ((0.2, 0.13), (0.2, -0.13), (-0.15, 0.13), (-0.15, -0.13))
    return tuple(Marker(family=MarkerFamily.ARTOOLKITPLUS_SIMPLE, id=i, side_m=0.156,
                        T_robot_marker=Pose(xyz=(x, y, 0.62), rpy_deg=(0.0, 0.0, 0.0)))
                 for i, (x, y) in zip(ids, xy, strict=True))


def _onboard() -> tuple[OnboardScanner, ...]:
    return (OnboardScanner(name="front_laser", T_robot_scanner=Pose(xyz=(0.3, 0.0, 0.35), rpy_deg=(0.0, 0.0, 0.0)),
                           angle_min_rad=-1.5708, angle_increment_rad=0.017453, beams=181, range_max_m=30.0,
                           rate_hz=25.0),)


def template_rig(n_cameras: int, n_scanners: int, odometry_only: bool = False) -> Rig:
    """The template's values as a validated :class:`Rig`.

    Parameters
    ----------
    n_cameras, n_scanners
        Fixed cameras and fixed laser scanners, 0 to :data:`MAX_SENSORS` each; both 0 with
        ``odometry_only``.
    odometry_only
        Only the robot's odometry and onboard scanner: no cameras, scanners, markers, hull or survey.
    """
    if not (0 <= n_cameras <= MAX_SENSORS and 0 <= n_scanners <= MAX_SENSORS):
        raise ValueError(f"0 to {MAX_SENSORS} cameras and scanners")
    if odometry_only and (n_cameras or n_scanners):
        raise ValueError("an odometry-only rig has no cameras or scanners")
    if odometry_only:
        robot = Robot(onboard_scanners=_onboard())
        return Rig(world=World(name="lab", description="odometry and onboard scans only"), robot=robot)
    hull = Hull(length_m=0.78, width_m=0.57, z_min_m=0.05, z_max_m=0.55) if n_scanners else None
    robot = Robot(hull=hull, markers=_markers() if n_cameras else (), onboard_scanners=_onboard())
    cx, cy = AREA_CENTRE_XY_M
    survey = Survey(reference_points=(
        ReferencePoint(name="O", xy=(0.0, 0.0), sigma_m=0.001),
        ReferencePoint(name="A", xy=(0.0, 2 * cy), sigma_m=0.001),
        ReferencePoint(name="B", xy=(2 * cx, 0.0), sigma_m=0.001)), hand_laser_sigma_m=0.0015)
    return Rig(world=World(name="lab", description="the instrumented room"), cameras=_cameras(n_cameras),
               laser_scanners=_scanners(n_scanners), robot=robot, survey=survey)


def _flow(v: Any) -> str:
    """A scalar or list as one line of YAML flow style."""
    if isinstance(v, float):
        return repr(v)
    if isinstance(v, list):
        return "[" + ", ".join(_flow(x) for x in v) + "]"
    return str(yaml.safe_dump(v, default_flow_style=True, width=10**6)).removesuffix("\n...\n").strip()


class _Emitter:
    """YAML text with each field's note above it, the first time its path appears."""

    def __init__(self, width: int) -> None:
        self.lines: list[str] = []
        self.width = width
        self.noted: set[str] = set()

    def note(self, text: str, indent: int) -> None:
        for line in textwrap.wrap(text, self.width - indent - 2):
            self.lines.append(" " * indent + "# " + line)

    def field_note(self, path: str, indent: int) -> None:
        if path in self.noted:
            return
        if path not in FIELD_NOTES:
            raise KeyError(f"no note for rig field {path}")
        self.noted.add(path)
        self.note(FIELD_NOTES[path], indent)

    def mapping(self, d: dict[str, Any], path: str, indent: int, first: str = "") -> None:
        """Emit ``d``; ``first`` prefixes its first key (a list item's ``- ``)."""
        for i, (k, v) in enumerate(d.items()):
            p = f"{path}.{k}" if path else k
            self.field_note(p, indent - (len(first) if first and not i else 0))
            lead = " " * indent if i or not first else " " * (indent - len(first)) + first
            if isinstance(v, dict):
                self.lines.append(f"{lead}{k}:")
                self.mapping(v, p, indent + 2)
            elif isinstance(v, list) and v and isinstance(v[0], dict):
                self.lines.append(f"{lead}{k}:")
                for item in v:
                    self.mapping(item, p + "[]", indent + 4, first="- ")
            else:
                self.lines.append(f"{lead}{k}: {_flow(v)}")
        if path in LATER_NOTES and path + "#later" not in self.noted:
            self.noted.add(path + "#later")
            self.note(LATER_NOTES[path], indent)


def template_text(rig: Rig, width: int = 100) -> str:
    """``rig`` as commented YAML: a note above each field's first occurrence (see :data:`FIELD_NOTES`).

    Raises
    ------
    KeyError
        A field of the rig has no note (a model field added without explaining it here).
    """
    doc = rig_to_dict(rig)
    em = _Emitter(width)
    em.note("gtrig rig file. Check it with `gtrig rig check rig.yaml`; the fields are explained once, at "
            "their first appearance; docs/formats.md and docs/recording.md say more.", 0)
    em.mapping(doc, "", 0)
    return "\n".join(em.lines) + "\n"


def template_field_paths(rig: Rig) -> list[str]:
    """Every field path of ``rig`` as written (``cameras[].name`` ...), in document order."""
    out: list[str] = []

    def walk(v: Any, path: str) -> None:
        if isinstance(v, dict):
            for k, x in v.items():
                p = f"{path}.{k}" if path else k
                out.append(p)
                walk(x, p)
        elif isinstance(v, list) and v and isinstance(v[0], dict):
            for x in v:
                walk(x, path + "[]")

    walk(rig_to_dict(rig), "")
    return list(dict.fromkeys(out))
