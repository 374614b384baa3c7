"""The process's C heap between long steps: hand freed memory back to the system (glibc).

A long run (an hour of recording, gtrig.pipeline) allocates and frees hundreds of MB of NumPy arrays
per stage. glibc's allocator keeps much of what is freed: arrays under 32 MB are served from the heap
once a larger mmapped block was freed (its mmap threshold rises to that block's size), and a heap's
free pages below its top go back to the system only through ``malloc_trim``. The process would then
hold each stage's high-water mark into the next stages, though the live data is far smaller (the
client kept ~690 MB after GTlaser on an hour of recording).

:func:`release_free_memory` is called by the pipeline after each stage; it is a garbage collection
alone off glibc.
"""

from __future__ import annotations

import ctypes
import gc
import sys
from functools import lru_cache
from typing import Any


@lru_cache(maxsize=1)
def _glibc() -> Any:
    """glibc's handle when this process runs on it, else None."""
    if not sys.platform.startswith("linux"):
        return None
    try:
        libc = ctypes.CDLL("libc.so.6")
    except OSError:
        return None
    if not hasattr(libc, "malloc_trim"):
        return None  # musl and others: nothing to hand back this way
    return libc


def release_free_memory() -> None:
    """Collect garbage, then return the heap's free pages to the system (``malloc_trim(0)``): the
    resident size then follows what is live, not what the last step held at its peak."""
    gc.collect()
    libc = _glibc()
    if libc is not None:
        libc.malloc_trim(0)


__all__ = ["release_free_memory"]
