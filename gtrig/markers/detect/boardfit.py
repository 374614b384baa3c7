"""Corner accuracy without truth: the residual of a known planar layout fitted to detected corners.

A printed board is flat and its marker corners are known in the board's plane; detected corners
that fit it to ``r`` px RMS (after a pose, or a homography plus a radial lens term for an uncalibrated
camera, has been fitted) are wrong by at most about ``r`` px each, as long as the layout and the lens
model are right (their errors add to the residual, they never hide a detector's error). The same fit
on two detectors' corners of the same photo therefore ranks their accuracy on real images.

* :func:`pose_fit_rms`: a calibrated camera (OpenCV's model) and a known board in metres, one planar
  pose per image (IPPE, then Levenberg-Marquardt on the reprojection error);
* :func:`grid_fit_rms`: an uncalibrated camera and a regular grid of square tags whose pitch and tag
  size are not known: a homography of the ideal grid, the tag size as a share of the pitch and two
  radial distortion terms about the image centre, fitted by least squares;
* :func:`grid_local_rms`: the same grid, but one homography per block of 2 x 2 adjacent tags (the
  tag size shared): a print that is not flat (or a lens the two radial terms miss) leaves a residual
  in the whole-grid fit that is the layout's, not the corners' error. On the 12 MP phone photo
  ``taggridphoto.jpg`` (233 px tags) the residuals of the whole-grid fit of every detector (gtrig and
  OpenCV's four refinements) are 95-97 % correlated, corner for corner, and the two radial terms
  bend a tag's side by under 0.03 px: the print's shape dominates that fit, and the 2 x 2 blocks
  remove most of it.
"""

from __future__ import annotations

import cv2
import numpy as np
from numpy.typing import NDArray
from scipy.optimize import least_squares, minimize_scalar

__all__ = ["charuco_marker_corners", "grid_fit_rms", "grid_local_rms", "pose_fit_rms"]


def charuco_marker_corners(squares_xy: tuple[int, int], square_m: float, marker_m: float,
                           dictionary: str = "DICT_6X6_250") -> dict[int, NDArray[np.float64]]:
    """Board-plane corners (4, 3) of every marker of an OpenCV ChArUco board, by marker ID, metres.

    The layout is OpenCV's own (``cv2.aruco.CharucoBoard``), corners in the printed order top-left,
    top-right, bottom-right, bottom-left (that of :class:`gtrig.markers.detect.Detection`).
    """
    d = cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, dictionary))
    board = cv2.aruco.CharucoBoard(squares_xy, square_m, marker_m, d)
    return {int(i): np.asarray(p, np.float64).reshape(4, 3)
            for i, p in zip(np.asarray(board.getIds()).ravel(), board.getObjPoints(), strict=True)}


def pose_fit_rms(corners_px: dict[int, NDArray[np.float64]], board_m: dict[int, NDArray[np.float64]],
                 K: NDArray[np.float64], dist: NDArray[np.float64]) -> float:
    """RMS reprojection residual (px, per corner coordinate pair) of one planar pose fitted to the
    detected corners ``corners_px`` (ID -> (4, 2) raw pixels) of the markers of ``board_m``
    (ID -> (4, 3), z = 0) through the camera ``K``, ``dist`` (OpenCV's model). NaN with fewer than
    two markers."""
    ids = sorted(set(corners_px) & set(board_m))
    if len(ids) < 2:
        return float("nan")
    obj = np.concatenate([board_m[i] for i in ids]).astype(np.float64)
    img = np.concatenate([np.asarray(corners_px[i], np.float64).reshape(4, 2) for i in ids])
    ok, rvec, tvec = cv2.solvePnP(obj, img, K, dist, flags=cv2.SOLVEPNP_IPPE)
    if not ok:
        return float("nan")
    rvec, tvec = cv2.solvePnPRefineLM(obj, img, K, dist, rvec, tvec)
    proj, _ = cv2.projectPoints(obj, rvec, tvec, K, dist)
    return float(np.sqrt(np.mean(np.sum((proj.reshape(-1, 2) - img) ** 2, axis=1))))


