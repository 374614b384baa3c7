"""Compiled edge refinement of whole quadrilaterals: one pass of :func:`.edges.refine_quads` (numba).

A pass takes every quad through the steps the public functions of :mod:`.edges` make one call each:
the band around each edge (:func:`.edges.gather_band`), the paper's end beyond it
(:func:`.edges.white_extent`, :func:`.edges.trim_outer`), the modelled light of the marker's corners
and cells (:func:`.edges.marker_context`, from the previous pass's lines; a saturated edge's context
blur from :func:`context_blur`), the blurred-step fits
(:func:`.edges.fit_sharp_edges`, with its refit of edges sharper than a pixel) and the next pass's blur
and end points; the last pass adds the lines' covariances and the corners
(:func:`.edges.intersect_corners`). The arithmetic is the same as theirs, step for step, so the
results agree with them to rounding; what goes is the interpreter's work per step and per edge, and
the temporaries of the array forms (most of the time on a marker of a few hundred band pixels per
edge). The quads are independent: the caller may split them between threads, and a quad's results do
not depend on the others fitted with it.

numba keys the cached machine code of these functions on this file's text alone, not on the kernels of
:mod:`._kernels` compiled into them (the edge model, the fits): a change there is picked up here only
once this file changes too or its ``__pycache__`` entries are removed.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit
from numpy.typing import NDArray

from gtrig.markers.detect._kernels import lm_edge, marker_context, quad_homographies

#: column of the parameters ``(theta, rho, a, b, log sigma, c, c_u)`` (:func:`.edges.fit_sharp_edges`)
_NP = 7


@njit(cache=True, nogil=True, error_model="numpy")
def gather_raw(gray: NDArray[np.uint8], p0: NDArray[np.float64], p1: NDArray[np.float64],
                w_in: NDArray[np.float64], w_out: NDArray[np.float64], excl: NDArray[np.float64],
                stride: NDArray[np.int64]
                ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64], NDArray[np.int64]]:
    """Band pixels of the edges ``p0 -> p1`` (E, 2) without a lens model: x, y, value, edge (each (M,),
    sorted by edge; :func:`.edges.gather_band`), every ``stride[e]``-th column.

    Each band is the parallelogram ``s in [excl, L - excl]``, ``d in [-w_in, w_out]`` (``s`` along the edge
    from ``p0``, ``d`` across it); it is scanned along the edge's major axis, where it is an interval of the
    other axis in every column, in one scan into arrays sized by a bound: each column of the edge's major
    axis holds at most ``(w_in + w_out) / |n_v| + 2`` pixels (``n_v`` the normal's minor component, at
    least ``1 / sqrt 2``).
    """
    h, w = gray.shape[0], gray.shape[1]
    E = p0.shape[0]
    t = np.empty((E, 2))
    nrm = np.empty((E, 2))
    L = np.empty(E)
    finite = np.zeros(E, np.bool_)
    bound = 0
    for e in range(E):
        tx, ty = p1[e, 0] - p0[e, 0], p1[e, 1] - p0[e, 1]
        L[e] = math.hypot(tx, ty)
        t[e, 0], t[e, 1] = tx / L[e], ty / L[e]
        nrm[e, 0], nrm[e, 1] = t[e, 1], -t[e, 0]
        swap = abs(t[e, 1]) > abs(t[e, 0])
        nv = abs(nrm[e, 0] if swap else nrm[e, 1])
        span = L[e] + w_in[e] + w_out[e]  # the band's extent along the major axis, at most
        per_col = (w_in[e] + w_out[e]) / max(nv, 0.5) + 3.0
        # an edge with a NaN end point or limit has no pixel (every test fails): left out
        finite[e] = (math.isfinite(span) and math.isfinite(per_col) and math.isfinite(p0[e, 0])
                     and math.isfinite(p0[e, 1]) and math.isfinite(excl[e]) and L[e] > 0.0)
        if finite[e]:
            bound += int((span / stride[e] + 3.0) * per_col)
    xs = np.empty(bound)
    ys = np.empty(bound)
    vs = np.empty(bound)
    es = np.empty(bound, np.int64)
    m = 0
    for e in range(E):
        if not finite[e]:
            continue
        swap = abs(t[e, 1]) > abs(t[e, 0])
        iu, iv = (1, 0) if swap else (0, 1)
        Au, Av, Tu, Tv, Nu, Nv = p0[e, iu], p0[e, iv], t[e, iu], t[e, iv], nrm[e, iu], nrm[e, iv]
        size_u, size_v = (h, w) if swap else (w, h)
        s_lo, s_hi = excl[e], L[e] - excl[e]
        if s_hi < s_lo:
            continue
        d_lo, d_hi = -w_in[e], w_out[e]
        umin, umax = np.inf, -np.inf
        for sv in (s_lo, s_hi):
            for dv in (d_lo, d_hi):
                cu = Au + sv * Tu + dv * Nu
                umin, umax = min(umin, cu), max(umax, cu)
        u0 = max(math.ceil(umin - 1e-6), 0)
        u1 = min(math.floor(umax + 1e-6), size_u - 1)
        a0 = int(math.floor(Au))
        for col in range(u0, u1 + 1):
            if (col - a0) % stride[e] != 0:
                continue
            du = col - Au
            if abs(Tv) < 1e-9:
                s_a, s_b = -np.inf, np.inf
            else:
                s_a, s_b = (s_lo - du * Tu) / Tv, (s_hi - du * Tu) / Tv
            d_a, d_b = (d_lo - du * Nu) / Nv, (d_hi - du * Nu) / Nv
            lo = max(min(s_a, s_b), min(d_a, d_b)) + Av
            hi = min(max(s_a, s_b), max(d_a, d_b)) + Av
            v0 = max(math.ceil(lo - 1e-6), 0)
            v1 = min(math.floor(hi + 1e-6), size_v - 1)
            for v in range(v0, v1 + 1):
                x, y = (v, col) if swap else (col, v)
                rx, ry = x - p0[e, 0], y - p0[e, 1]
                ss = rx * t[e, 0] + ry * t[e, 1]
                dd = rx * nrm[e, 0] + ry * nrm[e, 1]
                if dd >= d_lo and dd <= d_hi and ss >= s_lo and ss <= s_hi:
                    xs[m], ys[m], vs[m], es[m] = x, y, gray[y, x], e
                    m += 1
    return xs[:m], ys[:m], vs[:m], es[:m]


@njit(cache=True, inline="always", error_model="numpy")
def _to_raw(u: float, v: float, K: NDArray[np.float64], dist: NDArray[np.float64]) -> tuple[float, float]:
    """The raw pixel of the undistorted pixel ``(u, v)`` for the camera ``K`` (3, 3) and OpenCV's
    distortion ``dist`` (8,) (:meth:`.camera.Undistorter.to_raw`)."""
    y = (v - K[1, 2]) / K[1, 1]
    x = (u - K[0, 2] - K[0, 1] * y) / K[0, 0]
    k1, k2, p1, p2, k3, k4, k5, k6 = dist[0], dist[1], dist[2], dist[3], dist[4], dist[5], dist[6], dist[7]
    r2 = x * x + y * y
    radial = (1 + r2 * (k1 + r2 * (k2 + r2 * k3))) / (1 + r2 * (k4 + r2 * (k5 + r2 * k6)))
    xd = x * radial + 2 * p1 * x * y + p2 * (r2 + 2 * x * x)
    yd = y * radial + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y
    return K[0, 0] * xd + K[0, 1] * yd + K[0, 2], K[1, 1] * yd + K[1, 2]


@njit(cache=True, nogil=True, error_model="numpy")
def raw_boxes(h: int, w: int, p0: NDArray[np.float64], p1: NDArray[np.float64], w_in: NDArray[np.float64],
              w_out: NDArray[np.float64], K: NDArray[np.float64], dist: NDArray[np.float64]) -> NDArray[np.int64]:
    """Each band's box in the raw image of ``h`` x ``w`` pixels (E, 4) as ``(x0, y0, x1, y1)``, end exclusive
    (empty for an edge with a NaN): the bounding box of the raw positions (:func:`_to_raw`) of the corners
    of the edge ``p0 -> p1`` (E, 2, undistorted) widened by ``max(w_in, w_out)`` (E,) along and across it,
    one pixel more on each side and one for the end (:func:`_gather_undistorted`)."""
    E = p0.shape[0]
    out = np.zeros((E, 4), np.int64)
    for e in range(E):
        tx, ty = p1[e, 0] - p0[e, 0], p1[e, 1] - p0[e, 1]
        L = math.hypot(tx, ty)
        tx, ty = tx / L, ty / L
        nx, ny = ty, -tx
        ext = _nan_max(w_in[e], w_out[e])
        lo_x, lo_y, hi_x, hi_y = np.inf, np.inf, -np.inf, -np.inf
        finite = True
        for a, sa, sb in ((p0, -1.0, -1.0), (p0, 1.0, -1.0), (p1, -1.0, 1.0), (p1, 1.0, 1.0)):
            # the corner a + ext (sa n + sb t)
            rx, ry = _to_raw(a[e, 0] + ext * (sa * nx + sb * tx), a[e, 1] + ext * (sa * ny + sb * ty), K, dist)
            finite = finite and math.isfinite(rx) and math.isfinite(ry)
            lo_x, hi_x = min(lo_x, rx), max(hi_x, rx)
            lo_y, hi_y = min(lo_y, ry), max(hi_y, ry)
        if finite:
            out[e, 0] = max(int(math.floor(lo_x)) - 1, 0)
            out[e, 1] = max(int(math.floor(lo_y)) - 1, 0)
            out[e, 2] = min(int(math.ceil(hi_x)) + 2, w)
            out[e, 3] = min(int(math.ceil(hi_y)) + 2, h)
    return out


@njit(cache=True, nogil=True, error_model="numpy")
def _gather_undistorted(gray: NDArray[np.uint8], map_x: NDArray[np.float32], map_y: NDArray[np.float32],
                        boxes: NDArray[np.int64], p0: NDArray[np.float64], p1: NDArray[np.float64],
                        w_in: NDArray[np.float64], w_out: NDArray[np.float64], excl: NDArray[np.float64],
                        stride: NDArray[np.int64]
                        ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64], NDArray[np.int64]]:
    """Band pixels in undistorted coordinates: the raw pixels of each edge's box ``(x0, y0, x1, y1)``
    (E, 4; end exclusive, empty when ``x1 <= x0``) in row-major order whose undistorted position
    (``map_x``, ``map_y``) lies in the band (:func:`.edges.gather_band` with a lens model), of every
    ``stride[e]``-th raw column (row, for an edge nearer the vertical) from the box's first."""
    E = p0.shape[0]
    M = 0
    for e in range(E):
        if boxes[e, 2] > boxes[e, 0] and boxes[e, 3] > boxes[e, 1]:
            M += (boxes[e, 2] - boxes[e, 0]) * (boxes[e, 3] - boxes[e, 1])
    x = np.empty(M)
    y = np.empty(M)
    v = np.empty(M)
    es = np.empty(M, np.int64)
    m = 0
    for e in range(E):
        x0, y0, x1, y1 = boxes[e, 0], boxes[e, 1], boxes[e, 2], boxes[e, 3]
        if x1 <= x0 or y1 <= y0:
            continue
        tx, ty = p1[e, 0] - p0[e, 0], p1[e, 1] - p0[e, 1]
        L = math.hypot(tx, ty)
        tx, ty = tx / L, ty / L
        nx, ny = ty, -tx
        vertical = abs(ty) > abs(tx)
        for iy in range(y0, y1):
            if vertical and (iy - y0) % stride[e] != 0:
                continue
            for ix in range(x0, x1):
                if not vertical and (ix - x0) % stride[e] != 0:
                    continue
                px = float(map_x[iy, ix])
                py = float(map_y[iy, ix])
                rx, ry = px - p0[e, 0], py - p0[e, 1]
                s = rx * tx + ry * ty
                d = rx * nx + ry * ny
                if d >= -w_in[e] and d <= w_out[e] and s >= excl[e] and s <= L - excl[e]:
                    x[m], y[m], v[m], es[m] = px, py, gray[iy, ix], e
                    m += 1
    return x[:m], y[:m], v[:m], es[:m]


