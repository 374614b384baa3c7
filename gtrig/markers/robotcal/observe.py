"""Step 1: marker views in the hand-held images, and their corners in normalised camera coordinates.

Every decoded marker of a known ID becomes a :class:`View`: its four corners in raw pixels (OpenCV
convention, top-left, top-right, bottom-right, bottom-left as printed) and their 2 x 2 covariances from
:class:`gtrig.markers.detect.MarkerDetector`. The bundle adjustment works in normalised (undistorted,
``K^-1``) coordinates, where projection is a plain division by depth; the corners are undistorted once
and their covariances carried through the local Jacobian of the distortion.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from dataclasses import dataclass, replace
from pathlib import Path

import cv2
import numpy as np
from numpy.typing import NDArray

from gtrig import geometry as geo
from gtrig.errors import FormatError, InputError
from gtrig.io.camfile import CameraIntrinsics
from gtrig.rig.models import MarkerFamily

Array = NDArray[np.float64]


@dataclass(frozen=True)
class MarkerSpec:
    """A marker to calibrate: its family, ID and black-square side (metres)."""

    id: int
    side_m: float
    family: MarkerFamily = MarkerFamily.ARTOOLKITPLUS_SIMPLE


@dataclass(frozen=True)
class View:
    """One marker seen in one image.

    Attributes
    ----------
    image : the image's file name (no folder), which names it in reports.
    marker_id : the marker's ID.
    corners_px : (4, 2) raw-image pixels, TL, TR, BR, BL as printed.
    corner_cov : (4, 2, 2) covariance of each corner, px^2.
    corners_n : (4, 2) the same corners undistorted, normalised coordinates ``(x / z, y / z)``.
    cov_n : (4, 2, 2) their covariances in normalised coordinates.
    jac_px : (4, 2, 2) Jacobian of the projection ``d uv / d xn`` at each corner (pixels per unit).
    """

    image: str
    marker_id: int
    corners_px: Array
    corner_cov: Array
    corners_n: Array
    cov_n: Array
    jac_px: Array

    def with_sigma_floor(self, sigma_px: float) -> View:
        """This view with ``sigma_px^2 I`` added to every corner's covariance (pixels): the errors the
        detector's covariance does not know of (lens model residuals, print and plate flatness)."""
        if sigma_px <= 0:
            return self
        cov = self.corner_cov + sigma_px**2 * np.eye(2)
        Ji = np.linalg.inv(self.jac_px)
        return replace(self, corner_cov=cov, cov_n=Ji @ cov @ np.swapaxes(Ji, -1, -2))


def marker_object_points(side_m: float) -> Array:
    """The black square's corners (4, 3) in the marker frame (metres): TL, TR, BR, BL as printed, x right,
    y up, z out of the paper. This is also the order ``cv2.SOLVEPNP_IPPE_SQUARE`` requires."""
    a = 0.5 * side_m
    return np.array([[-a, a, 0.0], [a, a, 0.0], [a, -a, 0.0], [-a, -a, 0.0]])


def undistort_normalised(camera: CameraIntrinsics, uv: Array) -> tuple[Array, Array]:
    """Raw pixels ``uv`` (N, 2) to normalised coordinates (N, 2), and the Jacobians (N, 2, 2) of the
    distortion ``d uv / d xn`` at them (to carry covariances: ``cov_n = J^-1 cov_px J^-T``)."""
    uv = np.asarray(uv, float).reshape(-1, 2)
    K, dist = camera.camera_matrix, camera.dist_coeffs
    xn = np.asarray(cv2.undistortPoints(uv.reshape(-1, 1, 2), K, dist).reshape(-1, 2), dtype=np.float64)
    # OpenCV's fixed-point iteration stops short (~0.01 px near the image corners for strong radial
    # distortion); a few Newton steps on the forward model make it exact
    for _ in range(4):
        J = _distortion_jacobian(K, dist, xn)
        r = geo.project_points(np.c_[xn, np.ones(len(xn))], K, dist) - uv
        xn = np.asarray(xn - np.linalg.solve(J, r[:, :, None])[:, :, 0], dtype=np.float64)
    J = _distortion_jacobian(K, dist, xn)
    return xn, J


def _distortion_jacobian(K: Array, dist: Array, xn: Array) -> Array:
    """``d uv / d xn`` (N, 2, 2) of OpenCV's projection at normalised points ``xn`` (central differences)."""
    h = 1e-7
    J = np.empty((len(xn), 2, 2))
    for k in range(2):
        d = np.zeros(2)
        d[k] = h
        plus = geo.project_points(np.c_[xn + d, np.ones(len(xn))], K, dist)
        minus = geo.project_points(np.c_[xn - d, np.ones(len(xn))], K, dist)
        J[:, :, k] = (plus - minus) / (2 * h)
    return J


def image_files(folder: str | os.PathLike[str]) -> list[Path]:
    """The images of ``folder`` (PNG, JPEG, BMP, TIFF, PGM/PPM), sorted by name."""
    p = Path(folder)
    if not p.is_dir():
        raise InputError(f"{p}: no such folder")
    suffixes = (".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff", ".pgm", ".ppm")
    files = sorted(f for f in p.iterdir() if f.suffix.lower() in suffixes)
    if not files:
        raise InputError(f"{p}: no images ({', '.join(suffixes)}) in this folder")
    return files


def detect_views(files: Sequence[str | os.PathLike[str]], camera: CameraIntrinsics,
                 markers: Sequence[MarkerSpec]) -> tuple[list[View], dict[int, int]]:
    """Detect the markers of ``markers`` in every image.

    Returns
    -------
    views : every view of a known marker, in file order.
    unknown : {ID: count} of decoded markers that are not in ``markers`` (ignored; reported).
    """
    from gtrig.io.imagetone import declared_tone
    from gtrig.markers.detect import DetectorParams, MarkerDetector

    by_family: dict[MarkerFamily, set[int]] = {}
    for m in markers:
        by_family.setdefault(MarkerFamily(m.family), set()).add(m.id)
    detectors: dict[tuple[MarkerFamily, str], MarkerDetector] = {}  # per family and tone, made once
    views: list[View] = []
    unknown: dict[int, int] = {}
    w, h = camera.image_size
    for f in files:
        path = Path(f)
        img = cv2.imread(str(path), cv2.IMREAD_GRAYSCALE)
        if img is None:
            raise FormatError(f"{path}: not a readable image")
        if (img.shape[1], img.shape[0]) != (w, h):
            raise InputError(f"{path}: {img.shape[1]} x {img.shape[0]} px but the camera file is for {w} x {h}")
        tone = declared_tone(path)  # hand-held photos: a phone's JPEGs store light through sRGB's curve
        for fam in by_family:
            det = detectors.get((fam, tone))
            if det is None:
                det = detectors[(fam, tone)] = MarkerDetector(fam, camera.camera_matrix, camera.dist_coeffs,
                                                              DetectorParams(tone=tone))
            dets = det.detect(img)
            seen = [d.id for d in dets]
            for d in dets:
                if d.id not in by_family[fam]:
                    unknown[d.id] = unknown.get(d.id, 0) + 1
                    continue
                if seen.count(d.id) > 1:  # decoded twice in one image: a misread or a duplicate print
                    continue
                xn, J = undistort_normalised(camera, d.corners_px)
                Ji = np.linalg.inv(J)
                cov_n = Ji @ d.corner_cov @ np.swapaxes(Ji, -1, -2)
                views.append(View(path.name, d.id, np.asarray(d.corners_px, float),
                                  np.asarray(d.corner_cov, float), xn, cov_n, J))
    return views, unknown
