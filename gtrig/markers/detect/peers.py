"""Candidates and IDs from the field's detectors: OpenCV's ArUco detector and AprilTag 3.

Both run without their own corner refinement (gtrig refines every corner, :mod:`.refine`):

- OpenCV 5's ``cv2.aruco.ArucoDetector`` (Garrido-Jurado et al., "Automatic generation and detection of
  highly reliable fiducial markers under occlusion", Pattern Recognition 47, 2014; Romero-Ramirez et
  al., "Speeded up detection of squared fiducial markers", Image and Vision Computing 76, 2018) with its
  default parameters, for every family with an OpenCV dictionary and for ARToolKitPlus' codes as a
  custom dictionary whose ``markerBorderBits`` is the family's border (3 cells for the standard border);
- AprilTag 3 (:mod:`gtrig.markers.apriltag3`) at its default decimation and its default one thread, for
  the AprilTag families it reads. On the real photos it finds tags that OpenCV misses (far, tilted 36h11
  tags of the FRC field) and OpenCV finds some it misses: for 16h5, 25h9 and 36h11 both run and their
  candidates are pooled. Neither OpenCV's rejected candidates (one of PhotonVision's three such tags lies
  among them) nor AprilTag 3 on crops around them finds the others: it runs on the whole image.

A candidate is a quad in raw pixels, corners top-left, top-right, bottom-right, bottom-left as printed,
with the peer's ID; gtrig's cells confirm or refuse it (:mod:`.verify`).
"""

from __future__ import annotations

import functools
import itertools
import threading
from collections.abc import Iterator
from dataclasses import dataclass
from typing import Any, Literal

import cv2
import numpy as np
from numpy.typing import NDArray

from gtrig.markers.detect import _threads
from gtrig.markers.families import AT3_NAMES, family_spec, marker_cells, opencv_dictionary_name
from gtrig.rig.models import MarkerFamily

__all__ = ["PeerCandidate", "PeerParams", "find_peer_candidates", "peer_batches"]

Source = Literal["opencv", "apriltag3"]


@dataclass(frozen=True)
class PeerParams:
    """Which peers run.

    opencv : OpenCV's ArUco detector (families with an OpenCV dictionary or a custom one).
    apriltag3 : AprilTag 3 for the AprilTag families it reads (always for the families OpenCV lacks).
    at3_quad_decimate : AprilTag 3's decimation of the image for its quad search (its default 2; 1 finds
        smaller tags at about 3.5x the time).
    at3_max_hamming : AprilTag 3's detections with more corrected bits than this are not candidates
        (it corrects 2; on the FRC field's 16h5 photos every 2-bit reading off the field's IDs was false).
    opened_pass : OpenCV runs a second time on the image opened by a 3 x 3 grey-level opening, which
        removes thin bright lines across a marker's black border (a viewer's crosshair burnt into the
        frame breaks the border's contour in OpenCV's candidate stage); its markers join the others.
        Off by default (it doubles OpenCV's time): on PhotonVision's 85 frames it adds 19 of the 24
        markers that the peers miss and gtrig's former own candidate stage found, all under the overlay.
    """

    opencv: bool = True
    apriltag3: bool = True
    at3_quad_decimate: float = 2.0
    at3_max_hamming: int = 1
    opened_pass: bool = False


@dataclass(frozen=True)
class PeerCandidate:
    """One marker a peer reports.

    Attributes
    ----------
    quad_px : (4, 2) float
        Raw-image pixels (OpenCV's convention), top-left, top-right, bottom-right, bottom-left as printed.
    id : int
    source : "opencv" or "apriltag3"
    hamming : int
        Bits the peer corrected (AprilTag 3; 0 for OpenCV, which does not say).
    """

    quad_px: NDArray[np.float64]
    id: int
    source: Source
    hamming: int = 0



@functools.cache
def _opencv_dictionary(family: MarkerFamily) -> Any:
    """The OpenCV dictionary of ``family``: predefined, or built from gtrig's codes (ARToolKitPlus)."""
    name = opencv_dictionary_name(family)
    if name is not None:
        return cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, name))
    spec = family_spec(family)
    b = spec.border_cells
    rows = [cv2.aruco.Dictionary.getByteListFromBits(marker_cells(family, i)[b:-b, b:-b].astype(np.uint8))
            for i in range(spec.n_ids)]
    d = cv2.aruco.Dictionary(np.zeros((0, 1, 4), np.uint8), spec.data_cells, 0)
    d.bytesList = np.concatenate(rows, axis=0)
    # OpenCV corrects int(maxCorrectionBits * errorCorrectionRate) bits (rate 0.6): one cell at most here;
    # gtrig's decoder, with its per-ID tolerance, has the last word (:mod:`.verify`)
    d.maxCorrectionBits = max(1, spec.max_correction)
    return d


