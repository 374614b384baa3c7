"""Marker detection for GTvision: the markers package's detector when available, else OpenCV ArUco.

Both return :class:`~gtrig.vision.observations.MarkerView` lists for one image of one camera. The
ArUco path is also the seeds'-method baseline's corner source ("corners from OpenCV's ArUco subpixel
refinement"): ARToolKitPlus "simple ID" markers are read by ArUco through a custom dictionary
built from :func:`gtrig.markers.families.marker_cells` with ``markerBorderBits`` = the family's border.
"""

from __future__ import annotations

import importlib
import logging
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from typing import Any

import cv2
import numpy as np

from gtrig.errors import InputError
from gtrig.io.imagetone import DeclaredTone as Tone
from gtrig.rig.models import MarkerFamily, Rig
from gtrig.vision.observations import CameraGeometry, MarkerView, views_from_detections

log = logging.getLogger(__name__)

#: Corner sigma assumed for ArUco's subpixel corners, which come without a covariance, px.
ARUCO_SIGMA_PX = 0.5

#: Corner sigma written for a corner of a confirmed marker that lies outside the image (or less than
#: :data:`MEASURED_BORDER_PX` inside it), px: it is not measured but extrapolated from edges the image cuts
#: short, so it carries no weight and the marker's pose rests on its corners inside the image.
UNSEEN_CORNER_SIGMA_PX = 1.0e3

#: A corner is measured when it lies at least this far inside the image (from the outer edge of its border
#: pixels), px.
MEASURED_BORDER_PX = 1.0

#: Measured corners a marker cut by the image's edge needs to be kept.
MIN_MEASURED_CORNERS = 3

#: Version of what this module makes of the markers package's detections (the second start, the corners
#: released outside the image, a window's lens maps cut from the whole image's), part of the detector's
#: version in GTvision's checkpoint key.
VIEWS_VERSION = 3

#: Edge band beyond ``3 sigma`` of the second start (:func:`_second_start`), px, against the markers
#: package's 5 px (``DetectorParams.band_px``, an allowance for a phone's sharpening halo).
RETRY_BAND_PX = 2.0

DetectFn = Callable[[np.ndarray, CameraGeometry, Tone], list[MarkerView]]

#: A box of an image in pixels ``(x0, y0, x1, y1)``: columns ``x0 <= x < x1``, rows ``y0 <= y < y1``.
Box = tuple[int, int, int, int]

#: Detectors kept per GTvision process for image regions (each holds its region's undistortion maps).
_MAX_DETECTORS = 48


def _shifted(views: list[MarkerView], box: Box | None) -> list[MarkerView]:
    """Views found in the crop ``box`` of an image, their corners moved to the image's pixels."""
    if box is None or (box[0] == 0 and box[1] == 0):
        return views
    d = np.array([box[0], box[1]], float)
    return [replace(v, corners_px=v.corners_px + d) for v in views]


@dataclass(frozen=True)
class _ArucoCorner:
    id: int
    corners_px: np.ndarray
    corner_cov: np.ndarray | None = None


def aruco_for_rig(rig: Rig, subpix: bool = True) -> cv2.aruco.ArucoDetector:
    """OpenCV's ArUco detector for the rig's markers (one family, a dictionary of the rig's IDs in sorted
    order; the family's border width), with its default parameters and, with ``subpix``,
    ``CORNER_REFINE_SUBPIX``."""
    from gtrig.markers.families import family_spec, marker_cells

    fams = {m.family for m in rig.robot.markers}
    if len(fams) != 1:
        raise InputError("the ArUco fallback handles one marker family per rig")
    fam = fams.pop()
    spec = family_spec(fam)
    b = spec.border_cells
    bits = [marker_cells(fam, i)[b:-b, b:-b].astype(np.uint8) for i in sorted(m.id for m in rig.robot.markers)]
    dictionary = cv2.aruco.Dictionary(np.zeros((0, 1, 4), np.uint8), spec.data_cells, 0)
    dictionary.bytesList = np.concatenate([cv2.aruco.Dictionary.getByteListFromBits(x) for x in bits], axis=0)
    dictionary.maxCorrectionBits = 1 if fam in (MarkerFamily.ARTOOLKITPLUS_SIMPLE,
                                                MarkerFamily.ARTOOLKITPLUS_SIMPLE_THIN) else 0
    params = cv2.aruco.DetectorParameters()
    params.markerBorderBits = b
    if subpix:
        params.cornerRefinementMethod = cv2.aruco.CORNER_REFINE_SUBPIX
    return cv2.aruco.ArucoDetector(dictionary, params)


