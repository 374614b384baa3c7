"""Moved to :mod:`gtrig.geometry.se3avg` (a core module every stage may use); re-exported here for old imports."""

from gtrig.geometry.se3avg import (  # noqa: F401
    PoseMean,
    chordal_mean_rotation,
    elementwise_mean_pose,
    mean_pose,
    mean_rotation,
)
