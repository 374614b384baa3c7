"""Each camera's and each fixed scanner's clock offset, from that sensor's own observations against a
reference trajectory on the other sensors' clock.

A source's offset to odometry (:mod:`gtrig.sync.offset`) is limited by the odometry: its slip is a heading
random walk, so on a 75 s run the interval is a few milliseconds wide. The sensors *of* a GT system are
timed far better against each other, because the reference is then millimetre-accurate. Here:

* the **reference** is a smoothing of other GT fixes with the constant-velocity model (no odometry, so
  the odometry's clock never leaks into it: :func:`reference_track`); its clock is theirs;
* a **scanner** (:func:`scanner_offsets`), against GTvision smoothed: each foreground return, fired at
  ``t`` on the scanner's clock, lies on the robot's hull at the reference pose of ``t - tau_s``; its
  signed distance to the nearest visible side moves by ``-J . v`` per second of ``tau_s`` (``J`` the
  distance's derivative by the pose, ``v`` the reference's velocity). One weighted least-squares fit
  over every scanner's returns: per scanner ``tau_s``, per hull side a bias (the fabric's range bias, the
  hull's size, the reference frame's offset from the hull) and one yaw offset between the reference's
  robot frame and the hull;
* a **camera** (:func:`camera_offsets`), against GTlaser restamped by those scanner offsets
  (:func:`restamp_laser`) and smoothed: each GTvision pose minus the reference at its time minus the
  share-weighted offsets of the cameras that made it (:func:`checkpoint_membership`), linearised in the
  offsets (the reference's velocity), with a constant (x, y, yaw) bias per set of cameras (their
  calibration's error) as nuisance parameters; one fit for all cameras.

Why not the GTlaser track itself: it fits all scanners' points in one pose per frame, so its time is the
point-weighted mean of the scanners' clocks (shares that change with the robot's position), not any one
scanner's.

Intervals: a jackknife over blocks of ``block_s`` (the reference's errors stay correlated for about half
a second, so neither the points nor the instants are independent), Student's t with B - 1 dof.
Verdicts as in :mod:`gtrig.sync.offset`: ``unobservable`` (too few observations, or the robot hardly
moves in the sensor's view: the white-noise interval alone is wider than ``max_ci_s``), ``ambiguous``
(the jackknife interval wider than ``max_ci_s``, or the fit's cost has its minimum elsewhere than the
solution), else ``ok``. The curve of each estimate (``lags_s``, ``corr``) is the fit's ``min cost /
cost`` over trial offsets: 1 at the estimate.
"""

from __future__ import annotations

import os
from collections.abc import Mapping

import numpy as np

from gtrig.errors import InputError
from gtrig.io.odometry import OdometryLog
from gtrig.io.offsets import Z95
from gtrig.sync.cameras import camera_frame_stamps, camera_offsets, checkpoint_membership, restamp_vision
from gtrig.sync.offset import OffsetEstimate
from gtrig.sync.reference import Reference, reference_track
from gtrig.sync.returns import ScannerReturns, WindowedReturns, returns_of_recording
from gtrig.sync.scanners import restamp_laser, scanner_offsets
from gtrig.trajectory import PoseTrack

#: how cameras are timed by default: "pose" (GTvision's whole poses) or "reprojection" (each camera's corners)
CAMERA_METHOD = "pose"


# ------------------------------------------------------------------------------------------ together
def laser_clock(ret: ScannerReturns | WindowedReturns, laser: PoseTrack, scanners: list[OffsetEstimate]
                ) -> tuple[float, float]:
    """GTlaser's clock to GTvision's (s) and its standard error: the mean over GTlaser's usable poses of
    each frame's share-weighted scanner offsets (:func:`restamp_laser`'s shift), the scanners' errors taken
    as independent; ``(nan, nan)`` unless every scanner with returns in those frames has an ``ok`` offset."""
    u = laser.usable()
    if ret.frame_stamps_s.size == 0 or len(u) == 0:
        return float("nan"), float("nan")
    k, hit = ret.frame_of(u.stamps_s)
    if not np.any(hit):
        return float("nan"), float("nan")
    w = ret.frame_shares()[k[hit]].mean(axis=0)  # (S,) each scanner's mean share of GTlaser's poses
    by = {e.source.split("/", 1)[1]: e for e in scanners}
    tau, se = np.zeros(w.size), np.zeros(w.size)
    for i, n in enumerate(ret.names):
        e = by.get(n)
        if w[i] == 0:
            continue
        if e is None or e.verdict != "ok":
            return float("nan"), float("nan")
        tau[i], se[i] = e.offset_s, (e.ci95_s[1] - e.ci95_s[0]) / 2 / Z95
    return float(w @ tau), float(np.sqrt(np.sum((w * se) ** 2)))


