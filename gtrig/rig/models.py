"""Typed models of ``rig.yaml`` (pydantic v2).

All lengths are metres, angles radians unless a field name says ``_deg``; poses are
``T_parent_child`` (see :mod:`gtrig.geometry`). Unknown fields are refused, so a typo is an error
rather than a silently ignored setting. Plausibility bounds catch millimetres given as metres.
"""

from __future__ import annotations

import math
import re
from enum import StrEnum
from typing import Annotated, Literal, Self

import numpy as np
from pydantic import AfterValidator, BaseModel, ConfigDict, Field, field_validator, model_validator

from gtrig import geometry as geo

PoseCov = tuple[tuple[float, ...], ...]

#: the lens parameters a camera's ``pose_cov`` may continue with, in this order
LENS_PARAMETERS = ("fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2", "k3")


def _check_pose_cov(v: PoseCov | None, sizes: range) -> PoseCov | None:
    """A pose covariance must be square of an allowed size, symmetric and positive semi-definite."""
    if v is None:
        return v
    C = np.asarray(v, dtype=float) if all(len(r) == len(v) for r in v) else np.zeros((0, 1))
    if C.ndim != 2 or C.shape[0] != C.shape[1] or C.shape[0] not in sizes or not np.all(np.isfinite(C)):
        n = f"{sizes.start} x {sizes.start}" if len(sizes) == 1 else f"n x n, n from {sizes.start} to {sizes.stop - 1}"
        raise ValueError(f"pose_cov must be a finite {n} matrix (rows of numbers)")
    scale = max(float(np.max(np.abs(np.diag(C)))), 1e-300)
    if np.max(np.abs(C - C.T)) > 1e-6 * scale:
        raise ValueError("pose_cov must be symmetric")
    if float(np.min(np.linalg.eigvalsh(0.5 * (C + C.T)))) < -1e-9 * scale:
        raise ValueError("pose_cov must be positive semi-definite")
    return v


def pose_cov_rows(C: geo.Array) -> PoseCov:
    """A square array as the nested tuples a ``pose_cov`` field holds (symmetrised)."""
    C = 0.5 * (np.asarray(C, dtype=float) + np.asarray(C, dtype=float).T)
    return tuple(tuple(float(x) for x in row) for row in C)


# Anything larger than this in a room-scale installation is almost surely millimetres.
MAX_ROOM_EXTENT_M = 100.0


class _Strict(BaseModel):
    # NaN and infinities are refused in every number of a rig: none of them means anything there
    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False)


def _plain_name(v: str) -> str:
    """A sensor name is also a folder or file name in the recording: a plain name, never a path."""
    if not re.fullmatch(r"[A-Za-z0-9_][A-Za-z0-9_.+-]*", v) or v.endswith("."):
        raise ValueError(f"{v!r} is not a plain name (letters, digits, _ . + -): a sensor's name is a folder or "
                         "file name in the recording, never a path")
    return v


#: the name of a sensor whose data lie in the recording under that name
SensorName = Annotated[str, Field(min_length=1, max_length=100), AfterValidator(_plain_name)]


def _check_metres(value: float, limit: float, what: str = "value") -> float:
    if not math.isfinite(value):
        raise ValueError(f"{what} must be finite")
    if abs(value) > limit:
        raise ValueError(
            f"{value:g} m is implausible (limit {limit:g} m): millimetres given as metres? "
            f"write {value / 1000:g}"
        )
    return value


