"""Sub-pixel edges: a blurred-step model fitted to all the pixels of each marker edge.

Each edge of a candidate quadrilateral is the line ``n(theta) . (x - m) = rho`` (``m`` a fixed point
near the edge's middle, ``n = (cos theta, sin theta)`` pointing out of the black square). The
intensity of a pixel at signed distance ``d`` from the line is modelled as

    I(d, u) = (a + b * Phi(d / sigma)) * (1 + c * d + c_u * u)

(``Phi`` the standard normal CDF): a step from the black level ``a`` to the white level ``a + b``
blurred by a Gaussian of standard deviation ``sigma`` (optics plus pixel integration), under an
illumination that changes linearly across (``c``) and along (``c_u``, ``u`` the coordinate along the
edge from ``m``) the edge. Without the shading terms a lighting gradient or vignetting biases the
fitted line: the along-edge term, odd in ``u``, correlates with the line's angle and turns it,
moving the corners by up to 0.1 px at blur 2 px. The seven parameters
``(theta, rho, a, b, log sigma, c, c_u)`` of every edge are estimated jointly by damped
Gauss-Newton (Levenberg-Marquardt) on the pixels of a band around the edge, ends excluded. For a
straight edge the model is point-symmetric about the line, so the edge position is unbiased even
where the true blur kernel is not exactly Gaussian; this is what removes the inward pull of
gradient-based refinements. The approach is that of model-based edge localisation (e.g. Ye, Fan,
"Sub-pixel edge detection..." and the blurred-edge models of Kisworo, Venkatesh and West, 1994)
applied to the four lines of a square marker; corners are intersections of adjacent lines
(Hartley and Zisserman, "Multiple View Geometry", 2.2) and their 2 x 2 covariances are propagated
to first order from the (theta, rho) covariance of each fit, ``s^2 (J^T J)^-1``.

Clipped pixels are censored observations: a pixel at 255 (or 0) only says that the model's value is
at least (at most) that. White paper in sunlight often clips; fitting the clipped profile as if it
were the real one takes the white level for 255, puts the half-way grey too close to the black side
and shrinks a marker by 0.2-0.3 px per edge (a 0.5 % scale error, 1 cm in depth at 2.5 m). A clipped
pixel whose model value is beyond the clip level therefore adds neither residual nor gradient (Tobit
regression's hinge); the white level is then free to rise above 255, set by the unclipped pixels of
the ramp, and its uncertainty goes into the line's covariance. Only one side of the ramp is then
seen, so the symmetry argument above no longer holds and the profile's shape must be right: on
edges with clipped pixels the Gaussian ``Phi(d / sigma)`` is replaced by the step blurred by the
optics and integrated over the square pixel (:func:`pixel_step`), which takes four evaluations of
``Phi`` instead of one. On simulated over-exposed markers (white at 1.4-2.1 x the clip level) this
takes the corner error from 0.2-1.2 px (plain fit) to 0.012-0.017 px at blur 0, 0.04-0.08 px at
blur 0.5 px and 0.06-0.13 px at blur 1 px.

Coordinates are "fit coordinates": raw pixels, or undistorted pixels when a camera model is given
(edges are straight only after undistortion). Pixel centres are at integer coordinates.
"""

from __future__ import annotations

import dataclasses
import itertools
import warnings
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy.special import ndtr

from gtrig.markers.detect import _edge_kernels, _kernels, _threads
from gtrig.markers.detect.camera import Undistorter

_INV_SQRT_2PI = 1.0 / np.sqrt(2.0 * np.pi)
#: 8-bit clip levels: a pixel at or beyond these is censored (see the module docstring)
CLIP_LOW, CLIP_HIGH = 0.5, 254.5
#: variance of a unit box: a pixel's integration across an edge, px^2
PIXEL_VAR = 1.0 / 12.0
#: iteration limit of edges with clipped pixels, in multiples of the normal one
CLIPPED_ITER_FACTOR = 4
#: largest white level of a clipped edge, in multiples of the visible contrast: when only the foot of a
#: ramp is below the clip (a motion-blurred edge, whose ramp is linear), contrast and blur trade off and
#: the fit runs to a white level of thousands with a blur of a pixel, which spoils the decoding
MAX_CLIPPED_WHITE = 4.0
#: band pixels of one fit below which splitting it between threads costs more than it saves
_SPLIT_MIN_PX = 2000
#: parts a split fit is cut into (:func:`._threads.run_split`): with two, the calling thread waited for
#: the helper's half in 15 % of its samples on a loaded machine; with four the wait is at
#: most the part the helper is finishing
SPLIT_PARTS = 4
#: share of an edge's band pixels clipped above which the edge is fitted as clipped
CLIPPED_EDGE_SHARE = 0.1
#: effective Gaussian blur (px) below which an edge is refitted with the pixel-integrated step: a pixel
#: integrating the light of its square cannot show a step sharper than its own box (SD 0.29 px), but
#: aliased or sharpened photos do (the ChArUco photos of ``markers_real`` are nearly binary, edges
#: within one pixel), and there the Gaussian fit runs to its bound of 0.05 px, where the model is flat
#: in the line's position between pixel centres
SHARP_SIGMA_PX = 0.2


@dataclass(frozen=True)
class EdgeFit:
    """Fits of ``E`` edges (arrays of length E unless stated).

    theta, rho : line ``(cos theta, sin theta) . (x - mid) = rho``, fit coordinates.
    mid : (E, 2) the reference points.
    a, b, sigma : black level, white minus black (grey levels) and effective blur (pixels): the
        standard deviation of the optics' Gaussian and the pixel's unit box together.
    shade : (E, 2) relative illumination change per pixel across and along the edge.
    cov_line : (E, 2, 2) covariance of (theta, rho).
    rms : residual RMS (grey levels).
    n_px : pixels used.
    ok : the fit converged to a plausible edge.
    """

    theta: NDArray[np.float64]
    rho: NDArray[np.float64]
    mid: NDArray[np.float64]
    a: NDArray[np.float64]
    b: NDArray[np.float64]
    sigma: NDArray[np.float64]
    shade: NDArray[np.float64]
    cov_line: NDArray[np.float64]
    rms: NDArray[np.float64]
    n_px: NDArray[np.int64]
    ok: NDArray[np.bool_]

    def lines(self) -> NDArray[np.float64]:
        """(E, 3) lines ``(nx, ny, c)`` with ``n . x = c``."""
        n = np.column_stack([np.cos(self.theta), np.sin(self.theta)])
        return np.column_stack([n, self.rho + np.einsum("ij,ij->i", n, self.mid)])


@dataclass(frozen=True)
class EdgeSamples:
    """Band pixels of all edges, concatenated and sorted by edge.

    xy : (N, 2) fit coordinates; val : (N,) intensities; edge : (N,) edge index; starts : (E,) first
    index of each edge in the arrays (edges without pixels have none).
    """

    xy: NDArray[np.float64]
    val: NDArray[np.float64]
    edge: NDArray[np.int64]
    starts: NDArray[np.int64]


