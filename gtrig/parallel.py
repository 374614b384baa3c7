"""Process pools that are safe to fork from a process that has used OpenCV."""

from __future__ import annotations

import contextlib
from collections.abc import Callable, Iterator
from concurrent.futures import ProcessPoolExecutor
from typing import Any


@contextlib.contextmanager
def process_pool(
    workers: int, initializer: Callable[..., Any] | None = None, initargs: tuple[Any, ...] = ()
) -> Iterator[ProcessPoolExecutor]:
    """A ``ProcessPoolExecutor`` forked with OpenCV's thread pool quiesced.

    OpenCV's worker threads do not survive fork(): a child forked while the parent's OpenCV thread pool
    is alive can hang in its first parallel call (seen with calibration then GTvision in one process).
    Forking (rather than spawning) is kept so that workers share large read-only state at no cost. On an
    exception in the block (KeyboardInterrupt included) the chunks not yet started are cancelled.
    """
    import cv2

    threads = cv2.getNumThreads()
    cv2.setNumThreads(1)
    try:
        ex = ProcessPoolExecutor(workers, initializer=initializer, initargs=initargs)
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
