"""GTvision over a small rendered recording: instants, workers, checkpoint resume, outputs and CLI."""

from __future__ import annotations

import csv
from pathlib import Path

import cv2
import numpy as np
import pytest
from typer.testing import CliRunner

from gtrig.errors import InputError
from gtrig.io.frames import write_frame_index
from gtrig.io.tum import Trajectory, read_tum, write_tum
from gtrig.rig.load import dump_rig
from gtrig.sim.gtroom import VALIDATION_POSES, make_scene
from gtrig.vision.report import accuracy, summarize
from gtrig.vision.sequence import read_covariance_csv, run_recording, write_covariance_csv
from gtrig.vision.synthetic import render_markers, visible_views

POSES = (3, 5)  # validation poses seen by two cameras
FRAMES = 2


@pytest.fixture(scope="module")
def rec(tmp_path_factory) -> tuple[Path, object]:
    scene = make_scene(0)
    rig = scene.rig_true
    out = tmp_path_factory.mktemp("rec")
    rng = np.random.default_rng(0)
    Ts = [scene.T_world_robot(*VALIDATION_POSES[k]) for k in POSES]
    intervals = [(10.0 * i, 10.0 * i + 1.0) for i in range(len(POSES))]
    for cam in rig.cameras:
        seen = [any(c == cam.name for c, _, _ in visible_views(rig, T)) for T in Ts]
        if not any(seen):
            continue
        folder = out / "validation" / "cameras" / cam.name
        folder.mkdir(parents=True)
        stamps, files = [], []
        for i, (T, (t0, _)) in enumerate(zip(Ts, intervals, strict=True)):
            for f in range(FRAMES):
                name = f"{len(files):06d}.png"
                cv2.imwrite(str(folder / name), render_markers(rig, cam.name, T, rng) if seen[i] else
                            np.full((768, 1024), 90, np.uint8))
                stamps.append(t0 + 0.1 + 0.3 * f + 0.01 * int(cam.name[-1]))
                files.append(name)
        write_frame_index(folder, np.array(stamps), files)
    with open(out / "validation" / "poses.csv", "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["pose", "start_s", "end_s"])
        for i, (a, b) in enumerate(intervals):
            w.writerow([i + 1, a, b])
    (out / "truth").mkdir()
    write_tum(out / "truth" / "validation.tum",
              Trajectory.from_matrices(np.array([0.5 * (a + b) for a, b in intervals]), np.stack(Ts)))
    dump_rig(rig, out / "rig.calibrated.yaml")
    return out, rig


def test_validation_sequence_localizes_every_static_pose(rec):
    path, rig = rec
    res = run_recording(path, rig, "validation", planar=True, workers=1, detector="aruco")
    assert len(res.estimates) == len(POSES)
    assert all(e.ok for e in res.estimates), [e.reason for e in res.estimates]
    acc = accuracy(res, read_tum(path / "truth" / "validation.tum"))
    assert acc.localized == len(POSES)
    # ArUco corners on small markers: about half a pixel; still well under a centimetre
    assert acc.pos_err_max_m < 0.01 and np.degrees(acc.yaw_err_mean_rad) < 0.5
    rep = summarize(res)
    assert rep.localized == len(POSES) and rep.rms_px < 2.0
    assert sum(c.images_with_markers for c in rep.cameras) >= 2 * FRAMES


def test_workers_and_resume_give_identical_outputs(rec, tmp_path):
    path, rig = rec
    a = run_recording(path, rig, "validation", True, workers=1, detector="aruco",
                      chunk_size=1)
    b = run_recording(path, rig, "validation", True, workers=2, detector="aruco", chunk_size=1)
    # interrupted after the first instant, then resumed from the checkpoint
    ck = tmp_path / "ck.jsonl"

    def stop(done, total):
        if done >= 1:
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        run_recording(path, rig, "validation", True, workers=1, detector="aruco", checkpoint=ck,
                      progress=stop, chunk_size=1)
    assert len(ck.read_text().splitlines()) == 2  # header + one chunk
    c = run_recording(path, rig, "validation", True, workers=1, detector="aruco", checkpoint=ck, chunk_size=1)
    outs = []
    for r, name in ((a, "a"), (b, "b"), (c, "c")):
        write_tum(tmp_path / f"{name}.tum", r.trajectory())
        write_covariance_csv(tmp_path / f"{name}.csv", r)
        outs.append(((tmp_path / f"{name}.tum").read_bytes(), (tmp_path / f"{name}.csv").read_bytes()))
    assert outs[0] == outs[1] == outs[2]
    stamps, cov = read_covariance_csv(tmp_path / "a.csv")
    assert cov.shape == (len(POSES), 3, 3) and np.all(np.linalg.eigvalsh(cov) > 0)
    # the checkpoint of other markers: refused, or (a folder the caller owns) started afresh
    other = rig.model_copy(update={"robot": rig.robot.model_copy(update={"markers": tuple(
        m.model_copy(update={"side_m": m.side_m * 1.01}) for m in rig.robot.markers)})})
    with pytest.raises(InputError, match="checkpoint of another run"):
        run_recording(path, other, "validation", True, workers=1, detector="aruco", checkpoint=ck)
    d = run_recording(path, other, "validation", True, workers=1, detector="aruco", checkpoint=ck,
                      stale_checkpoint="restart")
    assert len(d.localized()) == len(POSES)


def test_cli_writes_tum_and_covariance(rec, tmp_path):
    from gtrig.cli.main import app

    path, _ = rec
    out = tmp_path / "gt_vision.tum"
    cov = tmp_path / "cov.csv"
    r = CliRunner().invoke(app, ["vision", "--rig", str(path / "rig.calibrated.yaml"),
                                 "--recording", str(path), "--out", str(out), "--covariance", str(cov),
                                 "--sequence", "validation",
                                 "--workers", "1", "--detector", "aruco"])
    assert r.exit_code == 0, r.output
    assert len(read_tum(out)) == len(POSES)
    _, c = read_covariance_csv(cov)
    assert c.shape == (len(POSES), 6, 6)
    assert not out.with_name(out.name + ".checkpoint.jsonl").exists()
    r = CliRunner().invoke(app, ["vision", "--rig", str(path / "rig.calibrated.yaml"), "--recording",
                                 str(tmp_path / "nowhere"), "--out", str(out)])
    assert r.exit_code == 2 and "error" in r.output


def test_pose_velocities_recover_a_constant_twist():
    from scipy.spatial.transform import Rotation

    from gtrig.vision.sequence import pose_velocities

    rng = np.random.default_rng(3)
    t = np.cumsum(rng.uniform(0.08, 0.12, 12))
    t[6:] += 1.0  # a gap: poses on both sides use one-sided differences there
    v, w = np.array([0.3, -0.1, 0.01]), np.array([0.0, 0.02, 0.5])
    T = np.tile(np.eye(4), (len(t), 1, 1))
    T[:, :3, 3] = np.outer(t, v) + [1.0, 2.0, 0.0]
    T[:, :3, :3] = Rotation.from_rotvec(np.outer(t, w)).as_matrix() @ Rotation.from_euler("z", 0.3).as_matrix()
    vel = pose_velocities(t, T)
    assert np.allclose(vel[:, :3], v, atol=1e-12)
    assert np.allclose(vel[:, 3:], w, atol=1e-9)
    assert np.all(pose_velocities(t[:1], T[:1]) == 0)


def test_timing_uncertainty_adds_the_hidden_motion():
    from dataclasses import replace

    from gtrig.vision.estimate import FrameEstimate, Status
    from gtrig.vision.sequence import VisionResult, with_timing_uncertainty

    def est(k: float) -> FrameEstimate:
        T = np.eye(4)
        T[0, 3] = 0.3 * k * 0.1  # 0.3 m/s along x, a frame every 0.1 s
        return FrameEstimate(k * 0.1, Status.OK, T_world_robot=T, cov_6x6=np.eye(6) * 1e-6, views=(("cam0", 3),))

    res = VisionResult("run", tuple(est(k) for k in range(5)), (), {"cam0": 5}, "gtrig", True, {})
    out = with_timing_uncertainty(res, {"cam0": 0.002})
    for e in out.estimates:
        extra = e.cov_6x6 - np.eye(6) * 1e-6
        assert extra[0, 0] == pytest.approx((0.3 * 0.002) ** 2)
        assert np.count_nonzero(np.abs(extra) > 1e-15) == 1
    assert res.estimates[0].cov_6x6[0, 0] == 1e-6  # the input is not changed
    # a static sequence and a camera without jitter are left alone
    static = replace(res, sequence="validation")
    assert with_timing_uncertainty(static, {"cam0": 0.002}) is static
    assert with_timing_uncertainty(res, {"cam0": 0.0}) is res


def test_checkpoint_is_not_reused_across_detector_versions(rec, tmp_path, monkeypatch):
    import gtrig.markers.detect as det

    path, rig = rec
    ck = tmp_path / "ck.jsonl"
    run_recording(path, rig, "validation", True, workers=1, detector="gtrig", checkpoint=ck)
    monkeypatch.setattr(det, "DETECTOR_VERSION", det.DETECTOR_VERSION + 1)
    with pytest.raises(InputError, match="checkpoint of another run"):
        run_recording(path, rig, "validation", True, workers=1, detector="gtrig", checkpoint=ck)


def test_checkpoint_follows_a_moved_recording(rec, tmp_path, monkeypatch):
    """The detections are keyed on the images' paths inside the recording: a copy elsewhere reuses them
    (no image is read again) and gives the same poses."""
    import shutil

    import gtrig.vision.sequence as seq

    path, rig = rec
    ck = tmp_path / "ck.jsonl"
    a = run_recording(path, rig, "validation", True, workers=1, detector="aruco", checkpoint=ck)
    moved = tmp_path / "moved"
    shutil.copytree(path, moved)

    def no_detection(*args, **kw):
        raise AssertionError("detected again")

    monkeypatch.setattr(seq, "_process_chunk", no_detection)
    b = run_recording(moved, rig, "validation", True, workers=1, detector="aruco", checkpoint=ck)
    assert [e.T_world_robot.tobytes() for e in a.localized()] == [e.T_world_robot.tobytes() for e in b.localized()]