def gather_band(
    gray: NDArray[np.uint8],
    p0: NDArray[np.float64],
    p1: NDArray[np.float64],
    w_in: NDArray[np.float64],
    w_out: NDArray[np.float64],
    end_excl: NDArray[np.float64],
    undist: Undistorter | None = None,
    stride: NDArray[np.int64] | int = 1,
) -> EdgeSamples:
    """Pixels in a band around each edge ``p0[e] -> p1[e]`` (E, 2), in fit coordinates.

    The band spans ``-w_in[e] <= d <= w_out[e]`` across the edge (``d > 0`` outside, i.e. to the left
    of the direction ``p0 -> p1`` on screen for a clockwise quad) and leaves ``end_excl[e]`` pixels out
    at both ends. With ``undist`` the band is selected in undistorted coordinates (raw pixels mapped
    through ``undist.map_x/map_y``) and the returned coordinates are undistorted. ``stride`` (E,) or
    scalar: only every ``stride``-th raw pixel column across the edge (row, for an edge nearer the
    vertical) is taken (:func:`band_stride`), counted from the column of ``p0`` (with ``undist``, from the
    first of the band's raw bounding box), so that a crop of the image takes the same pixels.
    """
    p0 = np.asarray(p0, np.float64)
    p1 = np.asarray(p1, np.float64)
    E = len(p0)
    t = p1 - p0
    L = np.hypot(t[:, 0], t[:, 1])
    t = t / L[:, None]
    n = np.column_stack([t[:, 1], -t[:, 0]])
    w_in, w_out, end_excl = (np.ascontiguousarray(np.broadcast_to(np.asarray(a, np.float64), (E,)))
                             for a in (w_in, w_out, end_excl))
    step = np.ascontiguousarray(np.broadcast_to(np.asarray(stride, np.int64), (E,)))
    if undist is None:
        x, y, val, edge = _edge_kernels.gather_raw(np.ascontiguousarray(gray), p0, p1, w_in, w_out, end_excl, step)
        return EdgeSamples(np.column_stack([x, y]), val, edge, _starts(edge, E))
    ix, iy, edge = _band_boxes_undistorted(gray.shape, p0, p1, t, n, w_in, w_out, undist)
    # every stride-th raw column (row) from the first of the edge's box (:func:`_band_boxes_undistorted`)
    vertical = np.abs(t[edge, 1]) > np.abs(t[edge, 0])
    major = np.where(vertical, iy, ix)
    first = np.full(E, np.iinfo(np.int64).max)
    np.minimum.at(first, edge, major)
    on = (major - first[edge]) % step[edge] == 0
    ix, iy, edge = ix[on], iy[on], edge[on]
    px = undist.map_x[iy, ix].astype(np.float64)
    py = undist.map_y[iy, ix].astype(np.float64)
    # the exact band test (the pixel sets above are supersets)
    rx, ry = px - p0[edge, 0], py - p0[edge, 1]
    s = rx * t[edge, 0] + ry * t[edge, 1]
    d = rx * n[edge, 0] + ry * n[edge, 1]
    sel = (d >= -w_in[edge]) & (d <= w_out[edge]) & (s >= end_excl[edge]) & (s <= (L - end_excl)[edge])
    edge = edge[sel]
    return EdgeSamples(np.column_stack([px[sel], py[sel]]), gray[iy[sel], ix[sel]].astype(np.float64), edge,
                       _starts(edge, E))


#: width of the bins of :func:`white_extent`'s across-edge profile (pixels)
PROFILE_STEP_PX = 0.5
#: fall below the white level, in units of the edge's contrast, that ends the white plateau: deeper
#: than a phone's sharpening halo settles back from its overshoot (the grid photo's tenth percentile
#: stays within 0.09 of its white level from 2 to 14 px beyond the edge), shallow enough to catch any
#: surround that would move the line (BENCHMARKS.md)
WHITE_END_DROP = 0.25
#: how far (in blur sigmas) the band stops short of the paper's end: the surround's blurred step is
#: 0.6 % of its fall there (1.5 sigma, 7 %, left 0.02-0.04 px outward on a mid-grey surround)
WHITE_END_SIGMAS = 2.5


def white_extent(
    samples: EdgeSamples,
    p0: NDArray[np.float64],
    p1: NDArray[np.float64],
    sigma: NDArray[np.float64],
    w_in: NDArray[np.float64],
    w_out: NDArray[np.float64],
    across: NDArray[np.float64] | None = None,
) -> NDArray[np.float64]:
    """Each edge's outer band limit where its white quiet zone ends, measured from the image.

    Outside a marker's black border lies white paper, and beyond it whatever the marker is stuck on.
    The step model sees only black and white: pixels of a darker surround in the band lower the
    fitted white level and tilt the shading, and the line moves outward (0.1-0.2 px on the
    simulator's 12 mm margins, 4.7 px at its cameras, with a band 5 px beyond ``3 sigma``). The
    band must therefore end before the paper does, however wide ``w_out`` allows.

    The mean of each edge's band pixels is taken in bins of :data:`PROFILE_STEP_PX` across the edge
    (``d``, pixels, > 0 outside; the mean, not the median, since the fit's bias follows the mean
    deficit), bounded at multiples of the bin width from the line (:func:`profile_origin`), so that an
    edge's bins do not depend on the other edges measured with it. The black level is the darkest
    bin inside (``-w_in <= d <= -sigma``), the white level the mean over
    ``2 sigma <= d <= 2 sigma + 1``; walking outward from ``2 sigma``, the plateau
    ends where the profile first falls :data:`WHITE_END_DROP` of the contrast below the white
    level; the paper's end is then where it is half-way between the white level and the lowest bin
    beyond (linearly interpolated between bin centres: a step's half-way point, whatever the
    surround's level), and the band ends :data:`WHITE_END_SIGMAS` blur sigmas before that. Only a
    fall ends it: a sharpening halo rises above the plateau and settles back, and a surround brighter
    than the paper is rare. Edges whose profile shows no such fall keep ``w_out``.

    Parameters
    ----------
    samples : band pixels of :func:`gather_band` with the limits ``w_in``, ``w_out`` (fit coordinates).
    p0, p1 : (E, 2) the edges' end points, the line the band was gathered around (fit coordinates).
    sigma : (E,) current blur estimate (pixels).
    w_in, w_out : (E,) the band's inner and outer half-widths (pixels).
    across : (N,) :func:`across_edge` of ``samples``, ``p0``, ``p1`` if known (else computed).

    Returns
    -------
    (E,) the outer limit (pixels beyond the line), at most ``w_out`` and at least ``min(w_out,
    max(1.5, sigma))`` (a margin narrower than that biases any step fit; the band keeps a ramp to fit,
    1.5 px as the small markers' outer band: a 20 px tag on a one-cell quiet zone needs it).
    """
    E = len(p0)
    w_in = np.broadcast_to(np.asarray(w_in, np.float64), (E,))
    w_out = np.broadcast_to(np.asarray(w_out, np.float64), (E,))
    sigma = np.broadcast_to(np.asarray(sigma, np.float64), (E,))
    out = w_out.copy()
    if E == 0 or len(samples.val) == 0:
        return out
    e = samples.edge
    d = across_edge(samples, p0, p1) if across is None else across
    lo = profile_origin(float(np.max(w_in)))
    nb = int(np.ceil((lo + float(np.max(w_out))) / PROFILE_STEP_PX)) + 1
    # the bins' counts and sums in one compiled pass (the same sums, in the pixels' order)
    cnt, tot = _kernels.band_profile(np.ascontiguousarray(d, np.float64), np.ascontiguousarray(e, np.int64),
                                     np.ascontiguousarray(samples.val, np.float64), lo, PROFILE_STEP_PX, nb, E)
    with np.errstate(invalid="ignore", divide="ignore"):
        prof = np.where(cnt >= 3, tot / cnt, np.nan)  # a bin of a couple of pixels says little
    centre = (np.arange(nb) + 0.5) * PROFILE_STEP_PX - lo  # (nb,)
    c = centre[None, :]
    s = sigma[:, None]
    inside = (c >= -w_in[:, None]) & (c <= -s)
    near = (c >= 2.0 * s) & (c <= 2.0 * s + 1.0)
    with np.errstate(invalid="ignore"), warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # all-NaN rows: edges left as they are
        black = np.nanmin(np.where(inside, prof, np.nan), axis=1)
        white = np.nanmean(np.where(near, prof, np.nan), axis=1)
    thr = white - WHITE_END_DROP * (white - black)
    below = (c >= 2.0 * s) & (c <= w_out[:, None]) & (prof < thr[:, None])
    below &= np.isfinite((white - black)[:, None]) & ((white - black) > 0)[:, None]
    has = below.any(axis=1)
    if not has.any():
        return out
    rows = np.flatnonzero(has)
    first = np.argmax(below[rows], axis=1)
    # the paper's end is where the profile is half-way down to the surround (the lowest bin beyond the
    # first fall); a fixed fall of WHITE_END_DROP would place it late on a surround that is only a
    # little darker than the paper
    after = np.arange(nb)[None, :] >= first[:, None]
    reach = c <= w_out[:, None]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        low = np.nanmin(np.where(after & reach[rows], prof[rows], np.nan), axis=1)
    half = np.minimum(0.5 * (white[rows] + low), thr[rows])
    fall = (c >= 2.0 * s[rows]) & reach[rows] & (prof[rows] < half[:, None])
    kk = np.where(fall.any(axis=1), np.argmax(fall, axis=1), first)
    level = np.where(fall.any(axis=1), half, thr[rows])
    d_end = centre[kk].copy()
    # interpolate between the crossing bin and the one before it, when that one is above the level
    prev = prof[rows, np.maximum(kk - 1, 0)]
    cur = prof[rows, kk]
    ok = (kk > 0) & np.isfinite(prev) & (prev > cur)
    frac = np.where(ok, (prev - level) / np.where(ok, prev - cur, 1.0), 1.0)
    d_end = np.where(ok, centre[np.maximum(kk - 1, 0)] + np.clip(frac, 0.0, 1.0) * PROFILE_STEP_PX, d_end)
    lim = d_end - WHITE_END_SIGMAS * sigma[rows]
    floor = np.minimum(w_out[rows], np.maximum(1.5, sigma[rows]))
    out[rows] = np.clip(lim, floor, w_out[rows])
    return out


