"""The process's C heap between long steps: hand freed memory back to the system (glibc).

A long run (an hour of recording, gtrig.pipeline) allocates and frees hundreds of MB of NumPy arrays
per stage. glibc's allocator keeps much of what is freed: arrays between its mmap threshold and 32 MB
are served from the heap once a larger mmapped block was freed (the threshold rises to that block's
size), and a heap's free pages below its top are returned only by ``malloc_trim``. The process then
holds the stages' high-water marks one on top of another, though the live data stays small (issue 24:
the client kept ~690 MB after GTlaser on an hour, of which a fifth was live).

:func:`release_free_memory` is called by the pipeline after each stage; :func:`bound_heap_growth` by
the command line at start (a library does not change its host's allocator). Both are no-ops off glibc.
"""

from __future__ import annotations

import ctypes
import gc
import logging
import sys
from functools import lru_cache
from typing import Any

log = logging.getLogger(__name__)

#: ``mallopt``'s parameter number for the mmap threshold (glibc's malloc.h)
_M_MMAP_THRESHOLD = -3

#: arrays at least this large are mmapped and so returned at once when freed; an explicit threshold also
#: stops glibc from raising it after each freed block. 1 MiB: a pose track's column of 10^5 poses is larger,
#: a detector's working image tile smaller (their page faults would cost more than they would return)
MMAP_THRESHOLD_BYTES = 1 << 20


@lru_cache(maxsize=1)
def _glibc() -> Any:
    """glibc's handle when this process runs on it (``malloc_trim`` and ``mallopt`` present), else None."""
    if not sys.platform.startswith("linux"):
        return None
    try:
        libc = ctypes.CDLL("libc.so.6")
    except OSError:
        return None
    if not (hasattr(libc, "malloc_trim") and hasattr(libc, "mallopt")):
        return None  # musl and others: nothing to tune
    return libc


def release_free_memory() -> None:
    """Collect garbage, then return the heap's free pages to the system (``malloc_trim(0)``): the
    resident size then follows what is live, not what the last step held at its peak."""
    gc.collect()
    libc = _glibc()
    if libc is not None:
        libc.malloc_trim(0)


def bound_heap_growth(mmap_threshold_bytes: int = MMAP_THRESHOLD_BYTES) -> bool:
    """Fix glibc's mmap threshold at ``mmap_threshold_bytes`` (it otherwise rises to every freed block's
    size, up to 32 MB, and later arrays that size fragment the heap). Returns whether it was set."""
    libc = _glibc()
    if libc is None:
        return False
    ok = bool(libc.mallopt(_M_MMAP_THRESHOLD, int(mmap_threshold_bytes)))
    if not ok:
        log.debug("mallopt(M_MMAP_THRESHOLD, %d) refused", mmap_threshold_bytes)
    return ok


__all__ = ["MMAP_THRESHOLD_BYTES", "bound_heap_growth", "release_free_memory"]
