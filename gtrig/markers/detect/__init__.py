"""High-accuracy square-marker detector built on the field's detectors.

Pipeline:

1. candidates and IDs (:mod:`.peers`): OpenCV's ArUco detector for every family with an OpenCV
   dictionary and for ARToolKitPlus' codes as custom dictionaries, AprilTag 3 for the AprilTag families
   it reads (pooled with OpenCV's for 16h5, 25h9 and 36h11, on a second thread while OpenCV's candidates
   go through the next steps), both without their own corner refinement;
2. edges (:mod:`.refine`, :mod:`.edges`): a blurred-step model ``a + b Phi(d / sigma)`` fitted by
   Gauss-Newton to all the pixels of a band around each edge, in undistorted coordinates when a camera
   is given; the first pass fits plain steps, the next ones hold the modelled light of the other edges
   and of the marker's own cells fixed (:func:`.edges.marker_context`);
3. corners: intersections of adjacent lines, with 2 x 2 covariances propagated from the line fits;
   fits that lack contrast, misfit the edge, are too blurred or move a corner too far are refused;
4. verification (:mod:`.verify`): the cells solved through the refined corners from the blur model;
   a peer's ID that they contradict is refused (a wrong-ID guard), and the corners are ordered as
   printed (top-left, top-right, bottom-right, bottom-left).

AprilTag 3's newer families (``tagStandard41h12``, ``tagStandard52h13``, ``tagCircle21h7``,
``tagCircle49h12``, ``tagCustom48h12``) have data cells outside their border square, so the edge model does
not apply: their corners and IDs are AprilTag 3's own, with a nominal covariance (:data:`AT3_ONLY_SIGMA_PX`).

Corners are in OpenCV's pixel convention (pixel centres at integer coordinates) of the raw image. With a
camera model, a crop of an image is detected with the camera matrix shifted by the crop's offset
(``cx - x0``, ``cy - y0``): the corners are then the crop's pixels.
"""

from __future__ import annotations

from collections import OrderedDict
from dataclasses import dataclass, field
from typing import Literal

import cv2
import numpy as np
from numpy.typing import NDArray

from gtrig.errors import InputError
from gtrig.markers.detect import _blas, _threads
from gtrig.markers.detect.camera import Undistorter
from gtrig.markers.detect.peers import PeerCandidate, PeerParams, find_peer_candidates, peer_batches
from gtrig.markers.detect.refine import RefineSettings, fit_reason, refine_quads
from gtrig.markers.detect.verify import Verdict, code_book, read_whiteness, read_whiteness_plain, verify_ids
from gtrig.markers.families import FamilySpec, decode_batch, family_spec
from gtrig.rig.models import MarkerFamily

__all__ = ["AT3_ONLY_SIGMA_PX", "DETECTOR_VERSION", "Detection", "DetectorParams", "MarkerDetector", "PeerParams",
           "Rejection", "UNREFINED_SIGMA_PX", "detect_markers"]

#: Raise when a change makes the default detector's output differ: GTvision's detection checkpoints
#: (``gtrig.vision.sequence``) are keyed on it, so that they are not reused across such a change.
DETECTOR_VERSION = 32

#: corner sigma written for AprilTag 3's newer families, whose corners gtrig does not refine, px
AT3_ONLY_SIGMA_PX = 0.5
#: corner sigma written for a peer's corners kept where the edge model could not fit the edges
#: (``DetectorParams.keep_unrefined``), px
UNREFINED_SIGMA_PX = 1.0


@dataclass(frozen=True)
class Detection:
    """One decoded marker.

    Attributes
    ----------
    id : int
    corners_px : (4, 2) float
        Raw-image pixels (OpenCV convention), top-left, top-right, bottom-right, bottom-left as printed.
    corner_cov : (4, 2, 2) float
        Covariance of each corner, px^2.
    hamming : int
        Data cells that disagreed with the code (gtrig's reading; AprilTag 3's corrected bits for its
        newer families).
    blur_px : float
        Mean fitted edge blur sigma, pixels (NaN where the corners are not refined).
    corner_common : (4, 2) float
        The corners' shared move, pixels, for one sigma of the offset that the edges of a marker whose
        white clips share (:func:`.edges.clipped_white_cov`): corners ``i`` and ``j`` covary by
        ``corner_common[i] corner_common[j]^T`` (each corner's own ``corner_cov`` holds its ``i = j`` part).
        Zeros for a marker seen whole.
    """

    id: int
    corners_px: NDArray[np.float64]
    corner_cov: NDArray[np.float64]
    hamming: int = 0
    blur_px: float = float("nan")
    corner_common: NDArray[np.float64] = field(default_factory=lambda: np.zeros((4, 2)))

    def to_json(self) -> dict[str, object]:
        """The ``detections`` entry of ``det.json``."""
        return {
            "id": self.id,
            "corners": [[float(u), float(v)] for u, v in self.corners_px],
            "corner_cov": [[[float(c) for c in row] for row in m] for m in self.corner_cov],
            "hamming": self.hamming,
            "blur_px": float(self.blur_px),
            "corner_common": [[float(u), float(v)] for u, v in self.corner_common],
        }


