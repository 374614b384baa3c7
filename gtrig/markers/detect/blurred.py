"""Small, blurred markers: candidates from a smoothed image and decoding by maximum likelihood.

At blur sigma 2 px a 20 px AprilTag 36h11 has cells of 2.5 px: the black border merges with the
blurred data cells, the dark mask of :mod:`.candidates` breaks the marker into fragments, and a
white cell among black ones keeps a fifth of the marker's contrast, below the noise of one cell, so
neither thresholding nor :func:`.decode.unblur_cells` reads it. All the pixels together still tell
the codes apart by hundreds of chi-square units. This module is the detector's second path, run on
what the first one left:

1. candidates (:func:`find_blurred_candidates`): the dark mask of a smoothed image at a looser
   ratio, where a blurred marker is one dark blob inside its white quiet zone; only small blobs
   (the first path finds the large ones) and no hole tests (the blob has none); and the holes of the
   quiet zone's bright ring (:mod:`.quiet`) at two window sizes. Each candidate is one or more
   outlines of one place; the detector drops those whose centre lies in a marker the first path found.
   Of a candidate's outlines, and the best of them moved onto the marker's outer edge
   (:mod:`.outline`: the reader's basin is about a pixel, an outline can be 1-4 px off), the one of
   least misfit at the start screen is read (:func:`_starts`);
2. geometry without the code: the 4 corners and the blur fitted by Gauss-Newton to every pixel of
   the square and half a cell around it, the model being the blurred-box one of
   :func:`.edges.marker_context` with the levels and the 36 cells' light free (linear, solved inside:
   variable projection), so the quad converges before any code is assumed. Clutter that this model
   cannot fit to about the expected misfit of a real marker stops here, most of it at the first
   evaluation. That misfit is the image noise (:func:`image_noise`) and a share of the contrast
   (``texture_share``): a printed, photographed marker is not the model's ideal box;
3. ranking: every code of the family in its 4 rotations through that geometry, the levels solved
   per code from sums linear and quadratic in the code, and a
   screen on the leader's margin and excess residual;
4. verification: the leader's corners and blur refitted with its cells fixed, the ranking repeated
   there (a code that beats it is refitted in turn), close runners-up refitted too. The free model
   nests every code's, so the right code's excess residual over it is about chi-square with 36
   degrees of freedom; a read is accepted when that excess is small and the best code beats every
   other hypothesis by a margin of ``min_margin`` chi-square units;
5. the light field, where steps 3-4 read nothing: the same steps again with a smooth additive light
   field over the marker in the free and every code's model (a quadratic in the pixel coordinates,
   ``light_degree``; :func:`_read_codes`), if the image shows one (``light_evidence_sd``). A highlight or
   the light's slope lifts black and white alike; the free cells absorb it over the data area and a
   code's two levels cannot, so the right code's excess measured the highlight, not the code (session
   36: 7774 and 664 chi-square units at the true corners of two glared 20 px markers of the hard set,
   1809 and 154 with the field, their margins 5574 and 756 rising to 12133 and 1046). The free model
   still nests every code's, so the excess test keeps its meaning. The flat model goes first because
   the field's columns share the geometry's information (a plane looks like a shift of the square's
   blurred edges, a bowl like a change of its size): on markers without glare they only add variance to
   the corners (``--quick``, 20 px at blur 2 px, 45 deg tilt in dim light: 0.41 -> 0.55 px with the
   field in every fit);
6. the free cells' reading, where steps 3-5 accept nothing: a code that wins by ``min_margin`` but fails
   the excess test is accepted when the free model's own cells, read at half the contrast, are that code
   within ``free_cells_off`` cells and every other code is far (:func:`_cells_agree`). Demosaicing,
   JPEG and paper texture leave a misfit spread thinly over every cell, which adds up to an excess as
   large as a few wrong cells' would, while a pattern that is not a code differs from its nearest code by
   whole cells (at least 6 on 1344 clutter candidates that reached these tests, session 38). It goes
   last because under glare the lit model's corners are the better ones.

Measured on ``bench/markers.py --quick`` (blur 2 px, noise 3): the 20 px markers are read with
margins of 130-9000 chi-square units and corner errors of 0.06-0.4 px; the right code's residual SD
is the image noise (2.8-3.5 grey levels against 3), 4.2 at 45 deg tilt in full light where the
model's cell corners under shear show.
"""

from __future__ import annotations

import dataclasses
import logging
from collections.abc import Callable
from dataclasses import dataclass

import cv2
import numpy as np
from numpy.typing import NDArray

from gtrig.markers.detect import _kernels
from gtrig.markers.detect._blas import matmul, one_thread
from gtrig.markers.detect.candidates import dark_mask, solid_quad
from gtrig.markers.detect.edges import quad_homographies
from gtrig.markers.detect.outline import snap_to_border
from gtrig.markers.detect.quiet import quiet_zone_quads

log = logging.getLogger(__name__)

__all__ = ["BlurredParams", "BlurredRead", "find_blurred_candidates", "image_noise", "read_blurred"]