class Pose(_Strict):
    """A rigid pose: ``xyz`` in metres and exactly one of ``quat_xyzw`` or ``rpy_deg``."""

    xyz: tuple[float, float, float]
    quat_xyzw: tuple[float, float, float, float] | None = None
    rpy_deg: tuple[float, float, float] | None = None

    @field_validator("xyz")
    @classmethod
    def _xyz_metres(cls, v: tuple[float, float, float]) -> tuple[float, float, float]:
        for c in v:
            _check_metres(c, MAX_ROOM_EXTENT_M, "xyz")
        return v

    @model_validator(mode="after")
    def _one_rotation(self) -> Self:
        if (self.quat_xyzw is None) == (self.rpy_deg is None):
            raise ValueError("give exactly one of quat_xyzw or rpy_deg")
        if self.quat_xyzw is not None:
            n = float(np.linalg.norm(self.quat_xyzw))
            if not 0.99 < n < 1.01:
                raise ValueError(f"quat_xyzw must be a unit quaternion (norm {n:.4g})")
        return self

    def matrix(self) -> geo.Array:
        """The 4 x 4 transform."""
        if self.quat_xyzw is not None:
            q = np.asarray(self.quat_xyzw) / np.linalg.norm(self.quat_xyzw)
            return geo.T_from_xyz_quat(self.xyz, q)
        assert self.rpy_deg is not None
        return geo.T_from_xyz_rpy(self.xyz, np.radians(self.rpy_deg))

    @classmethod
    def from_matrix(cls, T: geo.Array) -> Pose:
        """A pose from a 4 x 4 transform, stored as ``xyz`` and ``quat_xyzw``."""
        t, q = geo.xyz_quat_from_T(T)
        return cls(
            xyz=(float(t[0]), float(t[1]), float(t[2])),
            quat_xyzw=(float(q[0]), float(q[1]), float(q[2]), float(q[3])),
        )


class Camera(_Strict):
    """A fixed camera: OpenCV pinhole model with distortion, and its pose in the world."""

    name: SensorName
    resolution: tuple[Annotated[int, Field(gt=0, le=20000)], Annotated[int, Field(gt=0, le=20000)]]
    camera_matrix: tuple[
        tuple[float, float, float], tuple[float, float, float], tuple[float, float, float]
    ]
    dist_coeffs: tuple[float, ...] = (0.0, 0.0, 0.0, 0.0, 0.0)
    T_world_cam: Pose
    #: frame rate of a video camera; ``None`` for a camera that takes stills (calibration, validation)
    rate_hz: float | None = Field(default=None, gt=0, le=1000)
    #: standard deviation of the image time stamps about the true mid-exposure instants (trigger and
    #: transfer jitter), seconds; GTvision adds the motion it hides to every moving pose's covariance
    stamp_sigma_s: float = Field(default=0.0, ge=0, le=1.0)
    #: how the camera's image files store light, for the marker detector's edge fits: ``"auto"`` as
    #: each file declares it (JPEG and PNGs with an sRGB chunk: sRGB; others linear,
    #: :func:`gtrig.io.imagetone.declared_tone`), ``"linear"`` (machine-vision cameras) or ``"srgb"``
    #: (phones, webcams, a video's frames from such a camera)
    tone: Literal["auto", "linear", "srgb"] = "auto"
    #: covariance of ``T_world_cam`` as calibrated: the optical centre's move (world x, y, z, m), then
    #: the rotation ``R_world_cam <- Exp(dphi) R_world_cam`` (about world x, y, z, rad), optionally
    #: followed by the first n lens parameters of :data:`LENS_PARAMETERS` (px, unitless), jointly:
    #: (6 + n) x (6 + n). Written by the network calibration; GTvision weighs the cameras with it. The
    #: pose and lens errors of a calibration are strongly correlated (a principal point off by a
    #: fraction of a pixel is mostly undone by a turn of the camera), which the joint matrix keeps.
    pose_cov: PoseCov | None = None

    @field_validator("pose_cov")
    @classmethod
    def _pose_cov(cls, v: PoseCov | None) -> PoseCov | None:
        return _check_pose_cov(v, range(6, 6 + len(LENS_PARAMETERS) + 1))

    @field_validator("dist_coeffs")
    @classmethod
    def _dist_len(cls, v: tuple[float, ...]) -> tuple[float, ...]:
        if len(v) not in (4, 5, 8, 12, 14):
            raise ValueError(f"expected 4, 5, 8, 12 or 14 coefficients in OpenCV order, got {len(v)}")
        return v

    @model_validator(mode="after")
    def _intrinsics(self) -> Self:
        K = np.asarray(self.camera_matrix)
        w, h = self.resolution
        if K[0, 0] <= 0 or K[1, 1] <= 0:
            raise ValueError("camera_matrix: focal lengths must be positive")
        if tuple(K[2]) != (0.0, 0.0, 1.0) or K[1, 0] != 0.0:
            raise ValueError("camera_matrix: must be [[fx, s, cx], [0, fy, cy], [0, 0, 1]]")
        if not (0 <= K[0, 2] <= w and 0 <= K[1, 2] <= h):
            raise ValueError(f"camera_matrix: principal point ({K[0, 2]:g}, {K[1, 2]:g}) outside the image")
        return self

    @property
    def K(self) -> geo.Array:
        return np.asarray(self.camera_matrix, dtype=float)

    @property
    def dist(self) -> geo.Array:
        return np.asarray(self.dist_coeffs, dtype=float)


