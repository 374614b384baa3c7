"""Threads of one detection: how many it may use, and the helper threads that run parts beside it.

The compiled kernels (:mod:`._kernels`) and OpenCV release the GIL, so two threads of one detection
really run at once; the detector follows OpenCV's thread setting (``cv2.getNumThreads()``), which
OpenCV's own ArUco detector uses too and which GTvision's worker processes set to 1.
"""

from __future__ import annotations

import itertools
import os
import threading
from collections.abc import Callable, Iterable, Iterator, Sequence
from concurrent.futures import ThreadPoolExecutor
from contextlib import contextmanager
from typing import Any, TypeVar

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


def helper_pool() -> ThreadPoolExecutor:
    """Two helper threads shared by every detector of the process (one may hold the second path's
    candidate stage while the other takes half of a kernel's work)."""
    global _POOL
    with _LOCK:
        if _POOL is None:
            _POOL = ThreadPoolExecutor(max_workers=2, thread_name_prefix="gtrig-markers")
        return _POOL


def run_split(fn: Callable[..., T], parts: Sequence[tuple[Any, ...]]) -> list[T]:
    """``[fn(*p) for p in parts]``, the parts claimed in turn by this thread and one helper thread
    (:func:`ordered_map`): the caller never waits for a part nobody has started, only for the one a
    helper is finishing, so more parts than threads (the edge fits make four) bound that wait to a
    part's time while the helper pool is busy with the second path or its thread is descheduled."""
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
        if errors[k] is not None:
            raise errors[k]
        yield results[k]
        results[k] = None


_OPEN, _CLAIMED, _SKIPPED = 0, 1, 2


class Claims:
    """Tasks ``fn(*t)`` that a helper thread runs ahead, in order (:meth:`work`), while the caller
    decides which results it needs (:meth:`skip` the others) and takes them (:meth:`get`).

    Each task runs at most once, in whichever thread claims it first: :meth:`get` runs a task nobody
    has started itself, so the caller never waits on a helper that is busy elsewhere, and a result is
    that of ``fn(*t)`` whatever the threads.
    """

    def __init__(self, fn: Callable[..., T], tasks: Sequence[tuple[Any, ...]]) -> None:
        n = len(tasks)
        self._fn, self._tasks = fn, tasks
        self._lock = threading.Lock()
        self._state = [_OPEN] * n
        self._results: list[Any] = [None] * n
        self._errors: list[BaseException | None] = [None] * n
        self._done = [threading.Event() for _ in range(n)]

    def _claim(self, k: int, skipped_too: bool = False) -> bool:
        with self._lock:
            if self._state[k] == _OPEN or (skipped_too and self._state[k] == _SKIPPED):
                self._state[k] = _CLAIMED
                return True
            return False

    def _run(self, k: int) -> None:
        try:
            self._results[k] = self._fn(*self._tasks[k])
        except BaseException as exc:  # raised in the caller by get()
            self._errors[k] = exc
        finally:
            self._done[k].set()

    def work(self, order: Iterable[int] | None = None) -> None:
        """Run the tasks ``order`` (all by default) not yet claimed or skipped, in turn (the helper's
        side)."""
        for k in range(len(self._tasks)) if order is None else order:
            if self._claim(k):
                self._run(k)

    def skip(self, ks: Iterable[int]) -> None:
        """Tasks whose results are not needed: not started if nobody has started them yet."""
        with self._lock:
            for k in ks:
                if self._state[k] == _OPEN:
                    self._state[k] = _SKIPPED

    def get(self, k: int) -> Any:
        """The result of task ``k``, run here if nobody has started it (skipped or not)."""
        if self._claim(k, skipped_too=True):
            self._run(k)
        self._done[k].wait()
        if self._errors[k] is not None:
            raise self._errors[k]
        return self._results[k]


_CV_LOCK = threading.Lock()
_CV_STATE: dict[str, int] = {"depth": 0, "saved": 0}


@contextmanager
def opencv_one_thread() -> Iterator[None]:
    """OpenCV's own thread pool held to one thread while any detection is inside (process-wide, like
    :func:`._blas.one_thread` for BLAS: the first caller in sets it, the last one out restores it).

    A detection with two threads already runs its parts side by side (the second path's candidates
    beside the first path's, the traced boxes, the split kernels), so OpenCV splitting each call into
    stripes only adds threads to cores that are busy: its pool's workers wake for the stripes of small
    boxes and wait spinning after them. Held to one thread, the GT room's images took 13 % less CPU and
    6 % less wall time with the detector's two threads (session 38, BENCHMARKS.md issue 16). The results
    of the OpenCV calls do not depend on the stripes.
    """
    with _CV_LOCK:
        if _CV_STATE["depth"] == 0:
            _CV_STATE["saved"] = cv2.getNumThreads()
            if _CV_STATE["saved"] != 1:
                cv2.setNumThreads(1)
        _CV_STATE["depth"] += 1
    try:
        yield
    finally:
        with _CV_LOCK:
            _CV_STATE["depth"] -= 1
            if _CV_STATE["depth"] == 0 and _CV_STATE["saved"] != 1:
                cv2.setNumThreads(_CV_STATE["saved"])
