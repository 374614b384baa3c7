"""``gtrig evaluate``: files evo reads are read (a repeated stamp, a stamp stepping back), the TUM column
layout is checked (commas, w-first quaternions), the default association counts no motion as error for a
GT-grade reference and says which it used, ``--max-dt`` follows the sample periods, the pairing counts add
up, and ``evaluate poses`` pairs each reference pose with the estimate's pose at its own stamp."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from gtrig.cli.main import app
from gtrig.evaluate.associate import associate
from gtrig.evaluate.slam import evaluate_slam
from gtrig.io.formats import read_trajectory
from gtrig.io.posetrack import write_pose_track
from gtrig.trajectory import PoseTrack

runner = CliRunner()


def _fr1(shared_dir: Path) -> tuple[list[str], list[str], list[str]]:
    d = shared_dir / "data" / "trajectories"
    g = (d / "freiburg1_xyz-groundtruth.txt").read_text().splitlines()
    e = (d / "freiburg1_xyz-rgbdslam.txt").read_text().splitlines()
    return [ln for ln in g if ln.startswith("#")], [ln for ln in g if ln and not ln.startswith("#")], \
        [ln for ln in e if ln and not ln.startswith("#")]


def _write(p: Path, lines: list[str]) -> Path:
    p.write_text("\n".join(lines) + "\n")
    return p


def _slam(gt: Path, est: Path, *extra: str) -> tuple[int, str, str]:
    res = runner.invoke(app, ["evaluate", "slam", "--gt", str(gt), "--estimate", str(est), "--metrics", "evo",
                              "--format", "csv", *extra])
    return res.exit_code, res.stdout, res.stderr


def _ape_rmse(csv_text: str) -> float:
    m = re.search(r"^evo,APE trans,rmse,([-0-9.e]+),m$", csv_text, re.M)
    assert m, csv_text
    return float(m.group(1))


def test_repeated_and_back_stepping_stamps_read_as_evo(shared_dir: Path, tmp_path: Path) -> None:
    head, g, e = _fr1(shared_dir)
    gt = _write(tmp_path / "gt.txt", head + g)
    est = _write(tmp_path / "est.txt", e)
    code, ref_out, _ = _slam(gt, est)
    assert code == 0
    # TUM freiburg2_desk's ground truth repeats one stamp: the later pose is dropped, with one warning
    dup = g[:1001] + [g[1000].split()[0] + " " + " ".join(g[1001].split()[1:])] + g[1001:]
    # an estimate written out of order once: sorted
    back = e[:300] + [e[301], e[300]] + e[302:]
    code, out, err = _slam(_write(tmp_path / "gt_dup.txt", head + dup), _write(tmp_path / "est_back.txt", back))
    assert code == 0, err
    assert err.count("repeated stamp") == 1 and err.count("step back") == 1, err
    assert _ape_rmse(out) == pytest.approx(_ape_rmse(ref_out), abs=1e-12)
    # a clock reset (far back) would interleave two paths: refused with the line, as evo would be wrong too
    reset = e[:300] + [f"{float(e[0].split()[0]) - 100:.4f} " + " ".join(e[300].split()[1:])] + e[301:]
    code, _, err = _slam(gt, _write(tmp_path / "est_reset.txt", reset))
    assert code == 2 and "est_reset.txt:301: the time stamp steps back" in err


def test_tum_with_commas_and_w_first_quaternions(shared_dir: Path, tmp_path: Path) -> None:
    head, g, e = _fr1(shared_dir)
    gt = _write(tmp_path / "gt.txt", head + g)
    _, ref_out, _ = _slam(gt, _write(tmp_path / "est.txt", e))
    commas = _write(tmp_path / "est_commas.txt", [",".join(ln.split()) for ln in e])
    code, out, err = _slam(gt, commas)
    assert code == 0, err
    assert _ape_rmse(out) == pytest.approx(_ape_rmse(ref_out), abs=1e-12)  # read as TUM, not as EuRoC
    w_first = _write(tmp_path / "est_w.txt", [" ".join((c := ln.split())[:4] + [c[7]] + c[4:7]) for ln in e])
    code, out, err = _slam(gt, w_first)
    assert code == 2 and "the estimate's quaternions look written w first" in err and "2.86 rad" in err, err
    code, out, err = _slam(w_first, gt)  # the same file as the GT: the GT side named
    assert code == 2 and "the GT's quaternions look written w first" in err, err


def _path(t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """A robot driving a figure eight at about 0.5 m/s (x, y, heading)."""
    xy = np.column_stack([2 * np.sin(0.25 * t), np.sin(0.5 * t)])
    v = np.column_stack([0.5 * np.cos(0.25 * t), 0.5 * np.cos(0.5 * t)])
    return xy, np.arctan2(v[:, 1], v[:, 0])


def _gt_grade_pair(tmp_path: Path) -> tuple[Path, Path]:
    """A fused GT at 100 Hz with errors drawn from its 1 mm / 1 mrad covariance, and a perfect estimate of the
    same run: the truth at camera stamps (30 Hz, not on the GT's grid). 95 % of a perfect estimate's poses
    lie within the GT's 95 % region."""
    rng = np.random.default_rng(4)
    sig = 1e-3
    t_gt = 100.0 + np.arange(0, 40, 0.01)
    xy, th = _path(t_gt)
    cov = np.tile(np.diag([sig**2] * 3), (len(t_gt), 1, 1))
    gt = PoseTrack.from_xytheta(t_gt, np.column_stack([xy, th]) + rng.normal(0, sig, (len(t_gt), 3)), cov=cov)
    t_v = 100.0047 + np.arange(0, 39.9, 1 / 30)
    xy, th = _path(t_v)
    vis = PoseTrack.from_xytheta(t_v, np.column_stack([xy, th]))
    write_pose_track(gt, tmp_path / "gt_fused.tum", tmp_path / "gt_fused_cov.csv")
    write_pose_track(vis, tmp_path / "gt_vision.tum", tmp_path / "gt_vision_cov.csv")
    return tmp_path / "gt_fused.tum", tmp_path / "gt_vision.tum"


def test_default_association_counts_no_motion_as_error(tmp_path: Path) -> None:
    gt, vis = _gt_grade_pair(tmp_path)
    res = runner.invoke(app, ["evaluate", "slam", "--gt", str(gt), "--estimate", str(vis), "--align", "none"])
    assert res.exit_code == 0, res.output
    assert "association interpolate-gt (the GT interpolated at the estimate's stamps" in res.stdout
    assert "chosen as the GT is the denser track, tolerance from the sample periods" in res.stdout
    share = float(re.search(r"([0-9.]+) % of poses within the GT's 95 % region", res.stdout).group(1))
    assert share > 93.0, res.stdout
    near = runner.invoke(app, ["evaluate", "slam", "--gt", str(gt), "--estimate", str(vis), "--align", "none",
                               "--associate", "nearest"])
    share_near = float(re.search(r"([0-9.]+) % of poses within the GT's 95 % region", near.stdout).group(1))
    assert share_near < share - 20 and "the motion between the two stamps counts as error" in near.stdout


def test_max_dt_from_sample_periods_on_rawseeds(shared_dir: Path) -> None:
    b = shared_dir / "data" / "rawseeds" / "Bicocca_2009-02-25b"
    g = read_trajectory(b / "Bicocca_2009-02-25b-GROUNDTRUTH.csv")
    e = read_trajectory(b / "SOLUTION_GraphSLAM_Laser.csv")  # sampled every 0.214 s (median)
    fixed = associate(g, e, "interpolate", 0.2)
    sized = associate(g, e, "interpolate")
    assert len(fixed) == 462 and sized.max_dt_auto and sized.max_dt_s == pytest.approx(3 * 0.2139, abs=1e-3)
    assert len(sized) > 5400
    for a in (fixed, sized, associate(g, e), associate(g, e, "nearest")):
        s = a.summary()
        assert s["matched"] + s["anchor_outside"] + s["anchor_in_gaps"] == s["anchor_poses"], s


def test_pairing_counts_add_up_on_fr1(shared_dir: Path) -> None:
    d = shared_dir / "data" / "trajectories"
    g = read_trajectory(d / "freiburg1_xyz-groundtruth.txt")
    e = read_trajectory(d / "freiburg1_xyz-rgbdslam.txt")
    for method in ("nearest", "interpolate", "interpolate-gt", "auto"):
        for a, b in ((g, e), (e, g)):
            ev = evaluate_slam(a, b, metrics="evo", method=method)  # type: ignore[arg-type]
            s = ev.association.summary()
            assert s["matched"] + s["anchor_outside"] + s["anchor_in_gaps"] == s["anchor_poses"], (method, s)
            line = ev.association.describe()
            assert f"{s['matched']} paired + {s['anchor_outside']} outside" in line


def test_evaluate_poses_pairs_each_pose_at_its_own_stamp(tmp_path: Path) -> None:
    t = 50.0 + np.arange(1201) * 0.01
    xy, th = _path(t)
    ref = PoseTrack.from_xytheta(t, np.column_stack([xy, th]))
    write_pose_track(ref, tmp_path / "ref.tum")
    write_pose_track(ref.select(np.arange(0, 1201, 2)), tmp_path / "est.tum")  # the estimate at half the rate
    res = runner.invoke(app, ["evaluate", "poses", "--reference", str(tmp_path / "ref.tum"), "--estimate",
                              str(tmp_path / "est.tum"), "--format", "csv", "--per-pose"])
    assert res.exit_code == 0, res.output
    rows = [ln.split(",") for ln in res.stdout.splitlines() if re.match(r"^[0-9]+\.[0-9]+,", ln)]
    assert len(rows) == 601  # each estimate pose once, at its own stamp
    assert max(abs(float(c)) for r in rows for c in r[1:]) < 1e-8
