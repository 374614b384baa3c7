"""Corners of known markers refined by the blurred-step edge model (:mod:`.edges`).

Each quad's four edges are fitted to every pixel of a band around them: the first pass fits plain
blurred steps in a band kept inside the black border and away from the corners; the next passes hold
the modelled light of the other edges and of the marker's own white cells fixed
(:func:`.edges.marker_context`), so that the band may reach the corners and the cells. Corners are the
intersections of adjacent fitted lines, their 2 x 2 covariances propagated from the line fits
(:func:`.edges.intersect_corners`). A fit is refused when an edge lacks contrast, leaves a large
residual, is blurrier than allowed, or moves a corner too far from the peer's.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from gtrig.markers.detect.camera import Undistorter
from gtrig.markers.detect.edges import (
    EdgeFit,
    across_edge,
    fit_edges,
    gather_band,
    intersect_corners,
    marker_context,
    trim_outer,
    white_extent,
)
from gtrig.markers.detect.tone import Tone, to_light

__all__ = ["RefineSettings", "Refined", "refine_quads", "fit_reason"]

#: how far beyond the outer band (blur sigmas) :func:`.edges.white_extent` looks for the paper's end: with
#: the band ending 1.9 sigma before the paper the foot of its blurred end still moved the corners
#: 0.02-0.03 px outward
WHITE_LOOK_SIGMAS = 3.0


@dataclass(frozen=True)
class RefineSettings:
    """The edge fits' settings (:class:`gtrig.markers.detect.DetectorParams` documents each)."""

    band_px: float = 5.0
    white_end: bool = True
    margin_cells: float | None = None
    max_blur_px: float = 5.0
    min_contrast: float = 12.0
    max_rel_rms: float = 0.25
    max_corner_shift_px: float = 4.0
    max_corner_shift_side: float = 0.1
    passes: int = 3
    iterations: int = 10
    tol: float = 1e-3
    tone: Tone = "linear"


@dataclass(frozen=True)
class Refined:
    """The refined quads (Q of them, fit coordinates).

    corners : (Q, 4, 2) px, in the quads' order; cov : (Q, 4, 2, 2) px^2; ok : (Q,) the fit passed
    every test; shift : (Q,) px, the largest corner move from the start, and shift_limit : (Q,) px, the
    largest accepted; fit : the last pass's
    :class:`.edges.EdgeFit` (edges ``4q .. 4q + 3`` of quad ``q``).
    """

    corners: NDArray[np.float64]
    cov: NDArray[np.float64]
    ok: NDArray[np.bool_]
    shift: NDArray[np.float64]
    shift_limit: NDArray[np.float64]
    fit: EdgeFit

    @property
    def blur(self) -> NDArray[np.float64]:
        """(Q,) mean fitted blur sigma of each quad's edges, px."""
        return self.fit.sigma.reshape(-1, 4).mean(axis=1)

    @property
    def levels(self) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """(Q,) black level and contrast (light, grey-level scale), the means over each quad's edges."""
        return self.fit.a.reshape(-1, 4).mean(axis=1), self.fit.b.reshape(-1, 4).mean(axis=1)


