"""The RTS smoother run a block at a time (its forward state kept at each block's start, each block filtered
again on the way back) gives the bits of one pass over the whole track."""

from __future__ import annotations

import numpy as np
import pytest

import gtrig.smoothing as smoothing
from gtrig.laser.process_noise import local_ml_process_noise


def _track(n: int, seed: int = 3) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    t = np.cumsum(rng.uniform(0.012, 0.015, n))
    z = np.column_stack([np.sin(t), 0.5 * t, 0.3 * t]) + rng.normal(0, 0.003, (n, 3))
    z[rng.random(n) < 0.1] = np.nan  # frames not measured
    z[0] = [0.0, 0.0, 0.0]
    R = np.tile(np.diag([1e-5, 1e-5, 1e-4]), (n, 1, 1))
    return t, z, R


@pytest.mark.parametrize("order", [2, 3])
def test_blocks_give_the_whole_tracks_bits(monkeypatch: pytest.MonkeyPatch, order: int) -> None:
    t, z, R = _track(100)
    qd = np.column_stack([np.geomspace(1e-3, 1.0, 100)] * 3)
    monkeypatch.setattr(smoothing, "SMOOTH_BLOCK_FRAMES", 10**9)
    ref = smoothing.rts_smooth_varying(t, z, R, qd, order)
    ref_q = local_ml_process_noise(t, z, R, 0.1 * np.geomspace(1, 100, 5), 0.1 * np.geomspace(1, 100, 5), 0.3, order)
    # the smoother moved the poses (a test of a smoother that does nothing would pass the rest)
    assert np.nanmax(np.abs(ref[0] - z)) > 1e-4
    for block in (1, 7, 99):
        monkeypatch.setattr(smoothing, "SMOOTH_BLOCK_FRAMES", block)
        monkeypatch.setattr("gtrig.laser.process_noise.SMOOTH_BLOCK_FRAMES", block)
        got = smoothing.rts_smooth_varying(t, z, R, qd, order)
        assert got[0].tobytes() == ref[0].tobytes() and got[1].tobytes() == ref[1].tobytes(), block
        q = local_ml_process_noise(t, z, R, 0.1 * np.geomspace(1, 100, 5), 0.1 * np.geomspace(1, 100, 5), 0.3, order)
        assert q[0].tobytes() == ref_q[0].tobytes() and q[1].tobytes() == ref_q[1].tobytes(), block