class ArucoDetector:
    """OpenCV's ArUco detector with ``CORNER_REFINE_SUBPIX`` for the rig's markers (one family).

    Parameters
    ----------
    rig : the rig (its markers' family and IDs).
    sigma_px : the corner sigma written into each view's covariance.
    """

    name = "opencv-aruco-subpix"
    version = cv2.__version__

    def __init__(self, rig: Rig, sigma_px: float = ARUCO_SIGMA_PX) -> None:
        self.ids = sorted(m.id for m in rig.robot.markers)
        self._detector = aruco_for_rig(rig, subpix=True)
        self.sigma_px = float(sigma_px)

    def __call__(self, image: np.ndarray, camera: CameraGeometry, file_tone: Tone = "linear",
                 box: Box | None = None) -> list[MarkerView]:
        """The markers of ``image`` (inside ``box`` only, if given; corners in ``image``'s pixels)."""
        crop = image if box is None else np.ascontiguousarray(image[box[1]:box[3], box[0]:box[2]])
        corners, ids, _ = self._detector.detectMarkers(crop)  # gradient-based corners: no tone needed
        if ids is None:
            return []
        cov = np.tile(np.eye(2) * self.sigma_px**2, (4, 1, 1))
        dets = [_ArucoCorner(self.ids[int(i)], np.asarray(c, float).reshape(4, 2), cov)
                for c, i in zip(corners, ids.ravel(), strict=True)]
        return _shifted(views_from_detections(camera.name, dets, set(self.ids)), box)


