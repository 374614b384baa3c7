"""The detector's compiled kernels (:mod:`gtrig.markers.detect._kernels`) against finite differences
and plain NumPy forms of the same model, and the helper thread of the second path."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.special import ndtr

from gtrig.markers.detect import _kernels
from gtrig.markers.detect.edges import CLIP_HIGH, CLIP_LOW, pixel_step


def test_normal_cdf_within_its_bound() -> None:
    """The kernels' normal CDF (Abramowitz and Stegun 26.2.17) is within 7.5e-8 of SciPy's."""
    z = np.linspace(-12, 12, 200001)
    got = np.array([_kernels._ndtr(float(v)) for v in z[::50]])
    assert np.abs(got - ndtr(z[::50])).max() < 7.5e-8


@pytest.mark.parametrize("sigma", [0.05, 0.3, 1.0, 3.0])
def test_pixel_step_kernel_matches_the_numpy_form(sigma: float) -> None:
    """The compiled pixel-integrated step (its table of the normal CDF and density) gives the profile and
    its two derivatives of the NumPy form (SciPy's ``ndtr``) within 1e-6, sharp and blurred, axis-aligned
    (the narrowest box, where errors of the CDF are divided by 1e-4) and diagonal."""
    d = np.linspace(-4.0, 4.0, 321)
    for theta in (0.0, 1e-5, 0.02, 0.4, np.pi / 4, 1.3):
        c, s = np.cos(theta), np.sin(theta)
        ref = pixel_step(d, np.full_like(d, sigma), np.full_like(d, c), np.full_like(d, s))
        got = np.array([_kernels._pixel_step(float(x), sigma, c, s) for x in d]).T
        for k in range(3):
            np.testing.assert_allclose(got[k], ref[k], rtol=0, atol=1e-6)


def _prediction(X0: np.ndarray, X1: np.ndarray, extra: np.ndarray, P: np.ndarray, exact: bool) -> np.ndarray:
    """The blurred-step model of ``fit_sharp_edges`` (its module docstring), in NumPy."""
    th, rho, a, b, ls, ca, cu = P
    c, s = np.cos(th), np.sin(th)
    d = X0 * c + X1 * s - rho
    u = X1 * c - X0 * s
    sg = np.exp(ls)
    Phi = pixel_step(d, np.full_like(d, sg), np.full_like(d, c), np.full_like(d, s))[0] if exact else ndtr(d / sg)
    return (a + b * (Phi + extra)) * (1.0 + ca * d + cu * u)


@pytest.mark.parametrize("exact", [False, True])
def test_edge_normal_equations_match_finite_differences(exact: bool) -> None:
    """``J^T J``, ``J^T r`` and ``r^T r`` of the kernel equal those of a finite-difference Jacobian of
    the NumPy model (the clipped pixels that agree with the model left out)."""
    rng = np.random.default_rng(3)
    N = 400
    X0, X1 = rng.uniform(-4, 4, N), rng.uniform(-15, 15, N)
    extra = 0.05 * rng.standard_normal(N)
    P = np.array([0.3, 0.4, 40.0, 180.0, np.log(1.2), 0.01, -0.004])
    val = _prediction(X0, X1, extra, P + [0.01, 0.05, 1, -3, 0.05, 0, 0], exact) + rng.normal(0, 3, N)
    val = np.clip(val, 0, 255)
    clipped = (val >= CLIP_HIGH) | (val <= CLIP_LOW)
    G = np.empty((8, 8))
    _kernels.edge_normal_eq(X0, X1, val, extra, 0, N, P, clipped, exact, CLIP_LOW, CLIP_HIGH, G)
    r = val - _prediction(X0, X1, extra, P, exact)
    keep = ~(clipped & (((val >= CLIP_HIGH) & (r <= 0)) | ((val <= CLIP_LOW) & (r >= 0))))
    J = np.empty((7, N))
    for k in range(7):
        h = 1e-6 * max(1.0, abs(P[k]))
        dp = np.zeros(7)
        dp[k] = h
        J[k] = (_prediction(X0, X1, extra, P + dp, exact) - _prediction(X0, X1, extra, P - dp, exact)) / (2 * h)
    J, r = J[:, keep], r[keep]
    # the pixel's footprint across the edge turns with theta; the kernel leaves that derivative out
    # (a relative 2e-5 of the theta row here)
    rtol = 1e-4 if exact else 1e-5
    np.testing.assert_allclose(G[:7, :7], J @ J.T, rtol=rtol, atol=1e-6 * np.abs(J @ J.T).max())
    # the kernels' normal CDF is within 7.5e-8 of SciPy's: each residual within b 7.5e-8 (shading ~1)
    dr = 1.1 * P[3] * 7.5e-8
    np.testing.assert_allclose(G[:7, 7], J @ r, rtol=rtol, atol=dr * np.abs(J).sum(axis=1).max())
    assert abs(G[7, 7] - r @ r) <= 2.0 * dr * np.abs(r).sum() + 1e-9 * (r @ r)


def test_edge_lm_recovers_a_simulated_edge() -> None:
    """Levenberg-Marquardt from a start 0.8 px and 2 deg off lands on the simulated line within
    0.02 px, and its ``J^T J`` is the one at the estimate."""
    rng = np.random.default_rng(5)
    N = 900
    X0, X1 = rng.uniform(-5, 5, N), rng.uniform(-30, 30, N)
    truth = np.array([0.2, 0.1, 35.0, 190.0, np.log(1.0), 0.0, 0.0])
    val = _prediction(X0, X1, np.zeros(N), truth, False) + rng.normal(0, 3, N)
    start = truth + [np.radians(2), 0.8, 10, -30, 0.3, 0, 0]
    P, sse, JTJ = _kernels.edge_lm(X0, X1, val, np.zeros(N), np.array([0, N]), start[None], np.array([True]),
                                   np.zeros(0, bool), np.array([False]), 10, 4, 1e-4, np.array([np.sqrt(N)]),
                                   np.log(0.05), np.log(20.0), 4.0, CLIP_LOW, CLIP_HIGH)
    assert abs(P[0, 1] - truth[1]) < 0.02 and abs(P[0, 0] - truth[0]) < np.radians(0.05)
    G = np.empty((8, 8))
    _kernels.edge_normal_eq(X0, X1, val, np.zeros(N), 0, N, P[0], np.zeros(0, bool), False, CLIP_LOW, CLIP_HIGH, G)
    np.testing.assert_allclose(JTJ[0], G[:7, :7], rtol=1e-10)
    assert sse[0] == pytest.approx(G[7, 7], rel=1e-12)
    assert sse[0] / (N - 7) == pytest.approx(9.0, rel=0.15)


def _context_numpy(x, y, quad, H, sigma, white, dist):
    """``1 - S + R - Phi(d / sigma)`` of ``edges.marker_context``, vectorized over pixels."""
    n = white.shape[1]
    h = H[quad].T
    w3 = h[6] * x + h[7] * y + h[8]
    mx = (h[0] * x + h[1] * y + h[2]) / w3
    my = (h[3] * x + h[4] * y + h[5]) / w3
    scale = sigma / np.abs(w3) * n
    sx = scale * np.hypot(h[0] - mx * h[6], h[1] - mx * h[7])
    sy = scale * np.hypot(h[3] - my * h[6], h[4] - my * h[7])
    k = np.arange(n + 1)
    Fx = ndtr((mx[:, None] * n - k) / sx[:, None])
    Fy = ndtr((my[:, None] * n - k) / sy[:, None])
    X, Y = Fx[:, :-1] - Fx[:, 1:], Fy[:, :-1] - Fy[:, 1:]
    S = (Fx[:, 0] - Fx[:, -1]) * (Fy[:, 0] - Fy[:, -1])
    R = np.einsum("pi,pij,pj->p", Y, white[quad], X)
    return 1.0 - S + R - ndtr(dist / sigma)


def _quads(rng: np.random.Generator, Q: int) -> np.ndarray:
    base = np.array([[0.0, 0.0], [30.0, 0.0], [30.0, 30.0], [0.0, 30.0]])
    return np.stack([base + rng.uniform(-3, 3, (4, 2)) + rng.uniform(0, 200, 2) for _ in range(Q)])


def test_homographies_and_marker_context() -> None:
    """The kernels' homographies take each quad's corners to the unit square; the compiled context
    equals its NumPy form within the normal CDF's approximations (the grid lines' CDFs linear in a table,
    7.5e-6 each, in differences and products of a few of them; the edge's own 7.5e-8)."""
    rng = np.random.default_rng(8)
    quads = _quads(rng, 3)
    H = _kernels.quad_homographies(quads)
    p = np.concatenate([quads, np.ones((3, 4, 1))], axis=2) @ np.swapaxes(H, 1, 2)
    np.testing.assert_allclose(p[..., :2] / p[..., 2:], np.broadcast_to([[0, 0], [1, 0], [1, 1], [0, 1]], (3, 4, 2)),
                               atol=1e-12)
    assert np.isnan(_kernels.quad_homographies(np.zeros((1, 4, 2))).ravel()[:8]).all()
    N = 3000
    q = rng.integers(0, 3, N)
    xy = quads[q].mean(axis=1) + rng.uniform(-18, 18, (N, 2))
    white = rng.integers(0, 2, (3, 8, 8)).astype(float)
    sigma, dist = rng.uniform(0.4, 2.0, N), rng.uniform(-5, 5, N)
    H9 = H.reshape(-1, 9)
    got = _kernels.marker_context(xy[:, 0].copy(), xy[:, 1].copy(), q, H9, sigma, white, dist)
    np.testing.assert_allclose(got, _context_numpy(xy[:, 0], xy[:, 1], q, H9, sigma, white, dist), atol=4e-5)


def test_cell_design_is_the_profiles() -> None:
    """The fits' design is ``[1, 1 - S, F]`` with the cells free and ``[1, 1 - S + F code]`` for a code,
    with the profiles of :func:`_kernels.cell_profiles`."""
    rng = np.random.default_rng(12)
    quad = _quads(rng, 1)
    xy = quad[0].mean(axis=0) + rng.uniform(-18, 18, (300, 2))
    x, y = xy[:, 0].copy(), xy[:, 1].copy()
    H = _kernels.quad_homographies(quad)
    base, F = _kernels.cell_profiles(x, y, H, np.array([1.4]), 8, 1)
    free = _kernels.cell_design(x, y, H[0], 1.4, 8, 1, np.zeros(0))
    np.testing.assert_allclose(free, np.column_stack([np.ones(300), base[0], F[0]]), rtol=0, atol=1e-15)
    code = rng.integers(0, 2, 36).astype(float)
    one = _kernels.cell_design(x, y, H[0], 1.4, 8, 1, code)
    np.testing.assert_allclose(one, np.column_stack([np.ones(300), base[0] + F[0] @ code]), atol=1e-12)


def test_helper_pool_works_in_a_forked_child() -> None:
    """A process forked after the helper threads started gets a fresh pool (the inherited one has no
    threads, and work sent to it would never run)."""
    import multiprocessing as mp

    from gtrig.markers.detect import _threads

    assert _threads.run_split(abs, [(-1,), (-2,)]) == [1, 2]
    ctx = mp.get_context("fork")
    with ctx.Pool(1) as pool:
        assert pool.apply_async(_threads.run_split, (abs, [(-3,), (-4,)])).get(timeout=60) == [3, 4]