def profile_origin(w_in: float) -> float:
    """The origin (pixels inside the line) of :func:`white_extent`'s bins for inner bands up to ``w_in``
    wide: the first multiple of :data:`PROFILE_STEP_PX` beyond ``w_in``, so that every bin is bounded at
    multiples of the bin width from the line and no pixel of the band is before the first."""
    return float(PROFILE_STEP_PX * (np.floor(w_in / PROFILE_STEP_PX) + 1.0))


def trim_outer(samples: EdgeSamples, p0: NDArray[np.float64], p1: NDArray[np.float64],
               w_out: NDArray[np.float64], across: NDArray[np.float64] | None = None) -> EdgeSamples:
    """``samples`` without the pixels beyond ``w_out[e]`` (E,) outside their edge ``p0 -> p1`` (fit
    coordinates; the distance as in :func:`gather_band`, ``across`` if known: :func:`across_edge`)."""
    d = across_edge(samples, p0, p1) if across is None else across
    keep = d <= np.asarray(w_out, np.float64)[samples.edge]
    if keep.all():
        return samples
    # the kept pixels copied in one compiled pass (three NumPy gathers and a search before)
    xy, val, edge, starts = _kernels.band_keep(np.ascontiguousarray(samples.xy, np.float64),
                                               np.ascontiguousarray(samples.val, np.float64),
                                               np.ascontiguousarray(samples.edge, np.int64), keep, len(p0))
    return EdgeSamples(xy, val, edge, starts)


def across_edge(samples: EdgeSamples, p0: NDArray[np.float64], p1: NDArray[np.float64]) -> NDArray[np.float64]:
    """(N,) each band pixel's signed distance across its edge ``p0 -> p1`` (pixels, > 0 outside: the
    normal ``(t_y, -t_x)`` of :func:`gather_band`)."""
    t = p1 - p0
    t = t / np.hypot(t[:, 0], t[:, 1])[:, None]
    e = samples.edge
    rel = samples.xy - p0[e]
    return rel[:, 0] * t[e, 1] - rel[:, 1] * t[e, 0]


def _starts(edge: NDArray[np.int64], E: int) -> NDArray[np.int64]:
    """First index of each of ``E`` edges in ``edge`` (sorted), -1 for edges without pixels."""
    # a binary search in the sorted indices: np.unique sorted them again (0.13 against 0.013 ms on 30,000
    # band pixels; called for every band and trim)
    pos = np.searchsorted(edge, np.arange(E, dtype=edge.dtype))
    found = np.zeros(E, bool)
    inside = pos < len(edge)
    found[inside] = edge[pos[inside]] == np.flatnonzero(inside)
    return np.where(found, pos, -1).astype(np.int64)


def _band_boxes_undistorted(
    shape: tuple[int, ...], p0: NDArray[np.float64], p1: NDArray[np.float64], t: NDArray[np.float64],
    n: NDArray[np.float64], w_in: NDArray[np.float64], w_out: NDArray[np.float64], undist: Undistorter,
) -> tuple[NDArray[np.intp], NDArray[np.intp], NDArray[np.int64]]:
    """Raw pixels (x, y) and edge index of each edge's band's bounding box in the raw image (the
    band is straight only in undistorted coordinates, so its raw outline is bounded by a box)."""
    h, w = shape[:2]
    xs, ys, eds = [], [], []
    for e in range(len(p0)):
        a, b, te, ne = p0[e], p1[e], t[e], n[e]
        ext = max(w_in[e], w_out[e])
        box = undist.to_raw(np.array([a - ext * (ne + te), a + ext * (ne - te), b - ext * (ne - te),
                                      b + ext * (ne + te)]))
        x0 = max(int(np.floor(box[:, 0].min())) - 1, 0)
        x1 = min(int(np.ceil(box[:, 0].max())) + 2, w)
        y0 = max(int(np.floor(box[:, 1].min())) - 1, 0)
        y1 = min(int(np.ceil(box[:, 1].max())) + 2, h)
        if x1 <= x0 or y1 <= y0:
            continue
        gy, gx = np.mgrid[y0:y1, x0:x1]
        xs.append(gx.ravel())
        ys.append(gy.ravel())
        eds.append(np.full(gx.size, e, np.int64))
    if not xs:
        z = np.zeros(0, np.intp)
        return z, z, np.zeros(0, np.int64)
    return np.concatenate(xs), np.concatenate(ys), np.concatenate(eds)


def pixel_step(d: NDArray[np.float64], s: NDArray[np.float64], cos_t: NDArray[np.float64],
               sin_t: NDArray[np.float64]) -> tuple[NDArray[np.float64], ...]:
    """A unit step blurred by a Gaussian of ``s`` px and integrated over a square pixel, at signed
    distances ``d`` (pixel centre to the edge line, whose normal is ``(cos_t, sin_t)``).

    The pixel projects across the edge as the sum of two boxes of widths ``w1 = |cos_t|`` and
    ``w2 = |sin_t|``, so the profile is ``D[G2] / (w1 w2)`` with
    ``D[f] = f(d+h1+h2) - f(d+h1-h2) - f(d-h1+h2) + f(d-h1-h2)``, ``h = w / 2`` and
    ``G2(x) = (x^2 + s^2) / 2 Phi(x/s) + x s / 2 phi(x/s)`` the second antiderivative of ``Phi(x/s)``.
    Its derivatives follow from ``dG2/dx = x Phi + s phi`` and ``dG2/ds = s Phi``.

    Returns
    -------
    profile, d profile / d d, d profile / d log s : (N,) each.
    """
    # an axis-aligned edge has w2 = 0: the differences stay exact to ~1e-11 down to w2 = 1e-4
    w1 = np.maximum(np.abs(cos_t), 1e-4)
    w2 = np.maximum(np.abs(sin_t), 1e-4)
    h1, h2 = 0.5 * w1, 0.5 * w2
    s2 = s * s
    prof = np.zeros_like(d)
    slope = np.zeros_like(d)
    dls = np.zeros_like(d)
    for o1, o2, sign in ((1.0, 1.0, 1.0), (1.0, -1.0, -1.0), (-1.0, 1.0, -1.0), (-1.0, -1.0, 1.0)):
        x = d + o1 * h1 + o2 * h2
        z = x / s
        cdf = ndtr(z)
        sphi = s * _INV_SQRT_2PI * np.exp(-0.5 * z * z)
        prof += sign * (0.5 * (x * x + s2) * cdf + 0.5 * x * sphi)
        slope += sign * (x * cdf + sphi)
        dls += sign * cdf
    iw = 1.0 / (w1 * w2)
    return prof * iw, slope * iw, dls * (iw * s2)


