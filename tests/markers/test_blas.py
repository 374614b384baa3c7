"""The detector's matrix products in small BLAS calls (:mod:`gtrig.markers.detect._blas`)."""

from __future__ import annotations

import numpy as np
import pytest

from gtrig.markers.detect._blas import MAX_GEMM, MAX_GEMV, matmul


@pytest.mark.parametrize(("a_shape", "b_shape"), [
    ((10, 36, 324), (10, 324, 36)),  # unblur_cells' normal matrices (blocks of rows)
    ((10, 36, 324), (10, 324, 1)),  # and their right-hand sides (gemv-sized)
    ((2348, 36), (36,)),  # the second path's code ranking, a matrix-vector product
    ((2348, 36), (36, 36)),
    ((3, 5), (5, 4)),  # small: one call
])
def test_matmul_is_the_product(a_shape: tuple[int, ...], b_shape: tuple[int, ...]) -> None:
    rng = np.random.default_rng(0)
    a, b = rng.normal(size=a_shape), rng.normal(size=b_shape)
    got = matmul(a, b)
    assert got.shape == (a @ b).shape
    np.testing.assert_allclose(got, a @ b, rtol=1e-12, atol=1e-12)


def test_matmul_rows_of_a_transposed_view() -> None:
    # unblur_cells passes M's transpose as a view; its row blocks are the same product
    rng = np.random.default_rng(1)
    M = rng.normal(size=(4, 324, 36))
    Mt = M.transpose(0, 2, 1)
    np.testing.assert_allclose(matmul(Mt, M), Mt @ M, rtol=1e-12, atol=1e-12)


def test_limits_are_openblas_thresholds() -> None:
    # OpenBLAS threads a gemm above 65536 * GEMM_MULTITHREAD_THRESHOLD (4), a gemv from 2304 * 4
    assert MAX_GEMM == 262144 and MAX_GEMV == 9215