class BeamTiming(StrEnum):
    """How a scanner fires its beams within one scan.

    ``sweep``: a rotating mirror sweeps the beams one after the other, beam ``i`` at
    ``|angle_i - angle_0| / (2 pi rate_hz)`` after the first (SICK LMS, Hokuyo URG: the mirror turns
    once per period, so 180 degrees take half a period). ``simultaneous``: every beam of a scan fires
    at the same instant (flash solid-state devices, and simulators that stamp a whole scan at once).
    """

    SWEEP = "sweep"
    SIMULTANEOUS = "simultaneous"


class StampAt(StrEnum):
    """Which instant of the sweep a scan's time stamp refers to (drivers differ: the first beam, the
    middle of the sweep, or the last beam when the scan is sent). Meaningless for ``simultaneous``."""

    START = "start"
    MIDDLE = "middle"
    END = "end"


class LaserScanner(_Strict):
    """A 2D laser scanner: beam ``i`` points at ``angle_min_rad + i * angle_increment_rad``
    in the scanner's x-y plane.

    ``beam_timing`` and ``stamp_at`` say when each beam fired relative to the scan's stamp
    (:func:`gtrig.laser.fuse.beam_delays_s`); the default is a mirror sweep stamped at its first beam.
    """

    name: SensorName
    T_world_scanner: Pose
    angle_min_rad: float = Field(ge=-2 * math.pi, le=2 * math.pi)
    angle_increment_rad: float
    beams: int = Field(gt=1, le=100000)
    range_max_m: float = Field(gt=0)
    rate_hz: float = Field(gt=0, le=1000)
    range_sigma_m: float = Field(default=0.01, ge=0)
    beam_timing: BeamTiming = BeamTiming.SWEEP
    stamp_at: StampAt = StampAt.START
    #: standard deviation of the scan stamps' offset from the recording clock (the logging PC's
    #: synchronisation, the driver's latency), seconds; GTlaser adds the motion it hides to each pose
    stamp_sigma_s: float = Field(default=0.0, ge=0, le=1.0)

    @field_validator("angle_increment_rad")
    @classmethod
    def _inc(cls, v: float) -> float:
        if v == 0 or abs(v) > 0.5:
            raise ValueError(f"{v:g} rad is implausible: degrees given as radians?")
        return v

    @field_validator("range_max_m")
    @classmethod
    def _rmax(cls, v: float) -> float:
        return _check_metres(v, 500.0, "range_max_m")

    @property
    def angles_rad(self) -> geo.Array:
        return self.angle_min_rad + self.angle_increment_rad * np.arange(self.beams, dtype=np.float64)

    def beam_delays_s(self) -> geo.Array:
        """Firing time (B,) of each beam after the scan's stamp, seconds (negative: before it)."""
        if self.beam_timing == BeamTiming.SIMULTANEOUS:
            return np.zeros(self.beams)
        a = self.angles_rad
        d = np.abs(a - a[0]) / (2 * np.pi) / self.rate_hz
        ref = {StampAt.START: 0.0, StampAt.MIDDLE: 0.5 * d[-1], StampAt.END: d[-1]}[self.stamp_at]
        return d - ref


