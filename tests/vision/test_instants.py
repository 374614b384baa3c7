"""Instants: the array grouping against the rule it implements, on seeded random camera clocks."""

from __future__ import annotations

import pickle
import tracemalloc
from pathlib import Path

import numpy as np
import pytest

from gtrig.io.frames import FrameIndex
from gtrig.vision.instants import Instant, Instants, make_instants
from gtrig.vision.sequence import detection_chunks


def _index(name: str, stamps: np.ndarray) -> FrameIndex:
    n = stamps.size
    return FrameIndex(name, Path("/nonexistent") / name, np.arange(n), stamps, tuple(f"{i:06d}.png" for i in range(n)))


def _rule(indices: dict[str, FrameIndex], tol: float) -> list[Instant]:
    """The grouping rule, image by image: in time order (ties by camera name, then row), an image joins
    the open instant unless it is more than ``tol`` after that instant's first image or its camera is
    already in it; an instant's time is the mean of its stamps."""
    images = sorted((float(ix.stamps_s[i]), name, i) for name, ix in indices.items() for i in range(len(ix)))
    out: list[Instant] = []
    group: list[tuple[float, str, int]] = []
    for t, name, i in images:
        if group and (t - group[0][0] > tol or name in {g[1] for g in group}):
            out.append(Instant(float(np.mean([g[0] for g in group])), tuple((g[1], g[2]) for g in group)))
            group = []
        group.append((t, name, i))
    if group:
        out.append(Instant(float(np.mean([g[0] for g in group])), tuple((g[1], g[2]) for g in group)))
    return out


def _clocks(rng: np.random.Generator, n_cams: int, seconds: float) -> dict[str, FrameIndex]:
    """Cameras at 10-30 Hz; some share a trigger (stamps within a few ms), some run free, some drop frames."""
    out = {}
    trigger = np.arange(0.0, seconds, 0.1)
    for c in range(n_cams):
        if rng.random() < 0.5:  # triggered: the shared stamps with a jitter of up to 4 ms
            st = trigger + rng.uniform(-0.004, 0.004, trigger.size)
        else:
            st = np.arange(rng.uniform(0, 0.05), seconds, 1.0 / rng.uniform(10, 30))
        st = np.sort(st[rng.random(st.size) > 0.05])
        out[f"cam{c}"] = _index(f"cam{c}", st)
    return out


@pytest.mark.parametrize("seed", range(12))
def test_instants_follow_the_grouping_rule(seed: int) -> None:
    rng = np.random.default_rng(seed)
    indices = _clocks(rng, int(rng.integers(1, 9)), 20.0)
    tol = float(rng.choice([0.001, 0.005, 0.02]))
    got = make_instants(indices, "run", tol)
    want = _rule(indices, tol)
    assert len(got) == len(want)
    assert list(got) == want  # stamps bit for bit, images in the same order
    assert got[-1] == want[-1] and got[1:3] == want[1:3]
    # every image once; an instant's cameras distinct and within the tolerance of its first image
    seen = [img for ins in got for img in ins.images]
    assert len(seen) == len(set(seen)) == sum(len(ix) for ix in indices.values())
    for ins in got:
        cams = [c for c, _ in ins.images]
        st = [float(indices[c].stamps_s[r]) for c, r in ins.images]
        assert len(set(cams)) == len(cams) and max(st) - min(st) <= tol
    assert detection_chunks(got, indices, 7) == detection_chunks(want, indices, 7)
    back = pickle.loads(pickle.dumps(got))  # sent to workers and cached by the pipeline
    assert list(back) == want


def test_instants_take_a_few_bytes_each() -> None:
    """An hour of 4 cameras at 10 Hz: the instants cost far less than one object per instant (~270 B)."""
    rng = np.random.default_rng(3)
    indices = {f"cam{c}": _index(f"cam{c}", np.sort(rng.uniform(0, 3600.0, 36_000))) for c in range(4)}
    tracemalloc.start()
    try:
        ins = make_instants(indices, "run")
        kept, _ = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert isinstance(ins, Instants) and len(ins) > 100_000
    assert kept / len(ins) < 60


def test_validation_instants_are_the_static_intervals() -> None:
    indices = {"a": _index("a", np.arange(0.0, 10.0, 0.1)), "b": _index("b", np.arange(0.05, 10.0, 0.1))}
    got = make_instants(indices, "validation", intervals_s=np.array([[0.98, 2.02], [4.97, 5.52]]))
    assert [ins.stamp_s for ins in got] == [1.5, 0.5 * (4.97 + 5.52)]
    assert [len(ins.images) for ins in got] == [11 + 10, 6 + 5]  # a: 1.0 ... 2.0, b: 1.05 ... 1.95; 5.0 ... 5.5
    assert all(c in ("a", "b") for ins in got for c, _ in ins.images)
