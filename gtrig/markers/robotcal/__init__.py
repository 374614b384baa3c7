"""Marker-to-robot calibration from hand-held images (docs/markers.md).

The poses ``T_robot_marker`` of the markers on the robot, from images of the standing robot taken with
a calibrated hand-held camera, anchored on one marker whose pose on the robot is measured (marker 14,
the "dima-marker", in the seeds):

1. :mod:`.observe`: detect the markers (:class:`gtrig.markers.detect.MarkerDetector`, corners with
   covariances) and undistort their corners;
2. :mod:`.pnp`: both IPPE solutions of every view;
3. :mod:`.pairs`: relative poses of the pairs seen together, flips resolved by consistency across
   images, averaged on SE(3), outlier images of each pair named;
4. :mod:`.graph`: the pose graph over markers: maximum spanning tree from the anchor (bridges for
   markers never seen together), robust rotation and translation averaging over all edges, rejection
   of inconsistent edges;
5. :mod:`.imageposes` and :mod:`.bundle`: every image's pose, then a robust bundle adjustment of all
   image and marker poses on the corners, outlier views and images rejected and named, covariances
   from the Schur complement.

Entry points: :func:`calibrate_robot_markers` (images and a camera file) and :func:`calibrate_markers`
(a recording and its rig, for the pipeline).
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from pathlib import Path

from gtrig.errors import InputError
from gtrig.io.camfile import CameraIntrinsics, read_cam_yaml
from gtrig.markers.robotcal.calibrate import RobotCalibration, RobotCalOptions, calibrate_from_views
from gtrig.markers.robotcal.markersfile import (
    apply_to_rig,
    marker_errors,
    parse_anchor_pose,
    read_markers_yaml,
    specs_from_rig,
    write_markers_yaml,
)
from gtrig.markers.robotcal.observe import Array, MarkerSpec, detect_views, image_files
from gtrig.rig.models import Rig

__all__ = [
    "MarkerSpec",
    "RobotCalOptions",
    "RobotCalibration",
    "apply_to_rig",
    "calibrate_markers",
    "calibrate_robot_markers",
    "marker_errors",
    "parse_anchor_pose",
    "read_markers_yaml",
    "specs_from_rig",
    "write_markers_yaml",
]

DEFAULT_ANCHOR = 14  # the seeds' "dima-marker"


def calibrate_robot_markers(images: Sequence[str | os.PathLike[str]] | str | os.PathLike[str],
                            camera: CameraIntrinsics, markers: Sequence[MarkerSpec], anchor: int,
                            T_robot_anchor: Array, anchor_cov: Array | None = None,
                            options: RobotCalOptions | None = None) -> RobotCalibration:
    """Calibrate the markers' poses on the robot from hand-held images.

    Parameters
    ----------
    images : a folder of images or a list of image files (any format OpenCV reads), all of the same
        standing robot from the camera ``camera``.
    camera : the hand-held camera's intrinsics (``cam.yaml``).
    markers : the markers to calibrate (family, ID, side); detections of other IDs are ignored.
    anchor : the ID of the marker whose pose on the robot is measured.
    T_robot_anchor : (4, 4) its measured pose ``T_robot_marker`` (metres).
    anchor_cov : optional (6, 6) covariance of that measurement over (dt, dphi), robot axes; added to
        every marker's covariance (all markers move with the anchor).
    options : :class:`RobotCalOptions`.

    Returns
    -------
    RobotCalibration
        Poses and covariances of the calibrated markers (the anchor included, as given), and the
        rejected images, views and pairs with their reasons.
    """
    files = image_files(images) if isinstance(images, str | os.PathLike) else [Path(f) for f in images]
    if not files:
        raise InputError("no images given")
    names = [f.name for f in files]
    if len(set(names)) != len(names):
        raise InputError("two images have the same file name; they name the images in the report")
    views, unknown = detect_views(files, camera, markers)
    return calibrate_from_views(views, markers, anchor, T_robot_anchor, camera, len(files), anchor_cov,
                                unknown, options or RobotCalOptions())


def calibrate_markers(recording_dir: str | os.PathLike[str], rig: Rig, anchor: int = DEFAULT_ANCHOR,
                      options: RobotCalOptions | None = None) -> tuple[Rig, RobotCalibration]:
    """Calibrate a recording's markers from its ``handheld/`` set; the anchor's pose is the rig's.

    Returns the rig with the calibrated ``T_robot_marker`` and the calibration (report, covariances).
    """
    rec = Path(recording_dir)
    try:
        T_anchor = rig.marker(anchor).T_robot_marker.matrix()
    except KeyError:
        raise InputError(f"anchor marker {anchor} is not in the rig's robot.markers") from None
    cam = read_cam_yaml(rec / "handheld" / "camera.yaml")
    cal = calibrate_robot_markers(rec / "handheld" / "images", cam, specs_from_rig(rig), anchor, T_anchor,
                                  None, options)
    return apply_to_rig(rig, cal), cal