@njit(cache=True, nogil=True, error_model="numpy")
def _white_limit(d: NDArray[np.float64], v: NDArray[np.float64], lo_i: int, hi_i: int, step: float,
                 sigma: float, w_in: float, w_look: float, drop: float, end_sigmas: float) -> float:
    """:func:`.edges.white_extent` of one edge: its pixels ``lo_i:hi_i`` at distances ``d`` across it,
    values ``v``; bins of ``step`` on multiples of ``step`` (:func:`.edges.profile_origin`). Returns the
    outer limit (at most ``w_look``)."""
    lo = step * (math.floor(w_in / step) + 1.0)
    nb = int(math.floor((lo + w_look) / step)) + 2
    cnt = np.zeros(nb, np.int64)
    tot = np.zeros(nb)
    for i in range(lo_i, hi_i):
        f = math.floor((d[i] + lo) / step)
        k = 0 if not (f > 0.0) else (nb - 1 if f > nb - 1 else int(f))
        cnt[k] += 1
        tot[k] += v[i]
    prof = np.empty(nb)
    centre = np.empty(nb)
    for k in range(nb):
        prof[k] = tot[k] / cnt[k] if cnt[k] >= 3 else np.nan
        centre[k] = (k + 0.5) * step - lo
    black = np.inf
    n_black = 0
    white_sum = 0.0
    n_white = 0
    for k in range(nb):
        c = centre[k]
        if math.isnan(prof[k]):
            continue
        if c >= -w_in and c <= -sigma:
            black = min(black, prof[k])
            n_black += 1
        if c >= 2.0 * sigma and c <= 2.0 * sigma + 1.0:
            white_sum += prof[k]
            n_white += 1
    if n_black == 0 or n_white == 0:
        return w_look
    white = white_sum / n_white
    contrast = white - black
    if not (math.isfinite(contrast) and contrast > 0):
        return w_look
    thr = white - drop * contrast
    first = -1
    for k in range(nb):
        if centre[k] >= 2.0 * sigma and centre[k] <= w_look and prof[k] < thr:
            first = k
            break
    if first < 0:
        return w_look
    low = np.inf
    for k in range(first, nb):
        if centre[k] <= w_look and not math.isnan(prof[k]):
            low = min(low, prof[k])
    half = min(0.5 * (white + low), thr)
    kk = first
    level = thr
    for k in range(nb):
        if centre[k] >= 2.0 * sigma and centre[k] <= w_look and prof[k] < half:
            kk = k
            level = half
            break
    d_end = centre[kk]
    if kk > 0:
        prev, cur = prof[kk - 1], prof[kk]
        if math.isfinite(prev) and prev > cur:
            frac = min(max((prev - level) / (prev - cur), 0.0), 1.0)
            d_end = centre[kk - 1] + frac * step
    lim = d_end - end_sigmas * sigma
    floor = min(w_look, max(1.5, sigma))
    return min(max(lim, floor), w_look)