def fit_sharp_edges(
    samples: EdgeSamples,
    p0: NDArray[np.float64],
    p1: NDArray[np.float64],
    sigma0: NDArray[np.float64],
    iterations: int = 10,
    extra: NDArray[np.float64] | None = None,
    init: EdgeFit | None = None,
    tol: float = 1e-4,
    threads: int = 1,
    pixel_model: bool = False,
    sharp: NDArray[np.bool_] | None = None,
) -> tuple[EdgeFit, NDArray[np.bool_]]:
    """Fit the blurred-step model to every edge (see the module docstring); also the edges (E,) sharper than
    a pixel: those fitted with the pixel-integrated step without being saturated.

    Parameters
    ----------
    samples : band pixels from :func:`gather_band` (sorted by edge).
    p0, p1 : (E, 2) initial edge end points (fit coordinates); the initial line passes through them.
    sigma0 : (E,) initial blur, pixels.
    iterations : largest number of Levenberg-Marquardt iterations per edge.
    extra : (N,) optional known part of the profile, in units of the contrast ``b``, added to
        ``Phi(d / sigma)`` and held fixed (see :func:`marker_context`): the blurred light of the
        marker's other edges and of its white data cells, which the straight-step model lacks.
    init : a previous fit of the same edges to start from (its levels, shading and line, the line
        moved to the new reference points; the blur starts from ``sigma0``); without it the levels
        come from the band means.
    tol : an edge stops iterating once a step moves its line by less than this (pixels, the
        angle step weighted by the square root of the edge's pixel count, about its half length);
        the others go on, so well-conditioned edges do not pay for slow ones.
    threads : with 2 the edges are fitted in two groups of about equal pixel counts at once.
    pixel_model : fit every edge with the pixel-integrated step (:func:`pixel_step`). Otherwise only
        edges with clipped pixels are, and edges whose Gaussian blur falls below
        :data:`SHARP_SIGMA_PX` are refitted so (steps sharper than the pixel box).
    sharp : (E,) edges a previous pass found sharper than a pixel: fitted with the pixel-integrated step
        from the start (their Gaussian fit would only run the blur down to its bound again).
    """
    E = len(p0)
    t = p1 - p0
    t /= np.linalg.norm(t, axis=1, keepdims=True)
    n = np.column_stack([t[:, 1], -t[:, 0]])
    mid = 0.5 * (p0 + p1)
    theta = np.arctan2(n[:, 1], n[:, 0])
    rho = np.zeros(E)
    e = samples.edge
    v = np.ascontiguousarray(samples.val, np.float64)
    N = len(v)
    # the pixels relative to their edge's middle, the counts and the clipped pixels in one compiled pass
    # (eight passes of NumPy over the band were a third of this function's own time)
    X0, X1, cnt, clipped, n_clipped = _kernels.band_prep(np.ascontiguousarray(samples.xy, np.float64),
                                                         np.ascontiguousarray(e, np.int64),
                                                         np.ascontiguousarray(mid), v, E, CLIP_LOW, CLIP_HIGH)
    ls = np.log(np.maximum(sigma0, 0.3))
    if init is not None:
        n_old = np.column_stack([np.cos(init.theta), np.sin(init.theta)])
        rho_old = init.rho + np.einsum("ij,ij->i", n_old, init.mid - mid)
        P = np.column_stack([init.theta, rho_old, init.a, init.b, ls, init.shade])
    else:
        # initial levels: mean of the inner and outer halves of the band
        inner = (X0 * n[e, 0] + X1 * n[e, 1]) < 0
        sum_in = np.bincount(e, weights=v * inner, minlength=E)
        n_in = np.bincount(e, weights=inner.astype(float), minlength=E)
        sum_out = np.bincount(e, weights=v * ~inner, minlength=E)
        a = sum_in / np.maximum(n_in, 1)
        b = sum_out / np.maximum(cnt - n_in, 1) - a
        P = np.stack([theta, rho, a, b, ls, np.zeros(E), np.zeros(E)], axis=1)  # (E, 7)
    ext = np.zeros(N) if extra is None else np.asarray(extra, np.float64)
    NP = 7
    has = cnt > 8
    wt = np.sqrt(cnt)
    any_clipped = bool(n_clipped.any())
    # edges with a tenth of their band clipped (a saturated side, not noise in a dim black): fitted
    # with the pixel-integrated step, whose blur parameter is the optics' alone (sigma0 and the
    # returned sigma are the effective blur, optics and pixel together)
    slow = n_clipped > CLIPPED_EDGE_SHARE * cnt if any_clipped else np.zeros(E, bool)
    saturated = slow
    if pixel_model:
        slow = np.ones(E, bool)
    if sharp is not None:
        slow = slow | sharp
    if slow.any():
        P[slow, 4] = np.log(np.sqrt(np.maximum(np.exp(2 * P[slow, 4]) - PIXEL_VAR, 0.05**2)))
        # start the white level above the clip: from there the clipped pixels agree and the ramp's
        # pixels pull it down smoothly; from the clip level the hinge can hold it (a local minimum)
        P[saturated, 3] = np.minimum(np.maximum(P[saturated, 3], 2.0 * (CLIP_HIGH - P[saturated, 2])),
                                     MAX_CLIPPED_WHITE * (CLIP_HIGH - P[saturated, 2]))
    # a clipped edge's white level converges slowly (only the ramp's unclipped pixels set it) and
    # drags the line with it: such edges get more iterations and must also settle their contrast
    bounds = np.concatenate([[0], np.cumsum(cnt.astype(np.int64))])
    pix = (X0, X1, v, np.ascontiguousarray(ext))
    clip_arg = clipped if any_clipped else np.zeros(0, bool)
    P = np.ascontiguousarray(P, np.float64)
    # edges are independent: groups of edges of about equal pixel counts, claimed in turn by the threads
    cut = [0, E]
    if threads > 1 and N > _SPLIT_MIN_PX and E > 1:
        inner = np.clip(np.searchsorted(bounds, np.arange(1, SPLIT_PARTS) / SPLIT_PARTS * N), 1, E - 1)
        cut = [0, *sorted({int(c) for c in inner}), E]
    parts = [(*pix, bounds[a:b + 1], P[a:b], has[a:b], clip_arg, slow[a:b], iterations, CLIPPED_ITER_FACTOR, tol,
              wt[a:b], np.log(0.05), np.log(20.0), MAX_CLIPPED_WHITE, CLIP_LOW, CLIP_HIGH)
             for a, b in itertools.pairwise(cut)]
    res = _threads.run_split(_kernels.edge_lm, parts)
    P, cur, JTJ = (np.concatenate([r[k] for r in res]) for k in range(3))
    dof = np.maximum(cnt - NP, 1)
    s2 = cur / dof
    with np.errstate(all="ignore"):
        cov = np.linalg.pinv(JTJ)[:, :2, :2] * s2[:, None, None]
    ok = has & np.all(np.isfinite(P), axis=1) & np.all(np.isfinite(cov.reshape(E, -1)), axis=1)
    sigma = np.where(slow, np.sqrt(np.exp(2 * P[:, 4]) + PIXEL_VAR), np.exp(P[:, 4]))  # effective blur
    out = EdgeFit(P[:, 0], P[:, 1], mid, P[:, 2], P[:, 3], sigma, P[:, 5:7], cov, np.sqrt(s2),
                  cnt.astype(np.int64), ok)
    refit_sel = has & ~slow & (sigma < SHARP_SIGMA_PX)
    found = (slow & ~saturated) | refit_sel
    if not refit_sel.any():
        return out, found
    # edges sharper than a pixel: refitted with the pixel-integrated step, from the start
    sel = refit_sel[e]
    remap = np.cumsum(refit_sel) - 1
    sub_e = remap[e[sel]]
    sub = EdgeSamples(samples.xy[sel], v[sel], sub_e, _starts(sub_e, int(refit_sel.sum())))
    sub_init = None if init is None else _subset(init, refit_sel)
    refit, _ = fit_sharp_edges(sub, p0[refit_sel], p1[refit_sel], np.asarray(sigma0, np.float64)[refit_sel],
                               iterations, None if extra is None else ext[sel], sub_init, tol, threads,
                               pixel_model=True)
    return _merge(out, refit_sel, refit), found


