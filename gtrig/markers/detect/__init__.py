"""High-accuracy square-marker detector.

Pipeline (see issue 5 and the RAWSEEDS vision GT system):

1. candidates (:mod:`.candidates`): closure-normalised image, one threshold, connected components
   with morphological tests (size, solidity, Euler number, hole fraction), a four-vertex convex
   polygon refined into a robust quadrilateral by Huber line fits to the contour;
2. edges (:mod:`.edges`): a blurred-step model ``a + b Phi(d / sigma)`` fitted by Gauss-Newton to all
   the pixels of a band around each edge, in undistorted coordinates when a camera is given. The
   first pass fits plain steps in a band kept inside the black border and away from the ends; the
   next passes add the modelled light of the other edges and of the data cells decoded in the
   candidate stage (:func:`.edges.marker_context`), so the band may reach the corners and the cells
   (this removes a bias of up to 0.35 px on 20 px markers at blur 1 px);
3. corners: intersections of adjacent lines, with 2 x 2 covariances propagated from the line fits;
4. late rejection of implausible fits (contrast, residual, blur, corner displacement);
5. decoding (:mod:`.decode`) of the cells through the refined corners' homography, solved from the
   blur model (:func:`.decode.unblur_cells`), border check, and corners reordered as printed
   (top-left, top-right, bottom-right, bottom-left);
6. a second path for small, blurred markers (:mod:`.blurred`; ``BlurredParams(enabled=False)`` turns it
   off), on what the first one left: blobs of
   a smoothed dark mask, the corners and blur fitted to every pixel of the square with the cells
   free, every code ranked through that geometry by maximum likelihood, the leading codes refitted
   with their own geometry and accepted by a goodness-of-fit test and a chi-square margin.

Corners are in OpenCV's pixel convention (pixel centres at integer coordinates) of the raw image.
"""

from __future__ import annotations

import dataclasses
import functools
import math
from concurrent.futures import Future
from dataclasses import dataclass, field
from typing import Literal

import cv2
import numpy as np
from numpy.typing import NDArray

from gtrig.errors import InputError
from gtrig.markers.detect import _blas, _threads
from gtrig.markers.detect.blurred import BlurredParams, find_blurred_candidates, image_noise, read_blurred
from gtrig.markers.detect.camera import Undistorter
from gtrig.markers.detect.candidates import CandidateParams, find_candidates
from gtrig.markers.detect.decode import flat_samples, sample_cells, soft_code_margin, unblur_cells
from gtrig.markers.detect.edges import CLIP_HIGH, RefineParams, refine_quads
from gtrig.markers.detect.shading import read_shaded
from gtrig.markers.detect.tone import Tone, to_levels, to_light
from gtrig.markers.families import FamilySpec, _codebook, decode_batch, family_spec, marker_cells
from gtrig.rig.models import MarkerFamily

__all__ = ["DETECTOR_VERSION", "Detection", "DetectorParams", "MarkerDetector", "Rejection", "detect_markers"]

#: Raise when a change makes the default detector's output differ: GTvision's detection checkpoints
#: (``gtrig.vision.sequence``) are keyed on it, so that they are not reused across such a change.
DETECTOR_VERSION = 17