#: Stages at which a candidate can be dropped (the ``stage`` of a :class:`Rejection`).
Stage = Literal["fit", "decode", "duplicate"]


@dataclass(frozen=True)
class Rejection:
    """Why one peer's candidate did not become a detection (collected by ``MarkerDetector.detect(trace=...)``).

    Attributes
    ----------
    quad_px : (4, 2) float
        The peer's quadrilateral, raw-image pixels.
    stage : Stage
        ``fit`` (the edge fits: contrast, residual, blur, corner displacement), ``decode`` (gtrig's cells
        read through the refined corners contradict the peer's ID: a wrong-ID guard), ``duplicate``
        (another detection holds the place).
    reason : str
        The first test that failed, in words, with the peer and its ID.
    """

    quad_px: NDArray[np.float64]
    stage: Stage
    reason: str


@dataclass(frozen=True)
class DetectorParams(RefineSettings):
    """Detector settings: the edge fits' (:class:`.refine.RefineSettings`, whose fields these are, with a
    wider ``max_rel_rms``) and the peers', verification's and threads'.

    peers : which of the field's detectors give the candidates (:class:`.peers.PeerParams`).
    band_px : half-width of the edge band beyond ``3 sigma`` (pixels; the limits of a small marker's
        border and cells still apply). A real edge is not a Gaussian step out to its tails: a phone's
        sharpening leaves an overshoot 2-4 px beyond the transition, a display's pixels a staircase, and a
        band that ends inside them fits the white level to the halo and moves the line; 5 px beyond
        ``3 sigma`` reaches the plateaus. Its outer (white) half ends where the paper does
        (``white_end``, ``margin_cells``).
    white_end : end each edge's outer band where its white quiet zone ends, measured from the image
        (:func:`.edges.white_extent`): a band reaching past the paper into a darker surround moves the
        line outward, while wide margins keep the whole band.
    margin_cells : the printed white margin around the black square, in cells, when the caller knows it:
        the outer band then also ends ``2 sigma`` before it.
    max_blur_px : edges blurrier than this are refused.
    min_contrast : smallest accepted white - black difference (grey levels).
    max_rel_rms : largest accepted residual RMS / contrast of an edge fit (the peers have read the
        marker: the test only refuses fits that did not follow the edge; the residual also widens the
        corners' covariance).
    max_corner_shift_px, max_corner_shift_side : largest move of a corner from the peer's to the refined
        fit: the larger of this many pixels and this share of the marker's side (AprilTag 3's corners at
        its default decimation can be a few pixels off on large tags).
    keep_unrefined : a peer's marker whose edges the model cannot fit (a display's moire, an edge fused
        with a dark neighbour, a highlight's ramp) is kept with the peer's corners moved by OpenCV's
        ``cornerSubPix`` and a covariance of
        :data:`UNREFINED_SIGMA_PX` when gtrig's cells read through those corners do not contradict its
        ID; ``False`` drops it.
    passes : edge-fit passes; the first fits plain steps, the next ones hold the modelled light of the
        marker's corners and cells fixed (:func:`.edges.marker_context`).
    iterations : Levenberg-Marquardt iterations per pass (at most).
    tol : each edge stops iterating once a step moves its line by less than this (pixels).
    min_soft_margin : a peer's ID is refused when the code nearest gtrig's solved cells is another ID's
        and leads the peer's by at least this many chi-square units (:mod:`.verify`); 0: only the hard
        reading can refuse it.
    threads : threads a detection may use; 0 follows OpenCV's setting
        (``cv2.getNumThreads()``). OpenCV's detector runs with its own setting and AprilTag 3 on its one
        thread (:func:`.peers.apriltag3_candidates`), with 2 or more beside OpenCV's detection and the edge
        fits of OpenCV's candidates (:func:`.peers.peer_batches`); the edge fits of fewer than
        :data:`._threads.MIN_SPLIT_QUADS` quads stay in the calling thread.
    tone : how the camera stores light (:mod:`.tone`): ``"linear"`` (machine-vision cameras, the
        simulator) or ``"srgb"`` (phones, webcams, most JPEG photos); the edge fits take the stored levels
        back to light, where the blurred-step model holds.
    max_columns : pixel columns across each edge that the edge fits take at most: a longer edge takes every
        k-th column (:func:`.edges.band_stride`; a quad with a clipped edge takes them all); 0 takes them all
        (the default 28, :class:`.edges.RefineParams`; the trade-off between time and corner RMS in
        docs/markers.md).
    """

    max_rel_rms: float = 0.5
    peers: PeerParams = field(default_factory=PeerParams)
    keep_unrefined: bool = True
    min_soft_margin: float = 18.0
    threads: int = 0

    def refine_settings(self) -> RefineSettings:
        """The edge fits' part of these settings (these settings themselves: a :class:`.refine.RefineSettings`)."""
        return self


