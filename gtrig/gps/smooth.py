"""RTK-GPS fixes smoothed with odometry, through the fusion stage (gtrig.fusion, its API only).

The kept fixes become position fixes of the antenna at its lever arm on the robot
(:func:`gtrig.fusion.fixes_from_track`), fused with the wheel odometry by the fusion's EKF + RTS and
batch MAP; lost-fix stretches come out BRIDGED with the odometry's grown covariance. The heading is
observable only through motion (a position-only sensor sees yaw as the robot moves with its lever
arm); where its 1-sigma exceeds ``max_yaw_sigma_rad`` an observed pose is FLAGGED "heading not
observable".
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from gtrig.gps.groundtruth import GpsResult
from gtrig.io.odometry import OdometryLog
from gtrig.trajectory import PoseStatus, PoseTrack


def smooth_with_odometry(res: GpsResult, odometry: OdometryLog, lever_arm_m: tuple[float, float, float] = (0, 0, 0),
                         max_yaw_sigma_rad: float = np.radians(5.0), options: object | None = None) -> PoseTrack:
    """The robot's planar track (``cov_kind="xyyaw"``) from the kept fixes and ``odometry``.

    Parameters
    ----------
    res : :func:`~gtrig.gps.groundtruth.gps_ground_truth`'s result; its stamps must be on the
        odometry's clock.
    odometry : wheel odometry.
    lever_arm_m : the antenna in the robot frame (x forward, y left, z up), metres; x, y enter the fusion's
        measurement model (z is dropped: the track is planar).
    options : a :class:`gtrig.fusion.FusionOptions`, or None for its defaults.
    """
    from gtrig.fusion import FusionOptions, fixes_from_track, fuse

    fx = fixes_from_track(res.track, source="gps", lever_xy=(float(lever_arm_m[0]), float(lever_arm_m[1])))
    track, _report = fuse([fx], odometry, options if isinstance(options, FusionOptions) else FusionOptions())
    cov = track.cov_xytheta()
    if cov is None:
        return track
    weak = (np.sqrt(np.maximum(cov[:, 2, 2], 0)) > max_yaw_sigma_rad) & (track.status == PoseStatus.OK)
    status = np.where(weak, PoseStatus.FLAGGED, track.status).astype(np.uint8)
    reasons = tuple("heading not observable (yaw sigma > %.0f deg)" % np.degrees(max_yaw_sigma_rad) if w else r
                    for w, r in zip(weak, track.reasons, strict=True))
    return replace(track, status=status, reasons=reasons, source="gps+odometry", frame_id=res.frame)
