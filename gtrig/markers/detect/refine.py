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

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from gtrig.markers.detect.camera import Undistorter
from gtrig.markers.detect.edges import EdgeFit, RefineParams, clipped_white_cov
from gtrig.markers.detect.edges import refine_quads as edge_refine
from gtrig.markers.detect.tone import Tone, light_table

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
    max_columns: int = 28


@dataclass(frozen=True)
class Refined:
    """The refined quads (Q of them, fit coordinates).

    corners : (Q, 4, 2) px, in the quads' order; cov : (Q, 4, 2, 2) px^2; common : (Q, 4, 2) px, the
    corners' shared move for one sigma of a clipped white level (the second output of
    :func:`.edges.clipped_white_cov`; zeros for quads seen whole): corners ``i`` and ``j`` covary by
    ``common[i] common[j]^T``; ok : (Q,) the fit passed every test; shift : (Q,) px, the largest corner
    move from the start, and shift_limit : (Q,) px, the largest accepted; fit : the last pass's
    :class:`.edges.EdgeFit` (edges ``4q .. 4q + 3`` of quad ``q``).
    """

    corners: NDArray[np.float64]
    cov: NDArray[np.float64]
    common: NDArray[np.float64]
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


def refine_quads(gray: NDArray[np.uint8], quads: NDArray[np.float64], white: NDArray[np.float64],
                 border_cells: int, und: Undistorter | None, s: RefineSettings, threads: int = 1) -> Refined:
    """Refine quads (Q, 4, 2) (fit coordinates, clockwise on screen) of markers whose cells ``white``
    (Q, n, n; 1 = white, cell (0, 0) at corner 0) are known, with ``border_cells`` of black border: the
    passes of :func:`.edges.refine_quads` (compiled), then the fit's tests."""
    Q = np.asarray(quads, np.float64)
    side = np.linalg.norm(Q - np.roll(Q, -1, axis=1), axis=2)  # (Q, 4)
    params = RefineParams(s.passes, s.iterations, s.tol, s.band_px, s.white_end, WHITE_LOOK_SIGMAS, s.margin_cells,
                          s.max_blur_px, s.max_columns)
    light = None if s.tone == "linear" else light_table(s.tone)
    fit, corners, cov = edge_refine(gray, Q, white, border_cells, params, und, light, threads)
    clipped_cov, common = clipped_white_cov(fit, len(Q))
    cov = cov + clipped_cov
    ok_e = (fit.ok & (fit.b >= s.min_contrast) & (fit.rms <= s.max_rel_rms * np.abs(fit.b))
            & (fit.sigma <= s.max_blur_px) & (fit.sigma >= 0.06))
    ok = ok_e.reshape(-1, 4).all(axis=1)
    shift = np.linalg.norm(corners - Q, axis=2).max(axis=1)
    limit = _shift_limit(side, s)
    ok &= np.all(np.isfinite(corners.reshape(len(Q), -1)), axis=1) & (shift <= limit)
    ok &= np.all(np.isfinite(cov.reshape(len(Q), -1)), axis=1)
    return Refined(corners, cov, common, ok, shift, limit, fit)


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