@njit(cache=True, nogil=True, error_model="numpy")
def _start_params(X0: NDArray[np.float64], X1: NDArray[np.float64], v: NDArray[np.float64], lo: int, hi: int,
                  nx: float, ny: float, mid: NDArray[np.float64], ls: float, init: NDArray[np.float64],
                  init_mid: NDArray[np.float64], has_init: bool, P: NDArray[np.float64]) -> None:
    """The start of one edge's fit into ``P`` (7,) (:func:`.edges.fit_sharp_edges`): the previous fit's
    levels, shading and line moved to the new reference point ``mid`` with ``has_init``, else the
    means of the band's inner and outer halves; the blur from ``ls`` (log sigma)."""
    if has_init:
        c, s = math.cos(init[0]), math.sin(init[0])
        P[0] = init[0]
        P[1] = init[1] + (c * (init_mid[0] - mid[0]) + s * (init_mid[1] - mid[1]))
        P[2], P[3] = init[2], init[3]
        P[5], P[6] = init[5], init[6]
    else:
        sum_in = 0.0
        n_in = 0.0
        sum_out = 0.0
        for i in range(lo, hi):
            if X0[i] * nx + X1[i] * ny < 0:
                sum_in += v[i]
                n_in += 1.0
            else:
                sum_out += v[i]
        a = sum_in / max(n_in, 1.0)
        P[0] = math.atan2(ny, nx)
        P[1] = 0.0
        P[2] = a
        P[3] = sum_out / max((hi - lo) - n_in, 1.0) - a
        P[5], P[6] = 0.0, 0.0
    P[4] = ls


@njit(cache=True, nogil=True, error_model="numpy")
def _fit_edge(X0: NDArray[np.float64], X1: NDArray[np.float64], v: NDArray[np.float64], extra: NDArray[np.float64],
              lo: int, hi: int, nx: float, ny: float, mid: NDArray[np.float64], sigma0: float,
              init: NDArray[np.float64], init_mid: NDArray[np.float64], has_init: bool, want_cov: bool,
              cfg: NDArray[np.float64], P: NDArray[np.float64], cov: NDArray[np.float64], sharp: bool
              ) -> tuple[float, float, bool, bool]:
    """:func:`.edges.fit_sharp_edges` of one edge (pixels ``lo:hi`` relative to ``mid``, normal ``(nx, ny)``),
    its refit with the pixel-integrated step when the Gaussian one is sharper than a pixel included.

    ``cfg`` holds (iterations, tol, clipped iteration factor, clip low, clip high, clipped share, pixel
    variance, sharp sigma, max clipped white). ``sharp``: the edge was found sharper than a pixel before
    (a previous pass), and is fitted with the pixel-integrated step from the start. Writes the parameters
    into ``P`` (7,) and, with ``want_cov``, the (theta, rho) covariance into ``cov`` (2, 2). Returns the
    effective blur, the residual RMS, whether the fit is usable and whether the edge is sharper than a pixel
    (fitted with the pixel-integrated step without being saturated).
    """
    iterations, tol, factor = int(cfg[0]), cfg[1], int(cfg[2])
    clip_low, clip_high, share, pix_var, sharp_sigma, max_white = cfg[3], cfg[4], cfg[5], cfg[6], cfg[7], cfg[8]
    cnt = hi - lo
    n_clip = 0
    for i in range(lo, hi):
        if v[i] >= clip_high or v[i] <= clip_low:
            n_clip += 1
    clipped = np.empty(0, np.bool_)
    if n_clip > 0:
        clipped = np.zeros(v.shape[0], np.bool_)
        for i in range(lo, hi):
            clipped[i] = v[i] >= clip_high or v[i] <= clip_low
    saturated = n_clip > share * cnt
    has = cnt > 8
    JTJ = np.empty((_NP, _NP))
    G = np.empty((8, 8))
    ls0 = math.log(max(sigma0, 0.3))
    sigma = 0.0
    cur = 0.0
    slow = saturated
    for model in range(1 if sharp else 0, 2):
        # model 1: every edge on the pixel-integrated step (fit_sharp_edges' pixel_model refit); an edge a previous
        # pass found sharp starts there: its Gaussian fit would only run its blur down to the bound again
        # (a fifth of them at their iteration limit on real photos) before the same refit
        slow = saturated or model == 1
        _start_params(X0, X1, v, lo, hi, nx, ny, mid, ls0, init, init_mid, has_init, P)
        if slow:
            P[4] = math.log(math.sqrt(max(math.exp(2 * P[4]) - pix_var, 0.05**2)))
            if saturated:
                P[3] = min(max(P[3], 2.0 * (clip_high - P[2])), max_white * (clip_high - P[2]))
        if has:
            cur = lm_edge(X0, X1, v, extra, lo, hi, P, clipped, slow, iterations * factor if slow else iterations,
                          tol, math.sqrt(cnt), math.log(0.05), math.log(20.0), max_white, clip_low, clip_high,
                          JTJ, G)
        else:
            cur = 0.0
            JTJ[:] = 0.0
            for p in range(_NP):
                JTJ[p, p] = 1.0
        sigma = math.sqrt(math.exp(2 * P[4]) + pix_var) if slow else math.exp(P[4])
        if slow or not (has and sigma < sharp_sigma):
            break
    s2 = cur / max(cnt - _NP, 1)
    ok = has
    for p in range(_NP):
        ok = ok and math.isfinite(P[p])
    if want_cov:
        _line_block_inverse(JTJ, cov)
        for p in range(2):
            for q in range(2):
                cov[p, q] *= s2
                ok = ok and math.isfinite(cov[p, q])
    return sigma, math.sqrt(s2), ok, slow and not saturated