@dataclass(frozen=True)
class BlurredParams:
    """Tunables of the second path (pixel units refer to the input image).

    enabled : run the second path (the default). It costs 3-4 ms of CPU per image even where it finds
        nothing (its candidate stage, beside the first path when OpenCV has two threads) and 5-8 ms per
        marker it reads; on the bench it takes the markers of at least 20 px detected from 92.7 % to
        99.5 % (``bench/markers.py``; BENCHMARKS.md, Markers).
    smooth_px : Gaussian smoothing of the image before the dark mask (joins the fragments of the
        blurred border and cells).
    ratio_threshold : dark when smoothed image / closing < this; looser than the first path's 0.6
        since a blurred border never gets as dark as a sharp one.
    min_side_px, max_side_px : side range of the candidates; larger markers are the first path's.
    min_solidity : contour area / hull area.
    quiet_windows : window sides (pixels) of the quiet-zone candidates (:func:`.quiet.quiet_zone_quads`:
        the holes of the mask of pixels brighter than their neighbourhood's mean, the paper ring around a
        marker, on the smoothed image), in order. 11 px is about half the smallest marker this path reads
        (the ring of a 20 px tag is 2-5 px wide; at 21-31 px windows the dark background around a thin
        ring lowers the mean less than the marker's own dark half does, and the ring breaks); 7 px keeps
        the ring closed where a bright surface or a white cell next to a thin quiet zone pulls the 11 px
        mean up (session 37: with the other changes of that session, (7, 11) missed 20 of the hard
        bench's 1080 markers of >= 20 px on seeds 0-3, 5, 6, (7,) alone 26). A hole whose centre lies in
        an earlier candidate is kept as a further outline of that candidate
        (:func:`find_blurred_candidates`). Empty: off.
    quiet_offset : how much brighter than that mean (grey levels) a pixel of the ring is; about the noise
        the 3 x 3 median leaves.
    quiet_min_solidity : least area / hull area of a quiet-zone hole. Looser than the dark blobs'
        ``min_solidity``: a white cell next to a border broken by blur and demosaicing joins the ring and
        notches the hole by a cell (solidity 0.75-0.85 on the hard bench's missed 20 px tags), while its
        hull stays the marker's outline, and the reader starts from the outline moved onto the edge.
    quiet_ink_ratio : a hole's darkest tenth must be darker than this share of its ring's median. The
        ring is traced on its innermost bright pixels, already on the blurred border's slope: a
        low-contrast 20 px tag (paper 118, border 95 grey levels after the 1 px smoothing) reads 0.77-0.82.
    snap_reach_px : the reader's further start, the best outline of a candidate moved onto the marker's
        outer edge within this distance (pixels) (:func:`.outline.snap_to_border`, :func:`_starts`); 0: off.
    max_starts : starts read per candidate at most, those of least misfit at the start screen first
        (:func:`_start_share`); each further one costs a free fit where the first fails, mostly on clutter.
    max_free_misfit : the code-free fit's residual SD may be at most this many times the expected
        misfit of a marker (no code can fit better than the model with free cells, so clutter stops
        here, before the codes are tried).
    texture_share : the expected misfit of a marker at its true corners beyond the image noise, as a
        share of its contrast: the expected residual variance is ``noise^2 + (texture_share *
        contrast)^2``. Paper and toner texture, print gain, JPEG ringing at the edges and demosaicing
        zips all scale with the marker's contrast, and :func:`image_noise` does not see them (it reads
        the fine-grained noise that JPEG and demosaicing smooth away: 0.35-1.4 grey levels on
        ``bench/markers.py --hard`` images rendered with 2-5). Measured at the true corners of that
        set's 20 px markers: 2.4-12 % of the contrast, median 4-5 %.
    max_start_misfit : the free model's residual SD at the candidate's geometry, in units of the
        expected misfit, above which the fit is abandoned after its first evaluation (cheap rejection
        of clutter).
    max_start_share : ... or when the SD of its misfit beyond the noise exceeds this share of the
        fitted contrast (0.03-0.10 for the bench's markers, up to several for clutter).
    max_excess_sd : the best code's excess residual over the free fit may exceed its chi-square
        mean by this many SDs (see :func:`read_blurred`).
    excess_share : ... or by this share of the margin, whichever is larger: the model's own error
        (cell corners under shear, the pixel's box taken for a Gaussian) grows with the contrast as the
        margin does, while a pattern that is not a code differs from its nearest code by at least one
        cell of the at least ``h_min`` (11 for AprilTag 36h11) that separate it from the next one.
    min_margin : least margin of the runner-up code's residual sum of squares over the best one's,
        in units of the residual variance (chi-square units).
    screen_margin, screen_excess : the screen before the codes' own fits, at the free fit's geometry:
        the leader's margin must reach ``screen_margin`` and its excess may not exceed the larger of
        ``screen_excess`` and 4 times the margin (the right code's excess there is 30-1000, clutter's up to
        tens of thousands).
    top_codes : codes refitted with their own geometry while one beats the best so far (at most).
    refit_margin : runner-up codes within this margin of the best, at its geometry, are refitted too.
    code_iterations : Gauss-Newton iterations of a code's own geometry fit.
    min_contrast : least white - black difference, grey levels.
    max_blur_cells : largest fitted blur (SD), in cells of the fitted square. A pattern of alternate
        cells keeps ``exp(-pi^2 b^2 / 2)`` of its contrast through a Gaussian of ``b`` cells: 4 % at 0.8
        (the quick bench's 20 px tags at blur 2 px, read), 0.7 % at 1, 0.02 % at 1.3, where no cell can
        be told from its neighbour under the noise and a code that wins the ranking was made by the
        clutter's shape (an 11 px square on clutter under a 2 px defocus disk, fitted blur 1.8 px, read as
        ID 489: ``tests/markers/test_psf.py``, session 39).
    max_shift_px : largest move of a corner from the candidate to the fit.
    subsample_px, screen_px : about this many pixels (at least) serve the fit with free cells and the
        start screen before it; the codes' fits use every pixel.
    iterations : Gauss-Newton iterations of the fit with free cells (at most; in dim light more of
        them let the geometry drift, the free cells taking the border's place).
    light_degree : degree of the smooth additive light field of the second reading (step 5 of the
        module docstring, :func:`_light_basis`; 0: none, the flat reading alone). Glare is light added on
        top of black and white alike, a Gaussian of 0.2-0.8 marker sides on the hard set, and the
        lighting's slope over a marker is nearly planar: degree 2 (5 columns besides the constant) cuts
        the right code's excess residual over the free model by 2-4 times on the hard set's glared
        20 px markers (module docstring), while the margin over the next code, a matter of whole cells,
        stays or grows (the field is smooth, a cell's pattern is not). Degree 1 leaves most of the
        excess; degree 3 read no more markers on the hard set's seeds 0-3.
    light_evidence_sd : the second reading is made only where the light field lowers the free model's
        residual by more than chance (chi-square with the field's L columns: mean L + this many SDs); a
        clutter glyph read with the field's freedom on ``--clutter 150`` showed none (1.4 units), the
        glared markers it reads on the hard set 22-119.
    first_misfits : read also the first path's candidates rejected for an edge residual where this path has
        no candidate (``MarkerDetector._read_misfits``).
    free_cells_off : a code that fails the excess test (and the screen's) is still accepted when the free
        model's cells, each read at half the contrast, are that code within this many cells and every
        other code is more than twice as many cells further (:func:`_cells_agree`); None: off. Where
        demosaicing, JPEG and texture leave a misfit spread over the whole marker, the free cells absorb a
        little of it in every cell and the right code's excess grows with the contrast as a few wrong
        cells' would (the hard bench's 3/20/12/365: excess 1810 against a margin of 6068, its free cells
        0 cells off the code), while a pattern that is not a code is whole cells off: on clutter the free
        cells lay at least 6 cells off their leader (1344 candidates that reached these tests: 300 hard
        scenes of seed 102 and 400 ``--clutter`` scenes of seed 101, session 38).
    """

    enabled: bool = True
    smooth_px: float = 1.0
    ratio_threshold: float = 0.75
    min_side_px: float = 12.0
    max_side_px: float = 38.0
    min_solidity: float = 0.85
    quiet_windows: tuple[int, ...] = (7, 11)
    quiet_offset: float = 3.0
    quiet_min_solidity: float = 0.75
    quiet_ink_ratio: float = 0.85
    snap_reach_px: float = 3.0
    max_starts: int = 1
    max_free_misfit: float = 2.0
    texture_share: float = 0.05
    max_start_misfit: float = 8.0
    max_start_share: float = 0.15
    max_excess_sd: float = 5.0
    excess_share: float = 0.25
    min_margin: float = 40.0
    screen_margin: float = 20.0
    screen_excess: float = 400.0
    top_codes: int = 3
    refit_margin: float = 400.0
    code_iterations: int = 4
    min_contrast: float = 12.0
    max_blur_cells: float = 1.0
    max_shift_px: float = 4.0
    iterations: int = 3
    subsample_px: int = 200
    screen_px: int = 100
    light_degree: int = 2
    light_evidence_sd: float = 5.0
    free_cells_off: int | None = 2
    first_misfits: bool = True


