"""A results folder with every kind of file the report knows, written in the pipeline's layouts (fast: no
simulation), and a recording truth beside it."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from gtrig.io.posetrack import write_pose_track
from gtrig.io.tum import write_tum
from gtrig.trajectory import PoseStatus, PoseTrack


def _path(t: np.ndarray) -> np.ndarray:
    x, y = 2 * np.sin(0.1 * t), 1.5 * np.sin(0.2 * t)
    return np.column_stack([x, y, np.arctan2(np.gradient(y), np.gradient(x))])


@pytest.fixture(scope="session")
def results_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    root = tmp_path_factory.mktemp("demo")
    res, truth = root / "results", root / "recording" / "truth"
    rng = np.random.default_rng(0)
    t = 1700000000.0 + np.arange(0, 60, 0.01)
    write_tum(truth / "run.tum", PoseTrack.from_xytheta(t, _path(t - t[0])))
    for name, dt, sig in (("gt_laser", 0.0133, 1.5e-3), ("gt_vision_run", 0.0333, 2.5e-3)):
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
        "# Camera calibration report\n\n| camera | RMS (px) |\n|---|---|\n| cam0 | 0.035 |\n\nAll good.\n")
    with open(res / "gt_vision_run.checkpoint", "w", encoding="utf-8") as f:
        f.write(json.dumps({"key": "x", "version": 4}) + "\n")
        items = [{"obs": {"stamp_s": float(s), "cameras": ["cam0"], "views": [
            [f"cam{k % 3}", 3, (rng.uniform(100, 900, (4, 2))).tolist(), []] for k in range(2)]}} for s in t[::50]]
        f.write(json.dumps({"chunk": 1, "items": items}) + "\n")
    lag = np.linspace(-0.5, 0.5, 101)
    (res / "sync").mkdir()
    (res / "sync" / "laser_clocks.csv").write_text(
        "lag_s,corr_laser1,corr_laser2\n" + "".join(f"{v},{np.exp(-((v - 0.1) / 0.05) ** 2)},"
                                                   f"{np.exp(-((v + 0.2) / 0.05) ** 2)}\n" for v in lag))
    return res