@njit(cache=True, nogil=True, error_model="numpy")
def _line_block_inverse(A: NDArray[np.float64], out: NDArray[np.float64]) -> None:
    """The (theta, rho) block (2, 2) of ``A^-1`` for the symmetric (7, 7) ``A`` of an edge's normal
    equations, into ``out``: Cholesky of ``A`` scaled to a unit diagonal (its columns are grey levels,
    pixels and radians), two solves; the pseudo-inverse's block (NumPy's ``pinv``, a tenth of the speed)
    where ``A`` is not positive definite."""
    n = A.shape[0]
    d = np.empty(n)
    for i in range(n):
        if not (A[i, i] > 0.0):
            out[:, :] = np.linalg.pinv(A)[:2, :2]
            return
        d[i] = 1.0 / math.sqrt(A[i, i])
    Lw = np.zeros((n, n))
    for j in range(n):
        acc = A[j, j] * d[j] * d[j]
        for k in range(j):
            acc -= Lw[j, k] * Lw[j, k]
        if not (acc > 1e-14):
            out[:, :] = np.linalg.pinv(A)[:2, :2]
            return
        Lw[j, j] = math.sqrt(acc)
        for i in range(j + 1, n):
            acc = A[i, j] * d[i] * d[j]
            for k in range(j):
                acc -= Lw[i, k] * Lw[j, k]
            Lw[i, j] = acc / Lw[j, j]
    y = np.empty(n)
    for c in range(2):
        # L y = e_c, then L^T x = y; x is column c of the scaled inverse
        for i in range(n):
            acc = 1.0 if i == c else 0.0
            for k in range(i):
                acc -= Lw[i, k] * y[k]
            y[i] = acc / Lw[i, i]
        for i in range(n - 1, -1, -1):
            acc = y[i]
            for k in range(i + 1, n):
                acc -= Lw[k, i] * y[k]
            y[i] = acc / Lw[i, i]
        for r in range(2):
            out[r, c] = y[r] * d[r] * d[c]


@njit(cache=True, nogil=True, error_model="numpy")
def quad_corners(theta: NDArray[np.float64], rho: NDArray[np.float64], mid: NDArray[np.float64],
                 cov_line: NDArray[np.float64], corners: NDArray[np.float64], cov: NDArray[np.float64]) -> None:
    """Corners (4, 2) and their covariances (4, 2, 2) of one quad from its four lines (theta, rho (4,),
    mid (4, 2), cov_line (4, 2, 2)), written into ``corners`` and ``cov`` (:func:`.edges.intersect_corners`)."""
    for i in range(4):
        h = (i + 3) % 4
        c1, s1, c2, s2 = math.cos(theta[h]), math.sin(theta[h]), math.cos(theta[i]), math.sin(theta[i])
        r1 = rho[h] + (c1 * mid[h, 0] + s1 * mid[h, 1])
        r2 = rho[i] + (c2 * mid[i, 0] + s2 * mid[i, 1])
        det = c1 * s2 - s1 * c2
        # A = [[c1, s1], [c2, s2]]; its inverse's columns
        a00, a01, a10, a11 = s2 / det, -s1 / det, -c2 / det, c1 / det
        x = a00 * r1 + a01 * r2
        y = a10 * r1 + a11 * r2
        corners[i, 0], corners[i, 1] = x, y
        k1 = -s1 * (mid[h, 0] - x) + c1 * (mid[h, 1] - y)
        k2 = -s2 * (mid[i, 0] - x) + c2 * (mid[i, 1] - y)
        for r in range(2):
            for c in range(2):
                cov[i, r, c] = 0.0
        for (col0, col1, kk, C) in ((a00, a10, k1, cov_line[h]), (a01, a11, k2, cov_line[i])):
            # J = [col * kk, col] (2 x 2), J C J^T
            j00, j01, j10, j11 = col0 * kk, col0, col1 * kk, col1
            m00 = j00 * C[0, 0] + j01 * C[1, 0]
            m01 = j00 * C[0, 1] + j01 * C[1, 1]
            m10 = j10 * C[0, 0] + j11 * C[1, 0]
            m11 = j10 * C[0, 1] + j11 * C[1, 1]
            cov[i, 0, 0] += m00 * j00 + m01 * j01
            cov[i, 0, 1] += m00 * j10 + m01 * j11
            cov[i, 1, 0] += m10 * j00 + m11 * j01
            cov[i, 1, 1] += m10 * j10 + m11 * j11


