"""Simulated outdoor runs (3 seeds, a 240 s campus loop each) measured against their truth: the
fixed-only positions within their 3-sigma and their NEES, the float multipath outliers, and the
odometry-smoothed trajectory on the lost-fix stretches. Pooled over the seeds (the acceptance
figures), and per seed against the spread a correct covariance gives to errors that wander in time.

"Within 3 sigma" is the 3-D region that holds 99.73 % (``d^2 <= 14.16``, gtrig.evaluate.within)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from gtrig.evaluate.within import correlated_rates, mahalanobis2, within
from gtrig.gps.filter import FilterOptions
from gtrig.gps.frames import Origin
from gtrig.gps.groundtruth import GpsOptions, gps_ground_truth
from gtrig.io.tum import read_tum
from gtrig.sim.outdoor import OutdoorParams, simulate_outdoor

SEEDS = (0, 1, 2)


def _opts(meta: dict, **kw: object) -> GpsOptions:
    o = meta["origin"]
    return GpsOptions(clock="utc", origin=Origin(o["lat_deg"], o["lon_deg"], o["h_m"]), **kw)  # type: ignore[arg-type]


def _truth_at(path: Path, stamps: np.ndarray, k: int = 3) -> np.ndarray:
    tr = read_tum(path)
    return np.column_stack([np.interp(stamps, tr.stamps_s, tr.xyz[:, i]) for i in range(k)])


def _measure(rec: Path) -> dict[str, np.ndarray]:
    from gtrig.gps.smooth import smooth_with_odometry
    from gtrig.io.odometry import read_odometry

    meta = json.loads((rec / "truth" / "outdoor.json").read_text())
    out: dict[str, np.ndarray] = {}
    res = gps_ground_truth(rec / "gps" / "gps.log", _opts(meta))
    e = res.track.xyz - _truth_at(rec / "truth" / "antenna.tum", res.track.stamps_s)
    C = res.track.cov
    out["fixed_within"] = within(e, C, "region")
    # the share of runs with a correct covariance and the simulator's error wander at or below this one's
    rates = correlated_rates(res.track.stamps_s, C, OutdoorParams().tau_s, "region", n_draws=400)
    out["fixed_p_value"] = np.array([np.mean(rates <= out["fixed_within"].mean())])
    out["fixed_nees"] = mahalanobis2(e, C)
    out["fixed_err_h"] = np.linalg.norm(e[:, :2], axis=1)

    resf = gps_ground_truth(rec / "gps" / "gps.log", _opts(meta, filter=FilterOptions(fix="float", max_sigma_m=None)))
    gt = np.loadtxt(rec / "truth" / "gps_truth.csv", delimiter=",", skiprows=1)
    i = np.searchsorted(np.round(gt[:, 0], 3), np.round(resf.epochs.utc_s, 3))
    outlier = gt[i, 3] > 0
    rejected = resf.all_epochs.status == 3
    out["outlier_rejected"] = rejected[outlier]
    out["good_float_rejected"] = rejected[~outlier & (resf.epochs.quality == 5)]

    sm = smooth_with_odometry(res, read_odometry(rec / "odometry" / "odometry.csv"), tuple(meta["lever_arm_m"]))
    es = sm.xyz[:, :2] - _truth_at(rec / "truth" / "robot.tum", sm.stamps_s, 2)
    Cs = sm.cov_xytheta()[:, :2, :2]
    bridged = sm.status == 2
    out["bridged_within"] = within(es, Cs, "region")[bridged]
    out["smoothed_nees"] = mahalanobis2(es, Cs)
    out["source_ok"] = np.array([sm.cov_kind == "xyyaw" and sm.source == "gps+odometry"])
    return out


@pytest.fixture(scope="module")
def runs(tmp_path_factory: pytest.TempPathFactory) -> list[dict[str, np.ndarray]]:
    out = []
    for seed in SEEDS:
        rec = tmp_path_factory.mktemp(f"outdoor{seed}")
        simulate_outdoor(rec, seed=seed, params=OutdoorParams(duration_s=240.0))
        out.append(_measure(rec))
    return out


def _pool(runs: list[dict[str, np.ndarray]], key: str) -> np.ndarray:
    return np.concatenate([r[key] for r in runs])


def test_fixed_positions_within_3_sigma_and_nees(runs) -> None:
    within = _pool(runs, "fixed_within")
    assert within.size > 300
    assert within.mean() >= 0.99, within.mean()
    nees = _pool(runs, "fixed_nees").mean() / 3
    assert 0.5 <= nees <= 2.0, nees
    for r in runs:  # each run as likely as 1 in 100 correct runs, or more
        assert r["fixed_p_value"][0] > 0.01, (r["fixed_within"].mean(), r["fixed_p_value"][0])
    assert np.percentile(_pool(runs, "fixed_err_h"), 95) < 0.05  # RTK fixed: centimetres


def test_float_outliers_rejected(runs) -> None:
    rej = _pool(runs, "outlier_rejected")
    assert rej.size > 20 and rej.mean() >= 0.9, (rej.size, rej.mean())
    assert _pool(runs, "good_float_rejected").mean() <= 0.02


def test_smoothed_lost_fix_stretches_within_3_sigma(runs) -> None:
    assert all(r["source_ok"][0] for r in runs)
    within = _pool(runs, "bridged_within")
    assert within.size > 100, "the runs have lost-fix stretches to bridge"
    assert within.mean() >= 0.95, within.mean()
    nees = _pool(runs, "smoothed_nees").mean() / 2
    assert 0.5 <= nees <= 2.0, nees