_UNDISTORTERS: OrderedDict[tuple[bytes, bytes, tuple[int, int]], Undistorter] = OrderedDict()


def _undistorter(K: NDArray[np.float64], dist: NDArray[np.float64], shape: tuple[int, int]) -> Undistorter:
    """The :class:`.camera.Undistorter` of a camera and image size, the last 16 kept (crops of one size at
    one offset reuse theirs)."""
    key = (K.tobytes(), dist.tobytes(), shape)
    und = _UNDISTORTERS.get(key)
    if und is None:
        und = _UNDISTORTERS[key] = Undistorter(K, dist, shape)
        while len(_UNDISTORTERS) > 16:
            _UNDISTORTERS.popitem(last=False)
    else:
        _UNDISTORTERS.move_to_end(key)
    return und


class MarkerDetector:
    """Detector for one family (and optionally one camera).

    Parameters
    ----------
    family : MarkerFamily or str
    camera_matrix, dist_coeffs : optional camera model (OpenCV); with them edges are fitted in
        undistorted coordinates, corners still reported in raw pixels.
    params : DetectorParams
    """

    def __init__(
        self,
        family: MarkerFamily | str,
        camera_matrix: NDArray[np.float64] | None = None,
        dist_coeffs: NDArray[np.float64] | None = None,
        params: DetectorParams | None = None,
    ) -> None:
        self.spec: FamilySpec = family_spec(family)
        self.params = params or DetectorParams()
        self.K = None if camera_matrix is None else np.asarray(camera_matrix, float)
        self.dist = np.zeros(5) if dist_coeffs is None else np.asarray(dist_coeffs, float)

    def _undistorter(self, shape: tuple[int, int]) -> Undistorter | None:
        if self.K is None or not np.any(self.dist):
            return None
        return _undistorter(self.K, self.dist, shape)

    def detect(self, image: NDArray[np.generic], trace: list[Rejection] | None = None) -> list[Detection]:
        """Detect and decode markers in a grey (H, W) or colour (H, W, 3 | 4) image of any depth
        (:func:`to_gray`). Images too small to hold a marker give no detections.

        ``trace``, a list, receives a :class:`Rejection` for every peer candidate dropped on the way (what
        ``gtrig markers detect --debug DIR`` draws).
        """
        gray = to_gray(image)
        if min(gray.shape) < 8:
            return []
        if not self.spec.edge_model:
            return _dedupe([_unrefined(c) for c in find_peer_candidates(gray, self.spec.family, self.params.peers)],
                           trace)
        # each peer's batch is refined as it comes (AprilTag 3's may still run beside OpenCV's); the
        # detections keep the order of one batch of all the candidates: the refined ones, then the peer's
        # corners kept unrefined
        refined: list[Detection] = []
        unrefined: list[Detection] = []
        with _blas.one_thread():
            for cands in peer_batches(gray, self.spec.family, self.params.peers, _threads.threads(self.params.threads)):
                if cands:
                    nt = _threads.fit_threads(self.params.threads, len(cands))
                    r, u = self._refine_and_verify(gray, cands, trace, nt)
                    refined += r
                    unrefined += u
        return _dedupe(refined + unrefined, trace)

    def detect_expected(self, image: NDArray[np.generic], quads_px: NDArray[np.float64],
                        ids: NDArray[np.int64]) -> list[Detection]:
        """Markers expected at known places: each quad refined by the edge model from the given corners (no
        peer involved) and kept only when gtrig's cells, read through the refined corners, read as its
        expected ID.

        For a tracker's prediction (a marker's corners expected from the previous images, where a motion blur
        left the peers without a candidate) or a second start for a marker whose peer corners the edge fit
        did not follow. The fit passes the same tests as a peer's candidate (contrast, residual, blur,
        corner move from the start); the cells must then decode to the expected ID within the family's
        correction at the expected orientation, unambiguously, and no other ID's code may lead by the soft
        margin: a positive reading, stricter than a peer's ID, which only has to be left uncontradicted.

        Parameters
        ----------
        image : (H, W) or (H, W, C) image, as :meth:`detect` takes.
        quads_px : (K, 4, 2) float
            Expected corners, raw-image pixels, in printed order (top-left, top-right, bottom-right,
            bottom-left).
        ids : (K,) int
            The markers' expected IDs.

        Returns
        -------
        list of Detection
            The confirmed markers, corners ordered as printed (at most one per input quad, in input order).
        """
        Q0 = np.asarray(quads_px, np.float64).reshape(-1, 4, 2)
        expected = np.asarray(ids, np.int64).reshape(-1)
        if len(Q0) != len(expected):
            raise InputError(f"detect_expected: {len(Q0)} quads but {len(expected)} IDs")
        spec = self.spec
        if not len(Q0) or not spec.edge_model or np.any((expected < 0) | (expected >= spec.n_ids)):
            return []
        gray = to_gray(image)
        if min(gray.shape) < 8:
            return []
        nt = _threads.fit_threads(self.params.threads, len(Q0))
        with _blas.one_thread():
            return self._confirm_expected(gray, Q0, expected, nt)

    def _confirm_expected(self, gray: NDArray[np.uint8], Q0: NDArray[np.float64], expected: NDArray[np.int64],
                          nt: int) -> list[Detection]:
        """:meth:`detect_expected`'s fit and positive reading of quads ``Q0`` (K, 4, 2) raw px."""
        p, spec = self.params, self.spec
        und = self._undistorter(gray.shape)
        Q = Q0 if und is None else und.to_undistorted(Q0.reshape(-1, 2)).reshape(-1, 4, 2)
        book = code_book(spec.family)
        r = refine_quads(gray, Q, book.cells[expected], spec.border_cells, und, p, nt)
        idx = np.flatnonzero(r.ok)
        if not len(idx):
            return []
        w = read_whiteness(gray, r, idx, spec, p.tone, p.max_blur_px, und)
        v = verify_ids(w, expected[idx], spec, book, p.min_soft_margin)
        read, rot, _ = decode_batch(spec.family, (w > 0.5).astype(np.uint8), spec.max_correction)
        ok = v.ok & (read == expected[idx]) & (rot == 0) & (v.rot == 0)
        cands = [PeerCandidate(Q0[q], int(expected[q]), "opencv") for q in idx]
        keep = np.flatnonzero(ok)
        return self._accepted([cands[k] for k in keep], np.arange(len(keep)), v.take(keep), r.corners[idx[keep]],
                              r.cov[idx[keep]], r.blur[idx[keep]], und, None, r.common[idx[keep]])

    def _refine_and_verify(self, gray: NDArray[np.uint8], cands: list[PeerCandidate],
                           trace: list[Rejection] | None, nt: int) -> tuple[list[Detection], list[Detection]]:
        """The peers' candidates refined (:mod:`.refine`) and their IDs verified (:mod:`.verify`): the
        detections refined, and those kept with the peer's corners (``keep_unrefined``), each in the
        candidates' order."""
        p, spec = self.params, self.spec
        und = self._undistorter(gray.shape)
        Q0 = np.array([c.quad_px for c in cands])  # (Q, 4, 2) raw
        Q = Q0 if und is None else und.to_undistorted(Q0.reshape(-1, 2)).reshape(-1, 4, 2)
        peer_ids = np.array([c.id for c in cands], np.int64)
        book = code_book(spec.family)
        r = refine_quads(gray, Q, book.cells[peer_ids], spec.border_cells, und, p, nt)
        idx = np.flatnonzero(r.ok)
        bad = np.flatnonzero(~r.ok)
        if trace is not None and not p.keep_unrefined:
            for q in bad:
                trace.append(Rejection(Q0[q].copy(), "fit", f"{_who(cands[q])}: {fit_reason(r, int(q), p)}"))
        if not p.keep_unrefined:
            bad = bad[:0]
        if not len(idx) and not len(bad):
            return [], []
        whiteness = [read_whiteness(gray, r, idx, spec, p.tone, p.max_blur_px, und)] if len(idx) else []
        Qb = np.zeros((0, 4, 2))
        if len(bad):
            # the peer's corners moved to the nearest grey-level corner (OpenCV's cornerSubPix), gtrig's
            # cells read through them
            Qb = _corner_subpix(gray, Q0[bad])
            Qb = Qb if und is None else und.to_undistorted(Qb.reshape(-1, 2)).reshape(-1, 4, 2)
            whiteness.append(read_whiteness_plain(gray, Qb, spec, und))
        # both groups' IDs judged in one call (each row on its own: a call's fixed cost is most of a few
        # markers' reading)
        v = verify_ids(np.concatenate(whiteness), peer_ids[np.concatenate([idx, bad])], spec, book, p.min_soft_margin)
        k = len(idx)
        out = (self._accepted(cands, idx, v.take(slice(0, k)), r.corners[idx], r.cov[idx], r.blur[idx], und, trace,
                              r.common[idx]) if k else [])
        if not len(bad):
            return out, []
        cov = np.tile(np.eye(2) * UNREFINED_SIGMA_PX**2, (len(bad), 4, 1, 1))
        return out, self._accepted(cands, bad, v.take(slice(k, None)), Qb, cov, np.full(len(bad), np.nan), und, trace)

    def _accepted(self, cands: list[PeerCandidate], idx: NDArray[np.int64], v: Verdict, corners: NDArray[np.float64],
                  cov: NDArray[np.float64], blur: NDArray[np.float64], und: Undistorter | None,
                  trace: list[Rejection] | None, common: NDArray[np.float64] | None = None) -> list[Detection]:
        """Detections of the candidates ``idx`` whose IDs the verdict ``v`` accepts, corners (K, 4, 2),
        covariances (K, 4, 2, 2) and clipped markers' common moves (K, 4, 2; None: zeros) in fit coordinates
        taken to raw pixels, ordered as printed."""
        common = np.zeros(corners.shape) if common is None else common
        if und is not None:
            Jd = und.jacobian_to_raw(corners.reshape(-1, 2)).reshape(-1, 4, 2, 2)
            cov = Jd @ cov @ np.swapaxes(Jd, -1, -2)
            common = np.einsum("kcij,kcj->kci", Jd, common)
            corners = und.to_raw(corners.reshape(-1, 2)).reshape(-1, 4, 2)
        out = []
        for k, q in enumerate(idx):
            if not v.ok[k]:
                if trace is not None:
                    trace.append(Rejection(cands[q].quad_px.copy(), "decode", f"{_who(cands[q])}: {v.reason[k]}"))
                continue
            order = (np.arange(4) + int(v.rot[k])) % 4
            out.append(Detection(cands[q].id, corners[k][order].copy(), cov[k][order].copy(), int(v.hamming[k]),
                                 float(blur[k]), common[k][order].copy()))
        return out