@njit(cache=True, nogil=True, error_model="numpy")
def all_quad_corners(theta: NDArray[np.float64], rho: NDArray[np.float64], mid: NDArray[np.float64],
                     cov_line: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """:func:`quad_corners` of every quad of the lines ``4q .. 4q + 3`` (theta, rho (4Q,), mid (4Q, 2),
    cov_line (4Q, 2, 2)): corners (Q, 4, 2) and their covariances (Q, 4, 2, 2)."""
    Q = theta.shape[0] // 4
    corners = np.empty((Q, 4, 2))
    cov = np.empty((Q, 4, 2, 2))
    for q in range(Q):
        e0 = 4 * q
        quad_corners(theta[e0:e0 + 4], rho[e0:e0 + 4], mid[e0:e0 + 4], cov_line[e0:e0 + 4], corners[q], cov[q])
    return corners, cov


@njit(cache=True, nogil=True, error_model="numpy")
def _context(x: NDArray[np.float64], y: NDArray[np.float64], es: NDArray[np.int64], P: NDArray[np.float64],
             mid: NDArray[np.float64], sigma: NDArray[np.float64], white: NDArray[np.float64]) -> NDArray[np.float64]:
    """:func:`.edges.marker_context` of one quad's band pixels (edges ``es`` in 0..3) at its previous fits
    ``P`` (4, 7), ``mid`` (4, 2) and effective blurs ``sigma`` (4,); ``white`` (1, n, n)."""
    corners = np.empty((1, 4, 2))
    cov = np.empty((4, 2, 2))
    quad_corners(P[:, 0].copy(), P[:, 1].copy(), mid, np.zeros((4, 2, 2)), corners[0], cov)
    H = quad_homographies(corners).reshape(1, 9)
    N = x.shape[0]
    d = np.empty(N)
    sg = np.empty(N)
    cs = np.empty((4, 2))
    for k in range(4):
        cs[k, 0], cs[k, 1] = math.cos(P[k, 0]), math.sin(P[k, 0])
    for i in range(N):
        e = es[i]
        d[i] = cs[e, 0] * (x[i] - mid[e, 0]) + cs[e, 1] * (y[i] - mid[e, 1]) - P[e, 1]
        sg[i] = sigma[e]
    return marker_context(x, y, np.zeros(N, np.int64), H, sg, white, d)


@njit(cache=True, nogil=True, error_model="numpy")
def _edge_starts(es: NDArray[np.int64]) -> NDArray[np.int64]:
    """First index (5,) of each of a quad's four edges in its pixels' sorted edge indices ``es`` (0..3),
    and their number last."""
    starts = np.zeros(5, np.int64)
    for i in range(es.shape[0]):
        starts[es[i] + 1] += 1
    for k in range(4):
        starts[k + 1] += starts[k]
    return starts


@njit(cache=True, nogil=True, error_model="numpy")
def _trim_to_paper(x: NDArray[np.float64], y: NDArray[np.float64], raw: NDArray[np.float64], es: NDArray[np.int64],
                   starts: NDArray[np.int64], p0: NDArray[np.float64], p1: NDArray[np.float64],
                   w_in: NDArray[np.float64], w_out: NDArray[np.float64], w_look: NDArray[np.float64],
                   sigma: NDArray[np.float64], step: float, drop: float, end_sigmas: float
                   ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64], NDArray[np.int64]]:
    """A quad's band pixels (x, y, values, edge 0..3; ``starts`` of :func:`_edge_starts`) without those
    beyond the paper's end (:func:`_white_limit`, at most ``w_out``) or beyond ``w_out`` itself
    (:func:`.edges.white_extent`, :func:`.edges.trim_outer`); the edges stay sorted. ``p0``, ``p1``
    (4, 2) and the limits (4,) are the quad's."""
    unit = np.empty((4, 2))
    for k in range(4):
        tx, ty = p1[k, 0] - p0[k, 0], p1[k, 1] - p0[k, 1]
        L = math.hypot(tx, ty)
        unit[k, 0], unit[k, 1] = tx / L, ty / L
    N = x.shape[0]
    d = np.empty(N)
    for i in range(N):
        k = es[i]
        d[i] = (x[i] - p0[k, 0]) * unit[k, 1] - (y[i] - p0[k, 1]) * unit[k, 0]
    lim = np.empty(4)
    for k in range(4):
        lim[k] = min(w_out[k], _white_limit(d, raw, starts[k], starts[k + 1], step, sigma[k], w_in[k], w_look[k],
                                            drop, end_sigmas))
    m = 0
    for i in range(N):
        if d[i] <= lim[es[i]]:
            x[m], y[m], raw[m], es[m] = x[i], y[i], raw[i], es[i]
            m += 1
    return x[:m], y[:m], raw[:m], es[:m]


@njit(cache=True, nogil=True, error_model="numpy")
def _unstride_clipped(raw: NDArray[np.float64], es: NDArray[np.int64], stride: NDArray[np.int64],
                      share: float) -> bool:
    """Set a quad's column strides ``stride`` (4,) to 1 when more than ``share`` of one of its edges' band
    pixels (raw levels ``raw``, edges ``es`` in 0..3) are clipped at 0 or 255 (:func:`.edges.unstride_clipped`);
    returns whether they changed (the band is then gathered again)."""
    strided = False
    for k in range(4):
        strided = strided or stride[k] > 1
    if not strided:
        return False
    n = np.zeros(4, np.int64)
    n_clip = np.zeros(4, np.int64)
    for i in range(raw.shape[0]):
        n[es[i]] += 1
        if raw[i] >= 255.0 or raw[i] <= 0.0:
            n_clip[es[i]] += 1
    for k in range(4):
        if n_clip[k] > share * n[k]:
            for j in range(4):
                stride[j] = 1
            return True
    return False


