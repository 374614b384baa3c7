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
    signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGTERM, signal.SIGINT})  # held while forking
    _die_with_parent(parent_pid)
    if initializer is not None:
        initializer(*initargs)


def _fork_workers_now(ex: ProcessPoolExecutor) -> None:
    """Fork the pool's workers (a forking pool starts them all at its first task) with SIGTERM and SIGINT
    held: a signal that arrives inside the fork's at-fork callbacks runs the CLI's handler there, where
    Python ignores the exception it raises ("Exception ignored in _releaseLock"), and the run would go on
    as if never signalled. Held, it is delivered right after, in plain code."""
    import os
    import signal

    held = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGTERM, signal.SIGINT})
    try:
        ex.submit(os.getpid).result()
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, held)


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
        _fork_workers_now(ex)
        try:
            yield ex
        except BaseException:
            # interrupted (Ctrl-C) or failed: drop the chunks not started rather than computing them all
            # before giving control back (``with`` would wait for every submitted one)
            ex.shutdown(wait=True, cancel_futures=True)
            raise
        ex.shutdown(wait=True)
    finally:
        cv2.setNumThreads(threads)