def share_white(samples: EdgeSamples, fit: EdgeFit, sigma0: NDArray[np.float64], first: bool,
                params: RefineParams, extra: NDArray[np.float64] | None = None) -> EdgeFit:
    """``fit`` of quads' edges (4q .. 4q + 3) with each quad's saturated edges refitted where their white
    level exceeds the paper's, read on the quad's sharpest saturated edge (``_edge_kernels.share_white``,
    which :func:`refine_quads` calls in each pass): a clipped edge smeared across by motion trades its
    contrast against its blur and runs its white level up, moving its line into the white.

    ``samples``, ``sigma0`` and ``extra`` are those ``fit`` was fitted from; ``first`` the first pass
    (no covariances).
    """
    E = len(fit.theta)
    v = np.ascontiguousarray(samples.val, np.float64)
    rel = samples.xy - fit.mid[samples.edge]
    X0, X1 = np.ascontiguousarray(rel[:, 0]), np.ascontiguousarray(rel[:, 1])
    bounds = np.concatenate([[0], np.cumsum(np.bincount(samples.edge, minlength=E))]).astype(np.int64)
    ext = np.zeros(len(v)) if extra is None else np.ascontiguousarray(extra, np.float64)
    # (the blur's parameter is not read: a refit starts from ``sigma0``)
    P = np.column_stack([fit.theta, fit.rho, fit.a, fit.b, np.zeros(E), fit.shade])
    mid, sigma, cov = fit.mid.copy(), fit.sigma.copy(), fit.cov_line.copy()
    rms, ok = fit.rms.copy(), fit.ok.copy()
    cfg = _fit_cfg(params, first)
    for q in range(E // 4):
        sl = slice(4 * q, 4 * q + 4)
        _edge_kernels.share_white(X0, X1, v, ext, bounds[4 * q:4 * q + 5], np.ascontiguousarray(sigma0[sl]), first,
                                  cfg, P[sl], mid[sl], sigma[sl], cov[sl], rms[sl], ok[sl])
    return _edge_fit(P, mid, sigma, cov, rms, fit.n_px, ok)


def _subset(fit: EdgeFit, sel: NDArray[np.bool_]) -> EdgeFit:
    """The edges ``sel`` of ``fit``."""
    return EdgeFit(*(getattr(fit, f.name)[sel] for f in dataclasses.fields(EdgeFit)))


def _merge(fit: EdgeFit, sel: NDArray[np.bool_], part: EdgeFit) -> EdgeFit:
    """``fit`` with its edges ``sel`` replaced by ``part`` (a new EdgeFit; ``fit`` is unchanged)."""
    vals = {}
    for f in dataclasses.fields(EdgeFit):
        a = getattr(fit, f.name).copy()
        a[sel] = getattr(part, f.name)
        vals[f.name] = a
    return EdgeFit(**vals)


#: each corner's first line: corner ``k`` of a quad lies on edges ``k - 1`` and ``k``
_PREV = np.roll(np.arange(4), 1)


def _corner_lines(theta: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64],
                                                        NDArray[np.float64]]:
    """The unit normals (Q, 4, 2) of each corner's two lines (edges ``k - 1`` and ``k`` of ``theta`` (Q, 4),
    radians) and the inverse (Q, 4, 2, 2) of the matrix with them as rows (NaN where they are parallel):
    a corner moves by ``A^-1 e_j`` when its line ``j`` moves by one pixel along its normal."""
    n1 = np.stack([np.cos(theta[:, _PREV]), np.sin(theta[:, _PREV])], -1)
    n2 = np.stack([np.cos(theta), np.sin(theta)], -1)
    with np.errstate(all="ignore"):
        Ainv = np.linalg.inv(np.stack([n1, n2], axis=-2))
    return n1, n2, Ainv


