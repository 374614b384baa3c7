"""evo's APE and RPE, by gtrig, equal evo's own numbers on TUM fr1_xyz (RGBD-SLAM against motion capture)."""

from __future__ import annotations

import copy
from pathlib import Path

import numpy as np
import pytest

from gtrig.evaluate.associate import associate_nearest
from gtrig.evaluate.slam import evaluate_slam
from gtrig.io.formats import read_trajectory

evo_sync = pytest.importorskip("evo.core.sync")
evo_metrics = pytest.importorskip("evo.core.metrics")
evo_files = pytest.importorskip("evo.tools.file_interface")

D = Path(__file__).resolve().parents[2] / ".." / "shared" / "data" / "trajectories"
GT = D / "freiburg1_xyz-groundtruth.txt"
EST = D / "freiburg1_xyz-rgbdslam.txt"
pytestmark = pytest.mark.skipif(not GT.exists(), reason="TUM fr1_xyz data missing")
STATS = ("rmse", "mean", "median", "std", "min", "max")


@pytest.mark.parametrize("align", ["se3", "sim3"])
def test_ape_rpe_equal_evo(align: str) -> None:
    ref = evo_files.read_tum_trajectory_file(str(GT))
    est = evo_files.read_tum_trajectory_file(str(EST))
    r, e = evo_sync.associate_trajectories(ref, est, max_diff=0.01)
    e = copy.deepcopy(e)
    e.align(r, correct_scale=align == "sim3")
    ours = evaluate_slam(read_trajectory(GT), read_trajectory(EST), metrics="evo", align=align, method="nearest",
                         max_dt_s=0.01)
    assert len(ours.association) == r.num_poses
    assert np.allclose(ours.association.gt.xyz, r.positions_xyz, atol=1e-12)
    PR = evo_metrics.PoseRelation
    for rel, key in ((PR.translation_part, "trans"), (PR.rotation_angle_rad, "rot"), (PR.full_transformation, "full")):
        for metric, mine in ((evo_metrics.APE, ours.ape), (evo_metrics.RPE, ours.rpe)):
            m = metric(rel)
            m.process_data((r, e))
            theirs = m.get_all_statistics()
            got = mine[key].stats()
            assert len(mine[key].values) == len(m.error)
            for k in STATS:
                assert abs(got[k] - theirs[k]) < 1e-6, (metric.__name__, key, k, got[k], theirs[k])


@pytest.mark.parametrize("align", ["se3", "sim3"])
def test_default_association_equals_evos_interpolation(align: str) -> None:
    """The default (auto: the denser GT interpolated at the estimate's stamps, tolerance from the sample
    periods) gives evo's figures with ``sync_method=interpolation``: same pairs, same APE and RPE."""
    from evo.core.sync_method import SyncMethod

    ref = evo_files.read_tum_trajectory_file(str(GT))
    est = evo_files.read_tum_trajectory_file(str(EST))
    r, e = evo_sync.associate_trajectories(ref, est, max_diff=0.01, sync_method=SyncMethod.interpolation)
    e = copy.deepcopy(e)
    e.align(r, correct_scale=align == "sim3")
    ours = evaluate_slam(read_trajectory(GT), read_trajectory(EST), metrics="evo", align=align)
    a = ours.association
    assert (a.method, a.anchor, a.auto, a.max_dt_auto) == ("interpolate-gt", "est", True, True)
    assert abs(a.max_dt_s - 0.03) < 1e-3  # three of the GT's 10 ms periods
    assert len(a) == r.num_poses == 785
    assert np.allclose(a.gt.xyz, r.positions_xyz, atol=1e-9)
    assert np.allclose(ours.est_aligned.xyz, e.positions_xyz, atol=1e-6)
    s = a.summary()
    assert s["matched"] + s["anchor_outside"] + s["anchor_in_gaps"] == s["anchor_poses"] == 788
    PR = evo_metrics.PoseRelation
    for rel, key in ((PR.translation_part, "trans"), (PR.rotation_angle_rad, "rot"), (PR.full_transformation, "full")):
        for metric, mine in ((evo_metrics.APE, ours.ape), (evo_metrics.RPE, ours.rpe)):
            m = metric(rel)
            m.process_data((r, e))
            theirs = m.get_all_statistics()
            got = mine[key].stats()
            for k in STATS:
                assert abs(got[k] - theirs[k]) < 1e-6, (metric.__name__, key, k, got[k], theirs[k])