def sensor_offsets(rec_dir, rig, vision: PoseTrack, laser: PoseTrack | None = None,  # noqa: ANN001
                   cameras: bool = True, scanners: bool = True, sequence: str = "run",
                   checkpoint: str | os.PathLike[str] | None = None, camera_method: str = CAMERA_METHOD,
                   ) -> list[OffsetEstimate]:
    """Each scanner's and each camera's clock offset to GTvision's clock (the cameras' share-weighted mean).

    Scanners against GTvision smoothed alone (:func:`scanner_offsets`); then GTlaser restamped with the
    scanners' offsets (:func:`restamp_laser`: it is then on GTvision's clock too) is the reference of the
    cameras (:func:`camera_offsets`), which needs ``laser``. ``rig`` holds the calibrated scanners, the hull
    and the cameras. ``checkpoint``: GTvision's checkpoint of detections, which puts each one-camera pose
    at its camera's stamp (:func:`checkpoint_membership`; strongly advised). Add GTvision's own offset to a
    reference (:func:`to_reference`) for offsets to it. ``camera_method``: ``"reprojection"`` (each camera's
    own corners, :mod:`gtrig.sync.reprojection`; needs ``checkpoint``) or ``"pose"`` (GTvision's
    whole poses, :func:`camera_offsets`).
    """
    return sensor_offsets_and_laser_clock(rec_dir, rig, vision, laser, cameras, scanners, sequence, checkpoint,
                                          camera_method)[0]


def sensor_offsets_and_laser_clock(rec_dir, rig, vision: PoseTrack, laser: PoseTrack | None = None,  # noqa: ANN001
                                   cameras: bool = True, scanners: bool = True, sequence: str = "run",
                                   checkpoint: str | os.PathLike[str] | None = None,
                                   camera_method: str = CAMERA_METHOD, odometry: OdometryLog | None = None,
                                   odometry_offset_s: float = float("nan"),
                                   scan_cache: str | os.PathLike[str] | None = None,
                                   ) -> tuple[list[OffsetEstimate], tuple[float, float]]:
    """:func:`sensor_offsets` and GTlaser's clock to GTvision's with its standard error (:func:`laser_clock`;
    nan without ``laser``), seconds. With ``odometry`` and a finite ``odometry_offset_s`` (GTvision's clock
    minus odometry's, ``gtrig sync``), the pose fit's camera offsets are refined in the joint fit of GTvision,
    GTlaser and odometry (:mod:`gtrig.sync.joint_cameras`). ``scan_cache``: the folder of the
    scanner logs' parsed ranges GTlaser kept (:func:`gtrig.io.scans.index_scans`), read instead of the text."""
    from gtrig.errors import ConfigError
    from gtrig.fusion.measurements import fixes_from_track

    out: list[OffsetEstimate] = []
    if not (cameras or scanners):
        return out, (float("nan"), float("nan"))
    if rig.robot.hull is None or not rig.laser_scanners:
        raise ConfigError("rig: per-scanner offsets need the fixed scanners and robot.hull")
    cam_stamps = camera_frame_stamps(rec_dir, rig, sequence)
    timed = vision if checkpoint is None else restamp_vision(vision.usable(), checkpoint, cam_stamps)
    with returns_of_recording(rec_dir, rig, sequence, scan_cache=scan_cache) as ret:  # an hour's: a file
        sc = scanner_offsets(ret, reference_track([fixes_from_track(timed, "vision")]), rig.robot.hull.corners_xy())
    if scanners:
        out += sc
    clock = laser_clock(ret, laser, sc) if laser is not None else (float("nan"), float("nan"))
    if cameras:
        if laser is None:
            raise InputError("per-camera offsets need GTlaser's track (the cameras' reference)")
        ref = camera_reference(laser, ret, sc)
        if camera_method == "reprojection" and checkpoint is not None:
            out += reprojection_offsets(rig, vision, cam_stamps, ref, checkpoint)
        elif camera_method in ("pose", "reprojection"):  # no checkpoint: no corners, the poses only
            cams = camera_offsets(vision, cam_stamps, ref, checkpoint=checkpoint)
            if odometry is not None and np.isfinite(odometry_offset_s) and camera_method == "pose":
                from gtrig.sync.joint_cameras import joint_camera_offsets

                cams = joint_camera_offsets(vision, cam_stamps, restamp_laser(laser.usable(), ret, _ok_offsets(sc)),
                                            odometry, odometry_offset_s, cams, checkpoint=checkpoint)
            out += cams
        else:
            raise ConfigError(f"camera_method {camera_method!r}: 'reprojection' or 'pose'")
    return out, clock


