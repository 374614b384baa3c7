"""A recording through a bag and back: gtrig writes a recording's images, scans and odometry into
ROS 1 / ROS 2 bags, imports them into the recording layout, and gets the same files; the real /odom
of nav2_turtlebot.mcap imports into odometry.csv; bad input is one line, exit code 2, nothing written."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest
from typer.testing import CliRunner

from gtrig.cli.main import app
from gtrig.errors import FormatError, InputError
from gtrig.io.frames import read_frame_index, write_frame_index
from gtrig.io.odometry import OdometryLog, read_odometry, write_odometry_csv
from gtrig.io.rosbag._bag import BagWriter, header
from gtrig.io.rosbag.record_export import export_recording
from gtrig.io.rosbag.record_import import IMAGE_ENCODINGS, import_bag
from gtrig.io.rosbag.topics import list_topics, load_topics, topics_template
from gtrig.io.scans import ScanLog, write_scans
from gtrig.rig.load import dump_rig
from gtrig.sim.gtroom import make_scene


@pytest.fixture(scope="module")
def rig():  # type: ignore[no-untyped-def]
    return make_scene(0).rig_true


@pytest.fixture(scope="module")
def rec(tmp_path_factory: pytest.TempPathFactory, rig) -> Path:  # type: ignore[no-untyped-def]
    """A small recording in the layout: 2 cameras x 3 frames, every fixed scanner, one onboard
    scanner, odometry whose heading runs past pi."""
    root = tmp_path_factory.mktemp("rec")
    dump_rig(rig, root / "rig.yaml")
    rng = np.random.default_rng(7)
    run = root / "run"
    for k, cam in enumerate(rig.cameras[:2]):
        folder = run / "cameras" / cam.name
        folder.mkdir(parents=True)
        w, h = cam.resolution
        names = []
        for i in range(3):
            img = cv2.GaussianBlur(rng.integers(0, 256, (h, w), dtype=np.uint8), (0, 0), 1.5)
            names.append(f"{i:06d}.png")
            cv2.imwrite(str(folder / names[-1]), img)
        write_frame_index(folder, 1.7e9 + 0.1 * np.arange(3) + 0.003 * k, names)
    for sc in rig.laser_scanners:
        r = np.round(rng.uniform(0.2, sc.range_max_m - 0.1, (20, sc.beams)) * 1e4) / 1e4
        r[rng.random(r.shape) < 0.1] = np.nan
        write_scans(run / "lasers" / f"{sc.name}.csv", ScanLog(1.7e9 + np.arange(20) / sc.rate_hz, r))
    ob = rig.robot.onboard_scanners[0]
    r = np.round(rng.uniform(0.2, 20, (10, ob.beams)) * 1e4) / 1e4
    write_scans(run / "onboard" / f"{ob.name}.csv", ScanLog(1.7e9 + 0.05 * np.arange(10), r))
    n = 30
    th = np.linspace(0, 4.5, n)  # past pi: the layout's theta is continuous
    xy = np.round(rng.uniform(-3, 3, (n, 2)) * 1e9) / 1e9
    write_odometry_csv(run / "odometry.csv", OdometryLog(1.7e9 + 0.02 * np.arange(n), np.column_stack([xy, th]),
                                                         rng.uniform(0, 1, n), rng.uniform(-1, 1, n)))
    return root


def _same_recording(a: Path, b: Path) -> None:
    for f in sorted((a / "run").rglob("*")):
        if not f.is_file():
            continue
        g = b / f.relative_to(a)
        assert g.is_file(), f"{g} missing"
        if f.suffix == ".png":
            np.testing.assert_array_equal(cv2.imread(str(g), cv2.IMREAD_UNCHANGED),
                                          cv2.imread(str(f), cv2.IMREAD_UNCHANGED))
        else:
            assert g.read_bytes() == f.read_bytes(), f"{f.relative_to(a)} differs"


@pytest.mark.parametrize("name,ver", [("rec.bag", 1), ("rec_db3", 2)])  # MCAP: the CLI test
def test_recording_through_a_bag_gives_the_same_files(tmp_path: Path, rec: Path, name: str, ver: int) -> None:
    topics = export_recording(rec, tmp_path / name, ver)
    assert set(topics["cameras"]) == {"cam0", "cam1"} and topics["odometry"] == "/odom"
    out = tmp_path / "imported"
    rep = import_bag(tmp_path / name, topics, out, rig_path=rec / "rig.yaml", image_format="png")
    assert rep.counts["camera cam0"] == 3 and rep.counts["odometry odometry"] == 30
    _same_recording(rec, out)
    # both clocks are kept for a sync check
    stamps = (out / "run/stamps/laser-laser0.csv").read_text().splitlines()
    assert stamps[0] == "index,header_s,receive_s" and len(stamps) == 21
    assert not [p for p in out.iterdir() if p.name.startswith(".")]  # no temporary left behind


def test_video_import_decodes_to_the_same_frames(tmp_path: Path, rec: Path) -> None:
    topics = export_recording(rec, tmp_path / "v.bag", 1)
    out = tmp_path / "vid"
    import_bag(tmp_path / "v.bag", topics, out, rig_path=rec / "rig.yaml", video=True)
    idx = read_frame_index(out / "run/cameras/cam1")
    assert idx.video is not None and idx.video.name == "video.mkv"
    orig = read_frame_index(rec / "run/cameras/cam1")
    np.testing.assert_allclose(idx.stamps_s, orig.stamps_s, atol=1e-6)
    for i in (2, 0, 1):  # out of order: the decoder seeks back
        np.testing.assert_array_equal(idx.read(i), orig.read(i))
    # a frame count that disagrees with timestamps.csv is refused
    write_frame_index(out / "run/cameras/cam1", np.arange(4) * 0.1, [""] * 4)
    with pytest.raises(FormatError, match="video.mkv: 3 frames, but .* stamps 4"):
        read_frame_index(out / "run/cameras/cam1")


def test_real_odometry_imports_into_odometry_csv(tmp_path: Path, shared_dir: Path, rig) -> None:  # type: ignore[no-untyped-def]
    from rosbags.highlevel import AnyReader

    bag = shared_dir / "data/rosbags/nav2_turtlebot.mcap"
    dump_rig(rig, tmp_path / "rig.yaml")
    rep = import_bag(bag, {"odometry": "/odom", "trajectories": {"amcl": "/amcl_pose"}}, tmp_path / "r",
                     rig_path=tmp_path / "rig.yaml")
    odo = read_odometry(tmp_path / "r/run/odometry.csv")
    with AnyReader([bag]) as r:
        msgs = [r.deserialize(raw, c.msgtype) for c, _, raw in r.messages([c for c in r.connections
                                                                          if c.topic == "/odom"])]
    assert len(odo) == len(msgs) == rep.counts["odometry odometry"] == 2639
    yaw = np.array([np.arctan2(2 * (m.pose.pose.orientation.w * m.pose.pose.orientation.z),
                               1 - 2 * m.pose.pose.orientation.z ** 2) for m in msgs])
    np.testing.assert_allclose(odo.xytheta[:, 0], [m.pose.pose.position.x for m in msgs], atol=5e-10)
    np.testing.assert_allclose(np.angle(np.exp(1j * (odo.xytheta[:, 2] - yaw))), 0, atol=1e-6)
    assert np.all(np.abs(np.diff(odo.xytheta[:, 2])) < np.pi)  # unwrapped
    np.testing.assert_allclose(odo.v_mps, [m.twist.twist.linear.x for m in msgs], atol=5e-10)
    np.testing.assert_allclose(odo.omega_radps, [m.twist.twist.angular.z for m in msgs], atol=5e-10)
    np.testing.assert_allclose(odo.stamps_s, [m.header.stamp.sec + m.header.stamp.nanosec * 1e-9 for m in msgs],
                               atol=1e-9)
    from gtrig.io.formats import read_trajectory

    amcl = read_trajectory(tmp_path / "r/run/trajectories/amcl.tum")
    assert len(amcl) == 135 and amcl.cov is not None and amcl.cov_kind == "se3"


def test_list_and_template(shared_dir: Path, rig, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    s = {t.topic: t for t in list_topics(shared_dir / "data/rosbags/nav2_turtlebot.mcap")}
    assert s["/odom"].count == 2639 and s["/odom"].msgtype == "nav_msgs/msg/Odometry"
    assert 20 < s["/odom"].rate_hz < 35
    text = topics_template(list(s.values()), rig)
    (tmp_path / "t.yaml").write_text(text)
    cfg = load_topics(tmp_path / "t.yaml")  # the template itself loads
    assert cfg.odometry == "/odom" and cfg.trajectories["amcl_pose"] == "/amcl_pose"


def _bad_bag(path: Path, ver: int, kind: str, rig) -> dict:  # type: ignore[no-untyped-def]
    sc = rig.laser_scanners[0]
    with BagWriter(path, ver) as w:
        T = w.ts.types
        for i, t in enumerate([10.0, 10.1, 10.05] if kind == "backwards" else [10.0, 10.1]):
            if kind in ("beams", "angle", "backwards"):
                beams = sc.beams - (1 if kind == "beams" else 0)
                amin = sc.angle_min_rad + (0.01 if kind == "angle" else 0.0)
                w.write("/scan", 20.0 + i, T["sensor_msgs/msg/LaserScan"](
                    header=header(w.ts, ver, t, "l", i), angle_min=amin,
                    angle_max=amin + beams * sc.angle_increment_rad, angle_increment=sc.angle_increment_rad,
                    time_increment=0.0, scan_time=0.01, range_min=0.0, range_max=30.0,
                    ranges=np.ones(beams, np.float32), intensities=np.zeros(0, np.float32)))
            else:
                w.write("/img", 20.0 + i, T["sensor_msgs/msg/Image"](
                    header=header(w.ts, ver, t, "c", i), height=768, width=1024, encoding="mono16",
                    is_bigendian=0, step=2048, data=np.zeros(2048 * 768, np.uint8)))
    if kind == "encoding":
        return {"cameras": {rig.cameras[0].name: "/img"}}
    return {"lasers": {sc.name: "/scan"}}


@pytest.mark.parametrize("kind,exc,fragment", [
    ("beams", InputError, "has 179 beams, the rig's laser0 has 180"),
    ("angle", InputError, "angle_min"),
    ("encoding", InputError, "encoding 'mono16' is not supported \\(supported: mono8"),
    ("backwards", FormatError, "header stamps do not increase at message 3"),
])
def test_bad_bags_refused_and_nothing_written(tmp_path: Path, rig, kind: str, exc: type,  # type: ignore[no-untyped-def]
                                              fragment: str) -> None:
    topics = _bad_bag(tmp_path / "b.bag", 1, kind, rig)
    dump_rig(rig, tmp_path / "rig.yaml")
    out = tmp_path / "out"
    with pytest.raises(exc, match=fragment) as e:
        import_bag(tmp_path / "b.bag", topics, out, rig_path=tmp_path / "rig.yaml")
    assert "\n" not in str(e.value)
    assert not out.exists()  # nothing half-written, not even the folder
    assert "mono8" in IMAGE_ENCODINGS


def test_cli_errors_one_line_exit_2(tmp_path: Path, rec: Path, shared_dir: Path) -> None:
    runner = CliRunner()
    (tmp_path / "notabag.bag").write_text("hello\n")
    (tmp_path / "t.yaml").write_text("cameras:\n  cam0: /nope\n")
    cases = [
        (["import", "rosbag", str(tmp_path / "notabag.bag"), "--list"], "not a readable ROS 1 or ROS 2 bag"),
        (["import", "rosbag", str(shared_dir / "data/rosbags/ROS_example.bag"), "--topics", str(tmp_path / "t.yaml"),
          "--out", str(tmp_path / "o"), "--rig", str(rec / "rig.yaml")], "no topic /nope"),
        (["export", str(shared_dir / "data/rosbags/ROS_example.bag"), "--topic", "groundtruth", "--to", "kitti",
          "--out", str(rec / "rig.yaml")], "exists; refusing to overwrite it (use --force)"),
        (["export", str(rec), "--to", "kitti", "--out", str(tmp_path / "x.kitti")], "exports to rosbag1 or rosbag2"),
    ]
    for args, fragment in cases:
        r = runner.invoke(app, args)
        assert r.exit_code == 2, (args, r.output)
        lines = [ln for ln in r.output.splitlines() if ln.strip()]
        assert len(lines) == 1 and fragment in lines[0], r.output
    assert not (tmp_path / "o" / "run").exists()


def test_cli_export_and_import_round_trip(tmp_path: Path, rec: Path) -> None:
    r = CliRunner().invoke(app, ["export", str(rec), "--to", "rosbag2", "--out", str(tmp_path / "b.mcap")])
    assert r.exit_code == 0, r.output
    bag = str(tmp_path / "b.mcap")
    r = CliRunner().invoke(app, ["import", "rosbag", bag, "--list", "--rig", str(rec / "rig.yaml")])
    assert r.exit_code == 0, r.output
    yaml_text = r.output[r.output.index("# gtrig import rosbag"):]
    (tmp_path / "topics.yaml").write_text(yaml_text)
    r = CliRunner().invoke(app, ["import", "rosbag", bag, "--topics", str(tmp_path / "topics.yaml"),
                                 "--out", str(tmp_path / "rec2"), "--rig", str(rec / "rig.yaml")])
    assert r.exit_code == 0, r.output
    # the default PGM frames: the same pixels under .pgm names
    for cam in ("cam0", "cam1"):
        a, b = read_frame_index(rec / "run/cameras" / cam), read_frame_index(tmp_path / "rec2/run/cameras" / cam)
        assert b.files[0].endswith(".pgm")
        np.testing.assert_array_equal(a.stamps_s, b.stamps_s)
        for i in range(len(a)):
            np.testing.assert_array_equal(a.read(i), b.read(i))
    for f in ("lasers/laser0.csv", "onboard/sick_front.csv", "odometry.csv"):
        assert (rec / "run" / f).read_bytes() == (tmp_path / "rec2/run" / f).read_bytes()
    r = CliRunner().invoke(app, ["import", "rosbag", bag, "--topics", str(tmp_path / "topics.yaml"),
                                 "--out", str(tmp_path / "rec2")])
    assert r.exit_code == 2 and "exists; refusing" in r.output