@dataclass(frozen=True)
class BlurredRead:
    """One marker read by the second path.

    code : index into the ``codes`` given to :func:`read_blurred`.
    corners : (4, 2) fitted corners, quad orientation, pixels.
    corner_cov : (4, 2, 2) their covariances (first order, from the Gauss-Newton normal matrix), px^2.
    sigma : fitted blur, pixels.
    rms : residual SD of the best code, grey levels.
    margin : chi-square margin over the runner-up hypothesis.
    index : the candidate's index among the ``quads`` given to :func:`read_blurred`.
    """

    code: int
    corners: NDArray[np.float64]
    corner_cov: NDArray[np.float64]
    sigma: float
    rms: float
    margin: float
    index: int = -1


_NEXT = np.array([1, 2, 3, 0])


def find_blurred_candidates(gray: NDArray[np.uint8], params: BlurredParams, max_side_bg: float,
                            scale: int = 4) -> list[NDArray[np.float64]]:
    """Candidates of the second path: small dark blobs of the smoothed image and the holes of its
    quiet-zone masks, each as an (A, 4, 2) array of A >= 1 outlines (clockwise on screen, pixels) of the
    same place, to be read in order (:func:`read_blurred` with ``alternatives``): a dark blob's quad,
    then the quiet-zone holes whose centre lies in it, window by window.

    Parameters
    ----------
    gray : (H, W) uint8.
    params : :class:`BlurredParams`.
    max_side_bg, scale : the closing's largest dark object and downsampling (as in the first path).
    """
    # the kernel cut at 2 sigma (OpenCV's default is 3): 5 x 5 instead of 7 x 7 at 1 px, 40 % faster
    k = 2 * int(np.ceil(2.0 * params.smooth_px)) + 1
    g = cv2.GaussianBlur(gray, (k, k), params.smooth_px)
    mask = cv2.medianBlur(dark_mask(g, max_side_bg, scale, params.ratio_threshold), 3)
    # RETR_CCOMP puts a blob lying in a hole of a larger dark region (a marker in its quiet zone on a
    # dark background) at the top level again
    contours, hier = cv2.findContours(mask, cv2.RETR_CCOMP, cv2.CHAIN_APPROX_NONE)
    groups: list[list[NDArray[np.float64]]] = []
    if hier is not None:
        hier = hier[0]
        lengths = np.fromiter(map(len, contours), int, len(contours))
        lo, hi = 4 * params.min_side_px * 0.8, 4 * params.max_side_px * 1.3
        for i in np.flatnonzero((hier[:, 3] < 0) & (lengths >= lo) & (lengths <= hi)):
            q = solid_quad(contours[i], params.min_side_px, params.max_side_px, params.min_solidity)
            if q is not None:
                groups.append([q])
    # the quiet zone traced on the same smoothed image: its noise (sigma 3 on the --quick set) left specks
    # in the bright mask of the raw image that cost a third more tracing, for the same markers read
    _quiet_candidates(g, params, groups)
    return [np.stack(grp) for grp in groups]


def _quiet_candidates(gray: NDArray[np.uint8], params: BlurredParams, groups: list[list[NDArray[np.float64]]]
                      ) -> None:
    """Add the quiet-zone quads (:func:`.quiet.quiet_zone_quads`, each (4, 2)) of ``gray``, window by
    window, to ``groups`` (lists of outlines of one place, each (4, 2)): a quad whose centre lies in a
    group's first outline joins that group as a further outline to read (the dark blob's outline or a
    hole of another window may be the one off the marker: a notched hole, a blob bulging into a
    neighbour), unless it repeats one of them to within ``_SAME_PX``; any other starts a group."""
    for win in params.quiet_windows:
        polys = [np.asarray(grp[0], np.float32).reshape(-1, 1, 2) for grp in groups]
        for q in quiet_zone_quads(gray, win, params.quiet_offset, params.min_side_px, params.max_side_px,
                                  params.quiet_min_solidity, params.quiet_ink_ratio):
            ctr = tuple(map(float, q.mean(axis=0)))
            home = next((k for k, p in enumerate(polys) if cv2.pointPolygonTest(p, ctr, False) >= 0), None)
            if home is None:
                groups.append([q])
            elif all(_quad_distance(q, o) > _SAME_PX for o in groups[home]):
                groups[home].append(q)


#: outlines of one place closer than this (pixels, largest corner distance) are read once
_SAME_PX = 0.5


def _quad_distance(a: NDArray[np.float64], b: NDArray[np.float64]) -> float:
    """Largest corner distance (pixels) between quads ``a`` and ``b`` (each (4, 2), clockwise), over the
    four ways of pairing their corners."""
    return min(float(np.abs(np.roll(a, k, axis=0) - b).max()) for k in range(4))


