"""Step 2: both planar-PnP solutions of every marker view (IPPE).

A square seen from one viewpoint has two poses that fit its corners almost equally well when it is seen
nearly face-on or small (the plane mirrored about the line of sight, the "flip"). IPPE (Collins and
Bartoli, "Infinitesimal plane-based pose estimation", IJCV 109, 2014) returns both; which one is right is
decided later by consistency between views (:mod:`.pairs`), never by the reprojection error alone.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from gtrig import geometry as geo
from gtrig.markers.robotcal.observe import Array, View, marker_object_points


@dataclass(frozen=True)
class ViewPoses:
    """The two IPPE solutions of one view.

    Attributes
    ----------
    view : the view.
    T_cam_marker : (2, 4, 4) the two candidate poses, lower reprojection error first (the same pose
        twice when IPPE returned one).
    rms : (2,) reprojection RMS of each in normalised units (multiply by the focal length for pixels).
    """

    view: View
    T_cam_marker: Array
    rms: Array


def ippe_both(view: View, side_m: float) -> ViewPoses:
    """Both IPPE solutions of ``view`` for a marker of side ``side_m`` (metres), from its undistorted
    normalised corners (so the lens model enters only once, in :mod:`.observe`)."""
    obj = marker_object_points(side_m)
    n, rvecs, tvecs, errs = cv2.solvePnPGeneric(obj, view.corners_n.reshape(4, 1, 2), np.eye(3), None,
                                               flags=cv2.SOLVEPNP_IPPE_SQUARE)
    Ts = [geo.make_T(cv2.Rodrigues(r)[0], t.ravel()) for r, t in zip(rvecs[:n], tvecs[:n], strict=True)]
    err = np.asarray(errs, float).ravel()[:n] if errs is not None else np.zeros(n)
    if n == 1:
        Ts.append(Ts[0])
        err = np.r_[err, err]
    order = np.argsort(err[:2], kind="stable")
    return ViewPoses(view, np.stack([Ts[i] for i in order]), err[order])