@pytest.mark.parametrize("offset", [0.0, 0.013, -0.02])
def test_nearest_pairs_are_evos(offset: float) -> None:
    """Same pairs as evo's associate_trajectories, with an offset and both orders of lengths."""
    g, e = read_trajectory(GT), read_trajectory(EST)
    ref = evo_files.read_tum_trajectory_file(str(GT))
    est = evo_files.read_tum_trajectory_file(str(EST))
    for a, b, ta, tb in ((g, e, ref, est), (e, g, est, ref)):
        r1, r2 = evo_sync.associate_trajectories(ta, tb, max_diff=0.01, offset_2=offset)
        ours = associate_nearest(a, b, 0.01, offset)
        assert np.array_equal(ours.gt.xyz, r1.positions_xyz) and np.array_equal(ours.est.xyz, r2.positions_xyz)
        assert np.allclose(ours.dt_s, r2.timestamps + offset - r1.timestamps, atol=1e-6)


def test_a_pose_serving_two_pairs() -> None:
    """Two GT stamps nearest to one estimate pose (and the reverse): both pairs kept, as evo does."""
    from gtrig.trajectory import PoseTrack

    q = np.tile([0, 0, 0, 1.0], (3, 1))
    gt = PoseTrack(np.array([0.0, 0.004, 0.1]), np.eye(3), q)
    est = PoseTrack(np.array([0.002, 0.1, 0.2, 0.3]), np.eye(4)[:, :3], np.tile([0, 0, 0, 1.0], (4, 1)))
    a = associate_nearest(gt, est, 0.01)  # est longer: each GT stamp takes its nearest estimate pose
    assert len(a) == 3 and np.allclose(a.est.xyz[:2], est.xyz[0]) and np.all(np.diff(a.gt.stamps_s) > 0)
    b = associate_nearest(est, gt, 0.01)  # the GT longer: each estimate pose takes its nearest GT pose
    assert len(b) == 3 and np.allclose(b.gt.xyz, est.xyz[[0, 0, 1]]) and np.allclose(b.dt_s, [-0.002, 0.002, 0])


def test_estimate_written_out_of_order_scores_as_evo(tmp_path: Path) -> None:
    """An estimate whose stamps step back once: gtrig sorts it, evo pairs it as it stands; the APE (which
    does not depend on the order) is the same to the last digit, and equal to the ordered file's."""
    rows = [ln for ln in EST.read_text().splitlines() if ln and not ln.startswith("#")]
    swapped = tmp_path / "est_back.txt"
    swapped.write_text("\n".join(rows[:300] + [rows[301], rows[300]] + rows[302:]) + "\n")
    ref = evo_files.read_tum_trajectory_file(str(GT))
    r, e = evo_sync.associate_trajectories(ref, evo_files.read_tum_trajectory_file(str(swapped)), max_diff=0.01)
    e = copy.deepcopy(e)
    e.align(r)
    m = evo_metrics.APE(evo_metrics.PoseRelation.translation_part)
    m.process_data((r, e))
    theirs = m.get_all_statistics()
    for est in (swapped, EST):
        ours = evaluate_slam(read_trajectory(GT), read_trajectory(est), metrics="evo", align="se3",
                             method="nearest", max_dt_s=0.01)
        got = ours.ape["trans"].stats()
        for k in STATS:
            assert abs(got[k] - theirs[k]) < 1e-9, (est.name, k, got[k], theirs[k])
