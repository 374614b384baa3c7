"""The smoothings with odometry hold few bytes per node: their traced peak grows with the run's length by
less than the per-node budget (bench/fusion_memory.py measures it at 5-60 minutes)."""

from __future__ import annotations

import tracemalloc
from dataclasses import replace

import numpy as np
import pytest
from fusion_synth import long_run

from gtrig.fusion import FusionOptions, fuse_tracks
from gtrig.sync.joint_cameras import joint_reference

#: per source, the run-constant error's covariance (x, y, yaw; m^2, rad^2) the fusion stage considers
BIAS = {"vision": np.diag([0.07e-3, 0.07e-3, 1e-4]) ** 2, "laser": np.diag([1.0e-3, 0.95e-3, 3.8e-4]) ** 2}


def _fusion(odo, vision, laser) -> object:  # noqa: ANN001
    opts = FusionOptions(offsets_s={"vision": 0.0, "laser": 0.0}, offsets_sigma_s={"vision": 2e-4, "laser": 3e-4},
                         bias_cov=BIAS)
    return fuse_tracks({"vision": vision, "laser": laser}, odo, opts)


def _joint(odo, vision, laser) -> object:  # noqa: ANN001
    return joint_reference(vision, laser, odo, 0.0)


def _peak(call, minutes: float) -> tuple[int, float]:  # noqa: ANN001
    """(nodes, tracemalloc's peak in bytes) of ``call`` on a synthetic run of ``minutes``."""
    odo, vision, laser = long_run(minutes, seed=2)
    tracemalloc.start()
    try:
        call(odo, vision, laser)
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    return len(odo), float(peak)


@pytest.mark.parametrize(("call", "budget"), [(_fusion, 1800.0), (_joint, 1600.0)], ids=["fusion", "joint"])
def test_smoothing_peak_per_node_within_budget(call, budget: float) -> None:  # noqa: ANN001
    """Between a 2- and a 6-minute run (50 Hz odometry nodes, 75 Hz GTlaser, 10 Hz GTvision fixes: 1.7 fixes
    a node) the traced peak grows by under ``budget`` bytes a node: the fusion stage's call with the
    considered biases (1.2 kB measured; 2.7 kB with two normal-equations systems and the
    filter's covariances held through the batch solve, the solve's right-hand sides copied twice), the
    joint camera fit's reference (1.2 kB; 2.0 kB before). The peak is now the filter's backward-pass
    store (gains, conditional covariances and means: 288 B a node) on top of the merged fixes."""
    call(*long_run(1.0, seed=1))  # warm-up: compiled kernels' caches and lazy imports are not the call's
    n0, p0 = _peak(call, 2.0)
    n1, p1 = _peak(call, 6.0)
    per_node = (p1 - p0) / (n1 - n0)
    assert 0 < per_node < budget, f"{per_node:.0f} B a node"


def test_windowed_smoothing_is_the_one_batch_in_a_windows_memory() -> None:
    """A run smoothed in windows (60 s cores, 30 s overlaps, far shorter than the default 600 s: the seams'
    effects at their largest; the odometry parameters from every other core's information) is the one
    batch to micrometres and tens of microradians, its covariances to 5 % at most (at the run's first
    seconds; 4e-6 median), the parameters to a tenth of their sigma, the same fixes rejected; and its
    peak is half the batch's on 8 minutes (a window's working set instead of the run's)."""
    odo, vision, laser = long_run(8.0, seed=3)
    tracks = {"vision": vision, "laser": laser}
    # the odometry's noise as stated: the tolerances are the windows' own (with the noise fitted, the same
    # fit in both, the odometry ties each seam's sides closer and the seams count for more)
    opts = FusionOptions(bias_cov=BIAS, fit_odometry_noise=False)
    fuse_tracks(*_short(tracks, odo), replace(opts, window_s=20.0))  # warm-up, both paths
    tracemalloc.start()
    try:
        one, r1 = fuse_tracks(tracks, odo, replace(opts, window_s=None))
        _, peak_one = tracemalloc.get_traced_memory()
        tracemalloc.reset_peak()
        base = tracemalloc.get_traced_memory()[0]
        win, r2 = fuse_tracks(tracks, odo, replace(opts, window_s=60.0))
        peak_win = tracemalloc.get_traced_memory()[1] - base
    finally:
        tracemalloc.stop()
    assert len(r2.segments) == 8 and len(r1.segments) == 1
    np.testing.assert_array_equal(one.stamps_s, win.stamps_s)
    np.testing.assert_array_equal(one.status, win.status)
    e = win.xytheta() - one.xytheta()
    rel = np.abs(win.cov / one.cov - 1)[:, [0, 1, 2], [0, 1, 2]]
    assert np.hypot(e[:, 0], e[:, 1]).max() < 2e-5 and np.abs(e[:, 2]).max() < 5e-5  # 7.5 um, 26 urad
    assert rel.max() < 0.1 and np.median(rel) < 1e-3  # 5 % at the run's first seconds; 4e-6
    k1, s1 = np.array(r1.segments[0].odometry_params), np.array(r1.segments[0].odometry_params_sigma)
    for s in r2.segments:
        assert np.all(np.abs(np.array(s.odometry_params) - k1) < 0.25 * s1)  # 0.11 sigma at most
    same = [(o.source, o.stamp_s, o.stage) for o in r1.outliers]
    assert same == [(o.source, o.stamp_s, o.stage) for o in r2.outliers]
    assert peak_win < 0.6 * peak_one, (peak_win, peak_one)


def _short(tracks, odo):  # noqa: ANN001, ANN202
    """A minute of ``tracks`` and ``odo``, for a warm-up call."""
    from gtrig.io.odometry import OdometryLog

    t0 = odo.stamps_s[0]
    m = odo.stamps_s <= t0 + 60.0
    short = {k: t.select(np.flatnonzero(t.stamps_s <= t0 + 59.0)) for k, t in tracks.items()}
    return short, OdometryLog(odo.stamps_s[m], odo.xytheta[m], odo.v_mps[m], odo.omega_radps[m])


def test_a_failing_window_falls_back_to_the_one_batch(monkeypatch) -> None:  # noqa: ANN001
    """A window the one batch does not have may fail where the whole segment does not (a start without
    motion for position-only fixes): what the windows added is forgotten and the segment is one batch,
    bit for bit, counts and outliers included."""
    import importlib

    fuse_mod = importlib.import_module("gtrig.fusion.fuse")
    odo, vision, laser = long_run(4.0, seed=5)
    tracks = {"vision": vision, "laser": laser}
    one, r1 = fuse_tracks(tracks, odo, FusionOptions(window_s=None))
    real, calls = fuse_mod._smooth, []

    def failing(*a, **k):  # noqa: ANN002, ANN003, ANN202
        calls.append(1)
        if len(calls) == 6:  # pass 2's second window: the first window's core is already gathered
            raise fuse_mod.InputError("fusion: a window without motion")
        return real(*a, **k)

    monkeypatch.setattr(fuse_mod, "_smooth", failing)
    win, r2 = fuse_tracks(tracks, odo, FusionOptions(window_s=60.0))
    assert len(calls) > 6
    np.testing.assert_array_equal(one.stamps_s, win.stamps_s)
    np.testing.assert_array_equal(one.xytheta(), win.xytheta())
    np.testing.assert_array_equal(one.cov, win.cov)
    assert r1.sources == r2.sources and r1.segments == r2.segments and r1.outliers == r2.outliers
