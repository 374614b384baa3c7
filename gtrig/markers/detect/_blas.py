"""Matrix products in BLAS calls small enough to stay on the calling thread.

OpenBLAS (numpy's BLAS) runs a ``gemm`` whose ``m * n * k`` exceeds ``65536 * 4`` in several threads,
and a ``gemv`` whose ``m * n`` reaches ``2304 * 4`` (its ``GEMM_MULTITHREAD_THRESHOLD`` of 4). The
detector's products are a few hundred microseconds at most: handing them to OpenBLAS's threads costs
more than it saves, and its threads spin after each call, taking the core the detector's own helper
thread (:mod:`._threads`) would use. On a loaded 2-core machine one threaded ``36 x 512 x 36`` product
took 0.24-6.5 ms of wall time against 0.03 ms in one thread (BENCHMARKS.md), and
the bench's images spent three times the detector's own CPU in OpenBLAS's threads.

:func:`matmul` splits a product along the rows of its first operand (each row of the result is then
computed by the same kernel over the same ``k``, as in one call) into calls below those thresholds, and
:func:`gram` sums blocks of rows, unless BLAS is held to one thread (:func:`one_thread`, every detection),
where one call does each (the blocks moved the last bits of the results, and cost 3-5 % of a
detection).

LAPACK's solves are not split so: :func:`one_thread` keeps every BLAS call of a detection in its
calling thread (OpenBLAS's thread count is one per process, so it is set for the detection's span).
On the simulated GT room's images, loaded machine, a detection took 127 ms of CPU with OpenBLAS's
threads (70 % of it in ``numpy.linalg.solve`` of matrices of 36 to 144 rows) against 36 ms without
them; the detections are the same bit for bit.
"""

from __future__ import annotations

import threading
from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any

import numpy as np
from numpy.typing import NDArray

#: largest ``m * n * k`` of one ``gemm`` call (OpenBLAS threads above 65536 * 4)
MAX_GEMM = 65536 * 4
#: largest ``m * n`` of one ``gemv`` call (OpenBLAS threads from 2304 * 4)
MAX_GEMV = 2304 * 4 - 1


def matmul(a: NDArray[np.float64], b: NDArray[np.float64]) -> NDArray[np.float64]:
    """``a @ b`` for ``a`` (..., M, K) and ``b`` (..., K, N) or (K,) (stacks broadcast as in
    ``np.matmul``), in row blocks of ``a`` whose BLAS calls OpenBLAS keeps in one thread.

    A single row beyond the limits (``K * N`` above :data:`MAX_GEMM`) is left to one call.
    """
    if a.ndim < 2:
        raise ValueError("matmul: the first operand must be at least 2-D")
    m, k = a.shape[-2:]
    vec = b.ndim == 1 or b.shape[-1] == 1
    n = 1 if b.ndim == 1 else b.shape[-1]
    per_row = k * n
    rows = max(1, (MAX_GEMV if vec else MAX_GEMM) // max(per_row, 1))
    if rows >= m or _state["depth"] > 0:
        # inside :func:`one_thread` (every detection) no call is threaded: one call, without the
        # copies of the blocks (a tenth of the second path's reads)
        return a @ b
    axis = -1 if b.ndim == 1 else -2
    return np.concatenate([a[..., s0:s0 + rows, :] @ b for s0 in range(0, m, rows)], axis=axis)


def gram(m: NDArray[np.float64]) -> NDArray[np.float64]:
    """``m^T m`` for each matrix of ``m`` (Q, K, N): (Q, N, N), exactly symmetric.

    NumPy computes ``b.T @ b`` of one 2-D ``b`` by ``syrk`` (one triangle, mirrored): half the
    multiplications of the ``gemm`` that :func:`matmul` does on a stack. Each matrix's ``K`` rows are
    summed in blocks whose ``syrk`` OpenBLAS keeps in one thread (``N * N * rows`` at most
    :data:`MAX_GEMM`). Against :func:`matmul`'s ``gemm``: the same sums in another order (relative
    differences about 1e-15).
    """
    q, k, n = m.shape
    # inside :func:`one_thread` (every detection) one syrk per matrix: the blocks of 12 rows of a 144-column
    # design (the decoder's cells with the border free) cost 2.7 ms against 0.8 ms in one call
    rows = k if _state["depth"] > 0 else max(1, MAX_GEMM // max(n * n, 1))
    out = np.empty((q, n, n))
    for i in range(q):
        b = m[i, :rows]
        acc = b.T @ b
        for s0 in range(rows, k, rows):
            b = m[i, s0:s0 + rows]
            acc += b.T @ b
        out[i] = acc
    return out


_lock = threading.Lock()
_state: dict[str, Any] = {"depth": 0, "libs": None, "saved": []}


def _blas_libraries() -> list[Any]:
    """threadpoolctl's controllers of the BLAS libraries loaded (looked up once: the lookup reads every
    loaded library, a tenth of a millisecond, where setting a count through them takes a microsecond)."""
    if _state["libs"] is None:
        from threadpoolctl import ThreadpoolController

        _state["libs"] = list(ThreadpoolController().select(user_api="blas").lib_controllers)
    return list(_state["libs"])


@contextmanager
def one_thread() -> Iterator[None]:
    """BLAS (OpenBLAS, numpy's and SciPy's) in one thread per call while any caller is inside.

    The thread count is process-wide: the first caller in sets it to 1 and the last one out restores
    it, so detections in several threads at once (the detector's helper thread, a user's pool) never
    restore it under one another. A library already at one thread is not touched.
    """
    with _lock:
        if _state["depth"] == 0:
            saved = []
            for lib in _blas_libraries():
                n = int(lib.get_num_threads())
                if n != 1:
                    lib.set_num_threads(1)
                    saved.append((lib, n))
            _state["saved"] = saved
        _state["depth"] += 1
    try:
        yield
    finally:
        with _lock:
            _state["depth"] -= 1
            if _state["depth"] == 0:
                for lib, n in _state["saved"]:
                    lib.set_num_threads(n)
                _state["saved"] = []
