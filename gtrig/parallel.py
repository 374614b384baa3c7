"""Process pools that are safe to fork from a process that has used OpenCV."""

from __future__ import annotations

import contextlib
from collections.abc import Callable, Iterator
from concurrent.futures import ProcessPoolExecutor
from typing import Any


def _die_with_parent(parent_pid: int) -> None:
    """Ask Linux to send this worker SIGTERM when its parent dies (a SIGKILL of gtrig must not orphan
    workers blocked on a pipe); elsewhere a no-op."""
    import ctypes
    import os
    import signal
    import sys

    if sys.platform.startswith("linux"):
        try:
            libc = ctypes.CDLL(None, use_errno=True)
            PR_SET_PDEATHSIG = 1
            libc.prctl(PR_SET_PDEATHSIG, signal.SIGTERM)
        except (OSError, AttributeError):
            pass
    if os.getppid() != parent_pid:  # the parent died before the request took effect
        os._exit(1)


def _worker_start(parent_pid: int, initializer: Callable[..., Any] | None, initargs: tuple[Any, ...]) -> None:
    import signal

    # A forked worker inherits the CLI's SIGTERM handler, which unwinds by raising SystemExit: in a worker
    # that exception ends only the chunk (the pool sends it back as the chunk's result) and the worker
    # then waits for more work on a pipe its siblings keep open, so a SIGKILL of gtrig left workers alive.
    # Here SIGTERM (also the parent-death signal) ends the worker, and an interrupt is the parent's to
    # handle: it cancels the chunks not started and waits for the running ones.
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    _die_with_parent(parent_pid)
    if initializer is not None:
        initializer(*initargs)


@contextlib.contextmanager
def _interrupts_deferred() -> Iterator[None]:
    """Hold SIGTERM and SIGINT at the Python level for the block, then raise the first one that came.

    Blocking them with ``pthread_sigmask`` is not enough: it holds them for the calling thread only, and
    the kernel hands a process-directed signal to any thread that does not block it (a progress bar's,
    OpenCV's, numba's), after which CPython runs the handler in the main thread at its next bytecode,
    wherever that is. A Python-level handler runs only in the main thread and here only records."""
    import signal
    import threading

    if threading.current_thread() is not threading.main_thread():
        yield  # handlers can be set from the main thread only; a signal is the main thread's to handle
        return
    came: list[int] = []

    def record(signum: int, frame: object) -> None:
        came.append(signum)

    before = {s: signal.signal(s, record) for s in (signal.SIGTERM, signal.SIGINT)}
    try:
        yield
    finally:
        for s, handler in before.items():
            signal.signal(s, handler)
        if came:
            signal.raise_signal(came[0])


def _fork_workers_now(ex: ProcessPoolExecutor) -> None:
    """Fork the pool's workers (a forking pool starts them all at its first task) with interrupts deferred.

    A signal handled inside the fork's at-fork callbacks raises where Python ignores the exception
    ("Exception ignored in _releaseLock"), and the run would go on as if never signalled; one handled
    between the workers' start and their manager thread's leaves workers that nobody tells to stop, and
    the exit then waits for them forever (multiprocessing joins its children at exit). Deferred, the
    signal is raised once the pool is whole, where shutting the pool down ends its workers."""
    import os

    with _interrupts_deferred():
        ex.submit(os.getpid).result()


@contextlib.contextmanager
def process_pool(
    workers: int, initializer: Callable[..., Any] | None = None, initargs: tuple[Any, ...] = ()
) -> Iterator[ProcessPoolExecutor]:
    """A ``ProcessPoolExecutor`` forked with OpenCV's thread pool quiesced.

    OpenCV's worker threads do not survive fork(): a child forked while the parent's OpenCV thread pool
    is alive can hang in its first parallel call (seen with calibration then GTvision in one process).
    Forking (rather than spawning) is kept so that workers share large read-only state at no cost. On an
    exception in the block (KeyboardInterrupt included) the chunks not yet started are cancelled. Workers
    die with their parent, even when it is killed with SIGKILL.
    """
    import os

    import cv2

    threads = cv2.getNumThreads()
    cv2.setNumThreads(1)
    try:
        ex = ProcessPoolExecutor(workers, initializer=_worker_start, initargs=(os.getpid(), initializer, initargs))
        try:
            _fork_workers_now(ex)
            yield ex
        except BaseException:
            # interrupted (Ctrl-C) or failed: drop the chunks not started rather than computing them all
            # before giving control back (``with`` would wait for every submitted one)
            ex.shutdown(wait=True, cancel_futures=True)
            raise
        ex.shutdown(wait=True)
    finally:
        cv2.setNumThreads(threads)