def camera_reference(laser: PoseTrack, ret: ScannerReturns | WindowedReturns, scanners: list[OffsetEstimate]
                     ) -> Reference:
    """The cameras' reference: GTlaser's track restamped by the scanners' ``ok`` offsets (on GTvision's clock,
    :func:`restamp_laser`), smoothed (:func:`reference_track`)."""
    from gtrig.fusion.measurements import fixes_from_track

    return reference_track([fixes_from_track(restamp_laser(laser.usable(), ret, _ok_offsets(scanners)), "laser")])


def _ok_offsets(scanners: list[OffsetEstimate]) -> dict[str, float]:
    """Each scanner's ``ok`` offset by its name (``laser/<name>``)."""
    return {e.source.split("/", 1)[1]: e.offset_s for e in scanners if e.verdict == "ok"}


def reprojection_offsets(rig, vision: PoseTrack, cam_stamps: Mapping[str, np.ndarray], ref: Reference,  # noqa: ANN001
                         checkpoint: str | os.PathLike[str]) -> list[OffsetEstimate]:
    """:func:`gtrig.sync.reprojection.camera_offsets_reprojection` on the checkpoint's corners, relative
    to GTvision's clock (each camera's mean share of GTvision's poses); the pose fit where the checkpoint
    holds no per-camera corners (one of whole instants)."""
    from gtrig.sync.reprojection import camera_offsets_reprojection, read_camera_corners
    from gtrig.vision.observations import VisionModel

    corners = read_camera_corners(checkpoint, VisionModel.from_rig(rig), cam_stamps)
    if not corners:
        return camera_offsets(vision, cam_stamps, ref, checkpoint=checkpoint)
    _, share = checkpoint_membership(vision.usable().stamps_s, checkpoint, cam_stamps)
    names = [c for c in cam_stamps if c in corners]
    mean = dict(zip(list(cam_stamps), share.mean(axis=0), strict=True))
    return camera_offsets_reprojection({c: corners[c] for c in names}, ref, vision, mean)


def to_reference(sensor: OffsetEstimate, vision: OffsetEstimate) -> dict[str, object]:
    """``sensor`` (an offset to GTvision's clock, :func:`sensor_offsets`) as a ``sync.yaml`` entry: that
    offset and interval (``offset_to_vision_s``, ``ci95_to_vision_s``) and, when GTvision's own offset to the
    reference is ``ok``, the sum as ``offset_s`` with the two half-widths added in quadrature (independent
    fits)."""
    d = sensor.to_dict()
    d["offset_to_vision_s"], d["ci95_to_vision_s"] = d.pop("offset_s"), d.pop("ci95_s")
    d["offset_s"] = d["ci95_s"] = None
    if sensor.verdict == "ok" and vision.verdict == "ok":
        h = float(np.hypot(sensor.ci95_s[1] - sensor.ci95_s[0], vision.ci95_s[1] - vision.ci95_s[0])) / 2
        o = sensor.offset_s + vision.offset_s
        d["offset_s"], d["ci95_s"] = float(o), [float(o - h), float(o + h)]
    return d
