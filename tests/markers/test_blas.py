"""The detector's matrix products in small BLAS calls (:mod:`gtrig.markers.detect._blas`)."""

from __future__ import annotations

import numpy as np
import pytest

from gtrig.markers.detect._blas import MAX_GEMM, MAX_GEMV, gram, matmul


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


class _Recorder(np.ndarray):
    """An array that records the shapes of every product it is the left operand of."""

    calls: list[tuple[tuple[int, ...], tuple[int, ...]]] = []

    def __matmul__(self, other: np.ndarray) -> np.ndarray:
        _Recorder.calls.append((self.shape, other.shape))
        return np.asarray(self) @ other


@pytest.mark.parametrize(("a_shape", "b_shape"), [
    ((10, 36, 324), (10, 324, 36)),
    ((10, 36, 324), (10, 324, 1)),
    ((2348, 36), (36,)),
    ((2348, 36), (36, 36)),
])
def test_each_call_stays_under_openblas_threading(a_shape: tuple[int, ...], b_shape: tuple[int, ...]) -> None:
    # OpenBLAS threads a gemm above 65536 * 4 multiply-adds per matrix, a gemv from 2304 * 4 elements:
    # every call matmul makes must stay below, and the blocks must cover all rows of a
    rng = np.random.default_rng(2)
    a, b = rng.normal(size=a_shape).view(_Recorder), rng.normal(size=b_shape)
    _Recorder.calls = []
    got = matmul(a, b)
    assert len(_Recorder.calls) > 1  # these shapes are above the limits as one call
    np.testing.assert_allclose(np.asarray(got), np.asarray(a) @ b, rtol=1e-12, atol=1e-12)
    rows = 0
    for (sa, sb) in _Recorder.calls:
        m, k = sa[-2:]
        if len(sb) == 1 or sb[-1] == 1:
            assert m * k <= MAX_GEMV < 2304 * 4
        else:
            assert m * k * sb[-1] <= MAX_GEMM == 65536 * 4
        rows += m
    assert rows == a_shape[-2]


@pytest.mark.parametrize("shape", [(4, 324, 36), (2, 81, 9), (1, 7, 3), (0, 324, 36)])
def test_gram_is_the_normal_matrix(shape: tuple[int, int, int]) -> None:
    # unblur_cells' M^T M per quad: the product, exactly symmetric, in blocks of K below the limit
    rng = np.random.default_rng(3)
    M = rng.normal(size=shape)
    got = gram(M)
    assert got.shape == (shape[0], shape[2], shape[2])
    np.testing.assert_allclose(got, M.transpose(0, 2, 1) @ M, rtol=1e-12, atol=1e-12)
    assert np.array_equal(got, got.transpose(0, 2, 1))
    assert MAX_GEMM // (shape[2] ** 2) * shape[2] ** 2 <= MAX_GEMM


def _blas_threads() -> list[int]:
    from threadpoolctl import threadpool_info

    return [i["num_threads"] for i in threadpool_info() if i["user_api"] == "blas"]


def test_one_thread_holds_while_any_caller_is_inside_and_restores_after() -> None:
    """BLAS is one thread per call while any of two overlapping callers is inside (the first out must
    not restore it under the second), and the count from before comes back once both are out."""
    import threading

    from gtrig.markers.detect._blas import one_thread

    before = _blas_threads()
    inside, release, seen = threading.Event(), threading.Event(), []

    def second() -> None:
        with one_thread():
            inside.set()
            release.wait(10)
            seen.append(_blas_threads())

    with one_thread():
        assert set(_blas_threads()) == {1}
        t = threading.Thread(target=second)
        t.start()
        assert inside.wait(10)
    release.set()  # the first caller is out, the second still in
    t.join(10)
    assert seen and set(seen[0]) == {1}
    assert _blas_threads() == before


def test_detection_leaves_blas_threads_as_they_were() -> None:
    from gtrig.markers.detect import MarkerDetector

    rng = np.random.default_rng(3)
    before = _blas_threads()
    MarkerDetector("aruco_4x4_50").detect(rng.integers(0, 255, (240, 320), dtype=np.uint8))
    assert _blas_threads() == before