class GtrigDetector:
    """The markers package's detector (``gtrig.markers.detect.MarkerDetector(family, K, dist)``
    and its ``detect(image)``), adapted to :class:`MarkerView` lists."""

    name = "gtrig-markers"

    def __init__(self, rig: Rig, detector_class: type, version: str = "") -> None:
        self.version = version
        fams = {m.family for m in rig.robot.markers}
        if len(fams) != 1:
            raise InputError("GTvision handles one marker family per rig")
        self.family = fams.pop()
        self.ids = {m.id for m in rig.robot.markers}
        self._cls = detector_class
        self._tone = {c.name: c.tone for c in rig.cameras}
        # one detector per camera and tone (its undistortion set up once)
        self._per_camera: dict[tuple[str, str, Box | None], object] = {}
        self._params = getattr(importlib.import_module(detector_class.__module__), "DetectorParams", None)

    def prepare_lens_maps(self, cameras: Sequence[CameraGeometry]) -> None:
        """Compute the lens maps of ``cameras``' whole images in this process now.

        The maps (:class:`gtrig.markers.detect.camera.Undistorter`: the undistorted pixel of every raw pixel,
        about 0.15 s of CPU for 1024 x 768) are kept per camera and process, and every region's detector cuts
        its own from them. Computed once here before a local pool forks, they are inherited by every worker
        instead of computed again by each; the values are the same wherever they are computed."""
        from gtrig.markers.detect.camera import Undistorter

        for cam in cameras:
            dist = np.asarray(cam.dist, float)
            if np.any(dist):  # without distortion the detector needs no maps
                Undistorter(np.array(cam.K, float), dist, (cam.size[1], cam.size[0]))

    def _detector(self, camera: CameraGeometry, file_tone: Tone, box: Box | None, retry: bool = False) -> object:
        """The markers package's detector of ``camera`` for the region ``box`` (None: the whole image), made
        on first use (the most recently used regions' detectors are kept); with ``retry``, the one of the
        second start (its edge band :data:`RETRY_BAND_PX` beyond ``3 sigma``)."""
        tone = self._tone.get(camera.name, "auto")
        tone = file_tone if tone == "auto" else tone
        key = (camera.name + ("/retry" if retry else ""), tone, box)
        det = self._per_camera.get(key)
        if det is None:
            K = np.array(camera.K, float)
            if box is not None:
                from gtrig.markers.detect.camera import declare_crop

                # the window's lens maps cut from the whole image's: a window's own would cost a few detections
                K = declare_crop(K, np.asarray(camera.dist, float), (camera.size[1], camera.size[0]), box)
            kw: dict[str, Any] = {"tone": tone, **({"band_px": RETRY_BAND_PX} if retry else {})}
            args = () if self._params is None else (self._params(**kw),)
            det = self._per_camera[key] = self._cls(self.family, K, camera.dist, *args)
            if box is not None and len(self._per_camera) > _MAX_DETECTORS:
                # the oldest region's detector goes (a whole image's never: it is made once per camera)
                old = next(k for k in self._per_camera if k[2] is not None)
                del self._per_camera[old]
        elif box is not None:
            self._per_camera[key] = self._per_camera.pop(key)  # most recently used last
        return det

    def __call__(self, image: np.ndarray, camera: CameraGeometry, file_tone: Tone = "linear",
                 box: Box | None = None) -> list[MarkerView]:
        """The markers of ``image``, a frame of ``camera``; ``file_tone`` is how its file declares its
        samples (:func:`gtrig.io.imagetone.declared_tone`), used where the rig's camera says ``tone: auto``.
        With ``box`` only that part of the image is searched, by a detector whose camera matrix is shifted
        by the box's corner (``cx - x0``, ``cy - y0``; the distortion is unchanged, which is exact), and
        the corners are returned in ``image``'s pixels."""
        det = self._detector(camera, file_tone, box)
        crop = image if box is None else np.ascontiguousarray(image[box[1]:box[3], box[0]:box[2]])
        dets = det.detect(crop)  # type: ignore[attr-defined]
        if any(not np.isfinite(getattr(d, "blur_px", 0.0)) for d in dets):
            dets = _second_start(self._detector(camera, file_tone, box, retry=True), crop, dets)
        return _shifted(views_from_detections(camera.name, dets, self.ids), box)

    def expected(self, image: np.ndarray, camera: CameraGeometry, file_tone: Tone,
                 predicted: Sequence[tuple[int, np.ndarray]]) -> list[MarkerView]:
        """Markers expected in ``image`` (a frame of ``camera``) where no peer found them: each
        ``(marker_id, corners_px)`` (corners (4, 2) in the whole image's pixels, printed order, e.g. a
        tracker's prediction) refined by the edge model from those corners and kept only when gtrig's cells
        read through the refined corners give that ID (``MarkerDetector.detect_expected``); empty when the
        markers package has no such entry point.

        A marker cut by the image's edge is kept with its corners outside the image released
        (:func:`release_unseen_corners`) when at least :data:`MIN_MEASURED_CORNERS` are inside it."""
        det = self._detector(camera, file_tone, None)
        confirm = getattr(det, "detect_expected", None)
        if confirm is None or not predicted:
            return []
        quads = np.array([c for _, c in predicted], float).reshape(-1, 4, 2)
        ids = np.array([m for m, _ in predicted], np.int64)
        views = views_from_detections(camera.name, confirm(image, quads, ids), self.ids)
        h, w = image.shape[:2]
        return [r for v in views if (r := release_unseen_corners(v, (w, h))) is not None]


def measured_corners(corners_px: np.ndarray, size: tuple[int, int], border_px: float = MEASURED_BORDER_PX
                     ) -> np.ndarray:
    """Which corners (4, 2) (OpenCV pixels: the image spans ``-0.5 .. w - 0.5``) of an image of ``size``
    (w, h) lie at least ``border_px`` inside it: (4,) bool."""
    w, h = size
    c = np.asarray(corners_px, float)
    return ((c[:, 0] >= border_px - 0.5) & (c[:, 0] <= w - 0.5 - border_px)
            & (c[:, 1] >= border_px - 0.5) & (c[:, 1] <= h - 0.5 - border_px))