@njit(cache=True, nogil=True, error_model="numpy")
def refine_pass(gray: NDArray[np.uint8], lut: NDArray[np.float64], map_x: NDArray[np.float32],
                map_y: NDArray[np.float32], boxes: NDArray[np.int64], p0: NDArray[np.float64],
                p1: NDArray[np.float64], sigma0: NDArray[np.float64], w_in: NDArray[np.float64],
                w_out: NDArray[np.float64], w_look: NDArray[np.float64], excl: NDArray[np.float64],
                stride: NDArray[np.int64], white: NDArray[np.float64], band_cfg: NDArray[np.float64],
                fit_cfg: NDArray[np.float64], first: bool, active: NDArray[np.bool_], P: NDArray[np.float64],
                mid: NDArray[np.float64], sigma: NDArray[np.float64], cov: NDArray[np.float64],
                rms: NDArray[np.float64], n_px: NDArray[np.int64], ok: NDArray[np.bool_],
                sharp: NDArray[np.bool_], ctx: NDArray[np.float64], sat: NDArray[np.bool_]) -> None:
    """One pass of :func:`.edges.refine_quads` over ``Q`` quads (edges ``4q .. 4q + 3``), in place.

    Parameters
    ----------
    gray : (H, W) image. lut : (256,) light of each level (:func:`.tone.to_light`).
    map_x, map_y, boxes : with a lens model, the undistorted position of every raw pixel (H, W) and each
        edge's raw box (4Q, 4) (:func:`_gather_undistorted`); else ``boxes`` is empty.
    p0, p1 : (4Q, 2) the edges' end points; replaced by the fitted lines' points nearest to them.
    sigma0 : (4Q,) the blur the pass starts from; replaced by the median per quad of the fitted blurs.
    w_in, w_out, w_look, excl : (4Q,) the band's limits (:func:`.edges.gather_band`); ``w_look`` the
        outer limit read for the paper's end (``w_out`` itself when that is not looked for); stride : (4Q,)
        the column stride of each band (:func:`.edges.band_stride`).
    white : (Q, n, n) white cells. band_cfg : (white end looked for (0/1), bin width, white-end drop,
        white-end sigmas, blur lower clip, blur upper clip, settling move in pixels).
    fit_cfg : :func:`_fit_edge`'s ``cfg``. first : the first pass (plain steps, no covariances).
    active : (Q,) the quads this pass fits; one whose corners (:func:`quad_corners`) moved less than the
        settling move in a pass after the first is set False (it keeps this pass's fits).
    P, mid, sigma, cov, rms, n_px, ok : (4Q, 7), (4Q, 2), (4Q,), (4Q, 2, 2), (4Q,) x 3: the fits of
        :class:`.edges.EdgeFit` (``P`` its parameters), read as the previous pass's and replaced.
    sharp : (4Q,) the edges found sharper than a pixel (fitted with the pixel-integrated step, not being
        saturated), read as the previous pass's and replaced (:func:`_fit_edge`).
    ctx : (4Q, 3) the blurs of each edge's marker context (:func:`context_blur`), updated.
    sat : (4Q,) the edges saturated at the clip level (:func:`_saturated_edges`), read as the previous
        pass's and replaced.
    """
    Q = white.shape[0]
    undistorted = boxes.shape[0] > 0
    look, step, drop, end_sigmas = band_cfg[0] > 0.5, band_cfg[1], band_cfg[2], band_cfg[3]
    s_lo, s_hi, settle = band_cfg[4], band_cfg[5], band_cfg[6]
    init = np.empty((4, _NP))
    init_mid = np.empty((4, 2))
    new_mid = np.empty(2)
    for q in range(Q):
        if not active[q]:
            continue
        e0 = 4 * q
        sl = slice(e0, e0 + 4)
        w_band = w_look[sl] if look else w_out[sl]
        for _attempt in range(2):
            if undistorted:
                x, y, raw, es = _gather_undistorted(gray, map_x, map_y, boxes[sl], p0[sl], p1[sl], w_in[sl], w_band,
                                                    excl[sl], stride[sl])
            else:
                x, y, raw, es = gather_raw(gray, p0[sl], p1[sl], w_in[sl], w_band, excl[sl], stride[sl])
            if not _unstride_clipped(raw, es, stride[sl], fit_cfg[5]):
                break
        starts = _edge_starts(es)
        if look:
            x, y, raw, es = _trim_to_paper(x, y, raw, es, starts, p0[sl], p1[sl], w_in[sl], w_out[sl], w_look[sl],
                                           sigma0[sl], step, drop, end_sigmas)
            starts = _edge_starts(es)
        N = x.shape[0]
        v = np.empty(N)
        for i in range(N):
            v[i] = lut[int(raw[i])]
        if first:
            extra = np.zeros(N)
        else:
            extra = _context(x, y, es, P[sl], mid[sl], context_blur(sigma[sl], sat[sl], ctx[sl], s_lo, s_hi),
                             white[q:q + 1])
        for k in range(4):
            init[k] = P[e0 + k]
            init_mid[k] = mid[e0 + k]
        X0 = np.empty(N)
        X1 = np.empty(N)
        for k in range(4):
            e = e0 + k
            tx, ty = p1[e, 0] - p0[e, 0], p1[e, 1] - p0[e, 1]
            nl = math.sqrt(tx * tx + ty * ty)
            tx, ty = tx / nl, ty / nl
            new_mid[0], new_mid[1] = 0.5 * (p0[e, 0] + p1[e, 0]), 0.5 * (p0[e, 1] + p1[e, 1])
            lo, hi = starts[k], starts[k + 1]
            for i in range(lo, hi):
                X0[i] = x[i] - new_mid[0]
                X1[i] = y[i] - new_mid[1]
            sg, r, good, sharp[e] = _fit_edge(X0, X1, v, extra, lo, hi, ty, -tx, new_mid, sigma0[e], init[k],
                                              init_mid[k], not first, not first, fit_cfg, P[e], cov[e], sharp[e])
            mid[e, 0], mid[e, 1] = new_mid[0], new_mid[1]
            sigma[e], rms[e], n_px[e], ok[e] = sg, r, hi - lo, good
        share_white(X0, X1, v, extra, starts, sigma0[sl], first, fit_cfg, P[sl], mid[sl], sigma[sl], cov[sl],
                     rms[sl], ok[sl])
        _saturated_edges(v, starts, fit_cfg, sat[sl])
        if not first and corner_move(init, init_mid, P[sl], mid[sl]) < settle:
            active[q] = False
        _next_pass(P[sl], mid[sl], sigma[sl], s_lo, s_hi, p0[sl], p1[sl], sigma0[sl])


@njit(cache=True, nogil=True, error_model="numpy")
def context_blur(sigma: NDArray[np.float64], sat: NDArray[np.bool_], ctx: NDArray[np.float64], s_lo: float,
                 s_hi: float) -> NDArray[np.float64]:
    """The blur (4,) of a quad's marker context this pass, its edges' last fitted blurs ``sigma`` (4,)
    (effective, px) where they are not saturated (``sat`` (4,), the last pass's).

    A saturated edge sees only the foot of its ramp, and answers a wider context blur with a narrower fitted
    one: iterating fit and context from pass to pass alternates about their joint fixed point instead of
    reaching it. Its context blur is the secant step to the root of ``fit(c) - c`` through its last two
    passes (context blur ``c``, fitted blur), kept between the last context blur and the blur it gave and
    within ``[s_lo, s_hi]``; the plain iteration where fewer than two passes had a context or the two are
    parallel. ``ctx`` (4, 3): each edge's (context blur, fitted blur)
    of the pass before the last, and the last pass's context blur (NaN: none); updated in place."""
    out = np.empty(4)
    for k in range(4):
        c1, s1 = ctx[k, 2], sigma[k]
        c0, s0 = ctx[k, 0], ctx[k, 1]
        c = s1
        if sat[k] and math.isfinite(c0) and math.isfinite(s0) and math.isfinite(c1) and math.isfinite(s1):
            g1, g0 = s1 - c1, s0 - c0
            den = g1 - g0
            if abs(den) > 1e-9 and abs(c1 - c0) > 1e-9:
                # a fit that answers a wider context with a narrower blur has its fixed point between the
                # two: the step is clamped to that bracket
                c = min(max(c1 - g1 * (c1 - c0) / den, min(c1, s1), s_lo), max(c1, s1), s_hi)
        ctx[k, 0], ctx[k, 1], ctx[k, 2] = c1, s1, c
        out[k] = c
    return out


@njit(cache=True, nogil=True, error_model="numpy")
def _saturated_edges(v: NDArray[np.float64], starts: NDArray[np.int64], cfg: NDArray[np.float64],
                     sat: NDArray[np.bool_]) -> None:
    """Whether more than the clipped share (``cfg[5]``, :func:`_fit_edge`) of each of a quad's edges' band
    pixels ``v`` (edges from ``starts``) lies at the clip level ``cfg[4]``, into ``sat`` (4,)."""
    for k in range(4):
        lo, hi = starts[k], starts[k + 1]
        n_clip = 0
        for i in range(lo, hi):
            if v[i] >= cfg[4]:
                n_clip += 1
        sat[k] = hi - lo > 8 and n_clip > cfg[5] * (hi - lo)


#: relative excess over the paper's white level above which a saturated edge is refitted: the smeared
#: edges of the simulated room's sunlit markers ran to 1.3-5 times the sharpest edge's white, while edges
#: along the motion differed by about a tenth among themselves (shading, noise)
WHITE_SHARE_TOL = 0.1


