"""Threads of one detection: how many it may use, and the helper threads that run parts beside it.

The compiled kernels (:mod:`._kernels`), OpenCV and AprilTag 3 release the GIL, so two threads of one detection
really run at once; the detector follows OpenCV's thread setting (``cv2.getNumThreads()``), which
OpenCV's own ArUco detector uses too and which GTvision's worker processes set to 1.

OpenCV's own pool is left as the caller set it: the OpenCV calls after the peers (``cv2.remap`` of the
cells' samples, ``cv2.cornerSubPix``) are below the size at which OpenCV splits a call into stripes, and
setting its thread count stops and restarts its workers (0.1 ms idle, 2 ms on a loaded machine, twice
per detection).
"""

from __future__ import annotations

import itertools
import os
import threading
from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import ThreadPoolExecutor
from typing import Any, Generic, TypeVar

import cv2

T = TypeVar("T")

_POOL: ThreadPoolExecutor | None = None
_LOCK = threading.Lock()


def _forget_pool() -> None:
    # a forked child inherits the pool but not its threads: work sent to it would never run
    global _POOL, _LOCK
    _POOL = None
    _LOCK = threading.Lock()


os.register_at_fork(after_in_child=_forget_pool)


def threads(setting: int) -> int:
    """Threads a detection may use: ``setting``, or OpenCV's when it is 0."""
    return setting if setting > 0 else cv2.getNumThreads()


#: quads below which the edge fits stay in the calling thread: handing a share of the quads to the helper
#: thread costs about 40 us (once per refinement: a share's passes run in one compiled call), a marker's fit
#: about 0.5 ms, and on a loaded machine the helper may not run at all before the caller has done the work
MIN_SPLIT_QUADS = 4


def fit_threads(setting: int, n_quads: int) -> int:
    """Threads the edge fits of ``n_quads`` quads use: :func:`threads` of ``setting``, 1 below
    :data:`MIN_SPLIT_QUADS`."""
    return 1 if n_quads < MIN_SPLIT_QUADS else threads(setting)


def helper_pool() -> ThreadPoolExecutor:
    """Two helper threads shared by every detector of the process (they take parts of a kernel's work)."""
    global _POOL
    with _LOCK:
        if _POOL is None:
            _POOL = ThreadPoolExecutor(max_workers=2, thread_name_prefix="gtrig-markers")
        return _POOL


def run_split(fn: Callable[..., T], parts: Sequence[tuple[Any, ...]]) -> list[T]:
    """``[fn(*p) for p in parts]``, the parts claimed in turn by this thread and one helper thread
    (:func:`ordered_map`): the caller never waits for a part nobody has started, only for the one a
    helper is finishing, so more parts than threads (the edge fits make four) bound that wait to a
    part's time while the helper pool is busy or its thread is descheduled."""
    return list(ordered_map(fn, parts, 2))


def ordered_map(fn: Callable[..., T], tasks: Sequence[tuple[Any, ...]], threads: int) -> Iterator[T]:
    """``fn(*t)`` for every task ``t``, yielded in order, with ``threads - 1`` helper threads working
    ahead of the caller.

    Each task is claimed once, by whichever thread reaches it first, so the caller never waits for a
    task nobody has started (it runs the next unclaimed one itself), the helper pool may be busy
    elsewhere, and the results are those of ``[fn(*t) for t in tasks]`` whatever the threads. The
    caller consumes a result (pure Python, holding the GIL) while a helper computes the next one
    (OpenCV and the compiled kernels release it).
    """
    n = len(tasks)
    if threads < 2 or n < 2:
        for t in tasks:
            yield fn(*t)
        return
    claims = itertools.count()  # next() on a count is atomic under the GIL
    results: list[Any] = [None] * n
    errors: list[BaseException | None] = [None] * n
    done = [threading.Event() for _ in range(n)]

    def run(k: int) -> None:
        try:
            results[k] = fn(*tasks[k])
        except BaseException as exc:  # handed to the caller, raised where the result is consumed
            errors[k] = exc
        finally:
            done[k].set()

    def helper() -> None:
        while (k := next(claims)) < n:
            run(k)

    for _ in range(min(threads, n) - 1):
        helper_pool().submit(helper)
    for k in range(n):
        while not done[k].is_set():
            j = next(claims)
            if j >= n:
                done[k].wait()
                break
            run(j)
        err = errors[k]
        if err is not None:
            raise err
        yield results[k]
        results[k] = None


class Beside(Generic[T]):
    """``fn(*args)`` started on a helper thread (:func:`helper_pool`) while the caller works on, its result
    taken with :meth:`result`.

    The call is claimed once, by the helper or by :meth:`result`, whichever reaches it first: a caller
    never waits for a call nobody has started (the helper pool may be busy with another detection's work, or
    a loaded machine may not have run its thread yet), only for one a helper is finishing.
    """

    def __init__(self, fn: Callable[..., T], *args: Any) -> None:
        self._fn, self._args = fn, args
        self._claims = itertools.count()  # next() on a count is atomic under the GIL
        self._done = threading.Event()
        self._value: list[T] = []
        self._error: BaseException | None = None
        helper_pool().submit(self._run_unclaimed)

    def _run_unclaimed(self) -> None:
        if next(self._claims):
            return
        try:
            self._value.append(self._fn(*self._args))
        except BaseException as exc:  # handed to the caller, raised by result()
            self._error = exc
        finally:
            self._done.set()

    def result(self) -> T:
        """``fn(*args)``, run here if no helper has started it; its exception, if it raised one."""
        self._run_unclaimed()
        self._done.wait()
        if self._error is not None:
            raise self._error
        return self._value[0]
