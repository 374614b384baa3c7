"""GTlaser on one clock (gtrig.laser.clock): the scanners' measured offsets removed before the fit."""

from __future__ import annotations

import numpy as np
import pytest

from gtrig.geometry import wrap_angle
from gtrig.io.offsets import Z95
from gtrig.io.scans import ScanLog
from gtrig.laser import synth
from gtrig.laser.background import build_background
from gtrig.laser.clock import ScannerClock, clocks_from_sync, scanners_on_clock
from gtrig.laser.foreground import foreground_mask, foreground_threshold
from gtrig.laser.fuse import frame_points
from gtrig.laser.hull_icp import HullModel
from gtrig.laser.track import OK, track_frames
from tests.laser.test_speeds import DURATION_S, path


def test_clocks_from_sync_reads_the_scanner_entries():
    sources = {
        "vision": {"verdict": "ok", "offset_s": -0.0015, "ci95_s": [-0.005, 0.002]},
        "laser": {"verdict": "ok", "offset_s": 0.002, "ci95_s": [0.0, 0.004]},
        "laser/a": {"verdict": "ok", "offset_to_vision_s": 0.004, "ci95_to_vision_s": [0.003, 0.005],
                    "offset_s": 0.0025, "ci95_s": [-0.0015, 0.0065]},
        "laser/b": {"verdict": "ambiguous", "offset_to_vision_s": None, "ci95_to_vision_s": None},
        "vision/cam0": {"verdict": "ok", "offset_to_vision_s": 0.001, "ci95_to_vision_s": [0.0, 0.002]},
    }
    v = clocks_from_sync(sources, "vision")
    assert set(v) == {"a"}  # not the sources, not the cameras, not a scanner without a verdict of ok
    assert v["a"].offset_s == pytest.approx(0.004)
    assert v["a"].sigma_s == pytest.approx(0.001 / Z95)
    o = clocks_from_sync(sources, "odometry")
    assert o["a"].offset_s == pytest.approx(0.0025) and o["a"].sigma_s == pytest.approx(0.004 / Z95)
    assert clocks_from_sync(sources, "scanners") == {}


def _yaw_lag(room, offsets_s, clocks=None, seed=7):
    """Scans fired along a 2 m/s winding path (up to 2 rad/s), each scanner stamping on a clock
    ``offsets_s`` late; tracked with its stamps moved by ``clocks`` (None: as stamped). Returns the
    slope of the signed yaw error on the true yaw rate (s: err = -lag * rate), mean |yaw| (deg) and NEES/dof."""
    rng = np.random.default_rng(seed)
    scs = room["scanners"]
    fired = [np.arange(0.0, DURATION_S, 1 / 75) + 0.0031 * i for i in range(4)]
    at = path(2.0)
    bg = synth.swept_scan_sequence(scs, room["static"], room["hull"], lambda t: np.full((len(t), 3), 50.0),
                                   [f[:40] for f in fired], rng)
    run = synth.swept_scan_sequence(scs, room["static"], room["hull"], at, fired, rng)
    logs = {s.name: ScanLog(f + o, r) for s, f, o, r in zip(scs, fired, offsets_s, run, strict=True)}
    if clocks is not None:
        scs, logs = scanners_on_clock(scs, logs, clocks)
    models = [build_background(b, s) for b, s in zip(bg, scs, strict=True)]
    masks = [foreground_mask(logs[s.name].ranges_m, foreground_threshold(m)) for s, m in zip(scs, models, strict=True)]
    fp = frame_points(scs, [logs[s.name].stamps_s for s in scs], [logs[s.name].ranges_m for s in scs], masks)
    res = track_frames(fp, HullModel.from_hull(room["hull"]))
    ok = res.status == OK
    truth = at(res.stamps_s)
    rate = np.gradient(np.unwrap(truth[:, 2]), res.stamps_s)[ok]
    err = wrap_angle(res.xytheta[ok, 2] - truth[ok, 2])
    z = res.xytheta[ok] - truth[ok]
    z[:, 2] = err
    nees = float(np.mean(np.einsum("ni,nij,nj->n", z, np.linalg.inv(res.cov_xytheta[ok]), z))) / 3
    return -float(np.sum(err * rate) / np.sum(rate**2)), float(np.degrees(np.mean(np.abs(err)))), nees


def test_measured_offsets_remove_the_scanners_lag(room):
    # four clocks 3-6 ms late (a common lag of 4.5 ms, differences of +-1.5 ms): the track shows the lag
    offsets = np.array([0.003, 0.004, 0.005, 0.006])
    lag, yaw, _ = _yaw_lag(room, offsets)
    assert lag == pytest.approx(offsets.mean(), abs=0.0015)
    # each offset measured to 0.5 ms (the sync stage's accuracy) and removed: the lag is gone, the yaw
    # error is that of exact clocks, and the covariance holds the 0.5 ms that is left
    meas = offsets + np.array([0.0004, -0.0005, 0.0003, -0.0002])
    clocks = {s.name: ScannerClock(float(m), 0.0005) for s, m in zip(room["scanners"], meas, strict=True)}
    lag_c, yaw_c, nees_c = _yaw_lag(room, offsets, clocks)
    _, yaw_0, _ = _yaw_lag(room, np.zeros(4))
    print(f"lag {1e3 * lag:.2f} -> {1e3 * lag_c:.2f} ms; yaw {yaw:.3f} -> {yaw_c:.3f} deg (exact clocks "
          f"{yaw_0:.3f}); NEES/dof {nees_c:.2f}")
    assert abs(lag_c) < 0.001
    assert yaw_c < 0.8 * yaw
    assert yaw_c < yaw_0 + 0.02
    assert 0.2 < nees_c < 3.0


def test_scanners_on_clock_sets_the_offsets_uncertainty(room):
    s = room["scanners"][0]
    logs = {s.name: ScanLog(np.array([1.0, 1.1]), np.ones((2, s.beams)))}
    scs, out = scanners_on_clock([s], logs, {s.name: ScannerClock(0.002, 0.0004)})
    assert scs[0].stamp_sigma_s == pytest.approx(0.0004)
    np.testing.assert_allclose(out[s.name].stamps_s, [0.998, 1.098])
    scs, out = scanners_on_clock([s], logs, {})
    assert scs[0] is s and out[s.name] is logs[s.name]