@njit(cache=True, nogil=True, error_model="numpy")
def share_white(X0: NDArray[np.float64], X1: NDArray[np.float64], v: NDArray[np.float64], extra: NDArray[np.float64],
                starts: NDArray[np.int64], sigma0: NDArray[np.float64], first: bool, cfg: NDArray[np.float64],
                P: NDArray[np.float64], mid: NDArray[np.float64], sigma: NDArray[np.float64],
                cov: NDArray[np.float64], rms: NDArray[np.float64], ok: NDArray[np.bool_]) -> None:
    """Refit a quad's saturated edges whose white level exceeds the paper's, in place.

    One sheet under one light has one white level. A clipped edge sees only the foot of its ramp; when the
    ramp is also smeared across the edge by motion, contrast and blur trade off along it and the white level
    runs up, moving the line into the white. The sharpest of the quad's saturated edges (one the motion runs
    along) shows the most of its step below the clip: its white level bounds the others'. ``P``, ``mid``,
    ``sigma``, ``cov``, ``rms``, ``ok`` are the quad's four fits (:func:`refine_pass`), ``cfg`` the fits'
    settings (:func:`_fit_edge`).
    """
    clip_high, share, max_white = cfg[4], cfg[5], cfg[8]
    sat = np.zeros(4, np.bool_)
    paper = np.inf
    sharpest = np.inf
    for k in range(4):
        lo, hi = starts[k], starts[k + 1]
        n_clip = 0
        for i in range(lo, hi):
            if v[i] >= clip_high:
                n_clip += 1
        sat[k] = hi - lo > 8 and n_clip > share * (hi - lo) and ok[k]
        if sat[k] and sigma[k] < sharpest:
            sharpest = sigma[k]
            paper = P[k, 2] + P[k, 3]
    if not np.isfinite(paper):
        return
    sub = cfg.copy()
    init = np.empty(_NP)
    init_mid = np.empty(2)
    for k in range(4):
        a = P[k, 2]
        if not sat[k] or a + P[k, 3] <= paper * (1.0 + WHITE_SHARE_TOL) or a >= clip_high:
            continue
        sub[8] = min(max_white, (paper - a) / (clip_high - a))
        init[:] = P[k]
        init_mid[:] = mid[k]
        nx, ny = math.cos(P[k, 0]), math.sin(P[k, 0])
        sg, r, good, _sharp = _fit_edge(X0, X1, v, extra, starts[k], starts[k + 1], nx, ny, init_mid, sigma0[k],
                                        init, init_mid, True, not first, sub, P[k], cov[k], False)
        sigma[k], rms[k], ok[k] = sg, r, good


@njit(cache=True, nogil=True, error_model="numpy")
def corner_move(P0: NDArray[np.float64], mid0: NDArray[np.float64], P1: NDArray[np.float64],
                mid1: NDArray[np.float64]) -> float:
    """The largest distance (px) between the corners of a quad's lines ``P0`` (4, 7), ``mid0`` (4, 2) and
    those of ``P1``, ``mid1`` (:func:`quad_corners`; NaN where either has no intersection)."""
    c0 = np.empty((4, 2))
    c1 = np.empty((4, 2))
    cov = np.empty((4, 2, 2))
    no_cov = np.zeros((4, 2, 2))
    quad_corners(P0[:, 0].copy(), P0[:, 1].copy(), mid0, no_cov, c0, cov)
    quad_corners(P1[:, 0].copy(), P1[:, 1].copy(), mid1, no_cov, c1, cov)
    move = 0.0
    for i in range(4):
        dist = math.hypot(c1[i, 0] - c0[i, 0], c1[i, 1] - c0[i, 1])
        if math.isnan(dist):
            return np.nan
        move = max(move, dist)
    return move


@njit(cache=True, nogil=True, error_model="numpy")
def _next_pass(P: NDArray[np.float64], mid: NDArray[np.float64], sigma: NDArray[np.float64], s_lo: float,
               s_hi: float, p0: NDArray[np.float64], p1: NDArray[np.float64], sigma0: NDArray[np.float64]) -> None:
    """A quad's next start: the median of its four blurs clipped to ``[s_lo, s_hi]`` into ``sigma0``
    (4,), and the end points ``p0``, ``p1`` (4, 2) moved onto the fitted lines."""
    s = np.empty(4)
    nan = False
    for k in range(4):
        s[k] = min(max(sigma[k], s_lo), s_hi)
        nan = nan or math.isnan(sigma[k])
    s.sort()
    med = np.nan if nan else 0.5 * (s[1] + s[2])
    for k in range(4):
        sigma0[k] = med
        c, sn = math.cos(P[k, 0]), math.sin(P[k, 0])
        off = P[k, 1] + (c * mid[k, 0] + sn * mid[k, 1])
        for pt in (p0, p1):
            dist = (c * pt[k, 0] + sn * pt[k, 1]) - off
            pt[k, 0] -= dist * c
            pt[k, 1] -= dist * sn


@njit(cache=True, inline="always", error_model="numpy")
def _nan_max(a: float, b: float) -> float:
    """``np.maximum`` of two floats (NaN if either is)."""
    return a + b if (math.isnan(a) or math.isnan(b)) else (a if a >= b else b)


@njit(cache=True, inline="always", error_model="numpy")
def _nan_min(a: float, b: float) -> float:
    """``np.minimum`` of two floats (NaN if either is)."""
    return a + b if (math.isnan(a) or math.isnan(b)) else (a if a <= b else b)