def grid_fit_rms(corners_px: dict[int, NDArray[np.float64]], grid_rc: dict[int, tuple[int, int]],
                 image_size: tuple[int, int]) -> float:
    """RMS residual (px) of a regular tag grid fitted to detected corners of an uncalibrated photo.

    Parameters
    ----------
    corners_px : ID -> (4, 2) raw pixels, printed order (top-left, top-right, bottom-right, bottom-left).
    grid_rc : ID -> (column, row) of the tag in the grid, in the tag's printed axes (x right, y down).
    image_size : (width, height), for the distortion centre and scaling.

    The tag of grid cell (c, r) has its corners at ``(c + u k, r + v k)`` (u, v in {0, 1} in the
    printed order, ``k`` the tag side over the pitch), mapped by a homography and then distorted
    radially, ``x_d = x (1 + k1 rho^2 + k2 rho^4)`` about the image centre with ``rho`` in units of
    the half diagonal. NaN with fewer than four tags.
    """
    ids = sorted(set(corners_px) & set(grid_rc))
    if len(ids) < 4:
        return float("nan")
    uv = np.array([[0, 0], [1, 0], [1, 1], [0, 1]], np.float64)
    cr = np.array([grid_rc[i] for i in ids], np.float64)
    img = np.concatenate([np.asarray(corners_px[i], np.float64).reshape(4, 2) for i in ids])
    w, h = image_size
    c0 = np.array([(w - 1) / 2.0, (h - 1) / 2.0])
    half = 0.5 * np.hypot(w, h)

    def model(p: NDArray[np.float64]) -> NDArray[np.float64]:
        H = np.append(p[:8], 1.0).reshape(3, 3)
        g = (cr[:, None, :] + p[8] * uv[None]).reshape(-1, 2)
        q = np.column_stack([g, np.ones(len(g))]) @ H.T
        x = q[:, :2] / q[:, 2:]
        r2 = np.sum(((x - c0) / half) ** 2, axis=1, keepdims=True)
        return c0 + (x - c0) * (1.0 + p[9] * r2 + p[10] * r2 * r2)

    # start: the tag size from the detections' mean side over the mean pitch, then a homography of
    # the grid to the observed corners
    k0 = 0.5
    g0 = (cr[:, None, :] + k0 * uv[None]).reshape(-1, 2)
    H0, _ = cv2.findHomography(g0, img, 0)
    if H0 is None:
        return float("nan")
    H0 = H0 / H0[2, 2]
    p0 = np.concatenate([H0.ravel()[:8], [k0, 0.0, 0.0]])
    # the tag size first with the homography (the distortion terms start at 0)
    res = least_squares(lambda p: (model(p) - img).ravel(), p0, method="lm", x_scale="jac", max_nfev=2000)
    r = (model(res.x) - img).reshape(-1, 2)
    return float(np.sqrt(np.mean(np.sum(r * r, axis=1))))


_UV = np.array([[0, 0], [1, 0], [1, 1], [0, 1]], np.float64)


def grid_local_rms(corners_px: dict[int, NDArray[np.float64]], grid_rc: dict[int, tuple[int, int]],
                   block: int = 2) -> float:
    """RMS residual (px) of the tag grid fitted block by block: a homography per ``block`` x ``block``
    group of adjacent tags all detected, the tag size (a share of the pitch, either sign: the grid's
    numbering may run against the tags' printed axes) shared by all blocks.

    Parameters as in :func:`grid_fit_rms`. NaN when no block is complete.
    """
    cols = max((c for c, _ in grid_rc.values()), default=-1) + 1
    rows = max((r for _, r in grid_rc.values()), default=-1) + 1
    at = {grid_rc[i]: i for i in corners_px if i in grid_rc}
    blocks = []
    for c0 in range(cols - block + 1):
        for r0 in range(rows - block + 1):
            found = [at.get((c, r)) for c in range(c0, c0 + block) for r in range(r0, r0 + block)]
            ids = [i for i in found if i is not None]
            if len(ids) == len(found):
                cr = np.array([grid_rc[i] for i in ids], np.float64)
                img = np.concatenate([np.asarray(corners_px[i], np.float64).reshape(4, 2) for i in ids])
                blocks.append((cr, img))
    if not blocks:
        return float("nan")

    def sse(k: float) -> float:
        total = 0.0
        for cr, img in blocks:
            g = (cr[:, None, :] + k * _UV[None]).reshape(-1, 2)
            H, _ = cv2.findHomography(g, img, 0)
            if H is None:
                return np.inf
            total += float(np.sum((cv2.perspectiveTransform(g[None], H)[0] - img) ** 2))
        return total

    best = min((minimize_scalar(sse, bounds=b, method="bounded").x for b in ((0.05, 0.99), (-0.99, -0.05))), key=sse)
    return float(np.sqrt(sse(best) / sum(len(img) for _, img in blocks)))
