"""The seeds' GTvision, for side-by-side comparison (journal paper, section 5.3; deliverable AD2.3,
"Robot-frame").

One camera at a time; a pose per marker by planar PnP keeping the single best solution (the seeds used
Schweighofer and Pinz, "Robust pose estimation from a planar target", PAMI 28(12), 2006; OpenCV has no
implementation, so IPPE's lower-error solution stands in, which is what both return when the two
minima are distinct); the robot poses implied by the markers of one camera are averaged element by
element as 4 x 4 matrices (not a rigid transform, as the seeds did); cameras are never combined
("considered unfair"): when several cameras see the robot, the one seeing the most markers is kept.
Corners come from OpenCV's ArUco detector with ``CORNER_REFINE_SUBPIX``
(:class:`~gtrig.vision.detect.ArucoDetector`).
"""

from __future__ import annotations

from collections import defaultdict

import numpy as np

from gtrig import geometry as geo
from gtrig.vision.init import ippe_view
from gtrig.vision.observations import FrameObservations, VisionModel


def seeds_camera_poses(model: VisionModel, obs: FrameObservations) -> dict[tuple[str, int], np.ndarray]:
    """Per camera image ``(camera, frame)``: the element-wise mean (4, 4) of the per-marker robot poses."""
    per: dict[tuple[str, int], list[np.ndarray]] = defaultdict(list)
    for v in obs.views:
        s = ippe_view(model, v)
        per[(v.camera, v.frame)].append(s.T_world_robot[int(np.argmin(s.rms_px))])
    return {k: np.mean(np.stack(T), axis=0) for k, T in sorted(per.items())}


def seeds_frame_pose(model: VisionModel, obs: FrameObservations) -> np.ndarray | None:
    """The seeds' pose of one instant: the camera image with the most markers (ties: first camera);
    over a static interval with several images of that camera, their element-wise mean. None: no marker.
    """
    if not obs.views:
        return None
    count: dict[str, int] = defaultdict(int)
    for v in obs.views:
        count[v.camera] += 1
    best = max(sorted(count), key=lambda c: count[c])
    poses = [T for (c, _), T in seeds_camera_poses(model, obs).items() if c == best]
    return np.mean(np.stack(poses), axis=0)


def as_rigid(T: np.ndarray) -> np.ndarray:
    """The nearest rigid transform to an averaged matrix (to measure its rotation error)."""
    U, _, Vt = np.linalg.svd(T[:3, :3])
    R = U @ Vt
    if np.linalg.det(R) < 0:
        R = U @ np.diag([1, 1, -1]) @ Vt
    return geo.make_T(R, T[:3, 3])