def _corner_subpix(gray: NDArray[np.uint8], quads: NDArray[np.float64]) -> NDArray[np.float64]:
    """Quads (K, 4, 2) raw px moved by ``cv2.cornerSubPix`` with a window of an eighth of each side (2-5 px)."""
    q = np.array(quads, np.float64)
    side = np.linalg.norm(q - np.roll(q, -1, axis=1), axis=2).min(axis=1)  # (K,)
    win = np.clip(side / 8.0, 2, 5).astype(np.int64)
    crit = (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 30, 0.01)
    moved = np.empty_like(q)
    # cornerSubPix moves each point on its own: one call per window size
    for w in np.unique(win).tolist():
        sel = np.flatnonzero(win == w)
        pts = np.ascontiguousarray(q[sel].reshape(-1, 1, 2), np.float32)
        moved[sel] = cv2.cornerSubPix(gray, pts, (w, w), (-1, -1), crit).reshape(-1, 4, 2)
    # a corner that ran away (to another corner of the scene) keeps the peer's place
    far = np.linalg.norm(moved - q, axis=2) > 0.25 * side[:, None]
    return np.where(far[..., None], q, moved)


def _who(c: PeerCandidate) -> str:
    """A candidate's peer and ID, in words."""
    return f"{'OpenCV' if c.source == 'opencv' else 'AprilTag 3'} ID {c.id}"