def release_unseen_corners(view: MarkerView, size: tuple[int, int]) -> MarkerView | None:
    """``view`` with the covariance of each corner that is not measured (:func:`measured_corners`) set to
    :data:`UNSEEN_CORNER_SIGMA_PX` squared, or None when fewer than :data:`MIN_MEASURED_CORNERS` are measured.

    The edge model extrapolates a corner outside the image from two edges the image cuts short; its
    covariance, propagated from those lines' fits, holds their noise but not the model's error (about a
    tenth of a pixel on a whole edge), which the lever arm from the short visible edges to the corner
    multiplies: on the simulated room's run such corners are off by 0.9 px RMS against 0.3 px for the
    corners inside the image, with covariances that show neither. Such a corner is therefore not used; the
    pose rests on the marker's measured corners, whose edges run into the image."""
    seen = measured_corners(view.corners_px, size)
    if seen.all():
        return view
    if int(seen.sum()) < MIN_MEASURED_CORNERS:
        return None
    cov = np.array(view.corner_cov)
    cov[~seen] = np.eye(2) * UNSEEN_CORNER_SIGMA_PX**2
    common = None if view.corner_common is None else np.where(seen[:, None], view.corner_common, 0.0)
    return replace(view, corner_cov=cov, corner_common=common)


def _second_start(det: object, image: np.ndarray, dets: list[Any]) -> list[Any]:
    """``dets`` (the markers package's detections in ``image``) where those whose edges did not fit from
    the peer's corners (kept unrefined, ``blur_px`` NaN) are refined again by ``det`` from their unrefined
    corners: the edge fit's start is then within a fraction of a pixel of the edges, where a peer's
    whole-pixel corners can leave the first pass on a neighbouring edge in a noisy image. A marker whose
    second fit passes and whose cells read as its ID takes the refined corners; the others stay as they
    were.

    ``det`` is the second start's detector, whose edge band ends :data:`RETRY_BAND_PX` beyond ``3 sigma``:
    a first fit that failed says that something other than the marker's edge lies in the default band (a
    neighbour's edge, the surround past a narrow printed margin), and a band that still reaches it fits
    the white level to it and moves the line. On the simulated room's validation stops (seeds 1 and 2, the
    markers refitted from their second start) the corners came 0.02-0.03 px RMS off the truth with the 2 px
    band against 0.10-0.12 px with the default 5 px."""
    confirm = getattr(det, "detect_expected", None)
    redo = [k for k, d in enumerate(dets) if not np.isfinite(getattr(d, "blur_px", 0.0))]
    if confirm is None or not redo:
        return dets
    quads = np.array([dets[k].corners_px for k in redo], float)
    again = {d.id: d for d in confirm(image, quads, np.array([dets[k].id for k in redo], np.int64))}
    out = list(dets)
    for k in redo:
        if dets[k].id in again:
            out[k] = again.pop(dets[k].id)
    return out


def make_detector(rig: Rig, which: str = "auto") -> ArucoDetector | GtrigDetector:
    """The detector to use: ``"gtrig"`` (the markers package), ``"aruco"``, or ``"auto"`` (the markers
    package if it provides ``gtrig.markers.detect.MarkerDetector``, else ArUco, with a warning)."""
    if which in ("auto", "gtrig"):
        try:
            mod = importlib.import_module("gtrig.markers.detect")
            impl = mod.MarkerDetector
        except (ModuleNotFoundError, AttributeError):
            if which == "gtrig":
                raise InputError("the markers package's detector (gtrig.markers.detect) "
                                 "is not available") from None
            log.warning("gtrig.markers.detect is not available: falling back to OpenCV ArUco corners")
            return ArucoDetector(rig)
        return GtrigDetector(rig, impl, f"{getattr(mod, 'DETECTOR_VERSION', '')}/{VIEWS_VERSION}")
    if which == "aruco":
        return ArucoDetector(rig)
    raise InputError(f"unknown detector {which!r}; choose auto, gtrig or aruco")
