"""Compiled per-pixel kernels of the marker detector (numba).

The detector's time goes into a few loops over pixels: the edge fits' Levenberg-Marquardt with
their normal equations, the modelled light of a marker's corners and cells, the band scan, the
side points of the robust quadrilateral and, in the second path, the homographies, profiles,
design and Jacobian of the blurred-marker model. In NumPy every step of such a loop is a pass over
an array with its own temporaries, and on small markers the interpreter's overhead per call
dominates; compiled, each loop is one pass with its values in registers. The formulas are those
documented in :mod:`.edges` and :mod:`.blurred`; the tests hold the kernels against finite
differences and against NumPy forms of the same formulas. Every kernel releases the GIL (the
detector splits work between threads) and follows NumPy's float errors (inf / NaN, no exception).

``cache=True`` keeps the machine code next to the module, so only the first run on a machine pays
the compilation (about 8 s for all of them).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit
from numpy.typing import NDArray

_INV_SQRT_2PI = 1.0 / math.sqrt(2.0 * math.pi)
_SQRT_2PI = math.sqrt(2.0 * math.pi)


# Abramowitz and Stegun 26.2.17: Phi(z) = 1 - phi(z) t (b1 + t (b2 + ... + t b5)), t = 1 / (1 + p |z|),
# absolute error below 7.5e-8 (a millionth of a grey level per unit contrast, far below any noise).
# From the density, which the fits need anyway, it costs a third of libm's erfc.
_AS_P = 0.2316419
_AS_B = (0.319381530, -0.356563782, 1.781477937, -1.821255978, 1.330274429)


@njit(cache=True, inline="always", error_model="numpy")
def _ndtr_from_pdf(z: float, pdf: float) -> float:
    """Standard normal CDF at ``z`` given its density ``pdf`` = phi(z) (error < 7.5e-8)."""
    t = 1.0 / (1.0 + _AS_P * abs(z))
    q = pdf * t * (_AS_B[0] + t * (_AS_B[1] + t * (_AS_B[2] + t * (_AS_B[3] + t * _AS_B[4]))))
    return 1.0 - q if z >= 0.0 else q


@njit(cache=True, inline="always", error_model="numpy")
def _ndtr(z: float) -> float:
    return _ndtr_from_pdf(z, _INV_SQRT_2PI * math.exp(-0.5 * z * z))


#: nodes per unit of the tabulated normal CDF and density (:func:`_ndtr_pdf_tab`) and their reach (the CDF
#: is 0 or 1 to 1e-19 beyond)
_TAB_PER_UNIT = 64
_TAB_REACH = 9.0
_TAB_Z = np.arange(-_TAB_REACH * _TAB_PER_UNIT, _TAB_REACH * _TAB_PER_UNIT + 1) / _TAB_PER_UNIT
#: the normal CDF and density at the nodes (the CDF from libm's erfc, as SciPy's ``ndtr``)
_TAB_CDF = np.array([0.5 * math.erfc(-z / math.sqrt(2.0)) for z in _TAB_Z])
_TAB_PDF = _INV_SQRT_2PI * np.exp(-0.5 * _TAB_Z**2)


@njit(cache=True, inline="always", error_model="numpy")
def _ndtr_pdf_tab(z: float) -> tuple[float, float]:
    """Standard normal CDF and density at ``z``, each the cubic Hermite interpolant of the table's two
    nodes around ``z`` (values and slopes: ``Phi' = phi``, ``phi' = -z phi``): absolute errors below 3e-10,
    and continuous with their slopes (a Levenberg-Marquardt on a model with steps of its own rounding
    takes different paths from starts a rounding apart)."""
    u = (z + _TAB_REACH) * _TAB_PER_UNIT
    if not (u > 0.0):
        return (0.0, 0.0) if u <= 0.0 else (u, u)  # (NaN stays NaN)
    if u >= 2.0 * _TAB_REACH * _TAB_PER_UNIT:
        return 1.0, 0.0
    k = int(u)
    t = u - k
    h = 1.0 / _TAB_PER_UNIT
    t2 = t * t
    t3 = t2 * t
    h00 = 2.0 * t3 - 3.0 * t2 + 1.0
    h10 = (t3 - 2.0 * t2 + t) * h
    h01 = 3.0 * t2 - 2.0 * t3
    h11 = (t3 - t2) * h
    p0, p1 = _TAB_PDF[k], _TAB_PDF[k + 1]
    z0 = k * h - _TAB_REACH
    z1 = z0 + h
    cdf = h00 * _TAB_CDF[k] + h10 * p0 + h01 * _TAB_CDF[k + 1] + h11 * p1
    pdf = h00 * p0 - h10 * z0 * p0 + h01 * p1 - h11 * z1 * p1
    return cdf, pdf


@njit(cache=True, inline="always", error_model="numpy")
def _ndtr_tab(z: float) -> float:
    """Standard normal CDF at ``z`` from the table (:func:`_ndtr_pdf_tab`), without an exponential (the
    per-pixel sums of the marker's modelled light take a dozen CDFs per pixel)."""
    return _ndtr_pdf_tab(z)[0]


@njit(cache=True, inline="always", error_model="numpy")
def _ndtr_lin(z: float) -> float:
    """Standard normal CDF at ``z``, linear between the table's nodes (:func:`_ndtr_pdf_tab`'s): absolute
    error below 7.5e-6 (``h^2 / 8`` times the density's largest slope), at a third of the cubic's work.
    For sums held fixed during a fit (:func:`marker_context`), where no derivative is taken."""
    u = (z + _TAB_REACH) * _TAB_PER_UNIT
    if not (u > 0.0):
        return 0.0 if u <= 0.0 else u  # (NaN stays NaN)
    if u >= 2.0 * _TAB_REACH * _TAB_PER_UNIT:
        return 1.0
    k = int(u)
    return _TAB_CDF[k] + (u - k) * (_TAB_CDF[k + 1] - _TAB_CDF[k])


@njit(cache=True, nogil=True, error_model="numpy")
def _pixel_step(d: float, s: float, cos_t: float, sin_t: float) -> tuple[float, float, float]:
    """Scalar :func:`.edges.pixel_step`: profile, d/d d and d/d log s of the pixel-integrated step.

    The CDFs and densities come from the table (:func:`_ndtr_pdf_tab`), not from ``exp``: within 1e-7 of
    SciPy's forms where the rational CDF left 5e-5 (its error over the narrow box of a near axis-aligned
    edge), and a sharp edge's tiny blur puts ``z`` far out, where the exponential of ``-z^2 / 2`` runs into
    subnormal numbers: :func:`edge_normal_eq` took 159 ns per pixel at a blur of 0.05 px with ``exp``, 36 ns
    with the table (77 and 61 ns at 0.5 px).
    """
    w1 = max(abs(cos_t), 1e-4)
    w2 = max(abs(sin_t), 1e-4)
    h1, h2 = 0.5 * w1, 0.5 * w2
    s2 = s * s
    prof = 0.0
    slope = 0.0
    dls = 0.0
    for k in range(4):
        o1 = 1.0 if k < 2 else -1.0
        o2 = 1.0 if k % 2 == 0 else -1.0
        sign = o1 * o2
        x = d + o1 * h1 + o2 * h2
        cdf, pdf = _ndtr_pdf_tab(x / s)
        sphi = s * pdf
        prof += sign * (0.5 * (x * x + s2) * cdf + 0.5 * x * sphi)
        slope += sign * (x * cdf + sphi)
        dls += sign * cdf
    iw = 1.0 / (w1 * w2)
    return prof * iw, slope * iw, dls * iw * s2


#: pixels whose Jacobian rows :func:`edge_normal_eq` holds at once: the products of their columns are then
#: summed in vector registers (:func:`_gram_add`), four to eight pixels per instruction
_CHUNK = 64


@njit(cache=True, nogil=True, error_model="numpy", fastmath={"reassoc", "contract"})
def _gram_add(J: NDArray[np.float64], m: int, out: NDArray[np.float64]) -> None:
    """``out[p, q] += sum_i J[p, i] J[q, i]`` over the first ``m`` columns of ``J`` (8, C), ``q >= p``
    (the sums reassociated: the order of the additions is the vector unit's, not the pixels')."""
    for p in range(8):
        for q in range(p, 8):
            acc = 0.0
            for i in range(m):
                acc += J[p, i] * J[q, i]
            out[p, q] += acc


@njit(cache=True, nogil=True, error_model="numpy")
def edge_normal_eq(X0: NDArray[np.float64], X1: NDArray[np.float64], val: NDArray[np.float64],
                   extra: NDArray[np.float64], lo: int, hi: int, P: NDArray[np.float64],
                   clipped: NDArray[np.bool_], exact: bool, clip_low: float, clip_high: float,
                   out: NDArray[np.float64]) -> None:
    """``[J r]^T [J r]`` (8, 8) of the blurred-step model of :func:`.edges.fit_sharp_edges` for one edge,
    written into ``out``.

    Parameters
    ----------
    X0, X1 : (N,) pixel coordinates relative to the edge's reference point; the edge's pixels are
        ``lo:hi``.
    val, extra : (N,) intensities and the fixed profile part (:func:`.edges.marker_context`).
    P : (7,) parameters ``(theta, rho, a, b, log sigma, c, c_u)``.
    clipped : (N,) censored pixels (empty: none).
    exact : the edge is modelled by the pixel-integrated step.
    out : (8, 8): ``J^T J`` in ``[:7, :7]``, ``J^T r`` in ``[:7, 7]`` and ``r^T r`` in ``[7, 7]``,
        ``J`` the derivative of the prediction (so ``J^T r`` is minus half the gradient of ``r^T r``).

    The rows ``[J r]`` of :data:`_CHUNK` pixels are formed one pixel at a time, then their products
    summed by :func:`_gram_add`; a censored pixel's row is zero.
    """
    th, rho, a, b, ls, ca, cu = P[0], P[1], P[2], P[3], P[4], P[5], P[6]
    c, s = math.cos(th), math.sin(th)
    isg = math.exp(-ls)
    gk = b * isg * _INV_SQRT_2PI
    has_clip = clipped.shape[0] > 0
    J = np.empty((8, _CHUNK))
    out[:] = 0.0
    for start in range(lo, hi, _CHUNK):
        m = min(_CHUNK, hi - start)
        for j in range(m):
            i = start + j
            x0, x1 = X0[i], X1[i]
            dm = x0 * c + x1 * s  # distance from the reference point across the edge
            d = dm - rho
            u = x1 * c - x0 * s  # along the edge
            if exact:
                Phi, dP, sP = _pixel_step(d, 1.0 / isg, c, s)
                g = b * dP  # d pred / d d at unit shading
                q4 = -b * sP  # minus d pred / d log sigma at unit shading
            else:
                z = d * isg
                Phi, pdf = _ndtr_pdf_tab(z)
                e = pdf * _SQRT_2PI
                g = gk * e
                q4 = g * d
            Phi += extra[i]
            base = a + b * Phi
            f = 1.0 + ca * d + cu * u
            dd = g * f + base * ca
            r = val[i] - base * f
            if has_clip and clipped[i]:
                # censored: a clipped pixel the model puts beyond the clip level agrees
                if (val[i] >= clip_high and r <= 0.0) or (val[i] <= clip_low and r >= 0.0):
                    for p in range(8):
                        J[p, j] = 0.0
                    continue
            J[0, j] = dd * u - dm * cu * base  # theta
            J[1, j] = -dd  # rho
            J[2, j] = f  # a
            J[3, j] = Phi * f  # b
            J[4, j] = -q4 * f  # log sigma
            J[5, j] = base * d  # c
            J[6, j] = base * u  # c_u
            J[7, j] = r
        _gram_add(J, m, out)
    for p in range(8):
        for q in range(p + 1, 8):
            out[q, p] = out[p, q]


@njit(cache=True, error_model="numpy")
def _solve(A: NDArray[np.float64], b: NDArray[np.float64]) -> NDArray[np.float64]:
    """``A^-1 b`` by Gaussian elimination with partial pivoting (NaN where ``A`` is singular)."""
    n = b.shape[0]
    M = A.copy()
    x = b.copy()
    for k in range(n):
        piv = k
        for r in range(k + 1, n):
            if abs(M[r, k]) > abs(M[piv, k]):
                piv = r
        if M[piv, k] == 0.0 or not np.isfinite(M[piv, k]):
            x[:] = np.nan
            return x
        if piv != k:
            for c in range(n):
                M[k, c], M[piv, c] = M[piv, c], M[k, c]
            x[k], x[piv] = x[piv], x[k]
        for r in range(k + 1, n):
            f = M[r, k] / M[k, k]
            for c in range(k, n):
                M[r, c] -= f * M[k, c]
            x[r] -= f * x[k]
    for k in range(n - 1, -1, -1):
        acc = x[k]
        for c in range(k + 1, n):
            acc -= M[k, c] * x[c]
        x[k] = acc / M[k, k]
    return x


@njit(cache=True, nogil=True, error_model="numpy")
def lm_edge(X0: NDArray[np.float64], X1: NDArray[np.float64], val: NDArray[np.float64],
            extra: NDArray[np.float64], lo: int, hi: int, P: NDArray[np.float64], clipped: NDArray[np.bool_],
            slow: bool, iterations: int, tol: float, wt: float, ls_lo: float, ls_hi: float,
            max_white: float, clip_low: float, clip_high: float, JTJ: NDArray[np.float64],
            G: NDArray[np.float64]) -> float:
    """Levenberg-Marquardt of one edge (pixels ``lo:hi``) of :func:`edge_lm`, from and into ``P`` (7,).

    ``iterations`` is the edge's own limit (a clipped edge's already multiplied); ``JTJ`` (7, 7)
    receives ``J^T J`` at the estimate and ``G`` (8, 8) is scratch. Returns the residual sum of squares.
    """
    A = np.empty((7, 7))
    Pn = np.empty(7)
    JTr = np.empty(7)
    rhs = np.empty(7)
    edge_normal_eq(X0, X1, val, extra, lo, hi, P, clipped, slow, clip_low, clip_high, G)
    JTJ[:, :] = G[:7, :7]
    JTr[:] = G[:7, 7]
    cur = G[7, 7]
    lam = 1e-3
    for _it in range(iterations):
        A[:] = JTJ
        for p in range(7):
            A[p, p] += lam * (JTJ[p, p] + 1e-9)
        delta = _solve(A, JTr)
        if (P[4] <= ls_lo and delta[4] < 0.0) or (P[4] >= ls_hi and delta[4] > 0.0):
            # the blur at its bound and pushed beyond: the step of the other parameters with the blur held
            # (the clamped full step is not that step, and its line moves kept the fit from settling)
            for p in range(7):
                A[4, p] = 0.0
                A[p, 4] = 0.0
                rhs[p] = JTr[p]
            A[4, 4] = 1.0
            rhs[4] = 0.0
            delta = _solve(A, rhs)
        if not slow and abs(delta[1]) + abs(delta[0]) * wt < tol:
            # converged: a step this small is not worth the normal equations at its end
            break
        for p in range(7):
            Pn[p] = P[p] + delta[p]
        Pn[4] = min(max(Pn[4], ls_lo), ls_hi)
        if slow:
            Pn[3] = min(Pn[3], max_white * (clip_high - Pn[2]))
        edge_normal_eq(X0, X1, val, extra, lo, hi, Pn, clipped, slow, clip_low, clip_high, G)
        if G[7, 7] <= cur:
            P[:] = Pn
            cur = G[7, 7]
            JTJ[:, :] = G[:7, :7]
            JTr[:] = G[:7, 7]
            lam *= 0.3
        else:
            lam *= 10.0
        done = abs(delta[1]) + abs(delta[0]) * wt < tol
        if slow:
            done = done and abs(delta[3]) < 1e-3 * abs(P[3])
        if done:
            break
    return cur


@njit(cache=True, nogil=True, error_model="numpy")
def edge_lm(X0: NDArray[np.float64], X1: NDArray[np.float64], val: NDArray[np.float64],
            extra: NDArray[np.float64], bounds: NDArray[np.int64], P: NDArray[np.float64],
            has: NDArray[np.bool_], clipped: NDArray[np.bool_], slow: NDArray[np.bool_], iterations: int,
            slow_factor: int, tol: float, wt: NDArray[np.float64], ls_lo: float, ls_hi: float,
            max_white: float, clip_low: float, clip_high: float
            ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """Levenberg-Marquardt of every edge of :func:`.edges.fit_sharp_edges` (its docstring), each on its own
    (:func:`lm_edge`).

    Parameters
    ----------
    X0, X1, val, extra, clipped : as in :func:`edge_normal_eq`; edge ``k``'s pixels are
        ``bounds[k]:bounds[k + 1]``.
    P : (E, 7) initial parameters. has : (E,) edges with enough pixels (the others are left as they
        are). slow : (E,) clipped edges: the pixel-integrated step, ``slow_factor`` times the
        iterations, the white level at most ``max_white`` times the visible contrast, and their
        contrast must settle too.
    iterations, tol, wt : iteration limit; an edge stops once ``|d rho| + wt |d theta| < tol``.
    ls_lo, ls_hi : bounds of log sigma.

    Returns
    -------
    P (E, 7), residual sums of squares (E,) and ``J^T J`` (E, 7, 7) at the estimates (the identity for
    edges not fitted).
    """
    E = P.shape[0]
    P = P.copy()
    JTJ = np.zeros((E, 7, 7))
    cur = np.zeros(E)
    G = np.empty((8, 8))
    for k in range(E):
        if not has[k]:
            for p in range(7):
                JTJ[k, p, p] = 1.0
            continue
        cur[k] = lm_edge(X0, X1, val, extra, bounds[k], bounds[k + 1], P[k], clipped, slow[k],
                         iterations * slow_factor if slow[k] else iterations, tol, wt[k], ls_lo, ls_hi,
                         max_white, clip_low, clip_high, JTJ[k], G)
    return P, cur, JTJ


#: reach of the grid lines' blurred steps in :func:`marker_context`, in SDs: beyond it the CDF is 0 or 1 to
#: 1e-9 (a millionth of a grey level at full contrast), and the lines are set without evaluating (at 9 SDs
#: a small marker's pixel summed the cells of the whole grid)
_CONTEXT_SDS = 6.0


@njit(cache=True, inline="always", error_model="numpy")
def _saturated_grid(t: float, s: float, n: int, F: NDArray[np.float64]) -> tuple[int, int, float, float]:
    """``F[k] = Phi((t - k) / s)`` (:func:`_ndtr_lin`) for the grid lines ``k`` the cells ``[k0, k1)`` need,
    the cells whose ``F[k] - F[k + 1]`` may differ from 0 (lines beyond :data:`_CONTEXT_SDS` are 1 or 0,
    set without evaluating); returns ``k0``, ``k1`` and ``F[0]``, ``F[n]`` (the blurred square's extent).
    Only the entries ``k0 .. k1`` are written: a band pixel has one or two lines within reach of the
    grid's ``n + 1``, and filling the rest cost more than the CDFs."""
    lo = max(0, int(math.ceil(t - _CONTEXT_SDS * s)))
    hi = min(n, int(math.floor(t + _CONTEXT_SDS * s)))
    k0 = min(max(lo - 1, 0), n)
    k1 = min(hi + 1, n)
    inv = 1.0 / s
    for k in range(k0, k1 + 1):
        F[k] = 1.0 if k < lo else (0.0 if k > hi else _ndtr_lin((t - k) * inv))
    f0 = 1.0 if lo > 0 else (0.0 if hi < 0 else _ndtr_lin(t * inv))
    fn = 0.0 if hi < n else (1.0 if lo > n else _ndtr_lin((t - n) * inv))
    if hi < lo and not 0 < lo <= n:
        # no line within reach and none to step across: no cell
        return 0, 0, f0, fn
    return k0, k1, f0, fn


@njit(cache=True, nogil=True, error_model="numpy")
def marker_context(x: NDArray[np.float64], y: NDArray[np.float64], quad: NDArray[np.int64],
                   H: NDArray[np.float64], sigma: NDArray[np.float64], white: NDArray[np.float64],
                   dist: NDArray[np.float64]) -> NDArray[np.float64]:
    """Per-pixel :func:`.edges.marker_context`: ``1 - S + R - Phi(d / sigma)``.

    Parameters
    ----------
    x, y : (N,) fit coordinates of the band pixels; quad : (N,) their quad.
    H : (Q, 9) homographies to marker units (:func:`.edges.quad_homographies`, row-major).
    sigma : (N,) blur of each pixel's edge, pixels.
    white : (Q, n, n) white cells.
    dist : (N,) signed distance of each pixel to its edge's line, pixels.
    """
    N = x.shape[0]
    n = white.shape[1]
    out = np.empty(N)
    Fx = np.empty(n + 1)
    Fy = np.empty(n + 1)
    for i in range(N):
        g = quad[i]  # (elements indexed in place: a view per pixel costs more than the pixel's sums)
        xi, yi = x[i], y[i]
        w3 = H[g, 6] * xi + H[g, 7] * yi + H[g, 8]
        mx = (H[g, 0] * xi + H[g, 1] * yi + H[g, 2]) / w3
        my = (H[g, 3] * xi + H[g, 4] * yi + H[g, 5]) / w3
        scale = sigma[i] / abs(w3) * n
        ax, bx = H[g, 0] - mx * H[g, 6], H[g, 1] - mx * H[g, 7]
        ay, by = H[g, 3] - my * H[g, 6], H[g, 4] - my * H[g, 7]
        sx = scale * math.sqrt(ax * ax + bx * bx)  # (libm's hypot guards against overflow at 4x the cost)
        sy = scale * math.sqrt(ay * ay + by * by)
        # only the grid lines within _CONTEXT_SDS have a CDF other than 0 or 1: the cells' sum runs over the
        # rows and columns between them (the other products are 0)
        c0, c1, fx0, fxn = _saturated_grid(mx * n, sx, n, Fx)
        r0, r1, fy0, fyn = _saturated_grid(my * n, sy, n, Fy)
        R = 0.0
        for r in range(r0, r1):
            Yr = Fy[r] - Fy[r + 1]
            if Yr == 0.0:
                continue
            acc = 0.0
            for c in range(c0, c1):
                if white[g, r, c] != 0.0:
                    acc += white[g, r, c] * (Fx[c] - Fx[c + 1])
            R += Yr * acc
        S = (fx0 - fxn) * (fy0 - fyn)
        out[i] = 1.0 - S + R - _ndtr_tab(dist[i] / sigma[i])
    return out


@njit(cache=True, nogil=True, error_model="numpy")
def quad_homographies(quads: NDArray[np.float64]) -> NDArray[np.float64]:
    """Homographies (Q, 3, 3) taking corner ``k`` of each quad (Q, 4, 2) to (0, 0), (1, 0), (1, 1),
    (0, 1) in turn (:func:`.edges.quad_homographies`); NaN where a quad is degenerate."""
    Q = quads.shape[0]
    out = np.empty((Q, 3, 3))
    A = np.zeros((8, 8))
    rhs = np.empty(8)
    us = (0.0, 1.0, 1.0, 0.0)
    vs = (0.0, 0.0, 1.0, 1.0)
    for q in range(Q):
        A[:] = 0.0
        for k in range(4):
            x, y = quads[q, k, 0], quads[q, k, 1]
            u, v = us[k], vs[k]
            A[k, 0], A[k, 1], A[k, 2], A[k, 6], A[k, 7] = x, y, 1.0, -u * x, -u * y
            A[4 + k, 3], A[4 + k, 4], A[4 + k, 5], A[4 + k, 6], A[4 + k, 7] = x, y, 1.0, -v * x, -v * y
            rhs[k], rhs[4 + k] = u, v
        h = _solve(A, rhs)
        for i in range(8):
            out[q, i // 3, i % 3] = h[i]
        out[q, 2, 2] = 1.0
    return out


@njit(cache=True, inline="always", error_model="numpy")
def _grid_cdfs(h: NDArray[np.float64], xi: float, yi: float, sigma: float, n: int, Fx: NDArray[np.float64],
               Fy: NDArray[np.float64]) -> float:
    """At pixel ``(xi, yi)``, for the homography ``h`` (9,) to marker units and blur ``sigma``: the
    blurred indicators ``Fx[k]``, ``Fy[k]`` of being past grid line ``k`` (0..n) along each axis, and
    the blurred black square's complement ``1 - S``."""
    w3 = h[6] * xi + h[7] * yi + h[8]
    mx = (h[0] * xi + h[1] * yi + h[2]) / w3
    my = (h[3] * xi + h[4] * yi + h[5]) / w3
    s = sigma / abs(w3) * n
    sx = max(s * math.hypot(h[0] - mx * h[6], h[1] - mx * h[7]), 1e-3)
    sy = max(s * math.hypot(h[3] - my * h[6], h[4] - my * h[7]), 1e-3)
    for k in range(n + 1):
        Fx[k] = _ndtr((mx * n - k) / sx)
        Fy[k] = _ndtr((my * n - k) / sy)
    return 1.0 - (Fx[0] - Fx[n]) * (Fy[0] - Fy[n])


@njit(cache=True, nogil=True, error_model="numpy")
def cell_profiles(x: NDArray[np.float64], y: NDArray[np.float64], H: NDArray[np.float64],
                  sigma: NDArray[np.float64], n: int, border: int
                  ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """The blurred black square ``1 - S`` (K, N) and the blurred data cells ``F`` (K, N, d^2) at pixels
    ``(x, y)`` (N,) for K homographies ``H`` (K, 3, 3) to marker units and blurs ``sigma`` (K,)
    (:func:`.blurred._profiles`; the model of :func:`.edges.marker_context`)."""
    K, N = H.shape[0], x.shape[0]
    d = n - 2 * border
    base = np.empty((K, N))
    F = np.empty((K, N, d * d))
    Fx = np.empty(n + 1)
    Fy = np.empty(n + 1)
    for g in range(K):
        h = H[g].ravel()
        for i in range(N):
            base[g, i] = _grid_cdfs(h, x[i], y[i], sigma[g], n, Fx, Fy)
            for r in range(d):
                Yr = Fy[border + r] - Fy[border + r + 1]
                for c in range(d):
                    F[g, i, r * d + c] = Yr * (Fx[border + c] - Fx[border + c + 1])
    return base, F


@njit(cache=True, nogil=True, error_model="numpy")
def cell_design(x: NDArray[np.float64], y: NDArray[np.float64], H: NDArray[np.float64], sigma: float, n: int,
                border: int, code: NDArray[np.float64]) -> NDArray[np.float64]:
    """The linear design of the blurred-marker model at pixels ``(x, y)`` (N,) for the homography
    ``H`` (3, 3) to marker units and blur ``sigma``: columns ``[1, 1 - S, F]`` (N, 2 + d^2) with the
    cells free (``code`` empty), or ``[1, 1 - S + F code]`` (N, 2) for a code (d^2,) (the profiles of
    :func:`cell_profiles`)."""
    N = x.shape[0]
    d = n - 2 * border
    free = code.shape[0] == 0
    A = np.empty((N, 2 + d * d if free else 2))
    Fx = np.empty(n + 1)
    Fy = np.empty(n + 1)
    h = H.ravel()
    for i in range(N):
        base = _grid_cdfs(h, x[i], y[i], sigma, n, Fx, Fy)
        A[i, 0] = 1.0
        if free:
            A[i, 1] = base
            for r in range(d):
                Yr = Fy[border + r] - Fy[border + r + 1]
                for c in range(d):
                    A[i, 2 + r * d + c] = Yr * (Fx[border + c] - Fx[border + c + 1])
        else:
            acc = 0.0
            for r in range(d):
                Yr = Fy[border + r] - Fy[border + r + 1]
                for c in range(d):
                    if code[r * d + c] != 0.0:
                        acc += code[r * d + c] * Yr * (Fx[border + c] - Fx[border + c + 1])
            A[i, 1] = base + acc
    return A


@njit(cache=True, inline="always")
def _popcount64(x: np.uint64) -> int:
    """Set bits of a 64-bit word (SWAR: pairs, nibbles, bytes, then one multiply)."""
    x = x - ((x >> np.uint64(1)) & np.uint64(0x5555555555555555))
    x = (x & np.uint64(0x3333333333333333)) + ((x >> np.uint64(2)) & np.uint64(0x3333333333333333))
    x = (x + (x >> np.uint64(4))) & np.uint64(0x0F0F0F0F0F0F0F0F)
    return int((x * np.uint64(0x0101010101010101)) >> np.uint64(56))


@njit(cache=True, nogil=True)
def nearest_codes(words: NDArray[np.uint64], table: NDArray[np.uint64]
                  ) -> tuple[NDArray[np.int64], NDArray[np.int64], NDArray[np.int64]]:
    """For each packed observation ``words`` (K,), the nearest code of ``table`` (N, 4) (N codes in
    their 4 rotations): its flat index ``id * 4 + rotation`` (the first of equals), its Hamming
    distance, and the distance of the nearest code of any other ID (``families.decode_batch``;
    one pass instead of a (K, N, 4) table, 16 M pairs per 1000 candidates of the BCH family)."""
    K, N = words.shape[0], table.shape[0]
    best = np.empty(K, np.int64)
    h1 = np.empty(K, np.int64)
    h2 = np.empty(K, np.int64)
    for k in range(K):
        w = words[k]
        b, d1, d2 = 0, 1 << 30, 1 << 30  # d2: best of the other IDs
        for i in range(N):
            di = 1 << 30
            ri = 0
            for r in range(4):
                d = _popcount64(w ^ table[i, r])
                if d < di:
                    di, ri = d, r
            if di < d1:
                d2 = d1
                d1, b = di, i * 4 + ri
            elif di < d2:
                d2 = di
        best[k], h1[k], h2[k] = b, d1, d2
    return best, h1, h2


#: a blurred cell profile below this share of its peak (1) is left out of the cell reading's normal
#: equations: far from a cell its profile is a Gaussian tail of 1e-14 and less, which moves the solved
#: whiteness by about as much while it multiplies the work
_CELL_TINY = 1e-14


@njit(cache=True, inline="always", error_model="numpy")
def _grid_ndtr(t: float, s: float, n: int, F: NDArray[np.float64]) -> None:
    """``F[k] = Phi((t - k) / s)`` for the grid lines ``k = 0..n`` (libm's erfc, as SciPy's ``ndtr``).

    Beyond 8.5 SDs below ``t`` the CDF is 1 to the last bit of a double, beyond 9 SDs above it less
    than 1e-19: those lines are set without the erfc (most of the cost; a sharp marker's sample is
    within 9 SDs of 2-4 lines of a 13-line grid).
    """
    lo = max(0, int(math.ceil(t - 8.5 * s)))
    hi = min(n, int(math.floor(t + 9.0 * s)))
    inv = 1.0 / (s * math.sqrt(2.0))
    for k in range(0, min(lo, n + 1)):
        F[k] = 1.0
    for k in range(lo, hi + 1):
        F[k] = 0.5 * math.erfc((k - t) * inv)
    for k in range(max(hi + 1, lo), n + 1):
        F[k] = 0.0


@njit(cache=True, nogil=True, error_model="numpy")
def unblur_rows(px: NDArray[np.float64], mu: NDArray[np.float64], Hm: NDArray[np.float64],
                vals: NDArray[np.float64], sigma: NDArray[np.float64], black: NDArray[np.float64],
                contrast: NDArray[np.float64], n: int, border: int
                ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.int64]]:
    """The design ``M`` (Q, S, D), ``D = d^2``, and residual ``r`` (Q, S) of :func:`.decode.unblur_cells`'
    least squares, from its samples ``px`` (Q, S, 2) in fit coordinates (marker units ``mu`` (S, 3),
    homographies ``Hm`` (Q, 3, 3) to them, image values ``vals`` (Q, S)), and per quad the number of
    entries of ``M`` set (Q,).

    ``M``'s row of a sample is the outer product of the cells' blurred profiles across the two axes,
    ``Y_i X_j``; a profile below :data:`_CELL_TINY` (a Gaussian tail, far from the sample) is left 0.
    """
    Q, S = px.shape[0], px.shape[1]
    d = n - 2 * border
    D = d * d
    M = np.zeros((Q, S, D))
    r = np.empty((Q, S))
    nnz = np.zeros(Q, np.int64)
    Fx = np.empty(n + 1)
    Fy = np.empty(n + 1)
    for q in range(Q):
        h = Hm[q]
        for s in range(S):
            x, y = px[q, s, 0], px[q, s, 1]
            w3 = abs(h[2, 0] * x + h[2, 1] * y + h[2, 2])
            mx, my = mu[s, 0], mu[s, 1]
            sx = sigma[q] * math.hypot(h[0, 0] - mx * h[2, 0], h[0, 1] - mx * h[2, 1]) / w3 * n
            sy = sigma[q] * math.hypot(h[1, 0] - my * h[2, 0], h[1, 1] - my * h[2, 1]) / w3 * n
            _grid_ndtr(mx * n, sx, n, Fx)
            _grid_ndtr(my * n, sy, n, Fy)
            r[q, s] = (vals[q, s] - black[q]) / contrast[q] - (1.0 - (Fx[0] - Fx[n]) * (Fy[0] - Fy[n]))
            for i in range(d):
                yi = Fy[border + i] - Fy[border + i + 1]
                if abs(yi) <= _CELL_TINY:
                    continue
                for j in range(d):
                    xj = Fx[border + j] - Fx[border + j + 1]
                    if abs(xj) > _CELL_TINY:
                        M[q, s, i * d + j] = yi * xj
                        nnz[q] += 1
    return M, r, nnz


@njit(cache=True, nogil=True, error_model="numpy")
def sparse_gram(M: NDArray[np.float64]) -> NDArray[np.float64]:
    """``M^T M`` (D, D) of one sparse design ``M`` (S, D), summing only the products of each row's
    non-zero entries (a sharp marker's sample touches 1-4 of the d^2 cells)."""
    S, D = M.shape
    A = np.zeros((D, D))
    idx = np.empty(D, np.int64)
    for s in range(S):
        m = 0
        for k in range(D):
            if M[s, k] != 0.0:
                idx[m] = k
                m += 1
        for a in range(m):
            ka = idx[a]
            va = M[s, ka]
            for b in range(a, m):
                A[ka, idx[b]] += va * M[s, idx[b]]
    for a in range(D):
        for b in range(a + 1, D):
            A[b, a] = A[a, b]
    return A


@njit(cache=True, nogil=True, error_model="numpy")
def band_prep(xy: NDArray[np.float64], edge: NDArray[np.int64], mid: NDArray[np.float64], val: NDArray[np.float64],
              E: int, clip_low: float, clip_high: float
              ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64], NDArray[np.bool_],
                         NDArray[np.float64]]:
    """The band pixels ``xy`` (N, 2) of :func:`.edges.fit_sharp_edges` relative to their edge's middle ``mid``
    (E, 2): ``X0``, ``X1`` (N,); the pixels per edge (E,), the clipped pixels (N,) (``val`` at or beyond
    ``clip_low`` / ``clip_high``) and their number per edge (E,), counts as floats."""
    N = edge.shape[0]
    X0 = np.empty(N)
    X1 = np.empty(N)
    cnt = np.zeros(E)
    clipped = np.empty(N, np.bool_)
    n_clipped = np.zeros(E)
    for i in range(N):
        k = edge[i]
        X0[i] = xy[i, 0] - mid[k, 0]
        X1[i] = xy[i, 1] - mid[k, 1]
        cnt[k] += 1.0
        c = val[i] >= clip_high or val[i] <= clip_low
        clipped[i] = c
        if c:
            n_clipped[k] += 1.0
    return X0, X1, cnt, clipped, n_clipped


@njit(cache=True, nogil=True, error_model="numpy")
def band_profile(d: NDArray[np.float64], edge: NDArray[np.int64], val: NDArray[np.float64], lo: float, step: float,
                 nb: int, E: int) -> tuple[NDArray[np.int64], NDArray[np.float64]]:
    """Counts (E, nb) and sums (E, nb) of the band pixels' values ``val`` (N,) in bins of ``step`` pixels
    across their edge ``edge`` (N,), from ``-lo``, at the signed distances ``d`` (N,); a pixel beyond the
    first or last bin counts in it (:func:`.edges.white_extent`; its ``np.bincount`` form, sums in the
    pixels' order)."""
    cnt = np.zeros((E, nb), np.int64)
    tot = np.zeros((E, nb))
    for i in range(d.shape[0]):
        f = math.floor((d[i] + lo) / step)
        k = 0 if not (f > 0.0) else (nb - 1 if f > nb - 1 else int(f))
        cnt[edge[i], k] += 1
        tot[edge[i], k] += val[i]
    return cnt, tot


@njit(cache=True, nogil=True, error_model="numpy")
def band_keep(xy: NDArray[np.float64], val: NDArray[np.float64], edge: NDArray[np.int64], keep: NDArray[np.bool_],
              E: int) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.int64], NDArray[np.int64]]:
    """The band pixels ``keep`` (N,) of ``xy`` (N, 2), ``val``, ``edge`` (sorted), and each of the ``E``
    edges' first index among them (-1 for none; :func:`.edges.trim_outer`)."""
    m = 0
    for i in range(keep.shape[0]):
        if keep[i]:
            m += 1
    xy2 = np.empty((m, 2))
    val2 = np.empty(m)
    edge2 = np.empty(m, np.int64)
    starts = np.full(E, -1, np.int64)
    j = 0
    for i in range(keep.shape[0]):
        if keep[i]:
            xy2[j, 0] = xy[i, 0]
            xy2[j, 1] = xy[i, 1]
            val2[j] = val[i]
            k = edge[i]
            edge2[j] = k
            if starts[k] < 0:
                starts[k] = j
            j += 1
    return xy2, val2, edge2, starts