def _opencv_detector(family: MarkerFamily) -> Any:
    """A new ``cv2.aruco.ArucoDetector`` for ``family`` (default parameters, no corner refinement)."""
    params = cv2.aruco.DetectorParameters()
    params.markerBorderBits = family_spec(family).border_cells
    params.cornerRefinementMethod = cv2.aruco.CORNER_REFINE_NONE
    # a marker whose corner lies within OpenCV's default 3 px of the image's edge is whole and its edges
    # fit (the bands stop at the image): on the simulated room's validation stops the default lost one
    # marker in 33 (3 % of the views, with the stops' accuracy)
    params.minDistanceToBorder = 1
    if opencv_dictionary_name(family) is None:
        # ARToolKitPlus' codes: OpenCV reads each cell from its middle 0.74 by default; a blur of 2 px on a
        # 150 px marker's 12.5 px cells, stored through sRGB, then flips isolated cells and the marker is
        # lost. Their cells are large (6 x 6 data, 3-cell border): the middle 0.4 reads them
        params.perspectiveRemoveIgnoredMarginPerCell = 0.3
    return cv2.aruco.ArucoDetector(_opencv_dictionary(family), params)


_LOCAL = threading.local()


def _opencv_for_thread(family: MarkerFamily) -> Any:
    """One ArUco detector per family and thread (a detector is not meant to be shared between threads)."""
    cache: dict[MarkerFamily, Any] | None = getattr(_LOCAL, "cache", None)
    if cache is None:
        cache = _LOCAL.cache = {}
    det = cache.get(family)
    if det is None:
        det = cache[family] = _opencv_detector(family)
    return det


def uses_opencv(family: MarkerFamily) -> bool:
    """OpenCV reads ``family`` (every family but AprilTag 3's newer ones)."""
    return family_spec(family).edge_model


def uses_apriltag3(family: MarkerFamily) -> bool:
    """AprilTag 3 reads ``family``."""
    return family.value in AT3_NAMES


def opencv_candidates(gray: NDArray[np.uint8], family: MarkerFamily) -> list[PeerCandidate]:
    """OpenCV's markers of ``family`` in ``gray`` (its default threads)."""
    corners, ids, _ = _opencv_for_thread(family).detectMarkers(gray)
    if ids is None:
        return []
    quads = np.asarray(corners, np.float64).reshape(-1, 4, 2)
    return [PeerCandidate(q, int(i), "opencv") for q, i in zip(quads, ids.ravel().tolist(), strict=True)]


def apriltag3_candidates(gray: NDArray[np.uint8], family: MarkerFamily, params: PeerParams) -> list[PeerCandidate]:
    """AprilTag 3's markers of ``family`` in ``gray`` with at most ``params.at3_max_hamming`` corrected bits
    (its default one thread: with more, its clustering races, AprilRobotics/apriltag#387)."""
    from gtrig.markers.apriltag3 import at3_detect

    return [PeerCandidate(c, i, "apriltag3", h)
            for i, h, c in at3_detect(gray, AT3_NAMES[family.value], params.at3_quad_decimate)
            if h <= params.at3_max_hamming]


def find_peer_candidates(gray: NDArray[np.uint8], family: MarkerFamily, params: PeerParams) -> list[PeerCandidate]:
    """Every peer's candidates, pooled (:func:`peer_batches`' batches in turn, in the calling thread)."""
    return [c for batch in peer_batches(gray, family, params) for c in batch]


def peer_batches(gray: NDArray[np.uint8], family: MarkerFamily, params: PeerParams, threads: int = 1
                 ) -> Iterator[list[PeerCandidate]]:
    """The peers' candidates in two batches, as they come: OpenCV's (with its opened pass's), then AprilTag 3's.
    Where two peers report the same ID at the same place (centres closer than a quarter of the side), the
    first (OpenCV's) is kept: the second batch holds AprilTag 3's others only.

    With ``threads`` of 2 or more, AprilTag 3 runs on a helper thread (:class:`._threads.Beside`, on its
    one thread) while OpenCV runs with its own thread setting and the caller works on OpenCV's batch: on the
    real photos AprilTag 3 takes 1-3 times OpenCV's time, which then goes to the second core.
    """
    run_at3 = uses_apriltag3(family) and (params.apriltag3 or not uses_opencv(family))
    at3: _threads.Beside[list[PeerCandidate]] | None = None
    if run_at3 and threads >= 2:
        at3 = _threads.Beside(apriltag3_candidates, gray, family, params)
    held: list[PeerCandidate] = []
    if params.opencv and uses_opencv(family):
        held = opencv_candidates(gray, family)
        if params.opened_pass:
            opened = cv2.morphologyEx(gray, cv2.MORPH_OPEN, np.ones((3, 3), np.uint8))
            held += _others(held, opencv_candidates(np.asarray(opened, np.uint8), family))
        yield held
    if run_at3:
        yield _others(held, at3.result() if at3 is not None else apriltag3_candidates(gray, family, params))


def _others(held: list[PeerCandidate], more: list[PeerCandidate]) -> list[PeerCandidate]:
    """The candidates of ``more`` in turn that neither ``held`` nor an earlier one of them holds: the same ID
    at the same place (:func:`_same_place`)."""
    out: list[PeerCandidate] = []
    for c in more:
        if not any(o.id == c.id and _same_place(o.quad_px, c.quad_px) for o in itertools.chain(held, out)):
            out.append(c)
    return out


def _same_place(a: NDArray[np.float64], b: NDArray[np.float64]) -> bool:
    """Two quads (4, 2) centred within a quarter of the first's mean side."""
    side = float(np.linalg.norm(a - np.roll(a, -1, axis=0), axis=1).mean())
    return float(np.linalg.norm(a.mean(axis=0) - b.mean(axis=0))) < 0.25 * side
