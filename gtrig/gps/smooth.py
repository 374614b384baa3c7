"""RTK-GPS fixes smoothed with odometry, through the fusion stage (gtrig.fusion, its API only).

The kept fixes become position fixes of the antenna at its lever arm on the robot
(:func:`gtrig.fusion.fixes_from_track`), fused with the wheel odometry by the fusion's EKF + RTS and
batch MAP; lost-fix stretches come out BRIDGED with the odometry's grown covariance. The heading is
observable only through motion (a position-only sensor sees yaw as the robot moves with its lever
arm); where its 1-sigma exceeds ``max_yaw_sigma_rad`` an observed pose is FLAGGED "heading not
observable".

The fusion is planar; the antenna sits ``lever_arm_m[2]`` above the ground on a robot that rolls and
pitches on real ground (kerbs, camber, braking), so each fix's horizontal covariance gains the mount
term ``(lever_z * tilt_sigma_rad)^2`` (at least 1 cm): the point the fusion sees moves by that much
about the lever arm's nominal place.

RTK errors are not white: multipath and the residual atmosphere keep a fix's error for seconds
(the simulator's Gauss-Markov time constant is 8 s), so the fusion counts one independent fix per
``correlation_s`` (its effective-sample-size weighting, ``FusionOptions.correlation_s``): twice the
error's time constant, the window over which a first-order Gauss-Markov process gives one
independent sample.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from gtrig.gps.groundtruth import GpsResult
from gtrig.io.odometry import OdometryLog
from gtrig.trajectory import PoseStatus, PoseTrack


def smooth_with_odometry(res: GpsResult, odometry: OdometryLog, lever_arm_m: tuple[float, float, float] = (0, 0, 0),
                         max_yaw_sigma_rad: float = np.radians(5.0), tilt_sigma_rad: float = np.radians(2.0),
                         correlation_s: float = 16.0, options: object | None = None) -> PoseTrack:
    """The robot's planar track (``cov_kind="xyyaw"``) from the kept fixes and ``odometry``.

    Parameters
    ----------
    res : :func:`~gtrig.gps.groundtruth.gps_ground_truth`'s result; its stamps must be on the
        odometry's clock.
    odometry : wheel odometry.
    lever_arm_m : the antenna in the robot frame (x forward, y left, z up), metres; x, y enter the fusion's
        measurement model (z is dropped: the track is planar).
    tilt_sigma_rad : 1-sigma roll and pitch of the robot on the ground (the mount term).
    correlation_s : the window over which the fixes' errors count as one (module docstring).
    options : a :class:`gtrig.fusion.FusionOptions` (its ``correlation_s`` replaced), or None.
    """
    from gtrig.fusion import FusionOptions, fixes_from_track, fuse

    mount_m = max(abs(float(lever_arm_m[2])) * tilt_sigma_rad, 0.01)
    cov = res.track.cov + np.diag([mount_m**2, mount_m**2, 0.0])
    lever_xy = (float(lever_arm_m[0]), float(lever_arm_m[1]))
    fx = fixes_from_track(res.track.with_cov(cov), source="gps", lever_xy=lever_xy)
    fo = options if isinstance(options, FusionOptions) else FusionOptions()
    track, _report = fuse([fx], odometry, replace(fo, correlation_s=correlation_s))
    cov = track.cov_xytheta()
    if cov is None:
        return track
    weak = (np.sqrt(np.maximum(cov[:, 2, 2], 0)) > max_yaw_sigma_rad) & (track.status == PoseStatus.OK)
    status = np.where(weak, PoseStatus.FLAGGED, track.status).astype(np.uint8)
    reasons = tuple(f"heading not observable (yaw sigma > {np.degrees(max_yaw_sigma_rad):.0f} deg)" if w else r
                    for w, r in zip(weak, track.reasons, strict=True))
    return replace(track, status=status, reasons=reasons, source="gps+odometry", frame_id=res.frame)