def intersect_corners(fit: EdgeFit, n_quads: int) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Corners and their covariances from the fitted lines of ``n_quads`` quads (edges 4q .. 4q+3).

    Corner ``i`` of a quad is the intersection of its edges ``i - 1`` and ``i``. With the lines
    ``n_k . x = rho_k + n_k . m_k`` the corner is ``x = A^-1 r``; to first order
    ``dx/drho_k = A^-1 e_k`` and ``dx/dtheta_k = A^-1 e_k (t_k . (m_k - x))`` with ``t_k = dn_k/dtheta``.

    Returns
    -------
    corners : (Q, 4, 2); cov : (Q, 4, 2, 2)
    """
    th = fit.theta.reshape(n_quads, 4)
    rh = fit.rho.reshape(n_quads, 4)
    m = fit.mid.reshape(n_quads, 4, 2)
    C = fit.cov_line.reshape(n_quads, 4, 2, 2)
    th1, th2 = th[:, _PREV], th
    n1, n2, Ainv = _corner_lines(th)
    m1, m2 = m[:, _PREV], m
    r = np.stack([rh[:, _PREV] + np.einsum("qij,qij->qi", n1, m1), rh + np.einsum("qij,qij->qi", n2, m2)], -1)
    x = np.einsum("qcij,qcj->qci", Ainv, r)
    t1 = np.stack([-np.sin(th1), np.cos(th1)], -1)
    t2 = np.stack([-np.sin(th2), np.cos(th2)], -1)
    # Jacobian columns: (theta1, rho1) from line 1, (theta2, rho2) from line 2
    J1 = np.stack([Ainv[..., :, 0] * np.einsum("qci,qci->qc", t1, m1 - x)[..., None], Ainv[..., :, 0]], -1)
    J2 = np.stack([Ainv[..., :, 1] * np.einsum("qci,qci->qc", t2, m2 - x)[..., None], Ainv[..., :, 1]], -1)
    cov = J1 @ C[:, _PREV] @ np.swapaxes(J1, -1, -2) + J2 @ C @ np.swapaxes(J2, -1, -2)
    return x, cov


#: a saturated edge's line uncertainty (:func:`clipped_white_cov`) in effective blur sigmas per unit of the
#: fit's residual RMS over the visible contrast, set on the sunlit markers of ``bench/markers_clipped.py``
#: (seed 0: corner NEES/dof 0.86 still, 1.26 moving; 25 gave 0.47 and 0.67; seed 1, not used to set it:
#: 0.72 and 1.14)
CLIPPED_MISFIT_SIGMAS = 18.0
#: the part of that uncertainty that differs between the quad's edges, as a share of the common part
CLIPPED_EDGE_SHARE_OWN = 0.5


def _clipped_edge_sigma(fit: EdgeFit, n_quads: int) -> NDArray[np.float64]:
    """(Q, 4) the line sigma (px) of each saturated edge's unseen white level (:func:`clipped_white_cov`); 0
    for edges seen whole."""
    visible = CLIP_HIGH - fit.a
    saturated = (fit.b > visible) & (visible > 0)
    misfit = np.where(saturated, fit.rms / np.where(saturated, visible, 1.0), 0.0)
    return np.nan_to_num(CLIPPED_MISFIT_SIGMAS * fit.sigma * misfit).reshape(n_quads, 4)


def clipped_white_cov(fit: EdgeFit, n_quads: int) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """What the unseen white level of saturated edges adds to the corners' covariances (Q, 4, 2, 2), px^2,
    and how the corners move together for one sigma of the offset the quad's saturated edges share
    (Q, 4, 2), px.

    A saturated edge (fitted white level beyond the clip: ``b > CLIP_HIGH - a``) shows only the foot of its
    ramp. Its line, the ramp's half-way point, is extrapolated from that foot with the profile's model, and
    where the model misses the true profile (a motion smear's box, defocus over the pixel box) the white
    level and the line trade off: the fit's own covariance, from the pixel noise, does not show it. What
    shows the model's miss is the residual on the visible ramp: the line's sigma is taken as
    ``CLIPPED_MISFIT_SIGMAS * sigma_eff * rms / (CLIP_HIGH - a)`` (px; the effective blur ``sigma_eff``, the
    fit's residual RMS over the visible contrast), one offset along the outward normals of the quad's
    saturated edges together (one sheet under one light has one white level: the marker shrinks or grows
    as a whole), plus :data:`CLIPPED_EDGE_SHARE_OWN` of it on each edge on its own. Each corner takes both
    parts of its two edges through the lines' intersection (``dx / drho_k = A^-1 e_k``,
    :func:`intersect_corners`). The common part's correlation between corners is not in the per-corner
    covariance but in the second output, which the detections carry beside it: corners ``i`` and ``j`` of
    a quad covary by ``c_i c_j^T`` through it, and the pose of a marker averages its corners' own errors
    but not this one. Edges seen whole add nothing (zeros in both).

    On the simulated GT room's sunlit markers (``bench/markers_clipped.py``, seed 0) the common offset is
    0.05 px RMS along each edge's normal on still markers (effective blur 0.3 px) and 0.13 px on moving
    ones (0.4-0.7 px); among the residual, blur and unseen share of the step, the product of the blur and
    the relative residual follows it best (log correlation 0.56, against 0.32 for the blur alone and -0.31
    for the blur times the unseen share).
    """
    s_edge = _clipped_edge_sigma(fit, n_quads)
    _, _, Ainv = _corner_lines(fit.theta.reshape(n_quads, 4))
    common = Ainv[..., :, 0] * s_edge[:, _PREV, None] + Ainv[..., :, 1] * s_edge[..., None]
    common = np.where(np.isfinite(common), common, 0.0)
    own1 = Ainv[..., :, 0] * (CLIPPED_EDGE_SHARE_OWN * s_edge[:, _PREV, None])
    own2 = Ainv[..., :, 1] * (CLIPPED_EDGE_SHARE_OWN * s_edge[..., None])
    out = sum(np.einsum("qci,qcj->qcij", v, v) for v in (common, own1, own2))
    return np.where(np.isfinite(out), out, 0.0), common


def quad_homographies(quads: NDArray[np.float64]) -> NDArray[np.float64]:
    """Homographies (Q, 3, 3) from fit coordinates to marker units: corner ``k`` of each quad (Q, 4, 2)
    goes to (0, 0), (1, 0), (1, 1), (0, 1) in turn (the convention of :func:`.decode.sample_cells`).

    Solved as the 8 x 8 linear system of the direct linear transform with ``h33 = 1``
    (:func:`._kernels.quad_homographies`; NaN for a degenerate quad).
    """
    return _kernels.quad_homographies(np.ascontiguousarray(quads, np.float64))


def marker_context(
    samples: EdgeSamples,
    fit: EdgeFit,
    corners: NDArray[np.float64],
    white: NDArray[np.float64],
    threads: int = 1,
) -> NDArray[np.float64]:
    """The part of each band pixel's blurred profile that one straight step does not explain.

    A marker is a black square holding white data cells; blurred by a Gaussian of ``sigma`` pixels
    its reflectance is ``1 - S + R`` with ``S`` the blurred square and ``R`` the blurred white cells.
    Close to the middle of an edge this is ``Phi(d / sigma)``; near the corners the other edges, and
    on small or blurred markers the white cells one border-width inside (2.5 px at 20 px side for
    AprilTag 36h11), add light that biases a plain step fit by up to 0.35 px at blur 1 px. This
    returns ``1 - S + R - Phi(d / sigma)`` at the current estimate, for :func:`fit_sharp_edges` to hold
    fixed while it moves the line (the detector re-evaluates it between passes).

    Every cell is a square in marker units mapped by the quad's homography; locally the blur is a
    Gaussian in marker units whose marginal widths along the grid axes are ``sigma`` times the norms
    of the rows of d(marker)/d(pixel), and the blurred cell is taken as the product of the two 1-D
    blurred boxes (exact for a half-plane, a close approximation at cell corners under shear). The
    sum over cells is then the bilinear form ``Y^T W X`` of the per-row and per-column box profiles.

    Parameters
    ----------
    samples : band pixels (fit coordinates) of the edges of ``Q`` quads, edges ``4q .. 4q+3``.
    fit : current fits of those edges.
    corners : (Q, 4, 2) current corners (intersections of the fitted lines), clockwise on screen.
    white : (Q, n, n) 1 for white cells, in the quads' orientation (cell (0, 0) at corner 0, cell
        (0, n-1) at corner 1).

    threads : with 2 the pixels are evaluated in two halves at once.

    Returns
    -------
    (N,) float, in units of the edge contrast.
    """
    e = samples.edge
    x, y = samples.xy[:, 0], samples.xy[:, 1]
    # the angles' cosines and sines per edge, then per pixel: the same values (an element-wise ufunc), at
    # a hundredth of the transcendental calls
    d = np.cos(fit.theta)[e] * (x - fit.mid[e, 0]) + np.sin(fit.theta)[e] * (y - fit.mid[e, 1]) - fit.rho[e]
    H = quad_homographies(corners).reshape(-1, 9)
    W = np.ascontiguousarray(white, dtype=np.float64)
    xs, ys, quad, sg = np.ascontiguousarray(x), np.ascontiguousarray(y), e // 4, np.ascontiguousarray(fit.sigma[e])
    N = len(e)
    # pixels are independent: with two threads, parts claimed in turn by the threads
    cuts = ([round(k * N / SPLIT_PARTS) for k in range(SPLIT_PARTS + 1)] if threads > 1 and N > _SPLIT_MIN_PX
            else [0, N])
    parts = [(xs[a:b], ys[a:b], quad[a:b], H, sg[a:b], W, d[a:b]) for a, b in itertools.pairwise(cuts)]
    return np.concatenate(_threads.run_split(_kernels.marker_context, parts))


@dataclass(frozen=True)
class RefineParams:
    """The edge refinement's settings (:func:`refine_quads`; the detector's ``DetectorParams`` names).

    passes : fits per edge; the first fits plain steps, the next ones hold the modelled light of the
        marker's corners and cells fixed (:func:`marker_context`).
    iterations, tol : :func:`fit_sharp_edges`' iteration limit and line-step tolerance (pixels).
    band_px : half-width of the band beyond ``3 sigma`` (pixels).
    white_end : end each edge's outer band where its white quiet zone ends (:func:`white_extent`): the
        band's white half must not reach past the paper into the surround. The profile is read
        ``look_sigmas`` blur sigmas beyond the band, so that a paper's end just beyond it is seen (its
        blurred foot inside the band moves the line too).
    margin_cells : the printed white margin around the black square, in cells, if known.
    max_blur_px : upper clip of the blur a pass hands to the next (the lower is 0.3 px). The blur is
        about the same on the four edges of a marker: the next pass starts from their median, which
        recovers an edge whose plain-step fit collapsed to a sharp step (white cells one border-width
        inside pull sigma to 0 on small markers); its end points are the fitted lines' points nearest
        to the previous ones.
    max_columns : pixel columns across each edge at most (:func:`band_stride`): a longer edge takes every
        k-th column, so that a large marker costs about what one of ``max_columns`` pixels does; 0 takes
        every column. 28 (on the renders of ``bench/markers.py --refine-only --sweep``: 12-16 % less time than
        32 for corners 0.0007 / 0.002 px RMS further at blur <= 1 / 2 px; 24 let a sharpened edge's corners
        drift past 0.095 px).
    first_columns : the first pass's columns at most (:func:`band_stride`); 0 takes ``max_columns``. The first
        pass only gives the next ones their start, and 16 columns instead of 32 took 40 % less time with the
        renders' corners as close to the truth, but at 1.5 px blur a small marker's later passes then settled
        elsewhere: one pose of ``tests/vision/test_blur_pull.py`` at NEES / dof 8.1 (0.9 with 32), so the
        default keeps every column.
    settle_px : a quad whose corners moved less than this (pixels) in a pass after the first stops there,
        with that pass's fits and covariances (a pass moving them 0.1 px left the next one's move below
        0.08 px and the corner RMS unchanged on the renders of ``bench/markers.py --refine-only``, 60 % of
        the quads settled); 0 runs every pass on every quad.
    first_tol : the first pass's line-step tolerance (pixels). That pass only starts the next, which refits
        every line with the marker's modelled light to ``tol``. On real photos its fits converge about
        linearly (each line step a third to a half of the last): 0.03 px instead of ``tol`` took its fits from
        9.4 to 7.1-7.6 evaluations per edge on the PhotonVision and top-level sets of ``markers_real``.
    clipped_passes : passes at most of a quad with an edge saturated at the clip level (the others stop after
        ``passes``). Such an edge's fitted blur answers its context's blur inversely; its context blur then
        takes secant steps towards their joint fixed point (:func:`._edge_kernels.context_blur`), which
        needs passes beyond the third to settle.
    """

    passes: int = 3
    iterations: int = 10
    tol: float = 1e-3
    band_px: float = 5.0
    white_end: bool = True
    look_sigmas: float = 3.0
    margin_cells: float | None = None
    max_blur_px: float = 5.0
    max_columns: int = 28
    settle_px: float = 0.1
    first_columns: int = 0
    first_tol: float = 0.03
    clipped_passes: int = 9


def band_stride(side: NDArray[np.float64], params: RefineParams, first: bool = False) -> NDArray[np.int64]:
    """Each edge's column stride (E,) for edges ``side`` (E,) pixels long: ``floor(side / max_columns)``,
    at least 1 (every column with ``max_columns = 0``); for the ``first`` pass with
    :attr:`RefineParams.first_columns` where that is fewer."""
    side = np.asarray(side, np.float64)
    return _edge_kernels.band_stride(np.ascontiguousarray(side.ravel()), _columns(params, first)).reshape(side.shape)


def _columns(params: RefineParams, first: bool) -> int:
    """The columns a pass takes at most (0: every column; :func:`band_stride`)."""
    cols = params.max_columns
    if first and params.first_columns > 0 and (cols <= 0 or params.first_columns < cols):
        cols = params.first_columns
    return max(cols, 0)


def band_limits(sigma: NDArray[np.float64], side: NDArray[np.float64], cell: NDArray[np.float64],
                border: NDArray[np.float64], first: bool, params: RefineParams
                ) -> tuple[NDArray[np.float64], ...]:
    """A pass's band around each edge (all (E,), pixels): ``w_in``, ``w_out``, the outer limit read for the
    paper's end ``w_look`` (``w_out`` without :attr:`RefineParams.white_end`) and the ends left out.

    sigma : current blur; side : the edge's length in the candidate; cell, border : the marker's cell and
    border widths. The first pass (plain steps) keeps the band inside the black border and away from the
    ends; the next ones model the corners and the data cells, so the band may reach into them.
    """
    sigma, side, cell, border = (np.ascontiguousarray(a, np.float64).ravel()
                                 for a in np.broadcast_arrays(sigma, side, cell, border))
    # (the formulas: w = 3 sigma + band_px; w_out = max(1.5, min(w, cell + 1)), and with a known margin at most
    # margin_cells cell - 2 sigma, at least 1; the first pass: w_in = max(1, min(w, border - 1.5 sigma)), ends
    # min(max(3 sigma + 1, 0.08 side), 0.3 side) left out; the next: w_in = max(1, min(w, border + cell / 2)),
    # ends min(sigma, 0.3 side); w_look = w_out + look_sigmas sigma)
    margin = np.nan if params.margin_cells is None else float(params.margin_cells)
    return _edge_kernels.band_limits(sigma, side, cell, border, first, float(params.band_px), margin,
                                     params.white_end, float(params.look_sigmas))


def refine_quads(
    gray: NDArray[np.uint8],
    quads: NDArray[np.float64],
    white: NDArray[np.float64],
    border_cells: int,
    params: RefineParams | None = None,
    undist: Undistorter | None = None,
    light: NDArray[np.float64] | None = None,
    threads: int = 1,
) -> tuple[EdgeFit, NDArray[np.float64], NDArray[np.float64]]:
    """Sub-pixel corners of ``Q`` candidate quads: every pass of the edge fits in compiled code.

    Each pass gathers each edge's band (:func:`band_limits`, :func:`gather_band`), ends it where the
    white paper does (:func:`white_extent`, :func:`trim_outer`), fits the blurred step
    (:func:`fit_sharp_edges`; from the second pass on with :func:`marker_context` held fixed), and starts the
    next from the median blur of the quad's edges and the fitted lines, unless the pass (after the
    first) moved the quad's corners less than :attr:`RefineParams.settle_px`; the corners are the lines'
    intersections (:func:`intersect_corners`). The results are those of these functions called in
    turn (to rounding: ``tests/markers/test_refine_quads.py``), at a fraction of the time.

    Parameters
    ----------
    gray : (H, W) uint8 image.
    quads : (Q, 4, 2) candidate corners, clockwise on screen, fit coordinates.
    white : (Q, n, n) 1 for white cells, in the quads' orientation (:func:`marker_context`).
    border_cells : black border width, cells.
    undist : lens model; ``quads`` are then undistorted pixels.
    light : (256,) light of each grey level (:func:`.tone.to_light`); None for linear levels.
    threads : with 2 the quads are shared with a helper thread (each quad's results are those of one thread:
        the quads do not depend on each other). Every pass of a share of the quads runs in one compiled call
        (:func:`._edge_kernels.refine_all`: no interpreter work between the passes).

    Returns
    -------
    fit : the last pass's :class:`EdgeFit` (edges ``4q .. 4q+3``); corners : (Q, 4, 2); cov : (Q, 4, 2, 2).
    """
    prm = params or RefineParams()
    quads = np.ascontiguousarray(quads, np.float64).reshape(-1, 4, 2)
    lut = np.arange(256, dtype=np.float64) if light is None else np.ascontiguousarray(light, np.float64)
    cfg = np.array([prm.passes, _columns(prm, False), _columns(prm, True), prm.band_px,
                    np.nan if prm.margin_cells is None else prm.margin_cells, float(prm.white_end), prm.look_sigmas,
                    PROFILE_STEP_PX, WHITE_END_DROP, WHITE_END_SIGMAS, prm.max_blur_px, prm.settle_px,
                    prm.first_tol, prm.clipped_passes], np.float64)
    gray = np.ascontiguousarray(gray)
    W = np.ascontiguousarray(white, np.float64)
    if undist is None:
        lens: tuple[NDArray[np.float32], NDArray[np.float32], NDArray[np.float64], NDArray[np.float64]] = (
            np.zeros((0, 0), np.float32), np.zeros((0, 0), np.float32), np.eye(3), np.zeros(8))
    else:
        dist = np.zeros(8)
        dist[:min(8, undist.dist.size)] = undist.dist[:8]  # (the coefficients of Undistorter.to_raw)
        lens = (undist.map_x, undist.map_y, np.ascontiguousarray(undist.K, np.float64), dist)
    fit_cfg = _fit_cfg(prm)
    parts = [(gray, lut, *lens, quads[a:b], W[a:b], int(border_cells), cfg, fit_cfg)
             for a, b in itertools.pairwise(_quad_cuts(len(quads), threads))]
    res = _threads.run_split(_edge_kernels.refine_all, parts)
    if len(res) == 1:
        P, mid, sigma, cov_line, rms, n_px, ok, corners, cov = res[0]
    else:
        P, mid, sigma, cov_line, rms, n_px, ok, corners, cov = (np.concatenate(x) for x in zip(*res, strict=True))
    return _edge_fit(P, mid, sigma, cov_line, rms, n_px, ok), corners, cov


def _quad_cuts(n_q: int, threads: int) -> list[int]:
    """Bounds of the shares of ``n_q`` quads for ``threads`` (:data:`SPLIT_PARTS` shares with two, one
    with one)."""
    if threads <= 1 or n_q <= 1:
        return [0, n_q]
    return [0, *sorted({round(k * n_q / SPLIT_PARTS) for k in range(1, SPLIT_PARTS)} - {0, n_q}), n_q]


def _edge_fit(P: NDArray[np.float64], mid: NDArray[np.float64], sigma: NDArray[np.float64],
              cov_line: NDArray[np.float64], rms: NDArray[np.float64], n_px: NDArray[np.int64],
              ok: NDArray[np.bool_]) -> EdgeFit:
    """The :class:`EdgeFit` of the compiled passes' parameters ``P`` (4Q, 7) and fits."""
    return EdgeFit(P[:, 0].copy(), P[:, 1].copy(), mid, P[:, 2].copy(), P[:, 3].copy(), sigma, P[:, 5:7].copy(),
                   cov_line, rms, n_px, ok)