def _unrefined(c: PeerCandidate) -> Detection:
    """A peer's detection kept as reported (AprilTag 3's newer families), with a nominal covariance."""
    cov = np.tile(np.eye(2) * AT3_ONLY_SIGMA_PX**2, (4, 1, 1))
    return Detection(c.id, c.quad_px.copy(), cov, c.hamming)


def _dedupe(dets: list[Detection], trace: list[Rejection] | None = None) -> list[Detection]:
    """One detection per place: where two overlap (a centre within a quarter of the other's side), the
    refined one with fewer differing cells is kept (then the larger)."""
    if len(dets) < 2:
        return dets
    q = np.array([d.corners_px for d in dets])  # (D, 4, 2)
    x, y = q[..., 0], q[..., 1]
    area = 0.5 * np.abs(np.sum(x * np.roll(y, -1, axis=1) - np.roll(x, -1, axis=1) * y, axis=1))
    unrefined = np.array([not np.isfinite(d.blur_px) for d in dets])
    order = np.lexsort((-area, np.array([d.hamming for d in dets]), unrefined))
    near = _near(q.mean(axis=1), 0.25 * np.sqrt(area))
    kept = np.zeros(len(dets), bool)
    keep: list[int] = []
    for i in order:
        if (near[i] & kept).any():
            if trace is not None:
                why = f"ID {dets[i].id}: another detection here"
                trace.append(Rejection(dets[i].corners_px.copy(), "duplicate", why))
            continue
        kept[i] = True
        keep.append(int(i))
    return [dets[i] for i in sorted(keep)]


