"""Absolute fixes: what a GT source says about the robot, each at its own stamp with its own covariance.

A fix is ``(stamp, value, covariance, model)``: model ``pose`` sees the planar pose ``(x, y, yaw)`` of the
robot frame (GTvision, GTlaser, a scan matcher); model ``position`` sees the world ``(x, y)`` of a point
fixed on the robot at ``lever_xy`` (robot frame; an RTK-GPS antenna, a total-station prism). Any
:class:`~gtrig.trajectory.PoseTrack` becomes fixes: planar or se3 tracks as poses (the planar marginal of
their covariance), ``xyz`` tracks as positions (their x, y block).
"""

from __future__ import annotations

import enum
from dataclasses import dataclass

import numpy as np

from gtrig.errors import InputError
from gtrig.fusion.kernels import KIND_POSE, KIND_POSITION
from gtrig.trajectory import PoseTrack


class FixModel(enum.Enum):
    POSE = "pose"
    POSITION = "position"


@dataclass(frozen=True)
class Fixes:
    """Fixes of one source.

    Attributes
    ----------
    source : the source's name (reports name outliers by it).
    stamps_s : (M,) strictly increasing stamps, seconds (the source's clock).
    model : what they see (:class:`FixModel`).
    value : (M, 3) ``(x, y, yaw)`` (pose) or ``(x, y, 0)`` (position), metres, radians.
    cov : (M, 3, 3) covariances (position fixes: the x, y block; the third row and column unused).
    lever_xy : (2,) the point seen, in the robot frame (position fixes), metres.
    """

    source: str
    stamps_s: np.ndarray
    model: FixModel
    value: np.ndarray
    cov: np.ndarray
    lever_xy: np.ndarray

    def __len__(self) -> int:
        return int(self.stamps_s.size)

    @property
    def dim(self) -> int:
        return 3 if self.model is FixModel.POSE else 2

    def shifted(self, dt_s: float) -> Fixes:
        """The same fixes with ``dt_s`` added to each stamp (a clock offset applied)."""
        return Fixes(self.source, self.stamps_s + float(dt_s), self.model, self.value, self.cov, self.lever_xy)

    def between(self, t0_s: float, t1_s: float) -> Fixes:
        """The fixes stamped in ``[t0_s, t1_s]`` (seconds, this source's clock)."""
        m = (self.stamps_s >= t0_s) & (self.stamps_s <= t1_s)
        if m.all():
            return self  # frozen: no copy of every fix when all are inside (fusion's usual case)
        return Fixes(self.source, self.stamps_s[m], self.model, self.value[m], self.cov[m], self.lever_xy)

    def kind_code(self) -> int:
        return KIND_POSE if self.model is FixModel.POSE else KIND_POSITION


def fixes_from_track(track: PoseTrack, source: str | None = None, lever_xy: tuple[float, float] | None = None,
                     model: FixModel | None = None) -> Fixes:
    """The usable poses of ``track`` (OK and FLAGGED) as fixes.

    Parameters
    ----------
    track : a GT source's track; it must carry a covariance.
    source : name for reports (default ``track.source``).
    lever_xy : the seen point in the robot frame for position fixes (default the origin).
    model : force a model; by default ``pose`` unless the track is ``cov_kind="xyz"``.

    Raises
    ------
    InputError : no covariance, or a covariance that is not positive definite (named by its stamp).
    """
    name = source or track.source or "source"
    if track.cov is None:
        raise InputError(f"{name}: the track carries no covariance; fusion weighs every fix by its own")
    tr = track.usable()
    if model is None:
        model = FixModel.POSITION if tr.cov_kind == "xyz" else FixModel.POSE
    n = len(tr)
    value = np.zeros((n, 3))
    cov = np.zeros((n, 3, 3))
    if model is FixModel.POSE:
        c = tr.cov_xytheta()
        if c is None:
            raise InputError(f"{name}: a position-only track cannot give pose fixes")
        value[:] = tr.xytheta()
        cov[:] = c
        k = 3
    else:
        assert tr.cov is not None
        value[:, :2] = tr.xyz[:, :2]
        cov[:, :2, :2] = tr.cov[:, :2, :2] if tr.cov_kind in ("xyz", "xyyaw") else tr.cov[:, :2, :2]
        cov[:, 2, 2] = 1.0
        k = 2
    sub = cov[:, :k, :k]
    finite = np.all(np.isfinite(sub), axis=(1, 2))
    ok = finite.copy()
    if n:
        eig = np.full((n, k), -1.0)
        eig[finite] = np.linalg.eigvalsh(0.5 * (sub[finite] + np.swapaxes(sub[finite], 1, 2)))
        ok &= eig.min(axis=1) > 0
    if not np.all(ok):
        i = int(np.argmin(ok))
        raise InputError(f"{name}: the covariance of the pose stamped {tr.stamps_s[i]:.6f} is not positive definite")
    lever = np.zeros(2) if lever_xy is None else np.asarray(lever_xy, float).reshape(2)
    return Fixes(name, tr.stamps_s.copy(), model, value, cov, lever)