def _fit_cfg(prm: RefineParams, first: bool = False) -> NDArray[np.float64]:
    """The edge fits' settings of :func:`._edge_kernels.refine_pass` (``fit_cfg``; with ``first``, the first
    pass's)."""
    return np.array([prm.iterations, prm.first_tol if first else prm.tol, CLIPPED_ITER_FACTOR, CLIP_LOW, CLIP_HIGH,
                     CLIPPED_EDGE_SHARE, PIXEL_VAR, SHARP_SIGMA_PX, MAX_CLIPPED_WHITE], np.float64)


def refine_quads_stepwise(
    gray: NDArray[np.uint8],
    quads: NDArray[np.float64],
    white: NDArray[np.float64],
    border_cells: int,
    params: RefineParams | None = None,
    undist: Undistorter | None = None,
    light: NDArray[np.float64] | None = None,
) -> tuple[EdgeFit, NDArray[np.float64], NDArray[np.float64]]:
    """:func:`refine_quads` through the step functions, one array call per step and pass: the reference
    the compiled passes are held to (its tests, ``bench/markers.py --refine-only``). Same arguments and
    results."""
    prm = params or RefineParams()
    quads = np.asarray(quads, np.float64).reshape(-1, 4, 2)
    n_q, n = len(quads), white.shape[1]
    side = np.linalg.norm(quads - np.roll(quads, -1, axis=1), axis=2).ravel()
    cell = np.repeat(side.reshape(-1, 4).mean(axis=1) / n, 4)
    border = cell * border_cells
    p0 = quads.reshape(-1, 2).copy()
    p1 = np.roll(quads, -1, axis=1).reshape(-1, 2).copy()
    sigma = np.full(len(p0), 1.0)
    sharp = np.zeros(len(p0), bool)  # edges found sharper than a pixel (fit_sharp_edges)
    fit: EdgeFit | None = None
    stride = band_stride(side, prm)
    first_stride = band_stride(side, prm, first=True)
    active = np.ones(n_q, bool)
    ctx = np.full((len(p0), 3), np.nan)  # context blurs of the saturated edges' secant (context_blur)
    sat = np.zeros(len(p0), bool)  # edges saturated at the clip level in the last pass
    for k in range(max(prm.passes, prm.clipped_passes)):
        if k >= prm.passes:
            active &= sat.reshape(-1, 4).any(axis=1)
        if not active.any():
            break
        # the quads still moving, and their edges
        qs = np.flatnonzero(active)
        es = (4 * qs[:, None] + np.arange(4)).ravel()
        on = np.zeros(len(p0), bool)
        on[es] = True
        a0, a1, sg = p0[es], p1[es], sigma[es]
        w_in, w_out, w_look, excl = band_limits(sg, side[es], cell[es], border[es], k == 0, prm)
        st = (first_stride if k == 0 else stride)[es]
        samples = gather_band(gray, a0, a1, w_in, w_look, excl, undist, st)
        if unstride_clipped(samples, st):
            samples = gather_band(gray, a0, a1, w_in, w_look, excl, undist, st)
        if k == 0:
            first_stride[es] = st
            _keep_unstrided(first_stride, stride, side, prm)
        else:
            stride[es] = st
        if prm.white_end:
            d = across_edge(samples, a0, a1)
            w_out = np.minimum(w_out, white_extent(samples, a0, a1, sg, w_in, w_look, d))
            samples = trim_outer(samples, a0, a1, w_out, d)
        if light is not None:
            samples = dataclasses.replace(samples, val=np.asarray(light, np.float64)[samples.val.astype(np.intp)])
        if fit is None:
            first_fit, sharp[es] = fit_sharp_edges(samples, a0, a1, sg, iterations=prm.iterations,
                                                   tol=prm.first_tol)
            fit = share_white(samples, first_fit, sg, True, prm)
        else:
            prev = _subset(fit, on)
            before, _ = intersect_corners(prev, len(qs))
            extra = marker_context(samples, _context_fit(prev, qs, sat, ctx, prm), before, white[qs])
            new, sharp[es] = fit_sharp_edges(samples, a0, a1, sg, iterations=prm.iterations, extra=extra,
                                             init=prev, tol=prm.tol, sharp=sharp[es])
            new = share_white(samples, new, sg, False, prm, extra)
            after, _ = intersect_corners(new, len(qs))
            # a quad whose corners this pass moved less than settle_px stops (NaN moves go on)
            active[qs[np.linalg.norm(after - before, axis=2).max(axis=1) < prm.settle_px]] = False
            fit = _merge(fit, on, new)
        sat[es] = _saturated(samples, len(es))
        sigma[es] = np.repeat(np.median(np.clip(fit.sigma[es], 0.3, prm.max_blur_px).reshape(-1, 4), axis=1), 4)
        lines = fit.lines()[es]
        nvec = lines[:, :2]
        p0[es] = a0 - (np.einsum("ij,ij->i", nvec, a0) - lines[:, 2])[:, None] * nvec
        p1[es] = a1 - (np.einsum("ij,ij->i", nvec, a1) - lines[:, 2])[:, None] * nvec
    if fit is None:
        raise ValueError("refine_quads_stepwise: params.passes must be at least 1")
    corners, cov = intersect_corners(fit, len(quads))
    return fit, corners, cov


