"""Bags through the CLI as a user meets them: ``import rosbag --list > topics.yaml`` is a valid topics.yaml
proposing the bag's TF chains, an odometry-only import needs no rig, ``export`` from a bag without
``--topic`` lists what it holds, and frame ids survive a round trip through a bag."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from gtrig.cli.main import app
from gtrig.io.formats import read_trajectory
from gtrig.io.posetrack import write_pose_track
from gtrig.io.rosbag.topics import load_topics
from gtrig.trajectory import PoseTrack

runner = CliRunner()


def _list(bag: Path, out: Path) -> tuple[str, str]:
    res = runner.invoke(app, ["import", "rosbag", str(bag), "--list"])
    assert res.exit_code == 0, res.output
    out.write_text(res.stdout)
    return res.stdout, res.stderr


def test_list_writes_a_valid_topics_yaml_with_tf_chains(shared_dir: Path, tmp_path: Path) -> None:
    bag = shared_dir / "data/rosbags/nav2_turtlebot.mcap"
    out, err = _list(bag, tmp_path / "topics.yaml")
    assert "/amcl_pose" in err and "rate (Hz)" in err and "rate (Hz)" not in out  # the table on stderr
    cfg = load_topics(tmp_path / "topics.yaml")
    assert cfg.odometry == "/odom"
    assert cfg.trajectories == {"amcl_pose": "/amcl_pose", "tf_map_base_link": "/tf:map.base_link",
                                "tf_odom_base_link": "/tf:odom.base_link"}
    # the odometry-only import of that file needs no rig; each proposed chain reads
    res = runner.invoke(app, ["import", "rosbag", str(bag), "--topics", str(tmp_path / "topics.yaml"),
                              "--out", str(tmp_path / "rec")])
    assert res.exit_code == 0, res.output
    run = tmp_path / "rec" / "run"
    assert (run / "odometry.csv").is_file() and not (tmp_path / "rec" / "rig.yaml").exists()
    amcl = read_trajectory(run / "trajectories" / "amcl_pose.tum")
    tf_map = read_trajectory(run / "trajectories" / "tf_map_base_link.tum")
    assert (tf_map.frame_id, tf_map.child_frame_id) == ("map", "base_link")
    # AMCL's pose is map -> base_footprint (= base_link here): the TF chain agrees where both have a pose
    i = np.searchsorted(tf_map.stamps_s, amcl.stamps_s)
    ok = (i < len(tf_map)) & (np.abs(tf_map.stamps_s[np.minimum(i, len(tf_map) - 1)] - amcl.stamps_s) < 0.06)
    assert ok.sum() > 50
    assert np.median(np.linalg.norm(tf_map.xyz[i[ok], :2] - amcl.xyz[ok, :2], axis=1)) < 0.05


def test_tf_only_bag_proposes_its_chain(shared_dir: Path, tmp_path: Path) -> None:
    _list(shared_dir / "data/rosbags/tf_example.bag", tmp_path / "t.yaml")
    assert load_topics(tmp_path / "t.yaml").trajectories == {"tf_odom_base_link": "/tf:odom.base_link"}


def test_export_from_a_bag_lists_its_trajectories(shared_dir: Path, tmp_path: Path) -> None:
    res = runner.invoke(app, ["export", str(shared_dir / "data/rosbags/nav2_turtlebot.mcap"), "--to", "gtrig",
                              "--out", str(tmp_path / "a.tum")])
    assert res.exit_code == 2 and "Traceback" not in res.output
    line = [ln for ln in res.output.splitlines() if ln.startswith("error:")][0]
    for what in ("4 trajectories; choose one with --topic", "/amcl_pose (geometry_msgs/PoseWithCovarianceStamped, 135)",
                 "/odom (nav_msgs/Odometry, 2639)", "/tf:map.base_link (TF chain)"):
        assert what in line, line
    # a bag with one trajectory needs no --topic
    res = runner.invoke(app, ["export", str(shared_dir / "data/rosbags/tf_example.bag"), "--to", "gtrig",
                              "--out", str(tmp_path / "b.tum")])
    assert res.exit_code == 0 and "wrote 517 poses" in res.output, res.output


@pytest.mark.parametrize("to,name", [("rosbag1", "w.bag"), ("rosbag2", "w.mcap"), ("rosbag2", "w_db")])
def test_frames_and_poses_survive_a_round_trip(tmp_path: Path, to: str, name: str) -> None:
    t = 1700000300.0 + np.arange(200) * 0.02
    xy = np.column_stack([np.cos(0.1 * (t - t[0])), np.sin(0.1 * (t - t[0])), 0.1 * (t - t[0])])
    cov = np.tile(np.diag([1e-6, 2e-6, 3e-6]), (len(t), 1, 1))
    track = replace(PoseTrack.from_xytheta(t, xy, cov=cov), frame_id="world", child_frame_id="robot")
    write_pose_track(track, tmp_path / "gt.tum", tmp_path / "gt_cov.csv")
    res = runner.invoke(app, ["export", str(tmp_path / "gt.tum"), "--to", to, "--out", str(tmp_path / name)])
    assert res.exit_code == 0, res.output
    out, _ = _list(tmp_path / name, tmp_path / "topics.yaml")
    assert load_topics(tmp_path / "topics.yaml").trajectories["tf_world_robot"] == "/tf:world.robot"
    res = runner.invoke(app, ["export", str(tmp_path / name), "--to", "gtrig", "--out", str(tmp_path / "back.tum")])
    assert res.exit_code == 0, res.output
    back = read_trajectory(tmp_path / "back.tum", "gtrig")
    assert (back.frame_id, back.child_frame_id) == ("world", "robot")
    rows = [[ln.split() for ln in (tmp_path / f).read_text().splitlines()[1:]] for f in ("gt.tum", "back.tum")]
    assert [r[0] for r in rows[0]] == [r[0] for r in rows[1]]  # the stamps digit for digit
    assert np.allclose(np.array(rows[0], float)[:, 1:], np.array(rows[1], float)[:, 1:], rtol=0, atol=2e-12)
    assert back.cov is not None and np.allclose(back.cov, cov, rtol=1e-12)
