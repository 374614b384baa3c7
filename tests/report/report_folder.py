"""A results folder with every kind of file the report knows, written in the pipeline's layouts by the
pipeline's own writers where it has them (fast: no simulation), and a recording truth beside it.

The truth carries a height and a tilt, as the simulated robot's frame does, while the GT tracks are planar:
a planar track compared with it in 3-D would show the height as error."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from gtrig.fusion.fuse import FusionReport, Outlier, Segment
from gtrig.io.offsets import write_offsets
from gtrig.io.posetrack import write_pose_track
from gtrig.io.tum import write_tum
from gtrig.pipeline.context import AccuracyRow
from gtrig.pipeline.rows import write_accuracy_csv
from gtrig.sync.offset import OffsetEstimate
from gtrig.trajectory import PoseStatus, PoseTrack

#: the truth's robot frame above the floor (m) and its tilt (deg): not a planar track's error
TRUTH_HEIGHT_M, TRUTH_TILT_DEG = 0.3, 0.4
#: what the Markdown summary lists, item by item
MD_WARNINGS = ("poor coverage: cam0's boards cover 45 % of the image", "imprecise principal point of cam2")


def _tilted(t: np.ndarray, xytheta: np.ndarray) -> PoseTrack:
    """The truth: ``xytheta`` at ``TRUTH_HEIGHT_M``, rolled and pitched by ``TRUTH_TILT_DEG``."""
    T = np.tile(np.eye(4), (len(t), 1, 1))
    eul = np.column_stack([np.full(len(t), TRUTH_TILT_DEG), np.full(len(t), -TRUTH_TILT_DEG),
                           np.degrees(xytheta[:, 2])])
    T[:, :3, :3] = Rotation.from_euler("xyz", eul, degrees=True).as_matrix()
    T[:, :2, 3], T[:, 2, 3] = xytheta[:, :2], TRUTH_HEIGHT_M
    return PoseTrack.from_matrices(t, T)


def _path(t: np.ndarray) -> np.ndarray:
    x, y = 2 * np.sin(0.1 * t), 1.5 * np.sin(0.2 * t)
    return np.column_stack([x, y, np.arctan2(np.gradient(y), np.gradient(x))])


def make_results_dir(root: Path) -> Path:
    """Write the folder under ``root`` (``root/results``, ``root/recording/truth``); returns the results."""
    res, truth = root / "results", root / "recording" / "truth"
    rng = np.random.default_rng(0)
    t = 1700000000.0 + np.arange(0, 60, 0.01)
    write_tum(truth / "run.tum", _tilted(t, _path(t - t[0])))
    # three sources as a run has them: the fused track at 50 Hz between GTlaser's 75 Hz and GTvision's 30 Hz
    for name, dt, sig in (("gt_fused", 0.02, 1e-3), ("gt_laser", 0.0133, 1.5e-3),
                          ("gt_vision_run", 0.0333, 2.5e-3)):
        ts = t[0] + np.arange(0.5, 59, dt)
        n = ts.size
        C = np.tile(np.diag([sig**2, sig**2, np.radians(0.1) ** 2]), (n, 1, 1))
        xy = _path(ts - t[0]) + np.einsum("nij,nj->ni", np.linalg.cholesky(C), rng.standard_normal((n, 3)))
        status = np.zeros(n, np.uint8)
        status[rng.choice(n, 20, replace=False)] = PoseStatus.FLAGGED
        status[rng.choice(n, 5, replace=False)] = PoseStatus.REJECTED
        reasons = tuple("" if s == 0 else "test" for s in status)
        tr = PoseTrack.from_xytheta(ts, xy, cov=C, status=status, reasons=reasons, source=name)
        write_pose_track(tr, res / f"{name}.tum", res / f"{name}_cov.csv")
    (res / "accuracy.csv").write_text("stage,metric,value,unit,target,ok\nGTlaser,\"run, mean position error\","
                                      "1.5,mm,<= 5,1\nGTvision,\"run, max position error\",3.5,cm,<= 3,0\n")
    (res / "survey").mkdir()
    pts = rng.uniform(-3, 3, (8, 2))
    (res / "survey" / "world_points.csv").write_text(
        "name,x,y,cov_xx,cov_xy,cov_yy\n" + "".join(f"{i + 1},{p[0]},{p[1]},4e-7,1e-8,3e-7\n" for i, p in
                                                    enumerate(pts)))
    (truth / "world_points.csv").write_text(
        "name,x,y\n" + "".join(f"{i + 1},{p[0] + 3e-4},{p[1] - 2e-4}\n" for i, p in enumerate(pts)))
    (res / "survey" / "validation_poses.csv").write_text(
        "pose,x,y,theta,cov_xx,cov_xy,cov_xt,cov_yy,cov_yt,cov_tt\n"
        + "".join(f"{i + 1},{p[0]},{p[1]},0.5,2e-7,0,0,1e-7,0,2e-7\n" for i, p in enumerate(pts[:4])))
    (res / "calibration").mkdir()
    (res / "calibration" / "calibration_report.yaml").write_text(
        "intrinsics:\n" + "".join(f"  cam{k}:\n    rms_px: 0.03{k}\n" for k in range(3))
        + "network:\n  rms_px: 0.041\n  sigma_px: 0.027\n  world_board_rms_px:\n    cam1: 0.036\n  warnings: []\n"
        + "truth:\n" + "".join(f"  cam{k}:\n    joint_mm: 0.{k + 3}\n    chain_mm: {k + 2}.5\n" for k in range(3)))
    (res / "calibration" / "calibration_report.md").write_text(
        "# Camera calibration report\n\n| camera | RMS (px) |\n|---|---|\n| cam0 | 0.035 |\n\nAll good.\n\n"
        "## Warnings\n\n" + "".join(f"- {w}\n" for w in MD_WARNINGS))
    _checkpoint_v5(res / "gt_vision_run.checkpoint", rng)
    with open(res / "gt_vision_validation.checkpoint", "w", encoding="utf-8") as f:
        f.write(json.dumps({"key": "x", "version": 4}) + "\n")
        items = [{"obs": {"stamp_s": float(s), "cameras": ["cam0"], "views": [
            [f"cam{k % 3}", 3, (rng.uniform(100, 900, (4, 2))).tolist(), []] for k in range(2)]}} for s in t[::50]]
        f.write(json.dumps({"chunk": 1, "items": items}) + "\n")
    lag = np.linspace(-0.5, 0.5, 101)
    (res / "sync").mkdir()
    (res / "sync" / "laser_clocks.csv").write_text(
        "lag_s,corr_laser1,corr_laser2\n" + "".join(f"{v},{np.exp(-((v - 0.1) / 0.05) ** 2)},"
                                                   f"{np.exp(-((v + 0.2) / 0.05) ** 2)}\n" for v in lag))
    _run_records(res, t[0])
    return res


def _checkpoint_v5(path: Path, rng: np.random.Generator) -> None:
    """GTvision's detections, one line per camera and chunk of images: cam0 sees a marker in every other
    image, cam1 in every third, cam2 in none."""
    with open(path, "w", encoding="utf-8") as f:
        f.write(json.dumps({"key": "x", "version": 5}) + "\n")
        for cam, every in (("cam0", 2), ("cam1", 3), ("cam2", 0)):
            for chunk in range(3):
                frames = []
                for row in range(16 * chunk, 16 * chunk + 16):
                    seen = every and row % every == 0
                    dets = [[3, rng.uniform(50, 1000, (4, 2)).tolist(), np.tile(1e-4 * np.eye(2), (4, 1, 1)).tolist()]]
                    frames.append([row, dets if seen else []])
                f.write(json.dumps({"camera": cam, "frames": frames}) + "\n")


def _run_records(res: Path, t0: float) -> None:
    """The run's checks (summary.csv), clock offsets (sync.yaml), fusion report and rig."""
    write_accuracy_csv(res / "summary.csv", [
        AccuracyRow("survey", "world points", 8, ""),
        AccuracyRow("GTlaser", "run, frames localized", 97.5, "%", ">= 50", True),
        AccuracyRow("GTvision", "run, corner residual RMS", 1.7, "px", "<= 1", False),
        AccuracyRow("sync", "laser clock offset to odometry (unobservable)", float("nan"), "ms", "", False),
        AccuracyRow("fusion", "poses bridged by odometry", 1.5, "%")])
    lags = np.zeros(0)
    ok = OffsetEstimate("vision", "ok", 0.0123, (0.0118, 0.0128), 0.012, 0.93, 0.41, lags, lags, 12, "12 windows")
    bad = OffsetEstimate("laser", "unobservable", float("nan"), (float("nan"), float("nan")), float("nan"),
                         float("nan"), float("nan"), lags, lags, 0, "the robot hardly turns")
    scanner = {"verdict": "ok", "coarse_s": 0.002, "peak": 0.9, "second_peak": 0.2, "windows": 5,
               "reason": "5210 observations in 5 blocks of time", "offset_to_vision_s": -0.0021,
               "ci95_to_vision_s": [-0.0023, -0.0019], "offset_s": 0.0102, "ci95_s": [0.0097, 0.0107]}
    write_offsets(res / "sync.yaml", "odometry", {"vision": ok.to_dict(), "laser": bad.to_dict(),
                                                   "laser/laser0": scanner})
    seg = Segment(t0 + 0.5, t0 + 59, 2000, 30, 0.4, (1.0, 1.0, 0.0), (1e-3, 1e-3, 1e-3), 3)
    rep = FusionReport("batch", "odometry", {
        "vision": {"offered": 1770.0, "used": 1765.0, "rejected": 5.0, "downweighted": 2.0, "offset_s": 0.0123,
                   "offset_sigma_s": 0.0002},
        "laser": {"offered": 4400.0, "used": 4400.0, "rejected": 0.0, "downweighted": 0.0, "offset_s": 0.0,
                  "offset_sigma_s": 0.0}}, (seg,), (Outlier("vision", t0 + 12.25, 31.4, 3, "gate"),), 1.2)
    (res / "fusion_report.json").write_text(json.dumps(rep.to_dict(), indent=1, default=float) + "\n")
    (res / "rig.calibrated.yaml").write_text("cameras:\n" + "".join(
        f"- name: cam{k}\n  resolution: [1024, 768]\n" for k in range(3)))