@njit(cache=True, nogil=True, error_model="numpy")
def band_limits(sigma: NDArray[np.float64], side: NDArray[np.float64], cell: NDArray[np.float64],
                border: NDArray[np.float64], first: bool, band_px: float, margin_cells: float, white_end: bool,
                look_sigmas: float
                ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """:func:`.edges.band_limits` (its formulas) for edges of blur ``sigma``, length ``side``, cell and border
    widths ``cell``, ``border`` (all (E,), pixels): ``w_in``, ``w_out``, ``w_look``, the ends left out (E,).
    ``margin_cells`` NaN when the margin is unknown; ``w_look`` is ``w_out`` without ``white_end``."""
    E = sigma.shape[0]
    w_in = np.empty(E)
    w_out = np.empty(E)
    w_look = np.empty(E)
    excl = np.empty(E)
    for e in range(E):
        s = sigma[e]
        w = 3.0 * s + band_px
        wo = _nan_max(1.5, _nan_min(w, cell[e] + 1.0))
        if first:
            w_in[e] = _nan_max(1.0, _nan_min(w, border[e] - 1.5 * s))
            excl[e] = _nan_min(_nan_max(3.0 * s + 1.0, 0.08 * side[e]), 0.3 * side[e])
        else:
            w_in[e] = _nan_max(1.0, _nan_min(w, border[e] + 0.5 * cell[e]))
            excl[e] = _nan_min(s, 0.3 * side[e])
        if not math.isnan(margin_cells):
            wo = _nan_max(1.0, _nan_min(wo, margin_cells * cell[e] - 2.0 * s))
        w_out[e] = wo
        w_look[e] = wo + look_sigmas * s if white_end else wo
    return w_in, w_out, w_look, excl


@njit(cache=True, nogil=True, error_model="numpy")
def band_stride(side: NDArray[np.float64], columns: int) -> NDArray[np.int64]:
    """:func:`.edges.band_stride`: ``floor(side / columns)``, at least 1, for edges ``side`` (E,) pixels long
    (every column, 1, with ``columns`` 0)."""
    out = np.ones(side.shape[0], np.int64)
    if columns > 0:
        for e in range(side.shape[0]):
            out[e] = max(int(math.floor(side[e] / columns)), 1)
    return out


@njit(cache=True, nogil=True, error_model="numpy")
def quad_sides(quads: NDArray[np.float64], n: int, border_cells: int
               ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """Each edge's length, the cell and the border widths (all (4Q,), pixels) of quads (Q, 4, 2) with ``n``
    cells a side and ``border_cells`` of border (:func:`.edges.refine_quads`)."""
    Q = quads.shape[0]
    L = np.empty(4 * Q)
    cell = np.empty(4 * Q)
    border = np.empty(4 * Q)
    for q in range(Q):
        tot = 0.0
        for k in range(4):
            j = (k + 1) % 4
            dx, dy = quads[q, k, 0] - quads[q, j, 0], quads[q, k, 1] - quads[q, j, 1]
            L[4 * q + k] = math.sqrt(dx * dx + dy * dy)
            tot += L[4 * q + k]
        for k in range(4):
            cell[4 * q + k] = tot / 4.0 / n
            border[4 * q + k] = cell[4 * q + k] * border_cells
    return L, cell, border


@njit(cache=True, nogil=True, error_model="numpy")
def refine_all(gray: NDArray[np.uint8], lut: NDArray[np.float64], map_x: NDArray[np.float32],
               map_y: NDArray[np.float32], K: NDArray[np.float64], dist: NDArray[np.float64],
               quads: NDArray[np.float64], white: NDArray[np.float64], border_cells: int, cfg: NDArray[np.float64],
               fit_cfg: NDArray[np.float64]
               ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64], NDArray[np.float64],
                          NDArray[np.float64], NDArray[np.int64], NDArray[np.bool_], NDArray[np.float64],
                          NDArray[np.float64]]:
    """Every pass of :func:`.edges.refine_quads` in one thread (its loop, compiled).

    Parameters
    ----------
    gray : (H, W) image; lut : (256,) light of each level.
    map_x, map_y, K, dist : with a lens model, the undistorted position of every raw pixel (H, W), the camera
        (3, 3) and OpenCV's distortion coefficients (8,) (:class:`.camera.Undistorter`); without, ``map_x`` is
        empty (0, 0).
    quads : (Q, 4, 2) candidate corners (fit coordinates); white : (Q, n, n) white cells; border_cells : border
        width, cells.
    cfg : (passes, columns, first pass's columns (0: every column), band px, margin cells (NaN: unknown),
        white end looked for (0 / 1), look sigmas, profile step, white-end drop, white-end sigmas, max blur
        px, settle px, first pass's tolerance, passes of quads with a saturated edge): :class:`.edges.RefineParams`
        and the constants of :mod:`.edges`.
    fit_cfg : :func:`_fit_edge`'s ``cfg``.

    Returns
    -------
    P (4Q, 7), mid (4Q, 2), sigma (4Q,), cov_line (4Q, 2, 2), rms (4Q,), n_px (4Q,), ok (4Q,), corners
    (Q, 4, 2) and their covariances (Q, 4, 2, 2).
    """
    Q, n = quads.shape[0], white.shape[1]
    E = 4 * Q
    passes, columns, first_columns, clipped_passes = int(cfg[0]), int(cfg[1]), int(cfg[2]), int(cfg[13])
    band_px, margin_cells, white_end, look_sigmas = cfg[3], cfg[4], cfg[5] > 0.5, cfg[6]
    L, cell, border = quad_sides(quads, n, border_cells)
    p0 = np.empty((E, 2))
    p1 = np.empty((E, 2))
    for q in range(Q):
        for k in range(4):
            for c in range(2):
                p0[4 * q + k, c] = quads[q, k, c]
                p1[4 * q + k, c] = quads[q, (k + 1) % 4, c]
    sigma0 = np.full(E, 1.0)
    P = np.zeros((E, _NP))
    mid = np.zeros((E, 2))
    sigma = np.zeros(E)
    rms = np.zeros(E)
    cov_line = np.zeros((E, 2, 2))
    n_px = np.zeros(E, np.int64)
    ok = np.zeros(E, np.bool_)
    sharp = np.zeros(E, np.bool_)
    ctx = np.full((E, 3), np.nan)
    sat = np.zeros(E, np.bool_)
    stride = band_stride(L, columns)
    first_stride = band_stride(L, first_columns)
    first_stride0 = first_stride.copy()
    active = np.ones(Q, np.bool_)
    boxes = np.zeros((0, 4), np.int64)
    band_cfg = np.array([cfg[5], cfg[7], cfg[8], cfg[9], 0.3, cfg[10], cfg[11]])
    fit_first = fit_cfg.copy()
    fit_first[1] = cfg[12]  # the first pass's tolerance
    for k in range(max(passes, clipped_passes)):
        if k >= passes:
            # only quads with a saturated edge go on: their context blur's secant steps need the passes
            for q in range(Q):
                active[q] = active[q] and (sat[4 * q] or sat[4 * q + 1] or sat[4 * q + 2] or sat[4 * q + 3])
        if not active.any():
            break
        w_in, w_out, w_look, excl = band_limits(sigma0, L, cell, border, k == 0, band_px, margin_cells, white_end,
                                              look_sigmas)
        if map_x.shape[0] > 0:
            boxes = raw_boxes(gray.shape[0], gray.shape[1], p0, p1, w_in, w_look, K, dist)
        refine_pass(gray, lut, map_x, map_y, boxes, p0, p1, sigma0, w_in, w_out, w_look, excl,
                    first_stride if k == 0 else stride, white, band_cfg, fit_first if k == 0 else fit_cfg, k == 0,
                    active, P, mid, sigma, cov_line, rms, n_px, ok, sharp, ctx, sat)
        if k == 0:
            for q in range(Q):
                changed = False
                for j in range(4):
                    changed = changed or first_stride[4 * q + j] != first_stride0[4 * q + j]
                if changed:
                    for j in range(4):
                        stride[4 * q + j] = 1
    corners, cov = all_quad_corners(P[:, 0].copy(), P[:, 1].copy(), mid, cov_line)
    return P, mid, sigma, cov_line, rms, n_px, ok, corners, cov