#: how far beyond the outer band (blur sigmas) :func:`.edges.white_extent` looks for the paper's end:
#: with the band ending 1.9 sigma before the paper (a 3 sigma + 5 px margin under the 5 px band) the
#: foot of its blurred end still moved the corners 0.02-0.03 px outward (session 33)
WHITE_LOOK_SIGMAS = 3.0


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
        Data cells that disagreed with the code.
    blur_px : float
        Mean fitted edge blur sigma, pixels.
    """

    id: int
    corners_px: NDArray[np.float64]
    corner_cov: NDArray[np.float64]
    hamming: int = 0
    blur_px: float = float("nan")

    def to_json(self) -> dict[str, object]:
        """The ``detections`` entry of ``det.json``."""
        return {
            "id": self.id,
            "corners": [[float(u), float(v)] for u, v in self.corners_px],
            "corner_cov": [[[float(c) for c in row] for row in m] for m in self.corner_cov],
            "hamming": self.hamming,
            "blur_px": float(self.blur_px),
        }


#: Stages at which a candidate can be dropped (the ``stage`` of a :class:`Rejection`).
Stage = Literal["candidate", "predecode", "fit", "decode", "blurred", "duplicate"]


@dataclass(frozen=True)
class Rejection:
    """Why one candidate did not become a detection (collected by ``MarkerDetector.detect(trace=...)``).

    Attributes
    ----------
    quad_px : (4, 2) float
        The candidate's quadrilateral (or the contour's polygon approximation), raw-image pixels.
    stage : Stage
        ``candidate`` (morphological tests of the dark blob), ``predecode`` (cells read through the
        candidate quad far from every code), ``fit`` (the edge fits: contrast, residual, blur, corner
        displacement), ``decode`` (cells read through the refined corners), ``blurred`` (the second path).
    reason : str
        The first test that failed, in words.
    """

    quad_px: NDArray[np.float64]
    stage: Stage
    reason: str


@dataclass(frozen=True)
class DetectorParams:
    """Detector settings.

    candidates : :class:`CandidateParams`.
    band_px : half-width of the edge band beyond ``3 sigma`` (pixels; the limits of a small marker's
        border and cells still apply). A real edge is not a Gaussian step out to its tails: a phone's
        sharpening leaves an overshoot 2-4 px beyond the transition, a display's pixels a staircase,
        and a band that ends inside them fits the white level to the halo and moves the line. With
        5 px beyond ``3 sigma`` the band reaches the plateaus: the grid photo's block residual 0.888 ->
        0.775 px (0.681 with ``tone="srgb"``, SUBPIX 0.733), the ChArUco photos' 0.322-0.508 ->
        0.312-0.495 px, the simulator's RMS at blur 1 px 0.074 -> 0.070 px, for 6 % more CPU
        (1.5 px until session 28; BENCHMARKS.md, issue 16). Its outer (white) half ends where the
        paper does (``white_end``, ``margin_cells``).
    white_end : end each edge's outer band where its white quiet zone ends, measured from the image
        (:func:`.edges.white_extent`): a band reaching past the paper into a darker surround moves the
        line outward (the simulator's 12 mm margins, 4.7 px: +0.08-0.21 px per corner with the 5 px
        band; session 33, BENCHMARKS.md issue 18), while wide margins keep the whole band.
    margin_cells : the printed white margin around the black square, in cells, when the caller knows
        it: the outer band then also ends ``2 sigma`` before it (the measured end still applies).
    max_blur_px : edges blurrier than this are rejected.
    min_contrast : smallest accepted white - black difference (grey levels).
    max_rel_rms : largest accepted residual RMS / contrast of an edge fit.
    max_corner_shift_px : largest move of a corner from the candidate stage to the refined fit.
    max_hamming : decoder tolerance (default: the family's, capped by ``max_random_rate``).
    max_random_rate : without an explicit ``max_hamming`` the decoder corrects at most as many cells as
        leave a random pattern of the data cells this chance of decoding to some code in some rotation
        (:func:`_unconfirmed_max_hamming`). A family with few data cells cannot afford its full
        correction: ArUco 4x4_50's one cell lets 5.2 % of random patterns decode, and text does it,
        letters with a hole ("D", "0", "6") read as IDs 17 and 38 with a cell corrected on renders made
        apart from the project (issue 16, session 42); 5x5_100's three cells let 3.1 % through. At 2 %
        4x4_50 reads exact codes (as OpenCV's default ``errorCorrectionRate`` 0.6 of its one bit does),
        5x5_100 corrects 2 cells, 6x6_250 (0.65 %), AprilTag 36h11 (1.5 %) and the BCH family keep theirs.
    passes : edge-fit passes; the first fits plain steps, the next ones hold the modelled light of the
        marker's corners and data cells fixed (:func:`.edges.marker_context`), which two more passes
        make self-consistent (two passes in all leave 0.06 px RMS where three give 0.04 px).
    iterations : Levenberg-Marquardt iterations per pass (at most).
    tol : each edge stops iterating once a step moves its line by less than this (pixels). 1e-3 px
        instead of 1e-4 px saves a sixth of the iterations and moves the bench's corner RMS by less
        than 0.001 px; capping the warm-started passes at 3 iterations instead costs accuracy
        (0.078 px RMS at blur 1 px against 0.074 px).
    unblur : read the data cells by solving the blur model (:func:`.decode.unblur_cells`) instead of
        thresholding each cell.
    blurred : the second path, for small blurred markers (:class:`.blurred.BlurredParams`; on by
        default, ``BlurredParams(enabled=False)`` turns it off).
    threads : threads one detection may use; 0 follows OpenCV's setting (``cv2.getNumThreads()``,
        which OpenCV's own ArUco detector uses too, and which GTvision's worker processes set to 1).
        With two or more a helper thread runs, beside the first path, the second path's candidate
        stage and its reads, and traces the further thresholds' boxes ahead of the blob tests; the
        edge fits are split between two threads (:mod:`._threads`); the output is the same. OpenCV's own
        pool is held to one thread during a detection (:func:`._threads.opencv_one_thread`): these threads
        share the work instead.
    max_random_decode : a small blurred marker read only through the blur model by the pre-decoder,
        and not by the second path, keeps at most as many corrected cells as give a random pattern
        this chance of decoding (36h11: 4 cells; families that correct one cell: 1).
    min_soft_margin : a reading through the blur model (``unblur``) is kept when its code is the one
        nearest the solved cells in the least-squares sense and leads the runner-up by at least this
        many chi-square units of the cells' residual variance (:func:`.decode.soft_code_margin`); 0: off.
        18 units on 36 cells is a lead of half the best code's residual: true readings on the benches
        (hard set, non-Gaussian blur) lead by 0.8 of it and more (0.79 on a 13 px tag), the wrong
        readings of markers whose cells a blur has lost by 0.10-0.32.
    glare_max_residual : a candidate with resolved cells that the plain reading rejects (white border
        cells, split cells, no code) is read again against black and white levels that vary smoothly
        across it (:mod:`.shading`: glare on a glossy print) and kept when every cell lies within this
        share of the contrast from its colour's level; 0: off.
    tone : how the camera stores light (:mod:`.tone`): ``"linear"`` (machine-vision cameras, the
        simulator) or ``"srgb"`` (phones, webcams, most JPEG photos); the edge fits take the stored
        levels back to light, where the blurred-step model holds.
    """

    candidates: CandidateParams = field(default_factory=CandidateParams)
    band_px: float = 5.0
    white_end: bool = True
    margin_cells: float | None = None
    max_blur_px: float = 5.0
    min_contrast: float = 12.0
    max_rel_rms: float = 0.25
    max_corner_shift_px: float = 4.0
    max_hamming: int | None = None
    max_random_rate: float = 0.02
    passes: int = 3
    iterations: int = 10
    tol: float = 1e-3
    threads: int = 0

    unblur: bool = True
    blurred: BlurredParams = field(default_factory=BlurredParams)
    tone: Tone = "linear"
    max_random_decode: float = 0.005
    min_soft_margin: float = 18.0
    glare_max_residual: float = 0.3


class MarkerDetector:
    """Detector for one family (and optionally one camera; the undistortion maps are cached).

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
        self.spec = family_spec(family)
        self.params = params or DetectorParams()
        self.K = None if camera_matrix is None else np.asarray(camera_matrix, float)
        self.dist = np.zeros(5) if dist_coeffs is None else np.asarray(dist_coeffs, float)
        self._undist: Undistorter | None = None
        self._codes: NDArray[np.uint8] | None = None
        # hole area of a marker <= its data area
        inner = (self.spec.data_cells / self.spec.cells) ** 2
        self._hole_frac = min(0.9, inner + 0.1)
        p = self.params
        self._max_ham = (_unconfirmed_max_hamming(self.spec, p.max_random_rate) if p.max_hamming is None
                         else int(p.max_hamming))

    def _undistorter(self, shape: tuple[int, int]) -> Undistorter | None:
        if self.K is None or not np.any(self.dist):
            return None
        if self._undist is None or self._undist.shape != shape:
            self._undist = Undistorter(self.K, self.dist, shape)
        return self._undist

    def _border_mask(self) -> NDArray[np.bool_]:
        n, bc = self.spec.cells, self.spec.border_cells
        m = np.ones((n, n), bool)
        m[bc:-bc, bc:-bc] = False
        return m

    def _bits(self, v: NDArray[np.float64]) -> tuple[NDArray[np.uint8], NDArray[np.float64]]:
        """Cells (Q, n, n) thresholded midway between the border (black, median) and the ring of
        paper outside (white, median) sampled with them, ``v`` (Q, n + 2, n + 2); and the contrast."""
        ring = np.concatenate([v[:, 0, :], v[:, -1, :], v[:, 1:-1, 0], v[:, 1:-1, -1]], axis=1)
        inner = v[:, 1:-1, 1:-1]
        black = np.median(inner[:, self._border_mask()], axis=1)
        white = np.median(ring, axis=1)
        thr = 0.5 * (black + white)
        return (inner > thr[:, None, None]).astype(np.uint8), white - black

    def _predecode(self, gray: NDArray[np.uint8], Q: NDArray[np.float64], und: Undistorter | None,
                   trace: list[Rejection] | None = None
                   ) -> tuple[NDArray[np.float64], NDArray[np.int64], NDArray[np.int64], NDArray[np.int64],
                              NDArray[np.uint8]]:
        """Keep candidates whose cells, sampled through the initial quad, are close to a code.

        Returns the kept quads, their (id, rotation, hamming) against the initial quad and their cells
        as read (Q, n, n) in the quad's orientation.

        The threshold is midway between the border (black) and the outer ring (white paper); the
        tolerance is two cells more than the final decoder's, so this only removes clutter early.
        """
        n = self.spec.cells
        bc = self.spec.border_cells
        v = sample_cells(gray, Q, n, und, ring=1)
        bits, contrast = self._bits(v)
        bmask = self._border_mask()
        tol = self._max_ham + 2
        ids, rot, ham = decode_batch(self.spec.family, bits[:, bc:-bc, bc:-bc], tol)
        # a border cell under a highlight passes the midway level while it stays dark beside its own paper
        # (:meth:`_locally_white`, as the final decoder judges it)
        border_white = (bits.astype(bool) & self._locally_white(v))[:, bmask].sum(axis=1)
        ok_contrast = contrast >= self.params.min_contrast
        # the blur model only matters where the blur is a good part of a cell (a 1.5 px blur leaves the
        # cells of 5 px and more readable one by one): larger candidates that read as no code are clutter
        cell_px = np.sqrt(np.abs(_shoelace(Q))) / n
        # the border too: on a 20 px marker (2.5 px cells) blurred by 1-1.5 px a border cell between a
        # white data cell and the paper outside peaks at 0.4-0.6 of the contrast, and read one by one
        # up to 9 of the 28 read white (the hard bench, under Bayer demosaicing and JPEG)
        retry = np.flatnonzero(((ids < 0) | (border_white > n // 2)) & ok_contrast & (cell_px < 5.0))
        retried = np.zeros(len(Q), bool)
        if len(retry):
            # small blurred markers: a white cell among black ones peaks below the midway threshold, so
            # the plain reading fails; solve the cells through the blur model instead (as the final
            # decoder does), at the blur of a sharp-to-soft photo, with the levels of border and ring
            inner = v[retry, 1:-1, 1:-1]
            ring = np.concatenate([v[retry, 0, :], v[retry, -1, :], v[retry, 1:-1, 0], v[retry, 1:-1, -1]], axis=1)
            black = np.median(inner[:, bmask], axis=1)
            white = np.median(ring, axis=1)
            done = np.zeros(len(Q), bool)
            for sig in (1.0, 1.5):
                todo = retry[~done[retry]]
                if not len(todo):
                    break
                sel = np.searchsorted(retry, todo)
                # every cell, the border's too, solved through the blur model (the paper outside the
                # square is modelled, so the border cells need no ring)
                w = unblur_cells(gray, Q[todo], n, 0, np.full(len(todo), sig), black[sel], (white - black)[sel], und)
                i2, r2, h2 = decode_batch(self.spec.family, (w[:, bc:-bc, bc:-bc] > 0.5).astype(np.uint8), tol)
                bw2 = (w[:, bmask] > 0.5).sum(axis=1)
                hit = (i2 >= 0) & (bw2 <= n // 2)
                ids[todo[hit]], rot[todo[hit]], ham[todo[hit]] = i2[hit], r2[hit], h2[hit]
                border_white[todo[hit]] = bw2[hit]
                retried[todo[hit]] = True
                done[todo[hit]] = True
                bits[todo[hit]] = (w[hit] > 0.5)
        ok_levels = (border_white <= n // 2) & ok_contrast
        keep = (ids >= 0) & ok_levels
        if trace is not None:
            raw = Q if und is None else und.to_raw(Q.reshape(-1, 2)).reshape(-1, 4, 2)
            for k in np.flatnonzero(~keep):
                why = (f"contrast {contrast[k]:.0f} < {self.params.min_contrast:g}"
                       if contrast[k] < self.params.min_contrast
                       else f"{border_white[k]} white border cells" if border_white[k] > n // 2
                       else f"cells {ham[k]} from the nearest code (> {tol})")
                trace.append(Rejection(raw[k].copy(), "predecode", why))
        self._retried = retried[keep]
        return Q[keep], ids[keep], rot[keep], ham[keep], bits[keep]

    def _locally_white(self, v: NDArray[np.float64]) -> NDArray[np.bool_]:
        """Border cells (Q, n, n; the other cells True) brighter than the ring cell just outside them
        less half the contrast, ``v`` (Q, n + 2, n + 2) as in :meth:`_bits` (a corner cell against both
        of its outer neighbours)."""
        n = self.spec.cells
        ring = np.concatenate([v[:, 0, :], v[:, -1, :], v[:, 1:-1, 0], v[:, 1:-1, -1]], axis=1)
        black = np.median(v[:, 1:-1, 1:-1][:, self._border_mask()], axis=1)
        half = 0.5 * (np.median(ring, axis=1) - black)[:, None]
        out = np.ones((len(v), n, n), bool)
        inner = v[:, 1:-1, 1:-1]
        out[:, 0, :] &= inner[:, 0, :] > v[:, 0, 1:-1] - half
        out[:, -1, :] &= inner[:, -1, :] > v[:, -1, 1:-1] - half
        out[:, :, 0] &= inner[:, :, 0] > v[:, 1:-1, 0] - half
        out[:, :, -1] &= inner[:, :, -1] > v[:, 1:-1, -1] - half
        return out

    def _white_cells(self, ids: NDArray[np.int64], bits: NDArray[np.uint8]) -> NDArray[np.float64]:
        """The code's cells (Q, n, n), 1 = white, turned to the quads' orientation: of the four
        rotations of the printed pattern, the one closest to the cells as read."""
        out = np.empty(bits.shape, np.float64)
        for k, (mid, b) in enumerate(zip(ids, bits, strict=True)):
            cells = marker_cells(self.spec.family, int(mid))
            rots = [np.rot90(cells, r) for r in range(4)]
            out[k] = rots[int(np.argmin([np.count_nonzero(r != b) for r in rots]))]
        return out

    def detect(self, image: NDArray[np.generic], trace: list[Rejection] | None = None) -> list[Detection]:
        """Detect and decode markers in a grey (H, W) or colour (H, W, 3 | 4) image of any depth
        (:func:`_to_gray`). Images too small to hold a marker give no detections.

        ``trace``, a list, receives a :class:`Rejection` for every candidate dropped on the way (what
        ``gtrig markers detect --debug DIR`` draws). BLAS and OpenCV run in the calling threads meanwhile
        (:func:`._blas.one_thread`, :func:`._threads.opencv_one_thread`): the detection's own threads
        (``DetectorParams.threads``, by default OpenCV's setting as it was on the call) share the work.
        """
        nt = _threads.threads(self.params.threads)
        with _blas.one_thread(), _threads.opencv_one_thread():
            return self._detect(image, trace, nt)

    def _detect(self, image: NDArray[np.generic], trace: list[Rejection] | None, nt: int) -> list[Detection]:
        """:meth:`detect` with ``nt`` threads."""
        gray = _to_gray(image)
        if min(gray.shape) < max(8, int(self.params.candidates.min_side_px)):
            return []
        self._provisional: set[int] = set()
        self._misfits: list[NDArray[np.float64]] = []
        if not self.params.blurred.enabled:
            # without the second path the first path keeps to the markers it reads plainly (those read
            # only through the blur model are the second path's regime, where its corners are better)
            return _dedupe([d for d in self._detect_sharp(gray, trace, threads=nt) if id(d) not in self._provisional])
        if nt < 2:
            cands = self._blurred_candidates(gray)
            dets = self._detect_sharp(gray, trace)
            return self._merge_paths(gray, dets, cands, trace)
        # the second path beside the first: in a helper thread its candidate stage (OpenCV's filters
        # and contours, which release the GIL), then, once the first path's candidates are known, the
        # reading of those of its candidates that none of them covers, then, once the pre-decoder has
        # kept its candidates, of those that no detection can cover; the others wait for the first
        # path's detections (read ahead, most would be read in vain: half of them lie in markers the
        # first path finds, and on the bench those cost twice the others' CPU)
        ahead: Future[tuple[tuple[list[NDArray[np.float64]], float], _threads.Claims]] = Future()
        first: Future[list[NDArray[np.float64]]] = Future()
        kept: Future[list[NDArray[np.float64]] | None] = Future()
        jobs = [_threads.helper_pool().submit(self._blurred_ahead, gray, ahead, first, kept)]
        try:
            dets = self._detect_sharp(gray, trace, first, kept, nt)
            cands, reads = ahead.result()
            try:
                return self._merge_paths(gray, dets, cands, trace, reads, jobs)
            finally:
                reads.skip(range(len(cands[0])))
        finally:
            for fut in (first, kept):
                if not fut.done():
                    fut.set_result([] if fut is first else None)
            for job in jobs:
                job.result()  # no read left running into the next image (at most the one in progress)

    def _merge_paths(self, gray: NDArray[np.uint8], dets: list[Detection],
                     cands: tuple[list[NDArray[np.float64]], float], trace: list[Rejection] | None,
                     reads: _threads.Claims | None = None, jobs: list[Future[None]] | None = None
                     ) -> list[Detection]:
        """The first path's detections ``dets`` with the second path's on its candidates ``cands``
        (read, if given, from ``reads``: :meth:`_blurred_ahead`; ``jobs`` receives the helper's)."""
        # markers read only through the blur model in the pre-decoder are small and blurred: the second
        # path, whose model is made for them, reads them too, and its reading replaces the first's at
        # that place whatever ID it gives (two IDs at one place cannot both be right: under a defocus
        # disk a 20 px tag's pre-decoder reading came out as another ID, 5 cells corrected)
        prov = [d for d in dets if id(d) in self._provisional]
        sure = [d for d in dets if id(d) not in self._provisional]
        blurred = self._detect_blurred(gray, cands, sure, trace, reads, jobs)
        # one the second path does not read either keeps only as many corrected cells as leave a random
        # pattern little chance to decode (:func:`_unconfirmed_max_hamming`; a clutter glyph, a black
        # square with two white blobs, read as 36h11's ID 572 with 5 cells corrected, session 39)
        keep = [d for d in prov
                if d.hamming <= _unconfirmed_max_hamming(self.spec, self.params.max_random_decode)
                and not any(np.linalg.norm(b.corners_px.mean(axis=0) - d.corners_px.mean(axis=0))
                            < 0.25 * np.sqrt(_area(d.corners_px)) for b in blurred)]
        found = sure + keep + blurred
        return _dedupe(found + self._read_misfits(gray, cands, found))

    def _all_codes(self) -> NDArray[np.uint8]:
        """Every code (C, d, d) of the family in its four rotations, as read in a quad's orientation."""
        if self._codes is None:
            book = _codebook(self.spec.family)
            self._codes = np.concatenate([np.rot90(book, -r, axes=(1, 2)) for r in range(4)])
        return self._codes

    def _blurred_candidates(self, gray: NDArray[np.uint8]) -> tuple[list[NDArray[np.float64]], float]:
        """The second path's candidates (:func:`.blurred.find_blurred_candidates`: each (A, 4, 2), outlines
        of one place) and the image's noise SD (:func:`.blurred.image_noise`)."""
        p = self.params
        quads = find_blurred_candidates(gray, p.blurred, p.candidates.max_side_px(gray.shape), p.candidates.scale)
        return quads, image_noise(gray) if quads else float("nan")

    def _read_tasks(self, gray: NDArray[np.uint8], cands: tuple[list[NDArray[np.float64]], float]
                    ) -> list[tuple[object, ...]]:
        """:func:`.blurred.read_blurred`'s arguments for each candidate of ``cands`` on its own (its
        outlines read in order until one reads)."""
        quads, noise = cands
        return [(gray, q, self._all_codes(), self.spec.cells, self.spec.border_cells, self.params.blurred, noise, True)
                for q in quads]

    def _blurred_ahead(self, gray: NDArray[np.uint8],
                       ahead: Future[tuple[tuple[list[NDArray[np.float64]], float], _threads.Claims]],
                       first: Future[list[NDArray[np.float64]]],
                       kept: Future[list[NDArray[np.float64]] | None]) -> None:
        """The helper thread's part: the second path's candidates (:meth:`_blurred_candidates`), handed
        over in ``ahead`` with their reads (a :class:`._threads.Claims` of :func:`.blurred.read_blurred`
        per candidate), then the reads of those whose centre lies in no quad of ``first`` (the first
        path's candidates, raw pixels, once known), then of those that no detection can cover: whose
        centre lies more than the largest corner shift outside every quad of ``kept`` (the candidates the
        pre-decoder kept, raw pixels; None when not known in raw pixels, as with a lens model)."""
        try:
            cands = self._blurred_candidates(gray)
            reads = _threads.Claims(read_blurred, self._read_tasks(gray, cands))
        except BaseException as exc:
            ahead.set_exception(exc)
            return
        ahead.set_result((cands, reads))
        if not cands[0]:
            return
        centres = [q[0] for q in cands[0]]
        reads.work(_outside(centres, first.result()))
        polys = kept.result()
        if polys is not None:
            # a detection's corners lie within max_corner_shift_px of its kept quad's, so it lies within
            # that distance of the quad's hull: a candidate centred further out is read in any case (on
            # the --quick set, 1.9 per image lie in quads the pre-decoder rejected; read here, they no
            # longer wait for the edge fits)
            reads.work(_outside(centres, polys, self.params.max_corner_shift_px + 1.0))

    def _detect_blurred(self, gray: NDArray[np.uint8], cands: tuple[list[NDArray[np.float64]], float],
                        found: list[Detection], trace: list[Rejection] | None = None,
                        ahead: _threads.Claims | None = None, jobs: list[Future[None]] | None = None
                        ) -> list[Detection]:
        """The second path (:mod:`.blurred`) on its candidates ``cands`` (from
        :meth:`_blurred_candidates`) that no detection of the first path (``found``) covers.
        ``ahead`` holds their reads, made or to make (:meth:`_blurred_ahead`); with it a helper thread
        reads the next candidate while this one reads one (their compiled fits overlapping), its job
        put in ``jobs``.

        It works in raw pixels: over a marker of at most ``max_side_px`` the lens distortion is close
        to a homography.
        """
        # each candidate is one or more outlines of one place (A, 4, 2), its first the one it is known by
        quads_all = [q[0] for q in cands[0]]
        # a candidate whose centre lies inside a detection is that marker (or a part of it)
        todo = _outside(quads_all, [d.corners_px for d in found])
        quads = [quads_all[i] for i in todo]
        if not quads:
            return []
        codes = self._all_codes()
        if ahead is None:
            tasks = self._read_tasks(gray, cands)
            each = (read_blurred(*tasks[i]) for i in todo)
        else:
            ahead.skip(sorted(set(range(len(quads_all))) - set(todo)))
            if jobs is not None and len(todo) > 1:
                jobs.append(_threads.helper_pool().submit(ahead.work, todo))
            each = map(ahead.get, todo)
        reads = [dataclasses.replace(r, index=i) for i, rs in zip(todo, each, strict=True) for r in rs]
        if trace is not None:
            read_at = [r.corners.mean(axis=0) for r in reads]
            for q in quads:
                if not any(np.linalg.norm(c - q.mean(axis=0)) < 0.3 * np.ptp(q[:, 0]) for c in read_at):
                    trace.append(Rejection(q.copy(), "blurred", "no code fits the blurred square well enough"))
        out = []
        for r in reads:
            ids, rot, _ = decode_batch(self.spec.family, codes[r.code][None], 0)
            if ids[0] < 0:
                continue
            order = (np.arange(4) + rot[0]) % 4
            out.append(Detection(int(ids[0]), r.corners[order].copy(), r.corner_cov[order].copy(), 0, r.sigma))
        return out

    def _trace_fit(self, trace: list[Rejection], bad: NDArray[np.bool_], Q: NDArray[np.float64],
                   corners: NDArray[np.float64], fit: object, shift: NDArray[np.float64],
                   und: Undistorter | None) -> None:
        """Record why the edge fits of the candidates ``bad`` (Q,) were rejected."""
        p = self.params
        Qr = Q if und is None else und.to_raw(Q.reshape(-1, 2)).reshape(-1, 4, 2)
        for k in np.flatnonzero(bad):
            why = None
            for e in range(4 * k, 4 * k + 4):
                why = _fit_reason(bool(fit.ok[e]), float(fit.b[e]), float(fit.rms[e] / max(abs(fit.b[e]), 1e-9)),
                                  float(fit.sigma[e]), p)
                if why:
                    break
            if why is None:
                why = (f"corner moved {shift[k]:.1f} px > {p.max_corner_shift_px:g}"
                       if np.isfinite(shift[k]) else "edges do not intersect")
            trace.append(Rejection(Qr[k].copy(), "fit", why))

    def _detect_sharp(self, gray: NDArray[np.uint8], trace: list[Rejection] | None = None,
                      first: Future[list[NDArray[np.float64]]] | None = None,
                      kept: Future[list[NDArray[np.float64]] | None] | None = None, threads: int = 1
                      ) -> list[Detection]:
        """The first path: candidates, edge fits and decoding (module docstring, steps 1-5) with ``threads``
        threads; ``first`` receives the candidates (raw pixels) as soon as they are found, ``kept`` those the
        pre-decoder keeps (raw pixels; None with a lens model, whose undistorted quads are not raw pixels)."""
        p = self.params
        nt = threads
        quads = find_candidates(gray, p.candidates, self._hole_frac, trace, nt)
        if first is not None:
            first.set_result(quads)
        if not quads:
            if kept is not None:
                kept.set_result([])
            return []
        und = self._undistorter(gray.shape)
        Q0 = np.array(quads)  # (Q, 4, 2) raw
        Q = Q0 if und is None else und.to_undistorted(Q0.reshape(-1, 2)).reshape(-1, 4, 2)
        n = self.spec.cells
        Q, pre_id, pre_rot, pre_ham, pre_bits = self._predecode(gray, Q, und, trace)
        if kept is not None:
            kept.set_result(list(Q) if und is None else None)
        retried = self._retried
        if not len(Q):
            return []
        white = self._white_cells(pre_id, pre_bits)
        # the edge fits' passes, bands and corners in compiled code (edges.refine_quads)
        refine = RefineParams(p.passes, p.iterations, p.tol, p.band_px, p.white_end, WHITE_LOOK_SIGMAS, p.margin_cells,
                              p.max_blur_px)
        light = None if p.tone == "linear" else to_light(np.arange(256, dtype=np.float64), p.tone)
        fit, corners, cov = refine_quads(gray, Q, white, self.spec.border_cells, refine, und, light, nt)
        # late rejection
        ok_e = (fit.ok & (fit.b >= p.min_contrast) & (fit.rms <= p.max_rel_rms * np.abs(fit.b))
                & (fit.sigma <= p.max_blur_px) & (fit.sigma >= 0.06))
        ok = ok_e.reshape(-1, 4).all(axis=1)
        shift = np.linalg.norm(corners - Q, axis=2).max(axis=1)
        ok &= np.all(np.isfinite(corners.reshape(len(Q), -1)), axis=1) & (shift <= p.max_corner_shift_px)
        ok &= np.all(np.isfinite(cov.reshape(len(Q), -1)), axis=1)
        if trace is not None:
            self._trace_fit(trace, ~ok, Q, corners, fit, shift, und)
        # candidates whose edges the step model misfits (a highlight's ramp across the edge, which the
        # model's multiplicative shading cannot follow on the black side): the second path reads them
        misfit = np.flatnonzero(~ok & (fit.ok & (fit.rms > p.max_rel_rms * np.abs(fit.b))).reshape(-1, 4).any(axis=1))
        if len(misfit):
            Qm = Q[misfit] if und is None else und.to_raw(Q[misfit].reshape(-1, 2)).reshape(-1, 4, 2)
            self._misfits = list(Qm)
        if not ok.any():
            return []
        idx = np.flatnonzero(ok)
        corners, cov = corners[idx], cov[idx]
        blur = fit.sigma.reshape(-1, 4)[idx].mean(axis=1)
        vals, sub = sample_cells(gray, corners, n, und, ring=1, return_samples=True)
        bits, _ = self._bits(vals)
        sub = sub[:, 1:-1, 1:-1]
        thr = 0.5 * (vals[:, 1:-1, 1:-1].max(axis=(1, 2)) + vals[:, 1:-1, 1:-1].min(axis=(1, 2)))
        thr = thr[:, None, None]
        # cells must be uniform: printed patterns are aligned with the grid, clutter rarely is. A cell is
        # split when at least 3 of its 9 samples lie on the other side of that level from the rest; until
        # version 13 it was so when they lay on the other side from its bit, which is read against another
        # level (border to paper): a glared cell between the two levels counted as split with all its
        # samples alike (the hard bench's 45 px tags 1/45/14/51, 5/45/12/577, 6/45/6/231: 4-5 such cells)
        above = (sub > thr[..., None]).sum(axis=3)
        split = np.minimum(above, sub.shape[3] - above) >= 3
        cell_px = np.sqrt(np.array([_area(c) for c in corners])) / n
        mixed = split.sum(axis=(1, 2))
        bc = self.spec.border_cells
        # a border cell is white when it is so against the midway level and against the paper just
        # outside it too: a highlight on the print (glare) lifts black and white alike, so a border cell
        # under it passes the global midway level while it stays dark next to its own paper
        border_white = (bits.astype(bool) & self._locally_white(vals))[:, self._border_mask()].sum(axis=1)
        data = bits[:, bc:-bc, bc:-bc]
        if p.unblur:
            # cells solved through the blur model: isolated white cells of small markers peak below
            # the midway threshold and would flip when read one by one
            ab = fit.a.reshape(-1, 4)[idx].mean(axis=1), fit.b.reshape(-1, 4)[idx].mean(axis=1)
            # an over-exposed white level lies beyond 255 (edges.py censors clipped pixels): the cells
            # are read against the contrast the image can show
            ab = ab[0], np.minimum(ab[1], CLIP_HIGH + 0.5 - ab[0])
            if p.tone != "linear":
                # the cells are read in the stored levels
                black_lv = to_levels(ab[0], p.tone)
                ab = black_lv, to_levels(ab[0] + ab[1], p.tone) - black_lv
            wls = unblur_cells(gray, corners, n, bc, np.clip(blur, 0.3, p.max_blur_px), ab[0], ab[1], und)
            data = (wls > 0.5).astype(np.uint8)
            blurry = np.flatnonzero(cell_px < np.maximum(4.0, 3.0 * blur))
            if len(blurry):
                # where the blur is a good part of a cell the border cells read one by one flip as the data
                # cells do (a thin border between white cells and the paper peaks near the midway level):
                # they are judged through the blur model too, every cell solved with the paper outside
                w0 = unblur_cells(gray, corners[blurry], n, 0, np.clip(blur[blurry], 0.3, p.max_blur_px),
                                  ab[0][blurry], ab[1][blurry], und)
                border_white[blurry] = (w0[:, self._border_mask()] > 0.5).sum(axis=1)
        ids, rot, ham = decode_batch(self.spec.family, data, self._max_ham)
        good = (ids >= 0) & (border_white <= max(0, n // 4 - 1))
        soft_bad = np.zeros(len(ids), bool)
        if p.unblur and p.min_soft_margin > 0 and good.any():
            # the hard reading must be the code nearest the solved cells, and lead the next code clearly
            # (:func:`.decode.soft_code_margin`): a 20 px tag smeared 6 px by motion read as another ID
            # with 4 cells corrected led by 0.1 of its residual, every true reading of the benches by 0.8
            nearest, lead = soft_code_margin(wls, self._all_codes())
            soft_bad = good & ((nearest != rot * self.spec.n_ids + ids) | (lead < p.min_soft_margin))
            good &= ~soft_bad
        fine = cell_px >= np.maximum(4.0, 3.0 * blur)  # cells resolved: their insides must be uniform
        self._flat_mixed(mixed, sub, thr, (ids >= 0) & fine, ids, bits, corners, blur)
        good &= ~fine | (mixed <= max(1, n * n // 20))
        if p.glare_max_residual > 0:
            self._read_glared(vals, sub, np.flatnonzero(~good & fine & ~soft_bad), ids, rot, ham, good)
        # small, blurred markers: the cells read better through the candidate quad (its corners lie
        # inside the square, away from the blurred border); accept that reading when it is strict
        strict = self._max_ham
        fallback = ~good & (pre_ham[idx] <= strict) & ~fine & ~soft_bad
        ids = np.where(fallback, pre_id[idx], ids)
        rot = np.where(fallback, pre_rot[idx], rot)
        ham = np.where(fallback, pre_ham[idx], ham)
        good |= fallback
        if trace is not None:
            Qr = Q[idx] if und is None else und.to_raw(Q[idx].reshape(-1, 2)).reshape(-1, 4, 2)
            for k in np.flatnonzero(~good):
                why = (f"{border_white[k]} white border cells" if border_white[k] > max(0, n // 4 - 1)
                       else f"the solved cells do not single out code {ids[k]}" if soft_bad[k]
                       else f"{mixed[k]} cells not uniform" if ids[k] >= 0
                       else f"cells {ham[k]} from the nearest code (> {strict})")
                trace.append(Rejection(Qr[k].copy(), "decode", why))
        if und is not None:
            raw = und.to_raw(corners.reshape(-1, 2)).reshape(-1, 4, 2)
            Jd = und.jacobian_to_raw(corners.reshape(-1, 2)).reshape(-1, 4, 2, 2)
            cov = Jd @ cov @ np.swapaxes(Jd, -1, -2)
            corners = raw
        out = []
        for k in np.flatnonzero(good):
            order = (np.arange(4) + rot[k]) % 4
            out.append(Detection(int(ids[k]), corners[k][order].copy(), cov[k][order].copy(), int(ham[k]),
                                 float(blur[k])))
            if retried[idx[k]]:
                self._provisional.add(id(out[-1]))
        return out


    def _read_glared(self, vals: NDArray[np.float64], sub: NDArray[np.float64], cand: NDArray[np.int64],
                     ids: NDArray[np.int64], rot: NDArray[np.int64], ham: NDArray[np.int64],
                     good: NDArray[np.bool_]) -> None:
        """Read the candidates ``cand`` (indices into the arrays, whose cells are resolved and failed the
        plain reading) against smoothly varying black and white levels (:mod:`.shading`: glare on the
        print), and set ``ids``, ``rot``, ``ham`` and ``good`` (:meth:`_detect_sharp`'s working arrays,
        changed in place) where that reading is a code with a black border and uniform cells."""
        if not len(cand):
            return
        p, n, bc = self.params, self.spec.cells, self.spec.border_cells
        r = read_shaded(vals[cand], sub[cand], n, bc)
        i2, r2, h2 = decode_batch(self.spec.family, r.bits[:, bc:-bc, bc:-bc], self._max_ham)
        border_white = r.bits[:, self._border_mask()].sum(axis=1)
        ok = ((i2 >= 0) & (border_white <= max(0, n // 4 - 1)) & (r.mixed <= max(1, n * n // 20))
              & (r.contrast >= p.min_contrast) & (r.rel_residual <= p.glare_max_residual))
        sel = cand[ok]
        ids[sel], rot[sel], ham[sel] = i2[ok], r2[ok], h2[ok]
        good[sel] = True

    def _read_misfits(self, gray: NDArray[np.uint8], cands: tuple[list[NDArray[np.float64]], float],
                      found: list[Detection]) -> list[Detection]:
        """The second path's reading of the first path's candidates rejected for an edge residual
        (:meth:`_detect_sharp`; raw pixels) of its size range, where no detection and none of its own
        candidates ``cands`` lies.

        Under a highlight of a third of the paper's light, 10-16 px across and near the edge of a
        20-30 px marker, the step model's residual reaches 0.25-0.45 of the contrast; the second path,
        whose light field follows such a highlight, reads some of these candidates, but its blob finder
        may miss them in the glare (the hard bench's 4/20/10/226). Their cells have passed the
        pre-decoder: they are few (45 on 360 hard images) and cost about 5 ms each.
        """
        bp = self.params.blurred
        if not bp.first_misfits:
            return []
        quads = [q for q in self._misfits
                 if bp.min_side_px <= np.linalg.norm(q - np.roll(q, -1, axis=0), axis=1).mean() <= bp.max_side_px]
        quads = [quads[i] for i in _outside(quads, [d.corners_px for d in found] + [c[0] for c in cands[0]])]
        if not quads:
            return []
        noise = cands[1] if cands[0] else image_noise(gray)
        codes = self._all_codes()
        out = []
        for q in quads:
            for r in read_blurred(gray, q[None], codes, self.spec.cells, self.spec.border_cells, bp, noise, True):
                ids, rot, _ = decode_batch(self.spec.family, codes[r.code][None], 0)
                if ids[0] >= 0:
                    order = (np.arange(4) + rot[0]) % 4
                    out.append(Detection(int(ids[0]), r.corners[order].copy(), r.corner_cov[order].copy(), 0,
                                         r.sigma))
        return out

    def _flat_mixed(self, mixed: NDArray[np.int64], sub: NDArray[np.float64], thr: NDArray[np.float64],
                    sel: NDArray[np.bool_], ids: NDArray[np.int64], bits: NDArray[np.uint8],
                    corners: NDArray[np.float64], blur: NDArray[np.float64]) -> None:
        """Recount in place the split cells ``mixed`` (Q,) of the candidates ``sel`` (Q,) that fail the
        uniformity test, among the samples the blur leaves flat (:func:`.decode.flat_samples`).

        ``sub`` (Q, n, n, 9) are the cells' samples, ``thr`` (Q, 1, 1) the level that splits them,
        ``ids`` and ``bits`` (Q, n, n) the code read and the cells as read (for its rotation),
        ``corners`` (Q, 4, 2) px and ``blur`` (Q,) px the fit's. Under a highlight (glare 10-16 px
        across, a third of the paper's light) a black cell beside white ones is lifted to about the
        midway level, and its samples 0.25 cell from a white neighbour take another 15-30 % of the
        contrast at a blur of a quarter of a cell: they fall on the other side of the level from its
        centre while the cell is printed uniform (the hard bench's 45 px tags 11/45/7/276,
        13/45/4/451 and 23/45/5/313, blur 1.15-1.4 px, 4-6 such cells). Only the candidates that
        fail are recounted: the test costs nothing where it passes.
        """
        again = np.flatnonzero(sel & (mixed > max(1, self.spec.cells ** 2 // 20)))
        if not len(again):
            return
        flat = flat_samples(self._white_cells(ids[again], bits[again]), corners[again], blur[again])
        above = ((sub[again] > thr[again][..., None]) & flat).sum(axis=3)
        split = np.minimum(above, flat.sum(axis=3) - above) >= 3
        mixed[again] = split.sum(axis=(1, 2))


def _fit_reason(fit_ok: bool, b: float, rel: float, sigma: float, p: DetectorParams) -> str | None:
    """The first failed test of one edge fit (None: the edge passes)."""
    if not fit_ok:
        return "edge fit did not converge"
    if b < p.min_contrast:
        return f"edge contrast {b:.0f} < {p.min_contrast:g}"
    if rel > p.max_rel_rms:
        return f"edge residual {rel:.2f} of the contrast > {p.max_rel_rms:g}"
    if sigma > p.max_blur_px:
        return f"edge blur {sigma:.1f} px > {p.max_blur_px:g}"
    if sigma < 0.06:
        return f"edge blur {sigma:.2f} px < 0.06 (a step sharper than a pixel)"
    return None


def _outside(quads: list[NDArray[np.float64]], polys: list[NDArray[np.float64]], margin: float = 0.0) -> list[int]:
    """Indices of the ``quads`` (each (4, 2)) whose centre lies inside none of ``polys`` (each (4, 2)), or
    with ``margin`` > 0 (pixels), more than ``margin`` outside the convex hull of each."""
    if margin > 0:
        hulls = [cv2.convexHull(np.asarray(p, np.float32).reshape(-1, 1, 2)) for p in polys]
        return [i for i, q in enumerate(quads)
                if all(cv2.pointPolygonTest(h, tuple(map(float, q.mean(axis=0))), True) < -margin for h in hulls)]
    cv_polys = [np.asarray(p, np.float32).reshape(-1, 1, 2) for p in polys]
    return [i for i, q in enumerate(quads)
            if all(cv2.pointPolygonTest(p, tuple(map(float, q.mean(axis=0))), False) < 0 for p in cv_polys)]


@functools.lru_cache(maxsize=32)
def _unconfirmed_max_hamming(spec: FamilySpec, max_rate: float) -> int:
    """The most corrected cells (at most the family's correction) at which a random pattern of the
    ``d^2`` data cells decodes to one of the family's codes, in any of 4 rotations, with a probability
    of at most ``max_rate``: ``4 n_ids sum_k<=h C(d^2, k) / 2^(d^2)``. AprilTag 36h11 (587 IDs, 36 cells):
    5 cells 1.5 %, 4 cells 0.23 %; ARToolKitPlus simple (512 IDs, correction 1): 1 cell, 1e-6."""
    n = spec.data_cells**2
    h, ball = 0, 1
    while h < spec.max_correction:
        nxt = ball + math.comb(n, h + 1)
        if 4 * spec.n_ids * nxt / 2.0**n > max_rate:
            break
        h, ball = h + 1, nxt
    return h


def _dedupe(dets: list[Detection]) -> list[Detection]:
    """Drop detections whose centre lies within another detection of the same ID (keeps the larger)."""
    if len(dets) < 2:
        return dets
    dets = sorted(dets, key=lambda d: -_area(d.corners_px))
    keep: list[Detection] = []
    for d in dets:
        c = d.corners_px.mean(axis=0)
        near = [k for k in keep if k.id == d.id]
        if any(np.linalg.norm(k.corners_px.mean(axis=0) - c) < 0.25 * np.sqrt(_area(k.corners_px))
               for k in near):
            continue
        keep.append(d)
    return keep


def _shoelace(Q: NDArray[np.float64]) -> NDArray[np.float64]:
    """Signed areas (Q,) of quads (Q, 4, 2), square pixels."""
    x, y = Q[..., 0], Q[..., 1]
    return 0.5 * np.sum(x * np.roll(y, -1, axis=-1) - np.roll(x, -1, axis=-1) * y, axis=-1)


def _area(q: NDArray[np.float64]) -> float:
    x, y = q[:, 0], q[:, 1]
    return 0.5 * abs(float(np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y)))


def _to_gray(image: NDArray[np.generic]) -> NDArray[np.uint8]:
    """Any image OpenCV reads as the detector's 8-bit grey (H, W).

    Accepts (H, W), (H, W, 1), (H, W, 2) (grey + alpha), (H, W, 3) (BGR) and (H, W, 4) (BGRA) arrays
    of any integer, float or bool dtype. 8-bit data is used as is; deeper data (16-bit, float) is
    scaled linearly so that its largest finite value maps to 255, since a 12-bit sensor stored in 16
    bits would otherwise be nearly black; non-finite values become 0.
    """
    img = np.asarray(image)
    if img.ndim == 3 and img.shape[2] == 1:
        img = img[:, :, 0]
    elif img.ndim == 3 and img.shape[2] == 2:
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
        return cv2.cvtColor(np.ascontiguousarray(img), cv2.COLOR_BGR2GRAY if img.shape[2] == 3
                            else cv2.COLOR_BGRA2GRAY)
    return np.ascontiguousarray(img)


def detect_markers(
    image: NDArray[np.uint8],
    family: MarkerFamily | str,
    camera_matrix: NDArray[np.float64] | None = None,
    dist_coeffs: NDArray[np.float64] | None = None,
    params: DetectorParams | None = None,
) -> list[Detection]:
    """Detect markers of ``family`` in ``image``; see :class:`MarkerDetector`."""
    return MarkerDetector(family, camera_matrix, dist_coeffs, params).detect(image)
