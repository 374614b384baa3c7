"""The client's memory between stages: a stage's record is pickled straight into its file, not
built in memory beside the products, and what a stage freed is handed back to the system before the next
one runs (gtrig.memory)."""

from __future__ import annotations

import sys
import tracemalloc
from pathlib import Path

import numpy as np
import pytest

from gtrig.memory import release_free_memory
from gtrig.pipeline import StageOutput
from gtrig.pipeline.cache import load_record, save_record
from gtrig.trajectory import PoseTrack


def test_a_stage_record_is_written_without_a_copy_of_its_products(tmp_path: Path) -> None:
    n = 400_000  # an hour of GTlaser at ~110 Hz: 80 MB of poses and covariances
    rng = np.random.default_rng(0)
    quat = rng.normal(size=(n, 4))
    quat /= np.linalg.norm(quat, axis=1, keepdims=True)
    quat[quat[:, 3] < 0] *= -1
    cov = np.broadcast_to(np.diag([1e-6, 1e-6, 1e-6, 1e-4, 1e-4, 1e-4]), (n, 6, 6)).copy()
    track = PoseTrack(np.arange(n) * 0.01, rng.normal(size=(n, 3)), quat, cov)
    size_mb = (track.cov.nbytes + track.xyz.nbytes + track.quat_xyzw.nbytes) / 1e6
    out = StageOutput({"tracks/GTlaser/run": track})
    tracemalloc.start()
    try:
        tracemalloc.reset_peak()
        before = tracemalloc.get_traced_memory()[0]
        assert save_record(tmp_path, "laser", "k1", out)
        peak_mb = (tracemalloc.get_traced_memory()[1] - before) / 1e6
    finally:
        tracemalloc.stop()
    # pickle.dumps held the whole record (~ the products' size) in memory while writing it
    assert peak_mb < 0.1 * size_mb, f"writing the record took {peak_mb:.1f} MB for {size_mb:.0f} MB of products"
    back = load_record(tmp_path, "laser", "k1")
    assert back is not None
    got = back.products["tracks/GTlaser/run"]
    assert np.array_equal(got.cov, track.cov) and np.array_equal(got.stamps_s, track.stamps_s)


def _rss_mb() -> float:
    with open("/proc/self/status", encoding="ascii") as f:
        return next(int(ln.split()[1]) for ln in f if ln.startswith("VmRSS")) / 1e3


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="glibc's heap, read from /proc")
def test_freed_heap_memory_is_handed_back() -> None:
    from gtrig.memory import _glibc

    if _glibc() is None:
        pytest.skip("not glibc: nothing to hand back")
    # 100 kB blocks come from the heap (under glibc's 128 kB mmap threshold); one in eight kept alive
    # pins the heap's top, so without a trim the freed seven eighths stay resident
    blocks = [bytearray(100_000) for _ in range(3000)]
    for b in blocks:
        b[::4096] = b"\x01" * len(b[::4096])  # touch every page
    kept = blocks[::8]
    del blocks, b
    held = _rss_mb()
    release_free_memory()
    freed = held - _rss_mb()
    assert freed > 150, f"only {freed:.0f} MB of ~260 MB freed went back to the system"
    assert len(kept) == 375
