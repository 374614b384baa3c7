"""Pairing by stamp (interpolation, gaps, the time offset), the alignments, and ``evaluate poses`` on TUM files
paired by stamp instead of by row."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation
from typer.testing import CliRunner

from gtrig.cli.main import app
from gtrig.evaluate.align import apply_alignment, fit_alignment
from gtrig.evaluate.associate import associate_interpolate
from gtrig.evaluate.time_offset import estimate_time_offset
from gtrig.io.tum import write_tum
from gtrig.trajectory import PoseTrack


def _path(t: np.ndarray) -> PoseTrack:
    xyz = np.column_stack([2 * np.sin(0.3 * t), np.sin(0.5 * t), 0.1 * np.cos(0.2 * t)])
    q = Rotation.from_euler("zyx", np.column_stack([0.4 * t, 0.05 * np.sin(t), 0.02 * t])).as_quat()
    return PoseTrack(t, xyz, q)


def test_interpolation_gaps_and_span() -> None:
    gt = _path(np.arange(0, 20, 0.01))
    t_est = np.arange(2, 18, 1 / 30)
    t_est = t_est[(t_est < 8) | (t_est > 9)]  # a one-second dropout
    a = associate_interpolate(gt, _path(t_est), max_gap_s=0.2)
    # the analytic path at the GT stamps: SE(3) interpolation over 33 ms is good to the curvature's order
    truth = _path(a.gt.stamps_s)
    assert np.max(np.linalg.norm(a.est.xyz - truth.xyz, axis=1)) < 2e-4
    ang = (Rotation.from_quat(a.est.quat_xyzw) * Rotation.from_quat(truth.quat_xyzw).inv()).magnitude()
    assert np.max(ang) < 1e-4
    s = a.summary()
    assert s["gaps"] == 1 and 1.0 < s["gap_time_s"] < 1.1
    assert abs(s["anchor_in_gaps"] - 103) <= 4 and 400 <= s["anchor_outside"] <= 405
    assert s["matched"] + s["anchor_in_gaps"] + s["anchor_outside"] == len(gt)


def test_time_offset_recovered_with_interval() -> None:
    rng = np.random.default_rng(2)
    gt = _path(np.arange(0, 60, 0.01))
    true = 0.137
    t_est = np.arange(1, 59, 1 / 30)
    e = _path(t_est + true)  # the estimate's clock runs 0.137 s behind: t_gt = t_est + 0.137
    e = PoseTrack(t_est, e.xyz + rng.normal(0, 0.003, e.xyz.shape) + [3, -1, 0.2], e.quat_xyzw)
    to = estimate_time_offset(gt, e, "se3")
    assert to.low_s <= true <= to.high_s and abs(to.offset_s - true) < 2e-3 and to.high_s - to.low_s < 0.01


@pytest.mark.parametrize("kind", ["se2", "yaw", "se3", "sim3", "sim2"])
def test_alignment_recovers_a_known_transform(kind: str) -> None:
    gt = _path(np.arange(0, 30, 0.05))
    planar = kind in ("se2", "yaw", "sim2")
    R = Rotation.from_euler("z", 0.7) if planar else Rotation.from_euler("zyx", [0.7, 0.1, -0.2])
    scale = 1.3 if kind.startswith("sim") else 1.0
    t = np.array([1.0, -2.0, 0.0 if kind in ("se2", "sim2") else 0.4])
    # est = the GT moved into another frame: p_est = R^-1 (p_gt - t) / s
    xyz = (R.inv().apply(gt.xyz - t)) / scale
    q = (R.inv() * Rotation.from_quat(gt.quat_xyzw)).as_quat()
    est = PoseTrack(gt.stamps_s, xyz, q)
    a = fit_alignment(gt.xyz, est.xyz, kind)  # type: ignore[arg-type]
    back = apply_alignment(est, a)
    assert np.allclose(back.xyz, gt.xyz, atol=1e-9) and abs(a.scale - scale) < 1e-9
    ang = (Rotation.from_quat(back.quat_xyzw) * Rotation.from_quat(gt.quat_xyzw).inv()).magnitude()
    assert np.max(ang) < 1e-9


def test_poses_pairs_tum_by_stamp_not_row(tmp_path: Path) -> None:
    """Two TUM files whose rows do not line up (the estimate misses the GT's first pose): paired by stamp."""
    gt = _path(np.arange(0, 10, 0.5) + 0.25)
    est = gt.select(np.arange(1, len(gt)))
    est = PoseTrack(est.stamps_s + 0.004, est.xyz + [0.01, 0, 0], est.quat_xyzw)
    write_tum(tmp_path / "gt.tum", gt)
    write_tum(tmp_path / "est.tum", est)
    res = CliRunner().invoke(app, ["evaluate", "poses", "--reference", str(tmp_path / "gt.tum"), "--estimate",
                                   str(tmp_path / "est.tum"), "--format", "csv"])
    assert res.exit_code == 0, res.output
    lines = res.stdout.splitlines()
    mean = dict((r.split(",")[0], r.split(",")[1:]) for r in lines)["mean"]
    assert abs(float(mean[0]) + 0.01) < 1e-6  # reference - estimate = -1 cm in x, every pair
    assert f"{len(gt) - 1}/{len(gt)}" in res.stdout


def test_align_interval_and_auto_offset_through_evaluate_slam() -> None:
    from gtrig.evaluate.slam import evaluate_slam

    gt = _path(np.arange(0, 40, 0.02))
    t_est = np.arange(1, 39, 0.05)
    e = _path(t_est + 0.08)
    xyz = e.xyz + [2.0, 1.0, 0.0]
    xyz[t_est > 20] += [0.05, 0, 0]  # a jump in the second half: fit on the first only
    est = PoseTrack(t_est, xyz, e.quat_xyzw)
    ev = evaluate_slam(gt, est, align="se3", align_interval_s=(0, 19.5), t_offset_s="auto", method="interpolate",
                       metrics="evo")
    assert ev.time_offset is not None and abs(ev.time_offset.offset_s - 0.08) < 0.01
    err = ev.ape["trans"].values  # type: ignore[index]
    first = ev.association.gt.stamps_s < 19.5
    late = ev.association.gt.stamps_s > 21
    assert np.median(err[first]) < 2e-3 and abs(np.median(err[late]) - 0.05) < 5e-3
