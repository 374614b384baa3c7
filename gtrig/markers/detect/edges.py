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

Coordinates are "fit coordinates": raw pixels, or undistorted pixels when a camera model is given
(edges are straight only after undistortion). Pixel centres are at integer coordinates.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy.special import ndtr

from gtrig.markers.detect.camera import Undistorter

_INV_SQRT_2PI = 1.0 / np.sqrt(2.0 * np.pi)


@dataclass(frozen=True)
class EdgeFit:
    """Fits of ``E`` edges (arrays of length E unless stated).

    theta, rho : line ``(cos theta, sin theta) . (x - mid) = rho``, fit coordinates.
    mid : (E, 2) the reference points.
    a, b, sigma : black level, white minus black (grey levels) and blur (pixels).
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
) -> EdgeSamples:
    """Pixels in a band around each edge ``p0[e] -> p1[e]`` (E, 2), in fit coordinates.

    The band spans ``-w_in[e] <= d <= w_out[e]`` across the edge (``d > 0`` outside, i.e. to the left
    of the direction ``p0 -> p1`` on screen for a clockwise quad) and leaves ``end_excl[e]`` pixels out
    at both ends. With ``undist`` the band is selected in undistorted coordinates (raw pixels mapped
    through ``undist.map_x/map_y``) and the returned coordinates are undistorted.
    """
    h, w = gray.shape
    xs, vals, eds = [], [], []
    for e in range(len(p0)):
        a, b = p0[e], p1[e]
        t = b - a
        L = float(np.hypot(*t))
        t = t / L
        n = np.array([t[1], -t[0]])
        ext = max(w_in[e], w_out[e])
        box = np.array([a - ext * (n + t), a + ext * (n - t), b - ext * (n - t), b + ext * (n + t)])
        if undist is not None:
            box = undist.to_raw(box)
        x0 = max(int(np.floor(box[:, 0].min())) - 1, 0)
        x1 = min(int(np.ceil(box[:, 0].max())) + 2, w)
        y0 = max(int(np.floor(box[:, 1].min())) - 1, 0)
        y1 = min(int(np.ceil(box[:, 1].max())) + 2, h)
        if x1 <= x0 or y1 <= y0:
            continue
        if undist is None:
            gy, gx = np.mgrid[y0:y1, x0:x1]
            px = gx.ravel().astype(np.float64)
            py = gy.ravel().astype(np.float64)
        else:
            px = undist.map_x[y0:y1, x0:x1].ravel().astype(np.float64)
            py = undist.map_y[y0:y1, x0:x1].ravel().astype(np.float64)
        rx, ry = px - a[0], py - a[1]
        s = rx * t[0] + ry * t[1]
        d = rx * n[0] + ry * n[1]
        sel = (d >= -w_in[e]) & (d <= w_out[e]) & (s >= end_excl[e]) & (s <= L - end_excl[e])
        if not sel.any():
            continue
        xs.append(np.column_stack([px[sel], py[sel]]))
        vals.append(gray[y0:y1, x0:x1].ravel()[sel].astype(np.float64))
        eds.append(np.full(int(sel.sum()), e, np.int64))
    if not xs:
        z = np.zeros((0,))
        return EdgeSamples(np.zeros((0, 2)), z, z.astype(np.int64), np.full(len(p0), -1, np.int64))
    edge = np.concatenate(eds)
    starts = np.full(len(p0), -1, np.int64)
    u, first = np.unique(edge, return_index=True)
    starts[u] = first
    return EdgeSamples(np.concatenate(xs), np.concatenate(vals), edge, starts)


def fit_edges(
    samples: EdgeSamples,
    p0: NDArray[np.float64],
    p1: NDArray[np.float64],
    sigma0: NDArray[np.float64],
    iterations: int = 10,
    extra: NDArray[np.float64] | None = None,
    init: EdgeFit | None = None,
) -> EdgeFit:
    """Fit the blurred-step model to every edge (see the module docstring).

    Parameters
    ----------
    samples : band pixels from :func:`gather_band`.
    p0, p1 : (E, 2) initial edge end points (fit coordinates); the initial line passes through them.
    sigma0 : (E,) initial blur, pixels.
    iterations : largest number of Levenberg-Marquardt iterations (vectorised over all edges; stops
        when no line moves by more than 1e-4 px).
    extra : (N,) optional known part of the profile, in units of the contrast ``b``, added to
        ``Phi(d / sigma)`` and held fixed (see :func:`marker_context`): the blurred light of the
        marker's other edges and of its white data cells, which the straight-step model lacks.
    init : a previous fit of the same edges to start from (its levels, shading and line, the line
        moved to the new reference points; the blur starts from ``sigma0``); without it the levels
        come from the band means.
    """
    E = len(p0)
    t = p1 - p0
    t /= np.linalg.norm(t, axis=1, keepdims=True)
    n = np.column_stack([t[:, 1], -t[:, 0]])
    mid = 0.5 * (p0 + p1)
    theta = np.arctan2(n[:, 1], n[:, 0])
    rho = np.zeros(E)
    e = samples.edge
    X = samples.xy - mid[e]
    v = samples.val
    N = len(v)
    cnt = np.bincount(e, minlength=E).astype(np.float64)
    # initial levels: mean of the inner and outer halves of the band
    d0 = X[:, 0] * n[e, 0] + X[:, 1] * n[e, 1]
    inner = d0 < 0
    sum_in = np.bincount(e, weights=v * inner, minlength=E)
    n_in = np.bincount(e, weights=inner.astype(float), minlength=E)
    sum_out = np.bincount(e, weights=v * ~inner, minlength=E)
    n_out = cnt - n_in
    a = sum_in / np.maximum(n_in, 1)
    b = sum_out / np.maximum(n_out, 1) - a
    ls = np.log(np.maximum(sigma0, 0.3))
    P = np.stack([theta, rho, a, b, ls, np.zeros(E), np.zeros(E)], axis=1)  # (E, 7)
    if init is not None:
        n_old = np.column_stack([np.cos(init.theta), np.sin(init.theta)])
        rho_old = init.rho + np.einsum("ij,ij->i", n_old, init.mid - mid)
        P = np.column_stack([init.theta, rho_old, init.a, init.b, ls, init.shade])
    ext = np.zeros(N) if extra is None else np.asarray(extra, np.float64)
    lam = np.full(E, 1e-3)
    has = cnt > 8
    present, first = np.unique(e, return_index=True)
    NP = 7
    X0 = np.ascontiguousarray(X[:, 0])
    X1 = np.ascontiguousarray(X[:, 1])
    iu, ju = np.triu_indices(NP)

    def model(P: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Predicted intensities (N,) and the Jacobian transposed (7, N)."""
        Pe = P[e]
        c, s = np.cos(Pe[:, 0]), np.sin(Pe[:, 0])
        d = X0 * c + X1 * s - Pe[:, 1]
        sg = np.exp(Pe[:, 4])
        z = d / sg
        Phi = ndtr(z) + ext
        bb = Pe[:, 3]
        base = Pe[:, 2] + bb * Phi
        u = X1 * c - X0 * s  # along the edge; du/dtheta = -(d + rho)
        f = 1.0 + Pe[:, 5] * d + Pe[:, 6] * u
        pred = base * f
        g = bb * np.exp(-0.5 * z * z) * (_INV_SQRT_2PI / sg)
        dd = g * f + base * Pe[:, 5]  # d pred / d d
        J = np.empty((NP, N))
        J[0] = dd * u - base * Pe[:, 6] * (d + Pe[:, 1])
        J[1] = -dd
        J[2] = f
        J[3] = Phi * f
        J[4] = -g * d * f
        J[5] = base * d
        J[6] = base * u
        return pred, J

    def normal_eq(J: NDArray[np.float64], r: NDArray[np.float64]) -> tuple[NDArray[np.float64], ...]:
        """Per-edge J^T J (E, 7, 7), J^T r (E, 7) and r^T r (E,) by segmented sums."""
        M = np.concatenate([J[iu] * J[ju], J * r, (r * r)[None]], axis=0)
        prod = np.zeros((M.shape[0], E))
        if N:
            prod[:, present] = np.add.reduceat(M, first, axis=1)
        prod = prod.T
        JTJ = np.empty((E, NP, NP))
        JTJ[:, iu, ju] = prod[:, : len(iu)]
        JTJ[:, ju, iu] = prod[:, : len(iu)]
        return JTJ, prod[:, len(iu) : len(iu) + NP], prod[:, -1]

    pred, J = model(P)
    r = v - pred
    JTJ, JTr, cur = normal_eq(J, r)
    eye = np.eye(NP)
    for _ in range(iterations):
        A = JTJ + lam[:, None, None] * (JTJ * eye + 1e-9 * eye)
        A[~has] = eye
        delta = np.linalg.solve(A, JTr[..., None])[..., 0]
        delta[~has] = 0.0
        Pn = P + delta
        Pn[:, 4] = np.clip(Pn[:, 4], np.log(0.05), np.log(20.0))
        pred_n, J_n = model(Pn)
        r_n = v - pred_n
        JTJ_n, JTr_n, new = normal_eq(J_n, r_n)
        better = new <= cur
        P = np.where(better[:, None], Pn, P)
        cur = np.where(better, new, cur)
        JTJ = np.where(better[:, None, None], JTJ_n, JTJ)
        JTr = np.where(better[:, None], JTr_n, JTr)
        lam = np.where(better, lam * 0.3, lam * 10.0)
        if np.all(np.abs(delta[:, 1]) + np.abs(delta[:, 0]) * np.sqrt(cnt) < 1e-4):
            break
    dof = np.maximum(cnt - NP, 1)
    s2 = cur / dof
    JTJ[~has] = eye
    with np.errstate(all="ignore"):
        cov = np.linalg.pinv(JTJ)[:, :2, :2] * s2[:, None, None]
    ok = has & np.all(np.isfinite(P), axis=1) & np.all(np.isfinite(cov.reshape(E, -1)), axis=1)
    return EdgeFit(P[:, 0], P[:, 1], mid, P[:, 2], P[:, 3], np.exp(P[:, 4]), P[:, 5:7], cov, np.sqrt(s2),
                   cnt.astype(np.int64), ok)


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
    prev = np.roll(np.arange(4), 1)
    th1, th2 = th[:, prev], th
    n1 = np.stack([np.cos(th1), np.sin(th1)], -1)
    n2 = np.stack([np.cos(th2), np.sin(th2)], -1)
    m1, m2 = m[:, prev], m
    r = np.stack([rh[:, prev] + np.einsum("qij,qij->qi", n1, m1), rh + np.einsum("qij,qij->qi", n2, m2)], -1)
    A = np.stack([n1, n2], axis=-2)  # (Q, 4, 2, 2)
    with np.errstate(all="ignore"):
        Ainv = np.linalg.inv(A)
    x = np.einsum("qcij,qcj->qci", Ainv, r)
    t1 = np.stack([-np.sin(th1), np.cos(th1)], -1)
    t2 = np.stack([-np.sin(th2), np.cos(th2)], -1)
    # Jacobian columns: (theta1, rho1) from line 1, (theta2, rho2) from line 2
    J1 = np.stack([Ainv[..., :, 0] * np.einsum("qci,qci->qc", t1, m1 - x)[..., None], Ainv[..., :, 0]], -1)
    J2 = np.stack([Ainv[..., :, 1] * np.einsum("qci,qci->qc", t2, m2 - x)[..., None], Ainv[..., :, 1]], -1)
    cov = J1 @ C[:, prev] @ np.swapaxes(J1, -1, -2) + J2 @ C @ np.swapaxes(J2, -1, -2)
    return x, cov


