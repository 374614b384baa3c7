"""The one pose-track type: what every GT source returns and every consumer takes.

A :class:`PoseTrack` is a time-stamped sequence of robot poses ``T_world_robot`` with, per pose, a
covariance, a status and a reason. GTvision, GTlaser, fusion, RTK-GPS and scan matching return one;
evaluation, export and the report take one.

Covariance convention (the same as ROS's ``geometry_msgs/PoseWithCovariance``)
--------------------------------------------------------------------------------
The error of a pose is the world-frame perturbation ``xi = (dt, dphi)`` with

    t_est = t_true + dt,     R_est = Exp(dphi) R_true,

so ``dt`` is in metres along the world axes (``frame_id``) and ``dphi`` in radians about the fixed
world axes. ``cov_kind`` says which block a track carries:

- ``"se3"``: (N, 6, 6) over ``(x, y, z, rx, ry, rz)``;
- ``"xyyaw"``: (N, 3, 3) over ``(x, y, yaw)`` (a planar robot; ``yaw`` is ``rz``);
- ``"xyz"``: (N, 3, 3) over ``(x, y, z)`` (position only, e.g. a GPS antenna).

A planar track's poses still carry z and a full quaternion (z = 0, roll = pitch = 0 for the room's
robots), so every track writes as TUM.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass, field, replace
from typing import Literal

import numpy as np
from scipy.spatial.transform import Rotation

from gtrig import geometry as geo
from gtrig.stamps import ns_from_seconds, seconds_from_ns

CovKind = Literal["se3", "xyyaw", "xyz"]

COV_AXES: dict[str, tuple[str, ...]] = {
    "se3": ("x", "y", "z", "rx", "ry", "rz"),
    "xyyaw": ("x", "y", "yaw"),
    "xyz": ("x", "y", "z"),
}

#: the largest difference (s) between ``stamps_s`` and ``stamps_ns`` that still counts as one stamp: a float
#: epoch stamp (1.7e9 s) holds 0.24 us; both roundings together stay under it
NS_AGREE_S = 4e-7

#: indices of (x, y, yaw) inside the se3 block
PLANAR_INDEX = (0, 1, 5)


class PoseStatus(enum.IntEnum):
    """What a pose is worth.

    OK: measured and trusted. FLAGGED: measured, kept, but with a warning (its reason says why).
    BRIDGED: not measured at this stamp; carried over a gap by a motion model (fusion) with its grown
    covariance. REJECTED: measured and refused (an outlier, an ambiguity); kept in the track so that a
    report can name it, never used as ground truth.
    """

    OK = 0
    FLAGGED = 1
    BRIDGED = 2
    REJECTED = 3


def _frozen(a: np.ndarray) -> np.ndarray:
    a = np.ascontiguousarray(a)
    a.setflags(write=False)
    return a


@dataclass(frozen=True)
class PoseTrack:
    """Robot poses over time, with a covariance, a status and a reason per pose.

    Attributes
    ----------
    stamps_s : (N,) strictly increasing seconds (the recording's clock).
    xyz : (N, 3) positions of ``child_frame_id`` in ``frame_id``, metres.
    quat_xyzw : (N, 4) unit quaternions, ``w >= 0``.
    cov : (N, k, k) covariance of each pose in the convention of the module docstring, or ``None``
        when the source gives none. ``nan`` for a pose without one (a REJECTED pose may lack it).
    cov_kind : which block ``cov`` is (``"se3"``, ``"xyyaw"`` or ``"xyz"``).
    status : (N,) :class:`PoseStatus` codes (uint8).
    reasons : N strings, empty for an OK pose: why a pose is flagged, bridged or rejected.
    source : who made the track ("GTvision", "GTlaser", "fusion", "gps", ...).
    frame_id, child_frame_id : the world frame and the body frame (REP 105 names where they apply).
    stamps_ns : (N,) int64 or ``None``: the stamps as the source gave them, integer nanoseconds (a file's
        decimal text, a bag's header), so that every writer prints the stamp it read (gtrig.stamps). Kept
        only while it agrees with ``stamps_s`` (to :data:`NS_AGREE_S`): a track made with new ``stamps_s``
        (``dataclasses.replace``) drops it. :meth:`integer_stamps_ns` gives it, or the nanoseconds of
        ``stamps_s`` when it is ``None``.
    """

    stamps_s: np.ndarray
    xyz: np.ndarray
    quat_xyzw: np.ndarray
    cov: np.ndarray | None = None
    cov_kind: CovKind = "se3"
    status: np.ndarray = field(default_factory=lambda: np.zeros(0, np.uint8))
    reasons: tuple[str, ...] = ()
    source: str = ""
    frame_id: str = "world"
    child_frame_id: str = "robot"
    stamps_ns: np.ndarray | None = None

    def __post_init__(self) -> None:
        n = int(np.asarray(self.stamps_s).size)
        s = _frozen(np.asarray(self.stamps_s, dtype=float).reshape(n))
        xyz = _frozen(np.asarray(self.xyz, dtype=float).reshape(n, 3))
        q = np.asarray(self.quat_xyzw, dtype=float).reshape(n, 4)
        object.__setattr__(self, "stamps_s", s)
        object.__setattr__(self, "xyz", xyz)
        object.__setattr__(self, "quat_xyzw", _frozen(q))
        if self.status.size == 0 and n:
            object.__setattr__(self, "status", np.zeros(n, np.uint8))
        status = np.asarray(self.status, dtype=np.uint8).reshape(-1)
        object.__setattr__(self, "status", _frozen(status))
        if not self.reasons:
            object.__setattr__(self, "reasons", ("",) * n)
        if self.cov_kind not in COV_AXES:
            raise ValueError(f"cov_kind must be one of {sorted(COV_AXES)}, got {self.cov_kind!r}")
        if self.cov is not None:
            k = len(COV_AXES[self.cov_kind])
            cov = np.asarray(self.cov, dtype=float)
            if cov.shape != (n, k, k):
                raise ValueError(f"cov is {cov.shape}, expected {(n, k, k)} for cov_kind {self.cov_kind!r}")
            object.__setattr__(self, "cov", _frozen(cov))
        if status.shape != (n,) or len(self.reasons) != n:
            raise ValueError(f"status ({status.shape}) and reasons ({len(self.reasons)}) must have {n} entries")
        if n > 1 and np.any(np.diff(s) <= 0):
            raise ValueError("stamps_s must increase strictly")
        if self.stamps_ns is not None:
            ns = np.asarray(self.stamps_ns).reshape(-1)
            agree = ns.shape == (n,) and np.issubdtype(ns.dtype, np.integer)
            if agree and n:
                agree = bool(np.max(np.abs(seconds_from_ns(ns) - s)) <= NS_AGREE_S)
            object.__setattr__(self, "stamps_ns", _frozen(ns.astype(np.int64)) if agree else None)

    # --- construction -------------------------------------------------------------------------------

    @staticmethod
    def from_matrices(stamps_s: np.ndarray, T_world_robot: np.ndarray, **kw: object) -> PoseTrack:
        """From (N, 4, 4) transforms; ``kw`` are the other fields."""
        T = np.asarray(T_world_robot, dtype=float).reshape(-1, 4, 4)
        q = Rotation.from_matrix(T[:, :3, :3]).as_quat() if len(T) else np.zeros((0, 4))
        q[q[:, 3] < 0] *= -1
        return PoseTrack(np.asarray(stamps_s, dtype=float), T[:, :3, 3], q, **kw)  # type: ignore[arg-type]

    @staticmethod
    def from_xytheta(stamps_s: np.ndarray, xytheta: np.ndarray, **kw: object) -> PoseTrack:
        """A planar track from (N, 3) ``x, y, theta`` (z = 0, level); ``kw`` are the other fields
        (``cov`` then defaults to ``cov_kind="xyyaw"``)."""
        p = np.asarray(xytheta, dtype=float).reshape(-1, 3)
        half = 0.5 * p[:, 2]
        q = np.stack([np.zeros(len(p)), np.zeros(len(p)), np.sin(half), np.cos(half)], axis=1)
        q[q[:, 3] < 0] *= -1
        xyz = np.column_stack([p[:, :2], np.zeros(len(p))])
        kw.setdefault("cov_kind", "xyyaw")
        return PoseTrack(np.asarray(stamps_s, dtype=float), xyz, q, **kw)  # type: ignore[arg-type]

    @staticmethod
    def empty(source: str = "", cov_kind: CovKind = "se3") -> PoseTrack:
        k = len(COV_AXES[cov_kind])
        return PoseTrack(np.zeros(0), np.zeros((0, 3)), np.zeros((0, 4)), np.zeros((0, k, k)), cov_kind,
                         np.zeros(0, np.uint8), (), source)

    # --- views -----------------------------------------------------------------------------------------

    def __len__(self) -> int:
        return int(self.stamps_s.size)

    def integer_stamps_ns(self) -> np.ndarray:
        """(N,) int64 nanoseconds: :attr:`stamps_ns` when the source gave them, else those of
        :attr:`stamps_s` (gtrig.stamps.ns_from_seconds). Every writer prints these."""
        return self.stamps_ns if self.stamps_ns is not None else ns_from_seconds(self.stamps_s)

    @property
    def planar(self) -> bool:
        return self.cov_kind == "xyyaw"

    def matrices(self) -> np.ndarray:
        """(N, 4, 4) ``T_world_robot``."""
        T = np.tile(np.eye(4), (len(self), 1, 1))
        if len(self):
            T[:, :3, :3] = Rotation.from_quat(self.quat_xyzw).as_matrix()
        T[:, :3, 3] = self.xyz
        return T

    def yaw_rad(self) -> np.ndarray:
        """(N,) heading of the body x axis projected on the world x-y plane, wrapped to (-pi, pi]."""
        return geo.yaw_of_quats(self.quat_xyzw)

    def xytheta(self) -> np.ndarray:
        """(N, 3) planar poses ``x, y, yaw``."""
        return np.column_stack([self.xyz[:, :2], self.yaw_rad()])

    def cov_xytheta(self) -> np.ndarray | None:
        """(N, 3, 3) covariance of ``x, y, yaw`` (the planar marginal of an se3 covariance), or ``None``."""
        if self.cov is None or self.cov_kind == "xyz":
            return None
        if self.cov_kind == "xyyaw":
            return self.cov
        i = np.array(PLANAR_INDEX)
        return self.cov[:, i[:, None], i[None, :]]

    @property
    def ok(self) -> np.ndarray:
        """(N,) bool: the poses to use as ground truth (OK and FLAGGED)."""
        return (self.status == PoseStatus.OK) | (self.status == PoseStatus.FLAGGED)

    def counts(self) -> dict[str, int]:
        """Poses per status name."""
        return {s.name.lower(): int(np.sum(self.status == s)) for s in PoseStatus}

    # --- new tracks from this one (a track is never changed in place) -------------------------------

    def select(self, mask: np.ndarray, stamps_s: np.ndarray | None = None) -> PoseTrack:
        """The poses where ``mask`` (bool (N,) or indices, in the order given) holds; with ``stamps_s``
        (one per pose selected), those poses at new times, which may order them differently from their
        old ones (a pose restamped by its camera's clock offset can pass its neighbour)."""
        idx = np.arange(len(self))[np.asarray(mask)]
        new_stamps = self.stamps_s[idx] if stamps_s is None else np.asarray(stamps_s, dtype=float)
        ns = self.stamps_ns[idx] if self.stamps_ns is not None and stamps_s is None else None
        return replace(self, stamps_s=new_stamps, xyz=self.xyz[idx], quat_xyzw=self.quat_xyzw[idx],
                       cov=None if self.cov is None else self.cov[idx], status=self.status[idx],
                       reasons=tuple(self.reasons[i] for i in idx), stamps_ns=ns)

    def usable(self) -> PoseTrack:
        """Only the poses to use as ground truth (:attr:`ok`)."""
        return self.select(self.ok)

    def with_cov(self, cov: np.ndarray | None, cov_kind: CovKind | None = None) -> PoseTrack:
        return replace(self, cov=cov, cov_kind=cov_kind or self.cov_kind)

    def with_status(self, status: np.ndarray, reasons: tuple[str, ...] | list[str]) -> PoseTrack:
        return replace(self, status=np.asarray(status, np.uint8), reasons=tuple(reasons))

    def shifted(self, dt_s: float) -> PoseTrack:
        """The same poses with ``dt_s`` added to every stamp (a clock offset applied)."""
        ns = None if self.stamps_ns is None else self.stamps_ns + int(round(float(dt_s) * 1e9))
        return replace(self, stamps_s=self.stamps_s + float(dt_s), stamps_ns=ns)

    def span_s(self) -> tuple[float, float]:
        """(first, last) stamp; ``(nan, nan)`` when empty."""
        return (float(self.stamps_s[0]), float(self.stamps_s[-1])) if len(self) else (float("nan"),) * 2