class MarkerFamily(StrEnum):
    """Square ID marker families (:mod:`gtrig.markers.families` describes each)."""

    ARTOOLKITPLUS_SIMPLE = "artoolkitplus_simple"
    ARTOOLKITPLUS_SIMPLE_THIN = "artoolkitplus_simple_thin"
    ARTOOLKITPLUS_BCH = "artoolkitplus_bch"
    ARTOOLKITPLUS_BCH_THIN = "artoolkitplus_bch_thin"
    APRILTAG_16H5 = "apriltag_16h5"
    APRILTAG_25H9 = "apriltag_25h9"
    APRILTAG_36H10 = "apriltag_36h10"
    APRILTAG_36H11 = "apriltag_36h11"
    APRILTAG_STANDARD41H12 = "apriltag_standard41h12"
    APRILTAG_STANDARD52H13 = "apriltag_standard52h13"
    APRILTAG_CIRCLE21H7 = "apriltag_circle21h7"
    APRILTAG_CIRCLE49H12 = "apriltag_circle49h12"
    APRILTAG_CUSTOM48H12 = "apriltag_custom48h12"
    ARUCO_4X4_50 = "aruco_4x4_50"
    ARUCO_4X4_100 = "aruco_4x4_100"
    ARUCO_4X4_250 = "aruco_4x4_250"
    ARUCO_4X4_1000 = "aruco_4x4_1000"
    ARUCO_5X5_50 = "aruco_5x5_50"
    ARUCO_5X5_100 = "aruco_5x5_100"
    ARUCO_5X5_250 = "aruco_5x5_250"
    ARUCO_5X5_1000 = "aruco_5x5_1000"
    ARUCO_6X6_50 = "aruco_6x6_50"
    ARUCO_6X6_100 = "aruco_6x6_100"
    ARUCO_6X6_250 = "aruco_6x6_250"
    ARUCO_6X6_1000 = "aruco_6x6_1000"
    ARUCO_7X7_50 = "aruco_7x7_50"
    ARUCO_7X7_100 = "aruco_7x7_100"
    ARUCO_7X7_250 = "aruco_7x7_250"
    ARUCO_7X7_1000 = "aruco_7x7_1000"
    ARUCO_ORIGINAL = "aruco_original"
    ARUCO_MIP_36H12 = "aruco_mip_36h12"


class Marker(_Strict):
    """A square marker on the robot. ``side_m`` is the black square's side; the marker frame has its
    origin at the square's centre, x to the right and y up as printed, z out of the paper."""

    family: MarkerFamily = MarkerFamily.ARTOOLKITPLUS_SIMPLE
    id: int = Field(ge=0)
    side_m: float = Field(gt=0)
    T_robot_marker: Pose
    #: covariance (6 x 6) of ``T_robot_marker`` relative to the robot frame as the anchor marker realises
    #: it: the centre's move (robot x, y, z, m), then the rotation about robot x, y, z (rad), as
    #: :func:`gtrig.vision.covariance.pose_error_xi`; written by the marker-to-robot calibration. The
    #: anchor's own placement error, common to all markers, is not part of it.
    pose_cov: PoseCov | None = None

    @field_validator("pose_cov")
    @classmethod
    def _pose_cov(cls, v: PoseCov | None) -> PoseCov | None:
        return _check_pose_cov(v, range(6, 7))

    @field_validator("side_m")
    @classmethod
    def _side(cls, v: float) -> float:
        return _check_metres(v, 5.0, "side_m")


class Hull(_Strict):
    """The robot's rectangular hull ("gown") seen by the fixed scanners, in the robot frame."""

    length_m: float = Field(gt=0)
    width_m: float = Field(gt=0)
    z_min_m: float = Field(ge=0)
    z_max_m: float = Field(gt=0)
    offset_xy_m: tuple[float, float] = (0.0, 0.0)

    @field_validator("length_m", "width_m", "z_max_m")
    @classmethod
    def _size(cls, v: float) -> float:
        return _check_metres(v, 10.0, "size")

    @model_validator(mode="after")
    def _span(self) -> Self:
        if self.z_max_m <= self.z_min_m:
            raise ValueError("z_max_m must be above z_min_m")
        return self

    def corners_xy(self) -> geo.Array:
        """The hull outline (4, 2) in the robot frame, counter-clockwise from rear right."""
        hl, hw = self.length_m / 2, self.width_m / 2
        ox, oy = self.offset_xy_m
        return np.array([[-hl, -hw], [hl, -hw], [hl, hw], [-hl, hw]]) + [ox, oy]


class Odometry(_Strict):
    rate_hz: float = Field(default=50.0, gt=0, le=10000)


class OnboardScanner(_Strict):
    name: SensorName
    T_robot_scanner: Pose
    angle_min_rad: float
    angle_increment_rad: float
    beams: int = Field(gt=1)
    range_max_m: float = Field(gt=0)
    rate_hz: float = Field(gt=0)

    @field_validator("angle_increment_rad")
    @classmethod
    def _inc(cls, v: float) -> float:
        if v == 0 or abs(v) > 0.5:
            raise ValueError(f"{v:g} rad is implausible: degrees given as radians?")
        return v

    @property
    def angles_rad(self) -> geo.Array:
        return self.angle_min_rad + self.angle_increment_rad * np.arange(self.beams, dtype=np.float64)