def _near(centre: NDArray[np.float64], reach: NDArray[np.float64], block: int = 512) -> NDArray[np.bool_]:
    """(D, D) bool: centre ``i`` lies within ``reach[j]`` of centre ``j`` (centres (D, 2) px, reach (D,) px),
    the diagonal false; the distances in blocks of rows (memory bounded for thousands of markers)."""
    n = len(centre)
    out = np.zeros((n, n), bool)
    for r0 in range(0, n, block):
        d = np.linalg.norm(centre[r0:r0 + block, None, :] - centre[None, :, :], axis=2)
        out[r0:r0 + block] = d < reach[None, :]
    np.fill_diagonal(out, False)
    return out


def to_gray(image: NDArray[np.generic]) -> NDArray[np.uint8]:
    """Any image OpenCV reads as the detector's 8-bit grey (H, W).

    Accepts (H, W), (H, W, 1), (H, W, 2) (grey + alpha), (H, W, 3) (BGR) and (H, W, 4) (BGRA) arrays
    of any integer, float or bool dtype. 8-bit data is used as is; deeper data (16-bit, float) is
    scaled linearly so that its largest finite value maps to 255, since a 12-bit sensor stored in 16
    bits would otherwise be nearly black; non-finite values become 0.
    """
    img = np.asarray(image)
    if img.ndim == 3 and img.shape[2] in (1, 2):
        img = img[:, :, 0]
    if img.ndim not in (2, 3) or (img.ndim == 3 and img.shape[2] not in (3, 4)):
        raise InputError(f"expected a grayscale or colour image, got shape {img.shape}")
    if img.dtype != np.uint8:
        if img.dtype.kind not in "biuf":
            raise InputError(f"expected an image of numbers, got dtype {img.dtype}")
        f = np.nan_to_num(img.astype(np.float32), nan=0.0, posinf=0.0, neginf=0.0)
        lo = min(float(f.min()), 0.0) if f.size else 0.0
        hi = float(f.max()) if f.size else 1.0
        scale = 255.0 / (hi - lo) if hi > lo else 0.0
        img = np.clip((f - lo) * scale + 0.5, 0, 255).astype(np.uint8)
    if img.ndim == 3:
        return np.asarray(cv2.cvtColor(np.ascontiguousarray(img), cv2.COLOR_BGR2GRAY if img.shape[2] == 3
                                       else cv2.COLOR_BGRA2GRAY), np.uint8)
    return np.ascontiguousarray(img, np.uint8)


def detect_markers(
    image: NDArray[np.uint8],
    family: MarkerFamily | str,
    camera_matrix: NDArray[np.float64] | None = None,
    dist_coeffs: NDArray[np.float64] | None = None,
    params: DetectorParams | None = None,
) -> list[Detection]:
    """Detect markers of ``family`` in ``image``; see :class:`MarkerDetector`."""
    return MarkerDetector(family, camera_matrix, dist_coeffs, params).detect(image)
