"""Stage: fusion. One smoothed trajectory, with a covariance per pose, from GT sources and odometry.

API: :func:`fuse` (fixes of any sources, odometry or none), :func:`fuse_tracks` (pose tracks), the fix
model (:class:`Fixes`, :func:`fixes_from_track`: planar poses, or positions of a point on the robot with a
lever arm), :class:`FusionOptions` and :class:`FusionReport`. Estimators: gtrig.fusion.ekf (EKF + RTS) and
gtrig.fusion.batch (robust MAP) over the factors of gtrig.fusion.chain. Clock offsets: gtrig.sync.offset.
"""

from gtrig.fusion.fuse import FusionOptions, FusionReport, Outlier, Segment, fuse, fuse_tracks
from gtrig.fusion.measurements import Fixes, FixModel, fixes_from_track
from gtrig.fusion.process import ConstantVelocityNoise, OdometryNoise

__all__ = ["ConstantVelocityNoise", "Fixes", "FixModel", "FusionOptions", "FusionReport", "OdometryNoise", "Outlier",
           "Segment", "fixes_from_track", "fuse", "fuse_tracks"]