def _context_fit(prev: EdgeFit, qs: NDArray[np.intp], sat: NDArray[np.bool_], ctx: NDArray[np.float64],
                 params: RefineParams) -> EdgeFit:
    """``prev`` (the fits of quads ``qs``) with the blurs their marker context takes this pass
    (:func:`._edge_kernels.context_blur`; ``sat`` (E,), ``ctx`` (E, 3) of every quad, updated in place)."""
    sg = prev.sigma.copy()
    for j, q in enumerate(qs):
        sl = slice(4 * q, 4 * q + 4)
        sg[4 * j:4 * j + 4] = _edge_kernels.context_blur(np.ascontiguousarray(prev.sigma[4 * j:4 * j + 4]), sat[sl],
                                                         ctx[sl], 0.3, params.max_blur_px)
    return dataclasses.replace(prev, sigma=sg)


def _saturated(samples: EdgeSamples, n_edges: int) -> NDArray[np.bool_]:
    """Whether more than :data:`CLIPPED_EDGE_SHARE` of each edge's band pixels ``samples`` (light) lie at
    :data:`CLIP_HIGH` (E,), edges with more than 8 pixels."""
    cnt = np.bincount(samples.edge, minlength=n_edges)
    n_clip = np.bincount(samples.edge, weights=(samples.val >= CLIP_HIGH).astype(np.float64), minlength=n_edges)
    return (cnt > 8) & (n_clip > CLIPPED_EDGE_SHARE * cnt)


def unstride_clipped(samples: EdgeSamples, stride: NDArray[np.int64]) -> bool:
    """Set the column strides ``stride`` (E,) of every edge of a quad (edges ``4q .. 4q + 3``) to 1, in
    place, where more than :data:`CLIPPED_EDGE_SHARE` of one of its edges' band pixels ``samples`` (raw
    levels) are clipped at 0 or 255; returns whether any changed. A clipped edge is fitted on one side of
    its ramp with the pixel-integrated step, whose line depends on the pixels' phases across the edge:
    every column keeps them (on over-exposed renders a stride of 3 doubled the corner error)."""
    E = len(stride)
    cnt = np.bincount(samples.edge, minlength=E)
    clipped = (samples.val >= 255.0) | (samples.val <= 0.0)
    n_clip = np.bincount(samples.edge, weights=clipped.astype(np.float64), minlength=E)
    quad = (n_clip > CLIPPED_EDGE_SHARE * cnt).reshape(-1, 4).any(axis=1) & (stride.reshape(-1, 4) > 1).any(axis=1)
    if not quad.any():
        return False
    stride.reshape(-1, 4)[quad] = 1
    return True


def _keep_unstrided(first_stride: NDArray[np.int64], stride: NDArray[np.int64], side: NDArray[np.float64],
                    params: RefineParams) -> None:
    """After the first pass: every column in the next passes too (``stride`` (E,) set to 1, in place) for
    the quads whose first pass :func:`unstride_clipped` set to every column (``first_stride`` (E,))."""
    changed = (first_stride != band_stride(side, params, first=True)).reshape(-1, 4).any(axis=1)
    stride.reshape(-1, 4)[changed] = 1
