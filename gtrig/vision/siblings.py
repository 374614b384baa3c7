"""Markers cut by the image's edge predicted from the robot's other markers in the same image.

The peers (OpenCV, AprilTag 3) give no candidate for a marker whose outline the image's edge cuts, and the
tracker (:mod:`gtrig.vision.track`) predicts only markers it saw in the previous image: a marker cut in every
image of a stop, or cut from the first image of a chunk on, is never looked for. The robot's markers are one
rigid body whose geometry the rig holds (``T_robot_marker``), so the markers found in an image give the
robot's pose relative to that camera (a perspective-n-point fit of all their measured corners), and that pose
places the robot's other markers in the image. Those predicted across the image's edge, facing the camera,
with at least three corners inside the image and a side of some pixels, are returned for
:data:`gtrig.vision.track.ExpectFn` to confirm: the edge model is refined from the predicted corners and the
marker kept only when its cells read its ID. One image alone decides, so the detections of an image do not
depend on the others.
"""

from __future__ import annotations

import cv2
import numpy as np

from gtrig.vision.observations import CameraGeometry, MarkerView, VisionModel
from gtrig.vision.track import CONFIRM_CORNERS, inside_image

#: A corner whose variance is larger than this (px^2 per axis) is not measured (it was released as lying
#: outside the image) and does not enter the robot's pose fit.
MEASURED_VARIANCE_PX2 = 100.0

#: The robot's pose fitted to the markers found is not trusted when their corners' RMS residual exceeds this
#: (a marker read with another's ID, a rig whose markers are not where it says), px.
MAX_FIT_RMS_PX = 2.0


def robot_in_camera(views: list[MarkerView], camera: CameraGeometry, model: VisionModel
                    ) -> np.ndarray | None:
    """``T_cam_robot`` (4, 4) fitted to the measured corners of ``views`` (one camera's image) with the rig's
    marker corners in the robot frame (OpenCV's SQPnP, the global least-squares minimum), or None when the
    fit fails or its RMS residual exceeds :data:`MAX_FIT_RMS_PX`."""
    obj, img = [], []
    for v in views:
        seen = v.corner_cov[:, 0, 0] + v.corner_cov[:, 1, 1] < 2 * MEASURED_VARIANCE_PX2
        obj.append(model.corners_robot[v.marker_id][seen])
        img.append(v.corners_px[seen])
    P, uv = np.concatenate(obj), np.concatenate(img)
    if len(P) < 4:
        return None
    K, dist = np.asarray(camera.K, float), np.asarray(camera.dist, float)
    ok, rvec, tvec = cv2.solvePnP(P, uv, K, dist, flags=cv2.SOLVEPNP_SQPNP)
    if not ok:
        return None
    back, _ = cv2.projectPoints(P, rvec, tvec, K, dist)
    if float(np.sqrt(np.mean(np.sum((back.reshape(-1, 2) - uv) ** 2, axis=1)))) > MAX_FIT_RMS_PX:
        return None
    T = np.eye(4)
    T[:3, :3] = cv2.Rodrigues(rvec)[0]
    T[:3, 3] = tvec.ravel()
    return T


def cut_siblings(views: list[MarkerView], camera: CameraGeometry, model: VisionModel, min_side_px: float = 15.0
                 ) -> list[tuple[int, np.ndarray]]:
    """The robot's markers not in ``views`` (the markers found in one image of ``camera``) predicted across
    the image's edge (module docstring): ``(marker_id, corners_px (4, 2))``, corners in printed order, by
    marker ID."""
    if not views:
        return []
    T_cam_robot = robot_in_camera(views, camera, model)
    if T_cam_robot is None:
        return []
    found = {v.marker_id for v in views}
    K, dist = np.asarray(camera.K, float), np.asarray(camera.dist, float)
    out = []
    for mid in sorted(model.corners_robot):
        if mid in found:
            continue
        T_cam_marker = T_cam_robot @ model.T_robot_marker[mid]
        if T_cam_marker[:3, 2] @ T_cam_marker[:3, 3] >= 0:  # its printed face turned away from the camera
            continue
        p = model.corners_robot[mid] @ T_cam_robot[:3, :3].T + T_cam_robot[:3, 3]
        if np.any(p[:, 2] <= 0.05):
            continue
        uv = cv2.projectPoints(p, np.zeros(3), np.zeros(3), K, dist)[0].reshape(4, 2)
        side = float(np.min(np.linalg.norm(uv - np.roll(uv, 1, axis=0), axis=1)))
        if side < min_side_px or inside_image(uv, camera.size):
            continue  # too small, or whole in the image: the peers' to find
        if inside_image(uv, camera.size, at_least=CONFIRM_CORNERS):
            out.append((mid, uv))
    return out