class Robot(_Strict):
    #: the gown the fixed laser scanners see; GTlaser needs it, a vision-only rig leaves it out
    hull: Hull | None = None
    markers: tuple[Marker, ...] = ()
    #: covariance (6 x 6) of the error common to every marker: how far the robot frame the markers
    #: realise may be from the robot frame itself (the anchor's measured pose, or what the survey of the
    #: validation stops left of it; ``gtrig.vision.robot_frame``), over (dt, dphi) in robot axes, m and
    #: rad. GTvision adds it to every pose's covariance; none: nothing is added.
    markers_frame_cov: PoseCov | None = None
    odometry: Odometry = Odometry()
    onboard_scanners: tuple[OnboardScanner, ...] = ()

    @field_validator("markers_frame_cov")
    @classmethod
    def _frame_cov(cls, v: PoseCov | None) -> PoseCov | None:
        return _check_pose_cov(v, range(6, 7))

    @model_validator(mode="after")
    def _unique_markers(self) -> Self:
        keys = [(m.family, m.id) for m in self.markers]
        if len(keys) != len(set(keys)):
            raise ValueError("markers: the same family and id appear twice")
        return self


class ReferencePoint(_Strict):
    """A surveyed reference point on the floor: ``xy`` in the world frame, ``sigma_m`` its accuracy."""

    name: str = Field(min_length=1)
    xy: tuple[float, float]
    sigma_m: float = Field(default=0.002, ge=0)

    @field_validator("xy")
    @classmethod
    def _xy(cls, v: tuple[float, float]) -> tuple[float, float]:
        for c in v:
            _check_metres(c, MAX_ROOM_EXTENT_M, "xy")
        return v


class Survey(_Strict):
    reference_points: tuple[ReferencePoint, ...] = ()
    hand_laser_sigma_m: float = Field(default=0.002, ge=0, le=1.0)


class World(_Strict):
    """The world frame's name and, optionally, the room's outline: its walls' feet as a polygon ``(x, y)``
    in the world frame, metres, corner after corner (``gtrig sim --rig`` builds the room's walls from it)."""

    name: str = "world"
    description: str = ""
    outline_xy: tuple[tuple[float, float], ...] | None = None

    @field_validator("outline_xy")
    @classmethod
    def _outline(cls, v: tuple[tuple[float, float], ...] | None) -> tuple[tuple[float, float], ...] | None:
        if v is None:
            return v
        if len(v) < 3:
            raise ValueError(f"a room outline needs at least 3 corners, got {len(v)}")
        for p in v:
            for c in p:
                _check_metres(c, MAX_ROOM_EXTENT_M, "outline_xy")
        x, y = [p[0] for p in v], [p[1] for p in v]
        area = 0.5 * abs(sum(x[i] * y[i - 1] - x[i - 1] * y[i] for i in range(len(v))))
        if area <= 0.0:
            raise ValueError("the room outline encloses no area")
        return v


class Rig(_Strict):
    """The whole installation."""

    world: World = World()
    cameras: tuple[Camera, ...] = ()
    laser_scanners: tuple[LaserScanner, ...] = ()
    robot: Robot
    survey: Survey = Survey()

    @model_validator(mode="after")
    def _unique_names(self) -> Self:
        for what, names in (
            ("cameras", [c.name for c in self.cameras]),
            ("laser_scanners", [s.name for s in self.laser_scanners]),
            ("survey.reference_points", [p.name for p in self.survey.reference_points]),
        ):
            dup = {n for n in names if names.count(n) > 1}
            if dup:
                raise ValueError(f"{what}: duplicate name {sorted(dup)[0]!r}")
        return self

    def camera(self, name: str) -> Camera:
        for c in self.cameras:
            if c.name == name:
                return c
        raise KeyError(name)

    def scanner(self, name: str) -> LaserScanner:
        for s in self.laser_scanners:
            if s.name == name:
                return s
        raise KeyError(name)

    def marker(self, marker_id: int) -> Marker:
        for m in self.robot.markers:
            if m.id == marker_id:
                return m
        raise KeyError(marker_id)