def _band_widths(sigma: NDArray[np.float64], cell: NDArray[np.float64], border: NDArray[np.float64],
                 L: NDArray[np.float64], first: bool, s: RefineSettings
                 ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """Inner and outer half-widths of each edge's band and the length excluded at each end, px (E,)."""
    w = 3.0 * sigma + s.band_px
    if first:
        # plain step model: keep the band inside the black border and away from the ends
        w_in = np.maximum(1.0, np.minimum(w, border - 1.5 * sigma))
        excl = np.minimum(np.maximum(3.0 * sigma + 1.0, 0.08 * L), 0.3 * L)
    else:
        # the corners and the data cells are modelled: the band may reach into them
        w_in = np.maximum(1.0, np.minimum(w, border + 0.5 * cell))
        excl = np.minimum(sigma, 0.3 * L)
    w_out = np.maximum(1.5, np.minimum(w, cell + 1.0))
    if s.margin_cells is not None:
        w_out = np.maximum(1.0, np.minimum(w_out, s.margin_cells * cell - 2.0 * sigma))
    return w_in, w_out, excl


def _one_pass(gray: NDArray[np.uint8], p0: NDArray[np.float64], p1: NDArray[np.float64], sigma: NDArray[np.float64],
              widths: tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]],
              fit: EdgeFit | None, white: NDArray[np.float64], und: Undistorter | None, s: RefineSettings,
              threads: int) -> EdgeFit:
    """One pass of the edge fits from the end points ``p0``, ``p1`` (E, 2) (the previous pass ``fit``)."""
    w_in, w_out, excl = widths
    if s.white_end:
        # the band's white half must not reach past the paper into the surround: the profile is read
        # WHITE_LOOK_SIGMAS further out, so that a paper's end just beyond the band is seen
        w_look = w_out + WHITE_LOOK_SIGMAS * sigma
        samples = gather_band(gray, p0, p1, w_in, w_look, excl, und)
        d = across_edge(samples, p0, p1)
        w_out = np.minimum(w_out, white_extent(samples, p0, p1, sigma, w_in, w_look, d))
        samples = trim_outer(samples, p0, p1, w_out, d)
    else:
        samples = gather_band(gray, p0, p1, w_in, w_out, excl, und)
    if s.tone != "linear":
        samples = dataclasses.replace(samples, val=to_light(samples.val, s.tone))
    if fit is None:
        return fit_edges(samples, p0, p1, sigma, iterations=s.iterations, tol=s.tol, threads=threads)
    corners, _ = intersect_corners(fit, len(p0) // 4)
    extra = marker_context(samples, fit, corners, white, threads)
    return fit_edges(samples, p0, p1, sigma, iterations=s.iterations, extra=extra, init=fit, tol=s.tol,
                     threads=threads)


def refine_quads(gray: NDArray[np.uint8], quads: NDArray[np.float64], white: NDArray[np.float64],
                 border_cells: int, und: Undistorter | None, s: RefineSettings, threads: int = 1) -> Refined:
    """Refine quads (Q, 4, 2) (fit coordinates, clockwise on screen) of markers whose cells ``white``
    (Q, n, n; 1 = white, cell (0, 0) at corner 0) are known, with ``border_cells`` of black border."""
    Q = np.asarray(quads, np.float64)
    n = white.shape[1]
    side = np.linalg.norm(Q - np.roll(Q, -1, axis=1), axis=2)  # (Q, 4)
    cell = np.repeat(side.mean(axis=1) / n, 4)
    border = cell * border_cells
    p0 = Q.reshape(-1, 2)
    p1 = np.roll(Q, -1, axis=1).reshape(-1, 2)
    L = side.ravel()
    sigma = np.full(len(p0), 1.0)
    fit: EdgeFit | None = None
    for k in range(s.passes):
        fit = _one_pass(gray, p0, p1, sigma, _band_widths(sigma, cell, border, L, k == 0, s), fit, white, und, s,
                        threads)
        # the blur is about the same on the four edges of a marker: the next pass starts from their median,
        # which recovers an edge whose plain-step fit collapsed to a sharp step
        sigma = np.repeat(np.median(np.clip(fit.sigma, 0.3, s.max_blur_px).reshape(-1, 4), axis=1), 4)
        lines = fit.lines()
        # next pass: end points = the fitted line's points nearest to the previous ends
        nvec = lines[:, :2]
        p0 = p0 - (np.einsum("ij,ij->i", nvec, p0) - lines[:, 2])[:, None] * nvec
        p1 = p1 - (np.einsum("ij,ij->i", nvec, p1) - lines[:, 2])[:, None] * nvec
    assert fit is not None
    corners, cov = intersect_corners(fit, len(Q))
    ok_e = (fit.ok & (fit.b >= s.min_contrast) & (fit.rms <= s.max_rel_rms * np.abs(fit.b))
            & (fit.sigma <= s.max_blur_px) & (fit.sigma >= 0.06))
    ok = ok_e.reshape(-1, 4).all(axis=1)
    shift = np.linalg.norm(corners - Q, axis=2).max(axis=1)
    ok &= np.all(np.isfinite(corners.reshape(len(Q), -1)), axis=1) & (shift <= _shift_limit(side, s))
    ok &= np.all(np.isfinite(cov.reshape(len(Q), -1)), axis=1)
    return Refined(corners, cov, ok, shift, _shift_limit(side, s), fit)


def _shift_limit(side: NDArray[np.float64], s: RefineSettings) -> NDArray[np.float64]:
    """(Q,) largest accepted corner move, px, for quads with sides ``side`` (Q, 4) px."""
    return np.maximum(s.max_corner_shift_px, s.max_corner_shift_side * side.mean(axis=1))


def fit_reason(r: Refined, q: int, s: RefineSettings) -> str:
    """Why the fit of quad ``q`` of ``r`` was refused, in words."""
    f = r.fit
    for e in range(4 * q, 4 * q + 4):
        b, sigma = float(f.b[e]), float(f.sigma[e])
        rel = float(f.rms[e] / max(abs(b), 1e-9))
        if not f.ok[e]:
            return "edge fit did not converge"
        if b < s.min_contrast:
            return f"edge contrast {b:.0f} < {s.min_contrast:g}"
        if rel > s.max_rel_rms:
            return f"edge residual {rel:.2f} of the contrast > {s.max_rel_rms:g}"
        if sigma > s.max_blur_px:
            return f"edge blur {sigma:.1f} px > {s.max_blur_px:g}"
        if sigma < 0.06:
            return f"edge blur {sigma:.2f} px < 0.06 (a step sharper than a pixel)"
    shift = float(r.shift[q])
    return (f"corner moved {shift:.1f} px > {float(r.shift_limit[q]):.1f}" if np.isfinite(shift)
            else "edges do not intersect")