def image_noise(gray: NDArray[np.uint8]) -> float:
    """Robust SD of the image noise, grey levels: Immerkaer's 3 x 3 operator (``[1 -2 1]`` outer
    ``[1 -2 1]``, blind to planes and ramps, gain 6 on white noise) on every fourth row, sampled on a
    sparse grid, and the median of its magnitude (edges and texture are a minority of pixels and leave
    the median alone; ``|N(0, 1)|`` has median 0.6745). Dropping rows before filtering only changes
    which neighbours enter, still independent noise. The response of an 8-bit image is an integer:
    its median is interpolated within the integer bin it falls in, or it would move in steps of a
    twelfth of the noise."""
    k = np.array([[1, -2, 1], [-2, 4, -2], [1, -2, 1]], np.float32)
    r = np.abs(cv2.filter2D(gray[::4].astype(np.float32), -1, k)[1:-1, 1:-1:3]).astype(np.int32).ravel()
    hist = np.bincount(r)
    cum = np.cumsum(hist)
    m = int(np.searchsorted(cum, 0.5 * len(r)))
    below = cum[m] - hist[m]
    # bin m spans m - 0.5 .. m + 0.5 (0 .. 0.5 for the first): linear within it
    lo = max(m - 0.5, 0.0)
    med = lo + (0.5 * len(r) - below) / max(hist[m], 1) * (m + 0.5 - lo)
    return float(med) / (6.0 * 0.6745)


def _profiles(px: NDArray[np.float64], quads: NDArray[np.float64], sig: NDArray[np.float64], n: int,
              border: int) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """The blurred black square ``1 - S`` (K, N) and the blurred data cells ``F`` (K, N, d^2) at pixels
    ``px`` (N, 2) for K geometries ``quads`` (K, 4, 2) and blurs ``sig`` (K,) (the model of
    :func:`.edges.marker_context`; compiled in :func:`._kernels.cell_profiles`)."""
    return _kernels.cell_profiles(np.ascontiguousarray(px[:, 0]), np.ascontiguousarray(px[:, 1]),
                                  quad_homographies(quads), np.ascontiguousarray(sig, np.float64), n, border)


def _prediction_jacobian(px: NDArray[np.float64], quad: NDArray[np.float64], sig: float, n: int, border: int,
                         cells: NDArray[np.float64], contrast: float) -> NDArray[np.float64]:
    """Derivative (9, N) of the model ``a + b (1 - S) + F w`` at pixels ``px`` (N, 2) with respect to
    the 8 corner coordinates and the blur, at fixed levels and cells (``contrast`` = b, ``cells`` =
    b w as a (d, d) array).

    The corners act through the homography (its derivative by differences of the 8 x 8 solve, then
    the chain rule per pixel, in :func:`._kernels.cell_jacobian`), on the cell coordinates and on the
    local blur widths in cell units: one evaluation of the profiles instead of the nine of forward
    differences.
    """
    Qp = np.repeat(quad.reshape(1, 8), 9, axis=0)
    hq = 1e-4
    Qp[np.arange(1, 9), np.arange(8)] += hq
    Hs = quad_homographies(Qp.reshape(9, 4, 2))
    d = n - 2 * border
    return _kernels.cell_jacobian(np.ascontiguousarray(px[:, 0]), np.ascontiguousarray(px[:, 1]), Hs[0],
                                  (Hs[1:] - Hs[0]) / hq, float(sig), n, border,
                                  np.ascontiguousarray(cells, np.float64).reshape(d, d), float(contrast))


# The normal matrices below are products of a C-contiguous matrix with its own transpose, which NumPy
# computes by syrk (one triangle, mirrored: exactly symmetric, half the multiplications), in one BLAS call
# each: the reader runs inside :func:`._blas.one_thread` (:func:`read_blurred`), so no call is threaded.
# (Until session 38 each product was a batched gemm over chunks of 512 pixels, summed in Python: a fifth of
# the reads' time in copies and calls.)


