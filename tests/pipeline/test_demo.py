"""`gtrig demo --quick`: every stage runs on a small simulated recording and meets its accuracy there;
`gtrig run` on the same recording without its truth writes the same pose tracks byte for byte, reuses
finished stages, and `--from laser` reruns only GTlaser and what follows."""

from __future__ import annotations

import os
import shutil
import signal
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from gtrig import pipeline
from gtrig.cli.main import app
from gtrig.rig import load_rig


@pytest.fixture(scope="module")
def demo(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("demo")
    r = CliRunner().invoke(app, ["demo", "--quick", "--out", str(out)])
    assert r.exit_code == 0, r.output
    assert "skipped" not in r.output and "accuracy against truth" in r.output
    return out


def test_demo_quick_runs_every_stage_against_truth(demo: Path, tmp_path: Path) -> None:
    out = demo
    res = out / "results"
    for name in ("rig.calibrated.yaml", "markers.yaml", "gt_laser.tum", "gt_laser_cov.csv", "gt_laser_bias.yaml",
                 "gt_vision_validation.tum", "gt_vision_run.tum", "gt_vision_run_bias.yaml", "survey/world_points.csv",
                 "accuracy.csv"):
        assert (res / name).is_file(), name
    # the demo ends with the one-page report (its content is tests/report's)
    assert 'src="data:image/png;base64,' in (out / "report.html").read_text(encoding="utf-8")

    # the calibrated rig carries every calibrated part, not the operator's nominal values
    nominal, cal = load_rig(out / "recording" / "rig.yaml"), load_rig(res / "rig.calibrated.yaml")
    for part in ("cameras", "laser_scanners"):
        a = np.array([x.T_world_cam.matrix() if part == "cameras" else x.T_world_scanner.matrix()
                      for x in getattr(nominal, part)])
        b = np.array([x.T_world_cam.matrix() if part == "cameras" else x.T_world_scanner.matrix()
                      for x in getattr(cal, part)])
        assert np.abs(a - b).max() > 1e-3, part
    assert any(not np.allclose(m.T_robot_marker.matrix(), cal.marker(m.id).T_robot_marker.matrix())
               for m in nominal.robot.markers)
    # with the covariances of their calibrations, which GTvision uses
    assert all(c.pose_cov is not None and np.asarray(c.pose_cov)[0, 0] > 0 for c in cal.cameras)
    assert all(m.pose_cov is not None for m in cal.robot.markers)

    rows = pipeline.read_accuracy_csv(res / "accuracy.csv")
    assert rows[("survey", "world points, max error")] < 3.0  # mm
    assert rows[("survey", "validation poses, max position error")] < 3.0
    assert rows[("calibration", "cameras, worst position error")] < 5.0
    assert rows[("markers", "relative to the dima-marker, worst position error")] < 0.2
    assert rows[("markers", "relative to the dima-marker, worst orientation error")] < 0.02
    assert rows[("markers", "on the robot, worst position error")] < 1.0
    assert rows[("GTlaser", "run, mean position error")] < 5.0
    assert rows[("GTlaser", "run, mean |yaw| error")] < 0.1
    assert rows[("GTlaser", "run, OK frames off by > 5 cm")] == 0
    assert rows[("GTvision", "validation, mean position error")] < 1.0  # cm
    assert rows[("GTvision", "run, mean position error")] < 1.0
    # the markers' robot frame tied to the survey at the validation stops: the dima-marker's 0.1 deg
    # hand placement replaced by what 26 stops measured
    assert rows[("robot frame", "offset from the survey, position error")] < 1.0  # mm
    assert rows[("robot frame", "offset from the survey, yaw error")] < 0.05  # deg
    assert rows[("markers", "on the robot, surveyed frame, worst position error")] < 1.0
    assert rows[("markers", "on the robot, surveyed frame, worst orientation error")] < 0.1
    # each stop checked in the frame fitted from the others. The quick demo's cameras are calibrated
    # from 8 views and their covariances are about 2x optimistic (camera pose NEES / dof 0.7-3.4; 0.5-2
    # with the full sets), which GTvision inherits: 3.9 here, 0.6-1.2 on the full recordings
    assert 0.2 < rows[("GTvision", "validation, mean NEES / dof")] < 8.0

    # the verb on its own: the calibrated rig is in the surveyed frame already, so a second fit finds
    # no offset, and the rig it writes keeps the fit's common frame error. Not to the last bit: markers cut
    # by the image's edge are looked for where the rig places them, so the tied rig's sub-micrometre move
    # moves their start and the poses by as much (0.3 um measured)
    r2 = CliRunner().invoke(app, ["robot-frame", "--rig", str(res / "rig.calibrated.yaml"), "--recording",
                                  str(out / "recording"), "--out", str(tmp_path / "rig2.yaml"), "--workers", "1"])
    assert r2.exit_code == 0, r2.output
    assert "markers moved by 0.00 mm, 0.00 mm" in r2.output and "from 26 of 26 stops" in r2.output
    twice = load_rig(tmp_path / "rig2.yaml")
    for m in twice.robot.markers:
        np.testing.assert_allclose(m.T_robot_marker.matrix(), cal.marker(m.id).T_robot_marker.matrix(), atol=2e-6)
    yaw_sd_deg = np.degrees(np.sqrt(np.asarray(twice.robot.markers_frame_cov)[5, 5]))
    assert 0 < yaw_sd_deg < 0.05  # the survey's, not the hand's 0.1 deg
    bad = CliRunner().invoke(app, ["robot-frame", "--rig", str(out / "recording" / "rig.yaml"), "--recording",
                                   str(out / "recording"), "--out", str(tmp_path / "x.yaml"), "--anchor", "999"])
    assert bad.exit_code != 0 and "marker 999" in bad.output and "Traceback" not in bad.output


TRACKS = ("gt_laser.tum", "gt_laser_cov.csv", "gt_vision_validation.tum", "gt_vision_validation_cov.csv",
          "gt_vision_run.tum", "gt_vision_run_cov.csv")


def test_run_without_truth_writes_the_same_tracks(demo: Path, tmp_path: Path) -> None:
    from gtrig.io.posetrack import read_pose_track

    # the recording as a lab would have it: no truth/ (hard links: nothing copied, nothing changed)
    rec = tmp_path / "recording"
    shutil.copytree(demo / "recording", rec, copy_function=os.link, ignore=shutil.ignore_patterns("truth"))
    out = tmp_path / "out"
    out.mkdir()
    for seq in ("validation", "run"):  # the detections only (the images are the same): not what is compared
        shutil.copy(demo / "results" / f"gt_vision_{seq}.checkpoint", out)
    r = CliRunner().invoke(app, ["run", "--recording", str(rec), "--out", str(out)])
    assert r.exit_code == 0, r.output
    assert "without truth" in r.output and "accuracy against truth" not in r.output and "skipped" not in r.output
    for name in TRACKS:
        assert (out / name).read_bytes() == (demo / "results" / name).read_bytes(), name
    assert (out / "rig.calibrated.yaml").read_bytes() == (demo / "results" / "rig.calibrated.yaml").read_bytes()
    assert not (out / "accuracy.csv").exists() and (out / "summary.csv").is_file()
    checks = pipeline.read_accuracy_csv(out / "summary.csv")
    assert checks[("GTvision", "validation, poses localized")] == 26
    assert checks[("GTlaser", "run, frames localized")] > 90  # %
    assert checks[("robot frame", "stops used")] == 26
    # the instants GTvision leaves out are those with no marker in view: the others are localized
    seen_pct = checks[("GTvision", "run, instants with a marker in view, localized")]
    unseen = checks[("GTvision", "run, instants with no marker in view")]
    assert seen_pct >= 90 and 0 < unseen < checks[("GTvision", "run, poses localized")] + unseen
    warnings = [x for x in r.output.splitlines() if x.startswith("warning")]
    assert not any(" nan " in w or "(expected )" in w for w in warnings), warnings
    # the tracks read back as pose tracks with their statuses and covariances
    las = read_pose_track(out / "gt_laser.tum", out / "gt_laser_cov.csv")
    vis = read_pose_track(out / "gt_vision_run.tum", out / "gt_vision_run_cov.csv")
    assert las.source == "GTlaser" and vis.source == "GTvision" and las.cov_kind == vis.cov_kind == "xyyaw"
    assert las.ok.all() and np.all(np.linalg.eigvalsh(vis.cov) > 0)
    # nothing changed: every stage is reused
    r2 = CliRunner().invoke(app, ["run", "--recording", str(rec), "--out", str(out)])
    assert r2.exit_code == 0 and "reused (unchanged since their last run): survey, cameras, markers, " \
        "robot-frame, laser, vision" in r2.output, r2.output

    # the README's "your own recording" path goes on: the rig checked, the report, every export, and GTvision
    # scored against the fused track, each with no warning
    runner = CliRunner()
    (tmp_path / "export").mkdir()
    steps = [["rig", "check", str(rec / "rig.yaml")], ["report", str(out), "--out", str(tmp_path / "report.html")]]
    for fmt, name in (("tum", "e.tum"), ("gtrig", "g.tum"), ("kitti", "e.kitti"), ("euroc", "euroc"),
                      ("rawseeds", "e_rs.csv"), ("csv", "e.csv"), ("rosbag1", "e.bag"), ("rosbag2", "e.mcap")):
        steps.append(["export", str(out / "gt_fused.tum"), "--to", fmt, "--out", str(tmp_path / "export" / name)])
    steps.append(["evaluate", "slam", "--gt", str(out / "gt_fused.tum"), "--estimate", str(out / "gt_vision_run.tum"),
                  "--align", "none"])
    for args in steps:
        r = runner.invoke(app, args)
        assert r.exit_code == 0 and "warning" not in r.output.lower(), (args, r.output)
    assert "association interpolate-gt" in r.output  # a GT-grade reference: its poses interpolated, not nearest
    assert (tmp_path / "report.html").stat().st_size > 100_000


def test_from_laser_reruns_laser_and_what_follows(demo: Path) -> None:
    res = demo / "results"
    before = {n: (res / n).read_bytes() for n in (*TRACKS, "accuracy.csv")}
    r = CliRunner().invoke(app, ["run", "--recording", str(demo / "recording"), "--out", str(res), "--from", "laser"])
    assert r.exit_code == 0, r.output
    assert "reused (unchanged since their last run): survey, cameras, markers, robot-frame\n" in r.output
    for n, b in before.items():
        assert (res / n).read_bytes() == b, n


def test_run_on_a_dask_cluster_writes_the_same_tracks(demo: Path, tmp_path: Path) -> None:
    """``--dask`` on a cluster of separate ``dask scheduler`` / ``dask worker`` processes on 127.0.0.1: GTlaser,
    GTvision (the run's images detected again, on the workers) and fusion write the
    same bytes as the local process pool did."""
    pytest.importorskip("distributed")
    from tests.scale.cluster import dask_cluster

    out = tmp_path / "out"
    shutil.copytree(demo / "results", out)
    (out / "gt_vision_run.checkpoint").unlink()  # the stops' detections kept: the test's cost halved
    with dask_cluster(tmp_path / "dask", nworkers=2) as address:
        r = CliRunner().invoke(app, ["run", "--recording", str(demo / "recording"), "--out", str(out), "--from",
                                     "laser", "--dask", address])
    assert r.exit_code == 0, r.output
    assert (out / "gt_vision_run.checkpoint").is_file()  # detected again, chunk by chunk
    for name in (*TRACKS, "gt_fused.tum", "gt_fused_cov.csv", "accuracy.csv"):
        assert (out / name).read_bytes() == (demo / "results" / name).read_bytes(), name


@pytest.mark.faults
def test_run_killed_three_ways_resumes_to_the_same_tracks(demo: Path, tmp_path: Path) -> None:
    """SIGINT after the survey, SIGTERM after the cameras, SIGKILL after GTlaser (in GTvision's pool): no
    worker survives, the last rerun reuses what was finished and writes the demo's tracks byte for byte."""
    from kill_kit import finish, gtrig, interrupt, temporaries

    out = tmp_path / "out"
    out.mkdir()
    for seq in ("validation", "run"):  # the detections only, as above: the test is about the stages
        shutil.copy(demo / "results" / f"gt_vision_{seq}.checkpoint", out)
    args = ("run", "--recording", str(demo / "recording"), "--out", str(out), "--workers", "2")
    records = out / ".gtrig" / "stages"
    for sig, after in ((signal.SIGINT, "survey"), (signal.SIGTERM, "cameras"), (signal.SIGKILL, "laser")):
        interrupt(gtrig(*args), lambda a=after: (records / f"{a}.pkl").is_file(), sig)
        if sig != signal.SIGKILL:
            assert not temporaries(out)
    log = finish(gtrig(*args))
    assert "reused (unchanged since their last run): survey, cameras, markers, robot-frame, laser" in log, log
    assert not temporaries(out)
    for name in (*TRACKS, "rig.calibrated.yaml"):
        assert (out / name).read_bytes() == (demo / "results" / name).read_bytes(), name


def test_laser_clock_stage_moves_each_scanner_by_its_offset(demo: Path, tmp_path: Path) -> None:
    """The laser-clock stage (gtrig.laser.clock) on sync.yaml's scanner entries: the simulated offsets,
    stated to 1 ms at 95 % (the quick run is too short for the sync stage to measure them itself)."""
    from gtrig.config import RunConfig
    from gtrig.io.offsets import write_offsets
    from gtrig.io.posetrack import read_pose_track
    from gtrig.io.yamlfile import load_yaml
    from gtrig.laser.recording import calibrate_recording
    from gtrig.pipeline.context import Products, StageInput
    from gtrig.pipeline.laser import gtlaser_clock

    rec, res = demo / "recording", demo / "results"
    true = load_yaml(rec / "truth" / "laser_clocks.yaml")["run"]["clock_offsets_s"]
    rig = load_rig(res / "rig.calibrated.yaml")
    _, report = calibrate_recording(rec)
    inp = StageInput(rec, tmp_path, RunConfig(), Products(rig=rig, laser_report=report), True, workers=1)
    # no sync.yaml: no second track, and a check that says why
    o = gtlaser_clock(inp)
    assert not o.products and "not made" in o.checks[0].metric and o.checks[0].ok is False
    write_offsets(tmp_path / "sync.yaml", "odometry", {
        f"laser/{k}": {"verdict": "ok", "offset_to_vision_s": v, "ci95_to_vision_s": [v - 1e-3, v + 1e-3]}
        for k, v in true.items()})
    o = gtlaser_clock(inp)
    rows = {r.metric: r.value for r in (*o.rows, *o.checks)}
    assert rows["track on vision's clock: scanners without a measured offset"] == 0
    assert rows["run on vision's clock, mean |yaw| error"] < 0.1
    assert rows["run on vision's clock, OK frames off by > 5 cm"] == 0
    synced = read_pose_track(tmp_path / "gt_laser_synced.tum", tmp_path / "gt_laser_synced_cov.csv")
    plain = read_pose_track(res / "gt_laser.tum", res / "gt_laser_cov.csv")
    # every frame moved by a share-weighted mean of the offsets (the frames are formed on the stamps)
    k = np.clip(np.searchsorted(plain.stamps_s, synced.stamps_s), 1, len(plain) - 1)
    near = np.where(np.abs(plain.stamps_s[k - 1] - synced.stamps_s) < np.abs(plain.stamps_s[k] - synced.stamps_s),
                    plain.stamps_s[k - 1], plain.stamps_s[k])
    shift = near - synced.stamps_s
    offs = np.array(list(true.values()))
    assert offs.min() - 1e-6 <= np.median(shift) <= offs.max() + 1e-6 and abs(np.median(shift)) > 1e-7
    # the clocks' part of the covariance (yaw rate x sigma_t, the turns): 0.51 ms left of the rig's 2 ms
    assert np.mean(synced.cov[:, 2, 2]) < np.mean(plain.cov[:, 2, 2])
