"""A rigid body's poses over a recording: one :func:`gtrig.vision.body.estimate_body_pose` per instant, then
the covariances checked against the recording itself and scaled when they are too small.

The check (:func:`gtrig.vision.body_check.split_pose_nees`): at every instant seen by two cameras or more,
the pose from each camera alone against the pose from the others. Their pixels are independent, so the
NEES over 6 dof averages 1 when the covariances are right. On four unsynchronized webcams it averaged 6.6
to 8.1 (the cameras' images of one instant are up to 43 ms apart while the board moves by hand, and the
cameras' poses are known to a few tenths of a millimetre at best): the poses' covariances are multiplied by
that mean (the recording's variance factor) where it is above 1, as GTvision's noise calibration does for
its corners.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace

import numpy as np

from gtrig.trajectory import PoseTrack
from gtrig.vision.body import BodyOptions, BodyPose, BodyView, PointBody, estimate_body_pose
from gtrig.vision.body_check import split_pose_nees
from gtrig.vision.observations import CameraGeometry


@dataclass(frozen=True)
class BodyInstant:
    """The views of one instant: ``stamp_s`` (the median of its images' times) and ``views``."""

    stamp_s: float
    views: tuple[BodyView, ...]


@dataclass(frozen=True)
class BodyTrack:
    """The body's poses over a recording.

    Attributes
    ----------
    body : the tracked body.
    instants : every instant with a view; poses : (aligned) its pose, covariance scaled by ``variance_factor``
    split_nees : the NEES (6 dof) of every camera-split pair, before scaling
    variance_factor : mean split NEES over 6 (1 when it is below 1 or has fewer than ``min_splits`` pairs)
    """

    body: PointBody
    instants: tuple[BodyInstant, ...]
    poses: tuple[BodyPose, ...]
    split_nees: tuple[float, ...]
    variance_factor: float

    def to_pose_track(self) -> PoseTrack:
        """The localized poses, ``T_world_body`` with their (6, 6) covariances (world-frame perturbation)."""
        stamps, T, cov = [], [], []
        for p in self.poses:
            if p.ok and p.T_world_body is not None and p.cov_6x6 is not None:
                stamps.append(p.stamp_s)
                T.append(p.T_world_body)
                cov.append(p.cov_6x6)
        if not stamps:
            return PoseTrack.empty("body", "se3")
        return PoseTrack.from_matrices(np.array(stamps), np.stack(T), cov=np.stack(cov), cov_kind="se3",
                                       source="body", child_frame_id=self.body.name)


def group_instants(views: Sequence[tuple[int, BodyView]]) -> list[BodyInstant]:
    """Views grouped by instant (``(instant index, view)`` pairs: the frames one camera set shares), in
    time order; an instant's stamp is the median of its images' times."""
    by: dict[int, list[BodyView]] = {}
    for k, v in views:
        by.setdefault(int(k), []).append(v)
    out = [BodyInstant(float(np.median([v.stamp_s for v in vs])), tuple(sorted(vs, key=lambda v: v.camera)))
           for _, vs in sorted(by.items())]
    return sorted(out, key=lambda i: i.stamp_s)


def track_body(cameras: Mapping[str, CameraGeometry], body: PointBody, instants: Sequence[BodyInstant],
               options: BodyOptions | None = None, min_splits: int = 5) -> BodyTrack:
    """Every instant's pose, then the covariances scaled by the recording's split NEES (module docstring)."""
    options = options or BodyOptions()
    poses = [estimate_body_pose(cameras, body, i.views, i.stamp_s, options) for i in instants]
    splits: list[float] = []
    for p, i in zip(poses, instants, strict=True):
        if p.ok and len(p.cameras) >= 2:
            splits += split_pose_nees(cameras, body, [v for v in i.views if v.camera in p.cameras], options)
    factor = float(np.mean(splits)) / 6.0 if len(splits) >= min_splits else math.nan
    scale = factor if math.isfinite(factor) and factor > 1.0 else 1.0
    scaled = [replace(p, cov_6x6=p.cov_6x6 * scale) if p.cov_6x6 is not None else p for p in poses]
    return BodyTrack(body, tuple(instants), tuple(scaled), tuple(splits), scale)