def _solve_levels(I: NDArray[np.float64], A: NDArray[np.float64], ridge: NDArray[np.float64]
                  ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Least squares ``I ~ A c`` (``I`` (N,)) for K designs ``A`` (K, N, P), ``ridge`` (P,) added to the
    normal equations' diagonal. Returns residuals (K, N) and coefficients (K, P)."""
    K, N, P = A.shape
    r, c = np.empty((K, N)), np.empty((K, P))
    diag = np.arange(P)
    for k in range(K):
        Ak = np.ascontiguousarray(A[k])
        AtA = Ak.T @ Ak
        # a relative floor on the diagonal keeps a degenerate design (no pixel inside) solvable
        AtA[diag, diag] += ridge + 1e-9 * AtA[diag, diag].mean() + 1e-12
        c[k] = np.linalg.solve(AtA, Ak.T @ I)
        r[k] = I - Ak @ c[k]
    return r, c


def _fit_geometry(px: NDArray[np.float64], I: NDArray[np.float64], quad: NDArray[np.float64], sig: float,
                  n: int, border: int, code: NDArray[np.float64] | None, iterations: int,
                  stop_start: Callable[[float, float], bool] | None = None,
                  stop_iter: Callable[[float, float], bool] | None = None,
                  light: NDArray[np.float64] | None = None
                  ) -> tuple[NDArray[np.float64], float, float, NDArray[np.float64], NDArray[np.float64]]:
    """Corners and blur of one marker fitted to the pixels ``px`` (N, 2) of values ``I`` (N,) by
    damped Gauss-Newton, with the levels (and without ``code`` the cells' whiteness) solved linearly
    inside at every evaluation (variable projection; the Jacobian from :func:`_prediction_jacobian`,
    updated by Broyden's formula between fresh ones when the cells are fixed).

    Returns corners (4, 2), blur, residual sum of squares, the linear coefficients and the last
    Gauss-Newton normal matrix ``J^T J`` (9, 9) of the 8 corner coordinates and the blur (NaN without
    iterations); when ``stop_start(sse, contrast)`` holds at the start it returns at once, when
    ``stop_iter(sse, contrast)`` holds after an iteration it stops there. ``light`` (N, L): columns of
    the smooth light field added to the model (:func:`_light_basis`; fixed in the pixels, so they do not
    depend on the geometry), their coefficients last among the linear ones.
    """
    d2 = (n - 2 * border) ** 2
    n_light = 0 if light is None else light.shape[1]
    if code is None:
        # levels a, b and the cells' light b W: I = a + b (1 - S) + F (b W); a weak ridge keeps the
        # cells defined where the blur leaves one unseen
        ridge = np.r_[0.0, 0.0, np.full(d2, 1e-2), np.zeros(n_light)]
    else:
        ridge = np.zeros(2 + n_light)

    xs, ys = np.ascontiguousarray(px[:, 0]), np.ascontiguousarray(px[:, 1])
    code_arg = np.zeros(0) if code is None else np.ascontiguousarray(code, np.float64)

    def design(quads: NDArray[np.float64], sigs: NDArray[np.float64]) -> NDArray[np.float64]:
        """(1, N, P) design at one geometry (:func:`._kernels.cell_design`)."""
        H = quad_homographies(quads)[0]
        A = _kernels.cell_design(xs, ys, H, float(sigs[0]), n, border, code_arg)
        return (A if light is None else np.hstack([A, light]))[None]

    th = np.r_[quad.ravel(), sig]
    Acur = design(th[None, :8].reshape(1, 4, 2), th[None, 8])
    r, c = _solve_levels(I, Acur, ridge)
    sse = float(r[0] @ r[0])
    A = np.full((9, 9), np.nan)
    if stop_start is not None and stop_start(sse, float(c[0, 1])):
        return quad, sig, sse, c[0], A
    lam = 1e-3
    res = r[0]
    J = None
    fresh = False
    for _ in range(iterations):
        if J is None:
            # variable projection (Kaufman's form): the residual's derivative is the prediction's
            # derivative at fixed linear coefficients, projected off the design's columns
            cells = c[0, 2:2 + d2] if code is None else c[0, 1] * code
            dp = _prediction_jacobian(px, th[:8].reshape(4, 2), th[8], n, border, cells, c[0, 1])
            A0 = np.ascontiguousarray(Acur[0])
            G = A0.T @ A0
            G[np.diag_indices_from(G)] += ridge + 1e-9 * np.mean(np.diag(G)) + 1e-12
            dpT = np.ascontiguousarray(dp.T)
            proj = A0 @ np.linalg.solve(G, A0.T @ dpT)
            J = np.ascontiguousarray(-(dpT - proj).T)  # (9, N)
            fresh = True
        A = J @ J.T
        g = J @ res
        improved = False
        for _try in range(3):
            step = -np.linalg.solve(A + lam * (np.diag(np.diag(A)) + 1e-9 * np.eye(9)), g)
            tn = th + step
            tn[8] = np.clip(tn[8], 0.3, 5.0)
            An = design(tn[None, :8].reshape(1, 4, 2), tn[None, 8])
            rn, cn = _solve_levels(I, An, ridge)
            sn = float(rn[0] @ rn[0])
            if sn < sse:
                improved = True
                break
            lam *= 10.0
        if improved:
            # with a code, Broyden's rank-one update of the Jacobian; with free cells a fresh one each
            # time (updated, the geometry drifts with the cells in dim light)
            dth = tn - th
            J = None if code is None else J + np.outer(dth, rn[0] - res - dth @ J) / (dth @ dth)
            th, sse, c, res, Acur = tn, sn, cn, rn[0], An
            lam *= 0.3
            fresh = False
            if np.abs(step[:8]).max() < 0.01 or (stop_iter is not None and stop_iter(sse, float(c[0, 1]))):
                break
        elif fresh or J is None:
            break
        else:
            J = None  # the updated Jacobian went stale: a fresh one
    return th[:8].reshape(4, 2), float(th[8]), sse, c[0], A


def _rank_codes(px: NDArray[np.float64], I: NDArray[np.float64], quad: NDArray[np.float64], sig: float,
                n: int, border: int, codes: NDArray[np.float64], light: NDArray[np.float64] | None = None
                ) -> NDArray[np.float64]:
    """Residual sum of squares (C,) of every code (C, d^2) through one geometry, the levels solved per
    code from sums linear and quadratic in the code. With ``light`` (N, L), the columns of the smooth
    light field (:func:`_light_basis`), these are projected out of the image and the profiles first (the
    light field is the same nuisance for every code)."""
    base, F = _profiles(px, quad[None], np.array([sig]), n, border)
    base, F = base[0], F[0]
    if light is not None:
        # the residual maker of the light columns (the constant stays: the centring below)
        Q, _ = np.linalg.qr(light - light.mean(axis=0))
        I = I - Q @ (Q.T @ I)
        base = base - Q @ (Q.T @ base)
        F = F - Q @ (Q.T @ F)
    N = float(len(I))
    Sm = base.sum() + matmul(codes, F.sum(axis=0))
    F = np.ascontiguousarray(F)
    Ft = np.ascontiguousarray(F.T)
    G = F.T @ F
    Smm = base @ base + 2.0 * matmul(codes, matmul(Ft, base)) + np.einsum("ci,ci->c", matmul(codes, G), codes)
    SIm = I @ base + matmul(codes, matmul(Ft, I))
    var_m = Smm - Sm * Sm / N
    cov = SIm - I.sum() * Sm / N
    var_I = I @ I - I.sum() ** 2 / N
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where((cov > 0) & (var_m > 0), var_I - cov * cov / var_m, var_I)


def _pixels(gray: NDArray[np.uint8], quad: NDArray[np.float64], n: int, reach: float
            ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Pixel centres (N, 2) and values (N,) of the square ``quad`` and ``reach`` cells around it."""
    h, w = gray.shape
    x0, y0 = np.maximum(np.floor(quad.min(axis=0) - 4), 0).astype(int)
    x1, y1 = np.minimum(np.ceil(quad.max(axis=0) + 4), [w - 1, h - 1]).astype(int)
    if x1 <= x0 or y1 <= y0:
        return np.zeros((0, 2)), np.zeros(0)
    # compiled (:func:`._kernels.square_pixels`); a degenerate candidate's horizon can cross the box:
    # those pixels are not in the square
    H = quad_homographies(quad[None])[0]
    return _kernels.square_pixels(gray, int(x0), int(y0), int(x1), int(y1), np.ascontiguousarray(H), reach / n)


def _light_basis(px: NDArray[np.float64], quad: NDArray[np.float64], degree: int) -> NDArray[np.float64] | None:
    """Columns (N, L) of a smooth additive light field at pixels ``px`` (N, 2): the monomials of degree 1
    to ``degree`` in the pixel's offset from the centre of ``quad`` (4, 2), in units of its side
    (``L = 2`` for degree 1, 5 for 2); None for degree 0 (the constant level alone)."""
    if degree <= 0:
        return None
    side = max(float(np.linalg.norm(quad - np.roll(quad, -1, axis=0), axis=1).mean()), 1.0)
    u, v = ((px - quad.mean(axis=0)) / side).T
    cols = [u ** (k - j) * v ** j for k in range(1, degree + 1) for j in range(k + 1)]
    return np.ascontiguousarray(np.stack(cols, -1))


def _rows(a: NDArray[np.float64] | None, keep: NDArray[np.bool_]) -> NDArray[np.float64] | None:
    """The rows ``keep`` of ``a`` (None stays None)."""
    return None if a is None else a[keep]


def _spread_subset(px: NDArray[np.float64], k: int) -> NDArray[np.bool_]:
    """Every ``k``-th pixel of ``px`` (N, 2) on a sheared lattice (a checkerboard for ``k = 2``), so the
    subset covers the square evenly; all of them for ``k <= 1``."""
    if k <= 1:
        return np.ones(len(px), bool)
    x, y = px[:, 0].astype(np.int64), px[:, 1].astype(np.int64)
    return (x + max(1, k // 2) * y) % k == 0


def _cells_agree(cells: NDArray[np.float64], Wc: NDArray[np.float64], best: int, params: BlurredParams) -> bool:
    """Whether the free model's cells ``cells`` (d^2,), whiteness 0 (black) to 1 (white), each read at 0.5,
    are within ``params.free_cells_off`` cells of the code ``Wc[best]`` (Wc (C, d^2) every code) while every
    other code is at least ``2 free_cells_off + 1`` cells further."""
    k = params.free_cells_off
    if k is None:
        return False
    off = np.count_nonzero((cells[None] > 0.5) != (Wc > 0.5), axis=1)
    h = int(off[best])
    off[best] = np.iinfo(off.dtype).max
    log.debug("free cells: %d off the leader, %d off the next code", h, int(off.min()))
    return h <= k and int(off.min()) > h + 2 * k


def _read_codes(px: NDArray[np.float64], I: NDArray[np.float64], quad: NDArray[np.float64],
                start: tuple[NDArray[np.float64], float], sse_free: float, dof: int, Wc: NDArray[np.float64],
                n: int, border: int, params: BlurredParams, light: NDArray[np.float64] | None, max_excess: float,
                free: NDArray[np.float64]) -> tuple[BlurredRead, bool] | None:
    """Steps 3 and 4 of the module docstring for one candidate ``quad`` (4, 2) whose free fit gave the
    corners and blur ``start`` and the residual sum of squares ``sse_free`` on ``dof`` degrees of
    freedom: every code of ``Wc`` (C, d^2) ranked, the leaders refitted, and the read if the best code
    passes the margin and excess tests (``max_excess``: the chi-square bound of the excess), with True, or
    passes the margin test and its free cells read as it (:func:`_cells_agree`), with False; else None.
    ``light`` (N, L) (:func:`_light_basis`) or None: the light field's columns in every code's model
    (``sse_free`` must then be the free model's with them). ``cells`` (d^2,): the free model's cells'
    whiteness there (:func:`_cells_agree`).
    """
    q1, s1 = start
    s2 = sse_free / dof
    d2 = Wc.shape[1]
    cells = free[2:2 + d2] / max(float(free[1]), 1e-9)
    sse = _rank_codes(px, I, q1, s1, n, border, Wc, light)
    o = np.argsort(sse)[: params.top_codes]
    excess0, margin0 = (sse[o[0]] - sse_free) / s2, (sse[o[1]] - sse[o[0]]) / s2
    if margin0 < params.screen_margin or (excess0 > max(params.screen_excess, 4.0 * margin0)
                                          and not _cells_agree(cells, Wc, int(o[0]), params)):
        # before the codes' own fits: clutter that the free cells explain (a dark frame round a
        # pattern) fits no code by far more than the leader beats the next code; unless the free cells
        # themselves read as the leader (a misfit spread over a marker, not cells off the code)
        log.debug("blurred candidate at (%.0f, %.0f)%s: excess %.0f, margin %.0f at the free geometry: "
                  "rejected", *quad.mean(axis=0), "" if light is None else " (lit)", excess0, margin0)
        return None

    def code_fit(q: NDArray[np.float64], sig: float, code: NDArray[np.float64]) -> tuple:
        return _fit_geometry(px, I, q, sig, n, border, code, params.code_iterations, light=light)
    # the free cells absorb part of the geometry's misfit (and in dim light let it drift), so the
    # leader is refitted with its own geometry, and ranked again there; a code that then beats it
    # is refitted in turn (at most top_codes in all)
    fits = {int(o[0]): code_fit(q1, s1, Wc[o[0]])}
    while True:
        best = min(fits, key=lambda k: fits[k][2])
        sse = _rank_codes(px, I, fits[best][0], fits[best][1], n, border, Wc, light)
        sse[list(fits)] = np.inf
        nxt = int(np.argmin(sse))
        if sse[nxt] >= fits[best][2] or len(fits) >= params.top_codes:
            break
        fits[nxt] = code_fit(fits[best][0], fits[best][1], Wc[nxt])
    # a refit only lowers a code's residual: the margin at the best geometry bounds the final one
    rest = [f[2] for k, f in fits.items() if k != best] + [float(sse.min())]
    if (min(rest) - fits[best][2]) / s2 < params.min_margin:
        log.debug("blurred candidate at (%.0f, %.0f): margin %.0f after the leader's fit: rejected",
                  *quad.mean(axis=0), (min(rest) - fits[best][2]) / s2)
        return None
    for ci in np.argsort(sse)[:2]:
        if int(ci) not in fits and (sse[ci] - fits[best][2]) / s2 < params.refit_margin:
            fits[int(ci)] = code_fit(fits[best][0], fits[best][1], Wc[ci])
            sse[ci] = np.inf
    best = min(fits, key=lambda k: fits[k][2])
    qb, sb, sse_b, cb, JtJ = fits[best]
    rest = [f[2] for k, f in fits.items() if k != best] + [float(sse.min())]
    excess = (sse_b - sse_free) / s2
    margin = (min(rest) - sse_b) / s2
    strict = excess <= max(max_excess, params.excess_share * margin)
    # the excess is a misfit spread over the marker where the free cells read as the code itself
    cell_px = float(np.linalg.norm(qb - np.roll(qb, -1, axis=0), axis=1).mean()) / n
    ok = ((strict or _cells_agree(cells, Wc, best, params)) and margin >= params.min_margin
          and cb[1] >= params.min_contrast and np.abs(qb - quad).max() <= params.max_shift_px
          and sb <= params.max_blur_cells * cell_px)
    log.debug("blurred candidate%s: code %d, residual SD %.2f, excess %.0f, margin %.0f -> %s%s",
              "" if light is None else " (lit)", best, np.sqrt(s2), excess, margin, ok, "" if strict else " (cells)")
    if not ok:
        return None
    N = len(I)
    s2b = sse_b / max(N - 11 - (0 if light is None else light.shape[1]), 1)
    with np.errstate(all="ignore"):
        cov = s2b * np.linalg.pinv(JtJ)[:8, :8]
    cov = np.stack([cov[2 * k:2 * k + 2, 2 * k:2 * k + 2] for k in range(4)])
    return BlurredRead(best, qb, cov, sb, float(np.sqrt(s2b)), float(margin)), bool(strict)


def read_blurred(gray: NDArray[np.uint8], quads: NDArray[np.float64], codes: NDArray[np.uint8], n: int,
                 border: int, params: BlurredParams, noise: float, alternatives: bool = False) -> list[BlurredRead]:
    """Read the markers of candidate ``quads`` (Q, 4, 2) by maximum likelihood (module docstring).

    The model with free cells nests every code's model, so for the right code the excess residual
    ``(SSE_code - SSE_free) / s^2`` is chi-square with ``d^2`` degrees of freedom (``s^2`` the free
    fit's residual variance): a goodness-of-fit test for the code that needs no absolute noise level.
    The absolute level (``noise``) only rejects candidates that even the free model cannot explain.

    Parameters
    ----------
    gray : (H, W) uint8, the image the quads are in (no lens model: small markers are near-linear).
    quads : (Q, 4, 2) candidates, clockwise on screen.
    codes : (C, d, d) every code of the family in every rotation as read in a quad's orientation.
    n, border : cells per side (border included) and border width, cells.
    params : :class:`BlurredParams`.
    noise : SD of the image noise, grey levels (:func:`image_noise`); each candidate's expected
        residual variance adds ``(params.texture_share * contrast)^2`` to its square.
    alternatives : the quads are outlines of one candidate (:func:`find_blurred_candidates`): they are
        read in order and the first read is the only one returned.

    Each quad is read from its own geometry and, where that reads nothing, from the quad moved onto
    the marker's outer edge (:func:`_starts`).

    Returns
    -------
    The accepted reads (their ``index`` the quad's).
    """
    C = codes.shape[0]
    Wc = codes.reshape(C, -1).astype(np.float64)
    d2 = Wc.shape[1]
    var_noise = max(noise, 0.5) ** 2

    def expected_var(contrast: float) -> float:
        # a marker's misfit beyond the noise scales with its contrast (texture_share in BlurredParams)
        return var_noise + (params.texture_share * max(contrast, 0.0)) ** 2
    # the right code's excess residual is chi-square(d2): mean d2, SD sqrt(2 d2)
    max_excess = d2 + params.max_excess_sd * np.sqrt(2.0 * d2)
    out = []
    with one_thread():  # (the detector holds it already; the products below are small)
        for group in [list(range(len(quads)))] if alternatives else [[i] for i in range(len(quads))]:
            for index, start, pixels in _starts(gray, quads, group, n, border, params, var_noise, d2):
                read = _read_one(pixels, start, Wc, n, border, params, var_noise, expected_var, max_excess)
                if read is not None:
                    out.append(dataclasses.replace(read, index=index))
                    break
    return out


def _starts(gray: NDArray[np.uint8], quads: NDArray[np.float64], group: list[int], n: int, border: int,
            params: BlurredParams, var_noise: float, d2: int
            ) -> list[tuple[int, NDArray[np.float64], tuple[NDArray[np.float64], NDArray[np.float64]]]]:
    """Geometries to read the outlines ``quads[group]`` (each (4, 2)) of one candidate from, in order, with
    the index of the outline each comes from and its pixels (:func:`_pixels` with half a cell around it:
    the screen's and the read's): at most ``params.max_starts`` of the outlines and of the
    best one moved onto the marker's outer edge (:func:`.outline.snap_to_border`), least misfit at the
    start screen first (:func:`_start_share`; it grows with a start's distance from the marker, and only
    the fits from the best are paid for). The reader's basin is about a pixel, a candidate's outline can
    be 1-4 px off."""
    starts = [(i, quads[i], _pixels(gray, quads[i], n, 0.5)) for i in group]
    share = [_start_share(pix, q, n, border, params, var_noise, d2) for _, q, pix in starts]
    best = int(np.argmin(share))
    # a start is moved onto the edge only where the model's misfit there is within twice what the start
    # screen passes: the 151 outlines of markers of seeds 0-2 of the hard bench showed 0.05-0.30 of
    # their contrast (10th-99th percentile), half the clutter's outlines more than 0.16
    snapped = (None if params.snap_reach_px <= 0 or not share[best] <= 2.0 * params.max_start_share
               else snap_to_border(gray, starts[best][1], n, params.snap_reach_px))
    if snapped is not None and np.abs(snapped - starts[best][1]).max() >= 0.1:
        starts.append((starts[best][0], snapped, _pixels(gray, snapped, n, 0.5)))
        share.append(_start_share(starts[-1][2], snapped, n, border, params, var_noise, d2))
    # those the start screen rejects are not read
    starts = [starts[j] for j in np.argsort(share, kind="stable") if share[j] <= params.max_start_share]
    return starts[:params.max_starts]


def _start_share(pixels: tuple[NDArray[np.float64], NDArray[np.float64]], quad: NDArray[np.float64], n: int,
                 border: int, params: BlurredParams, var_noise: float, d2: int) -> float:
    """The start screen of :func:`read_blurred` at the geometry ``quad`` (4, 2) with its ``pixels``
    (:func:`_pixels`: centres (N, 2), values (N,)), on a spread subset of about ``params.screen_px`` of
    them: the free model's misfit beyond the noise as a share of its fitted contrast, or inf where the
    screen rejects the start for another reason (too few pixels, too little contrast, a misfit beyond
    ``params.max_start_misfit`` times the expected one)."""
    px, I = pixels
    if len(I) < 3 * d2:
        return np.inf
    screen = _spread_subset(px, len(I) // params.screen_px)
    dof = max(int(screen.sum()) - 11 - d2, 1)
    _, _, sse, c, _ = _fit_geometry(px[screen], I[screen], quad, 1.5, n, border, None, 0)
    contrast = float(c[1])
    expected = var_noise + (params.texture_share * max(contrast, 0.0)) ** 2
    if contrast < params.min_contrast or sse > params.max_start_misfit**2 * expected * dof:
        log.debug("blurred candidate at (%.0f, %.0f): start SD %.2f, contrast %.0f: rejected",
                  *quad.mean(axis=0), np.sqrt(sse / dof), contrast)
        return np.inf
    return float(np.sqrt(max(sse / dof - var_noise, 0.0)) / contrast)


def _read_one(pixels: tuple[NDArray[np.float64], NDArray[np.float64]], quad: NDArray[np.float64],
              Wc: NDArray[np.float64], n: int, border: int, params: BlurredParams, var_noise: float,
              expected_var: Callable[[float], float], max_excess: float) -> BlurredRead | None:
    """Steps 2-5 of the module docstring for one geometry ``quad`` (4, 2) and its ``pixels`` (:func:`_pixels`
    with half a cell around it, as :func:`_starts` gives them) (:func:`read_blurred`'s other arguments and
    its closures ``expected_var`` and ``max_excess``): the read, or None."""
    d2 = Wc.shape[1]
    px, I = pixels
    N = len(I)
    if N < 3 * d2:
        return None
    dof = max(N - 11 - d2, 1)
    # the free fit only has to bring the geometry close, and the start screen (most of what clutter
    # costs) only to tell a marker's misfit from clutter's: both on a spread subset of the pixels
    half = _spread_subset(px, N // params.subsample_px)
    dof_h = max(int(half.sum()) - 11 - d2, 1)

    def hopeless(sse0: float, contrast: float, dof: int = dof_h) -> bool:
        # at the candidate's geometry a marker's misfit is a small share of its contrast (the
        # corners are within a pixel or two); clutter's is not, or there is no contrast at all
        excess_sd = np.sqrt(max(sse0 / dof - var_noise, 0.0))
        return (sse0 > params.max_start_misfit**2 * expected_var(contrast) * dof
                or contrast < params.min_contrast or excess_sd > params.max_start_share * contrast)

    def misfit(sse1: float, contrast: float, dof: int = dof_h) -> bool:
        # after an iteration of the free fit: beyond what any marker of this contrast leaves
        return sse1 > (1.1 * params.max_free_misfit) ** 2 * expected_var(contrast) * dof
    # the start screen on fewer pixels was passed (:func:`_starts`)
    q1, s1, sse_free, cf, _ = _fit_geometry(px[half], I[half], quad, 1.5, n, border, None, params.iterations,
                                            stop_start=hopeless, stop_iter=misfit)
    if not half.all() and sse_free <= (params.max_free_misfit**2) * expected_var(float(cf[1])) * dof_h:
        # the free model's residual on every pixel, for the excess test of the codes' fits
        _, _, sse_free, cf, _ = _fit_geometry(px, I, q1, s1, n, border, None, 0)
    else:
        sse_free *= dof / dof_h
    s2 = sse_free / dof
    var = expected_var(float(cf[1]))
    if (s2 > (params.max_free_misfit**2) * var or cf[1] < params.min_contrast
            or np.abs(q1 - quad).max() > params.max_shift_px):
        log.debug("blurred candidate at (%.0f, %.0f): free fit SD %.2f (expected %.2f), contrast %.0f, "
                  "shift %.1f px: rejected", *quad.mean(axis=0), np.sqrt(s2), np.sqrt(var), cf[1],
                  np.abs(q1 - quad).max())
        return None
    # the flat model first: where it reads, its corners are the most precise (the light field's
    # columns share the geometry's information: a plane looks like a shift of the square's blurred
    # edges, a bowl like a change of its size); where it does not, the model with the light field. A read
    # that passed on its free cells alone (:func:`_cells_agree`) is the last resort: under a highlight the
    # lit model's corners are the better ones (the glare test of tests/markers/test_blurred.py: median
    # corner error 1.06 px from the flat model's, below 0.6 px from the lit one's)
    got = _read_codes(px, I, quad, (q1, s1), sse_free, dof, Wc, n, border, params, None, max_excess, cf)
    if got is not None and got[1]:
        return got[0]
    fallback = None if got is None else got[0]
    light = _light_basis(px, quad, params.light_degree)
    if light is not None:
        # the free model with the field too (it nests every code's), at the free fit's geometry
        n_light = light.shape[1]
        _, _, sse_lit, c_lit, _ = _fit_geometry(px, I, q1, s1, n, border, None, 0, light=light)
        # only where the image shows a light field: the flat free model is nested in the lit one, so
        # without a field its residual drop is about chi-square with n_light degrees of freedom
        # (clutter read with the field's freedom had none: 1.4 units against 22-119 for glared markers)
        evidence = (sse_free - sse_lit) / (sse_lit / max(dof - n_light, 1))
        if evidence > n_light + params.light_evidence_sd * np.sqrt(2.0 * n_light):
            lit = _read_codes(px, I, quad, (q1, s1), sse_lit, max(dof - n_light, 1), Wc, n, border,
                              params, light, max_excess, c_lit)
            if lit is not None:
                return lit[0]
        else:
            log.debug("blurred candidate at (%.0f, %.0f): light field's evidence %.1f: no second reading",
                      *quad.mean(axis=0), evidence)
    return fallback
