"""The compiled forms against the NumPy / OpenCV forms they replaced (the same values)."""

from __future__ import annotations

import cv2
import numpy as np
import pytest
from scipy.special import ndtr

from gtrig.markers.detect import _kernels
from gtrig.markers.detect.decode import unblur_cells
from gtrig.markers.detect.edges import EdgeSamples, _starts, quad_homographies, trim_outer
from gtrig.markers.detect.sampling import bilinear

_OFFS = np.array([-0.25, 0.0, 0.25])


def _unblur_numpy(gray: np.ndarray, quads: np.ndarray, n: int, border: int, sigma: np.ndarray,
                  black: np.ndarray, contrast: np.ndarray) -> np.ndarray:
    """unblur_cells in NumPy: the dense design from SciPy's ndtr and one solve."""
    d = n - 2 * border
    Q = len(quads)
    c = (np.arange(border, n - border)[:, None] + 0.5 + _OFFS[None, :]).ravel() / n
    gy, gx = np.meshgrid(c, c, indexing="ij")
    mu = np.stack([gx.ravel(), gy.ravel(), np.ones(gx.size)], -1)
    Hm = quad_homographies(quads)
    p = mu @ np.linalg.inv(Hm).transpose(0, 2, 1)
    px = p[..., :2] / p[..., 2:]
    vals = bilinear(gray, px.reshape(-1, 2)[:, 0], px.reshape(-1, 2)[:, 1]).reshape(Q, -1)
    k = np.arange(n + 1, dtype=np.float64)
    x, y = px[..., 0], px[..., 1]
    H = Hm[:, None]
    w3 = H[..., 2, 0] * x + H[..., 2, 1] * y + H[..., 2, 2]
    mx, my = mu[:, 0], mu[:, 1]
    sig = sigma[:, None]
    sx = sig * np.hypot(H[..., 0, 0] - mx * H[..., 2, 0], H[..., 0, 1] - mx * H[..., 2, 1]) / np.abs(w3) * n
    sy = sig * np.hypot(H[..., 1, 0] - my * H[..., 2, 0], H[..., 1, 1] - my * H[..., 2, 1]) / np.abs(w3) * n
    Fx = ndtr((mx[:, None] * n - k) / sx[..., None])
    Fy = ndtr((my[:, None] * n - k) / sy[..., None])
    X = (Fx[..., :-1] - Fx[..., 1:])[..., border:n - border]
    Y = (Fy[..., :-1] - Fy[..., 1:])[..., border:n - border]
    S = (Fx[..., 0] - Fx[..., -1]) * (Fy[..., 0] - Fy[..., -1])
    M = (Y[..., :, None] * X[..., None, :]).reshape(Q, len(mx), d * d)
    r = (vals - black[:, None]) / contrast[:, None] - (1.0 - S)
    A = M.transpose(0, 2, 1) @ M
    lam = 1e-2 * np.trace(A, axis1=1, axis2=2) / (d * d)
    w = np.linalg.solve(A + lam[:, None, None] * np.eye(d * d), M.transpose(0, 2, 1) @ r[..., None]
                        + lam[:, None, None] * 0.5)
    return w.reshape(Q, d, d)


@pytest.mark.parametrize(("n", "border", "side", "blur"), [
    (8, 1, 24.0, 1.0), (8, 0, 20.0, 1.5), (8, 1, 120.0, 0.4), (12, 0, 36.0, 0.4), (12, 3, 60.0, 0.8),
])
def test_unblur_cells_is_the_dense_solve(n: int, border: int, side: float, blur: float) -> None:
    # sparse and dense designs alike (a sharp large marker leaves most of its design 0)
    rng = np.random.default_rng(n + border)
    gray = cv2.GaussianBlur(rng.integers(20, 230, (200, 240)).astype(np.uint8), (0, 0), 1.0)
    quads = []
    for _ in range(3):
        c = rng.uniform(70, 130, 2)
        a = rng.uniform(0, np.pi / 2)
        R = np.array([[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]])
        sq = (np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]]) * side / 2) @ R.T
        quads.append(c + sq + rng.normal(0, 0.5, (4, 2)))
    quads = np.array(quads)
    sigma = np.full(3, blur)
    black, contrast = np.full(3, 30.0), np.full(3, 170.0)
    got = unblur_cells(gray, quads, n, border, sigma, black, contrast)
    ref = _unblur_numpy(gray, quads, n, border, sigma, black, contrast)
    np.testing.assert_allclose(got, ref, rtol=0, atol=1e-9)


def test_starts_is_the_first_index_of_each_edge() -> None:
    rng = np.random.default_rng(2)
    for _ in range(300):
        E = int(rng.integers(1, 30))
        edge = np.sort(rng.integers(0, E, int(rng.integers(0, 500)))).astype(np.int64)
        ref = np.full(E, -1, np.int64)
        u, first = np.unique(edge, return_index=True)
        ref[u] = first
        np.testing.assert_array_equal(_starts(edge, E), ref)


def test_band_profile_is_the_bincount() -> None:
    rng = np.random.default_rng(3)
    E, nb, lo, step = 7, 30, 6.0, 0.5
    edge = np.sort(rng.integers(0, E, 4000)).astype(np.int64)
    d = rng.uniform(-9.0, 12.0, 4000)
    val = rng.uniform(0, 255, 4000)
    k = np.clip(np.floor((d + lo) / step).astype(np.int64), 0, nb - 1)
    flat = edge * nb + k
    cnt, tot = _kernels.band_profile(d, edge, val, lo, step, nb, E)
    np.testing.assert_array_equal(cnt, np.bincount(flat, minlength=E * nb).reshape(E, nb))
    np.testing.assert_array_equal(tot, np.bincount(flat, weights=val, minlength=E * nb).reshape(E, nb))


def test_trim_outer_keeps_the_pixels_inside() -> None:
    rng = np.random.default_rng(4)
    E = 4
    edge = np.sort(rng.integers(0, E, 600)).astype(np.int64)
    s = EdgeSamples(rng.uniform(0, 50, (600, 2)), rng.uniform(0, 255, 600), edge, _starts(edge, E))
    p0, p1 = rng.uniform(0, 50, (E, 2)), rng.uniform(0, 50, (E, 2))
    w_out = np.array([1.0, 3.0, -100.0, 5.0])  # edge 2 loses every pixel
    got = trim_outer(s, p0, p1, w_out)
    t = (p1 - p0) / np.hypot(*(p1 - p0).T)[:, None]
    rel = s.xy - p0[edge]
    keep = rel[:, 0] * t[edge, 1] - rel[:, 1] * t[edge, 0] <= w_out[edge]
    np.testing.assert_array_equal(got.xy, s.xy[keep])
    np.testing.assert_array_equal(got.val, s.val[keep])
    np.testing.assert_array_equal(got.edge, edge[keep])
    np.testing.assert_array_equal(got.starts, _starts(edge[keep], E))


