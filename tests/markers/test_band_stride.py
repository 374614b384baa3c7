"""The edge fits' cheaper pieces: the column stride of the bands, the tabulated normal CDF and density,
and the line covariance's block inverse."""

from __future__ import annotations

import numpy as np
from numba import njit
from scipy.special import ndtr
from scipy.stats import norm

from gtrig.markers.detect import _edge_kernels, _kernels
from gtrig.markers.detect.edges import RefineParams, band_stride, gather_band, unstride_clipped


def _band(gray: np.ndarray, shift: tuple[int, int], stride: int) -> np.ndarray:
    """The band pixels (M, 2) of three edges of a quad moved by ``shift`` (integer pixels), minus the shift."""
    p0 = np.array([[40.3, 30.7], [150.2, 41.9], [140.6, 160.1]]) + shift
    p1 = np.array([[150.2, 41.9], [140.6, 160.1], [30.8, 150.4]]) + shift
    s = gather_band(gray, p0, p1, np.full(3, 4.0), np.full(3, 6.0), np.full(3, 5.0), stride=np.full(3, stride))
    return s.xy - np.asarray(shift, float)


def test_stride_takes_every_kth_column_from_the_edge_start_and_a_crop_the_same() -> None:
    """A stride of k keeps exactly the full band's pixels whose column across the edge (row, for an edge
    nearer the vertical) is k apart from the start point's, with their values; a crop moved by whole
    pixels takes the same pixels."""
    gray = np.random.default_rng(0).integers(0, 256, (260, 280)).astype(np.uint8)
    full = _band(gray, (0, 0), 1)
    p0 = np.array([[40.3, 30.7], [150.2, 41.9], [140.6, 160.1]])
    p1 = np.array([[150.2, 41.9], [140.6, 160.1], [30.8, 150.4]])
    t = p1 - p0
    e_full = gather_band(gray, p0, p1, np.full(3, 4.0), np.full(3, 6.0), np.full(3, 5.0)).edge
    for k in (2, 3, 5):
        s = gather_band(gray, p0, p1, np.full(3, 4.0), np.full(3, 6.0), np.full(3, 5.0), stride=np.full(3, k))
        vertical = np.abs(t[e_full, 1]) > np.abs(t[e_full, 0])
        major = np.where(vertical, full[:, 1], full[:, 0]).astype(int)
        start = np.floor(np.where(vertical, p0[e_full, 1], p0[e_full, 0])).astype(int)
        want = full[(major - start) % k == 0]
        np.testing.assert_array_equal(s.xy, want)
        np.testing.assert_array_equal(s.val, gray[want[:, 1].astype(int), want[:, 0].astype(int)])
        assert 0.9 / k < len(s.xy) / len(full) < 1.1 / k + 0.05
        big = np.zeros((400, 400), np.uint8)
        big[37:297, 51:331] = gray
        np.testing.assert_array_equal(_band(big, (51, 37), k), s.xy)


def test_band_stride_caps_the_columns_and_clipped_quads_take_them_all() -> None:
    """``band_stride`` keeps at most ``max_columns`` columns (every one with 0); a quad one of whose edges
    has more than a tenth of its band clipped gets stride 1 on all four edges, the others keep theirs."""
    side = np.array([20.0, 31.0, 64.0, 200.0])
    np.testing.assert_array_equal(band_stride(side, RefineParams(max_columns=32)), [1, 1, 2, 6])
    np.testing.assert_array_equal(band_stride(side, RefineParams(max_columns=0)), [1, 1, 1, 1])
    gray = np.full((120, 240), 120, np.uint8)
    gray[20:60, 130:200] = 255  # clipped paper under the second quad's first edge
    quads = np.array([[[20, 20], [80, 20], [80, 80], [20, 80]], [[140, 30], [200, 30], [200, 90], [140, 90]]], float)
    p0 = quads.reshape(-1, 2)
    p1 = np.roll(quads, -1, axis=1).reshape(-1, 2)
    stride = np.full(8, 3, np.int64)
    s = gather_band(gray, p0, p1, np.full(8, 3.0), np.full(8, 3.0), np.full(8, 4.0), stride=stride)
    assert unstride_clipped(s, stride)
    np.testing.assert_array_equal(stride, [3, 3, 3, 3, 1, 1, 1, 1])
    assert not unstride_clipped(s, stride)


def test_tabulated_normal_cdf_and_density_within_their_bounds() -> None:
    """The table's cubic Hermite interpolants are within 3e-10 of SciPy's CDF and density from -12 to 12
    (0 and 1 beyond the table), and NaN stays NaN."""
    f = njit(lambda z: _kernels._ndtr_pdf_tab(z))
    z = np.linspace(-12.0, 12.0, 48_001)
    got = np.array([f(v) for v in z])
    assert np.abs(got[:, 0] - ndtr(z)).max() < 3e-10
    assert np.abs(got[:, 1] - norm.pdf(z)).max() < 3e-10
    assert np.isnan(f(np.nan)[0])


def test_line_block_inverse_is_the_pseudo_inverse_block() -> None:
    """The (theta, rho) block of the inverse from the scaled Cholesky equals NumPy's pinv's on normal
    matrices whose columns differ in scale by 1e6, and falls back to it on a singular one."""
    rng = np.random.default_rng(3)
    out = np.empty((2, 2))
    for _ in range(200):
        J = rng.normal(size=(60, 7)) * np.array([1.0, 0.1, 100.0, 30.0, 3.0, 1e-3, 1e-4])
        A = J.T @ J
        _edge_kernels._line_block_inverse(A, out)
        want = np.linalg.pinv(A)[:2, :2]
        np.testing.assert_allclose(out, want, rtol=1e-7, atol=1e-12 * np.abs(want).max())
    A = np.eye(7)
    A[4, 4] = 0.0
    _edge_kernels._line_block_inverse(A, out)
    np.testing.assert_allclose(out, np.eye(2))