def quad_homographies(quads: NDArray[np.float64]) -> NDArray[np.float64]:
    """Homographies (Q, 3, 3) from fit coordinates to marker units: corner ``k`` of each quad (Q, 4, 2)
    goes to (0, 0), (1, 0), (1, 1), (0, 1) in turn (the convention of :func:`.decode.sample_cells`).

    Solved as the 8 x 8 linear system of the direct linear transform with ``h33 = 1``, batched.
    """
    Q = len(quads)
    dst = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])
    x, y = quads[..., 0], quads[..., 1]  # (Q, 4)
    u, v = np.broadcast_to(dst[:, 0], (Q, 4)), np.broadcast_to(dst[:, 1], (Q, 4))
    z, o = np.zeros((Q, 4)), np.ones((Q, 4))
    A = np.concatenate([np.stack([x, y, o, z, z, z, -u * x, -u * y], -1),
                        np.stack([z, z, z, x, y, o, -v * x, -v * y], -1)], axis=1)  # (Q, 8, 8)
    rhs = np.concatenate([u, v], axis=1)
    with np.errstate(all="ignore"):
        h = np.linalg.solve(A, rhs[..., None])[..., 0]
    return np.concatenate([h, np.ones((Q, 1))], axis=1).reshape(Q, 3, 3)


def marker_context(
    samples: EdgeSamples,
    fit: EdgeFit,
    corners: NDArray[np.float64],
    white: NDArray[np.float64],
) -> NDArray[np.float64]:
    """The part of each band pixel's blurred profile that one straight step does not explain.

    A marker is a black square holding white data cells; blurred by a Gaussian of ``sigma`` pixels
    its reflectance is ``1 - S + R`` with ``S`` the blurred square and ``R`` the blurred white cells.
    Close to the middle of an edge this is ``Phi(d / sigma)``; near the corners the other edges, and
    on small or blurred markers the white cells one border-width inside (2.5 px at 20 px side for
    AprilTag 36h11), add light that biases a plain step fit by up to 0.35 px at blur 1 px. This
    returns ``1 - S + R - Phi(d / sigma)`` at the current estimate, for :func:`fit_edges` to hold
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

    Returns
    -------
    (N,) float, in units of the edge contrast.
    """
    n = white.shape[1]
    Hm = quad_homographies(corners)
    e = samples.edge
    q = e // 4
    xy = samples.xy
    out = np.zeros(len(e))
    k = np.arange(n + 1, dtype=np.float64)
    for qq in np.unique(q):
        sel = q == qq
        H = Hm[qq]
        x, y = xy[sel, 0], xy[sel, 1]
        w3 = H[2, 0] * x + H[2, 1] * y + H[2, 2]
        mx = (H[0, 0] * x + H[0, 1] * y + H[0, 2]) / w3
        my = (H[1, 0] * x + H[1, 1] * y + H[1, 2]) / w3
        sg = fit.sigma[e[sel]]
        # marginal blur in cell units: sigma times |grad m| (d m / d pixel = (H_row - m H_3) / w3)
        sx = sg * np.hypot(H[0, 0] - mx * H[2, 0], H[0, 1] - mx * H[2, 1]) / np.abs(w3) * n
        sy = sg * np.hypot(H[1, 0] - my * H[2, 0], H[1, 1] - my * H[2, 1]) / np.abs(w3) * n
        Fx = ndtr((mx[:, None] * n - k) / sx[:, None])  # (N, n + 1): past the k-th grid line
        Fy = ndtr((my[:, None] * n - k) / sy[:, None])
        X = Fx[:, :-1] - Fx[:, 1:]
        Y = Fy[:, :-1] - Fy[:, 1:]
        S = (Fx[:, 0] - Fx[:, -1]) * (Fy[:, 0] - Fy[:, -1])
        R = np.einsum("pi,ij,pj->p", Y, white[qq], X)
        th = fit.theta[e[sel]]
        d = (np.cos(th) * (x - fit.mid[e[sel], 0]) + np.sin(th) * (y - fit.mid[e[sel], 1]) - fit.rho[e[sel]])
        out[sel] = 1.0 - S + R - ndtr(d / sg)
    return out
