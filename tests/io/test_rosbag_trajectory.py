"""Trajectories in bags: the real bags of evo's test data read as evo reads them, gtrig's bags read
back by rosbags and by evo with the same poses, covariances through ROS's 6 x 6, one-line errors."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from gtrig.errors import FormatError, InputError
from gtrig.io.formats import read_trajectory, write_trajectory
from gtrig.io.rosbag import read_bag_trajectory, write_bag_trajectory
from gtrig.io.rosbag.covariance import UNMEASURED_VAR, from_ros, to_ros
from gtrig.trajectory import PoseTrack

evo_fi = pytest.importorskip("evo.tools.file_interface")


def _evo_read(bag: Path, topic: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(stamps, xyz, quat_xyzw) as evo reads ``topic``."""
    if bag.suffix == ".bag":
        from rosbags.rosbag1 import Reader
    else:
        from rosbags.rosbag2 import Reader
    with Reader(bag) as r:
        t = evo_fi.read_bag_trajectory(r, topic)
    q = t.orientations_quat_wxyz[:, [1, 2, 3, 0]]
    return t.timestamps, t.positions_xyz, q


def _same_as_evo(track: PoseTrack, bag: Path, topic: str) -> None:
    st, xyz, q = _evo_read(bag, topic)
    assert len(track) == len(st)
    np.testing.assert_array_equal(track.stamps_s, st)
    np.testing.assert_array_equal(track.xyz, xyz)
    q = q * np.where(q[:, 3:] < 0, -1.0, 1.0)  # gtrig keeps w >= 0: the same rotation
    n = np.linalg.norm(q, axis=1, keepdims=True)
    # ORB-SLAM's quaternions are unit to 1e-7 only: gtrig normalises them (evo keeps them as published)
    q = np.where(np.abs(n - 1) > 1e-12, q / n, q)
    np.testing.assert_allclose(track.quat_xyzw, q, rtol=0, atol=2e-16)


@pytest.mark.parametrize("bag,topic", [
    ("ROS_example.bag", "groundtruth"),
    ("ROS_example.bag", "ORB-SLAM"),
    ("ROS_example.bag", "S-PTAM"),
    ("nav2_turtlebot.mcap", "/odom"),
    ("nav2_turtlebot.mcap", "/amcl_pose"),
])
def test_real_bags_read_as_evo_reads_them(shared_dir: Path, bag: str, topic: str) -> None:
    path = shared_dir / "data/rosbags" / bag
    track = read_trajectory(path, topic=topic)  # the front door: a bag by its name
    _same_as_evo(track, path, topic)


def test_amcl_covariance_survives_import_and_export(shared_dir: Path, tmp_path: Path) -> None:
    from rosbags.highlevel import AnyReader

    path = shared_dir / "data/rosbags/nav2_turtlebot.mcap"
    with AnyReader([path]) as r:
        conns = [c for c in r.connections if c.topic == "/amcl_pose"]
        published = np.array([r.deserialize(raw, c.msgtype).pose.covariance for c, _, raw in r.messages(conns)])
    track = read_bag_trajectory(path, "/amcl_pose")
    assert track.cov_kind == "se3" and np.any(published)
    np.testing.assert_array_equal(track.cov.reshape(-1, 36), published)
    for out, fmt in ((tmp_path / "amcl.bag", "rosbag1"), (tmp_path / "amcl_db3", "rosbag2"),
                     (tmp_path / "amcl.mcap", "rosbag2"), (tmp_path / "amcl.csv", "csv"),
                     (tmp_path / "amcl.tum", "gtrig")):
        write_trajectory(track, out, fmt)
        back = read_trajectory(out, fmt, **({"topic": "/gtrig/pose"} if fmt.startswith("rosbag") else {}))
        np.testing.assert_array_equal(back.cov.reshape(-1, 36), published)
        np.testing.assert_allclose(back.xyz, track.xyz, atol=1e-9)


def test_tf_ros1_and_ros2_bags_agree_and_match_the_messages(shared_dir: Path) -> None:
    from rosbags.highlevel import AnyReader

    d = shared_dir / "data/rosbags"
    one = read_bag_trajectory(d / "tf_example.bag", "/tf:odom.base_footprint")
    two = read_bag_trajectory(d / "tf_example", "/tf:odom.base_footprint")
    np.testing.assert_array_equal(one.stamps_s, two.stamps_s)
    np.testing.assert_array_equal(one.xyz, two.xyz)
    np.testing.assert_array_equal(one.quat_xyzw, two.quat_xyzw)
    # the one moving link: its messages exactly
    with AnyReader([d / "tf_example.bag"]) as r:
        msgs = [r.deserialize(raw, c.msgtype) for c, _, raw in r.messages([c for c in r.connections
                                                                          if c.topic == "/tf"])]
    tr = [t for m in msgs for t in m.transforms if t.child_frame_id == "base_footprint"]
    np.testing.assert_array_equal(one.xyz, [[t.transform.translation.x, t.transform.translation.y,
                                            t.transform.translation.z] for t in tr])
    # through the static link base_footprint -> base_link: composed with it
    chained = read_bag_trajectory(d / "tf_example.bag", "/tf:odom.base_link")
    static = [t for m in _static(d / "tf_example.bag") for t in m.transforms][0]
    T_fb = np.eye(4)
    T_fb[:3, :3] = Rotation.from_quat([static.transform.rotation.x, static.transform.rotation.y,
                                       static.transform.rotation.z, static.transform.rotation.w]).as_matrix()
    T_fb[:3, 3] = [static.transform.translation.x, static.transform.translation.y, static.transform.translation.z]
    np.testing.assert_allclose(chained.matrices(), one.matrices() @ T_fb, atol=1e-12)
    assert (chained.frame_id, chained.child_frame_id) == ("odom", "base_link")


def _static(bag: Path) -> list:
    from rosbags.highlevel import AnyReader

    with AnyReader([bag]) as r:
        return [r.deserialize(raw, c.msgtype) for c, _, raw in r.messages([c for c in r.connections
                                                                          if c.topic == "/tf_static"])]


def test_tf_chain_with_two_moving_links(shared_dir: Path) -> None:
    # map -> odom (AMCL, ~10 Hz, post-dated) then odom -> base_link (~27 Hz): at base_link's stamps,
    # with map -> odom interpolated between its messages (linear, slerp)
    from scipy.spatial.transform import Slerp

    path = shared_dir / "data/rosbags/nav2_turtlebot.mcap"
    full = read_bag_trajectory(path, "/tf:map.base_link")
    mo = read_bag_trajectory(path, "/tf:map.odom")
    ob = read_bag_trajectory(path, "/tf:odom.base_link")
    assert full.stamps_s[0] >= mo.stamps_s[0] and full.stamps_s[-1] <= mo.stamps_s[-1]
    assert len(full) > 0.9 * np.sum((ob.stamps_s >= mo.stamps_s[0]) & (ob.stamps_s <= mo.stamps_s[-1]))
    i_ob = np.searchsorted(ob.stamps_s, full.stamps_s)
    np.testing.assert_array_equal(ob.stamps_s[i_ob], full.stamps_s)
    T_mo = np.tile(np.eye(4), (len(full), 1, 1))
    T_mo[:, :3, :3] = Slerp(mo.stamps_s, Rotation.from_quat(mo.quat_xyzw))(full.stamps_s).as_matrix()
    T_mo[:, :3, 3] = np.column_stack([np.interp(full.stamps_s, mo.stamps_s, mo.xyz[:, k]) for k in range(3)])
    np.testing.assert_allclose(full.matrices(), T_mo @ ob.matrices()[i_ob], atol=1e-9)


def _track(n: int, cov_kind: str) -> PoseTrack:
    rng = np.random.default_rng(11)
    k = {"se3": 6, "xyyaw": 3, "xyz": 3}[cov_kind]
    A = rng.normal(0, 1e-2, (n, k, k))
    T = np.tile(np.eye(4), (n, 1, 1))
    T[:, :3, :3] = Rotation.random(n, random_state=2).as_matrix()
    T[:, :3, 3] = rng.normal(0, 3, (n, 3))
    return PoseTrack.from_matrices(1.7e9 + 0.1 * np.arange(n) + rng.uniform(0, 0.01, n), T,
                                   cov=A @ np.swapaxes(A, 1, 2), cov_kind=cov_kind, frame_id="map",
                                   child_frame_id="base_link")


@pytest.mark.parametrize("name,ver", [("t.bag", 1), ("t2", 2), ("t.mcap", 2)])
def test_written_bags_read_back_by_rosbags_and_evo(tmp_path: Path, name: str, ver: int) -> None:
    track = _track(30, "se3")
    bag = tmp_path / name
    write_bag_trajectory(track, bag, ver)
    _same_as_evo(read_bag_trajectory(bag, "/gtrig/pose"), bag, "/gtrig/pose")
    st, xyz, q = _evo_read(bag, "/gtrig/pose")
    # a Unix-time float stamp is written to the microsecond, as by every format (gtrig.stamps)
    np.testing.assert_allclose(st, track.stamps_s, rtol=0, atol=5e-7 + 2.4e-7)
    np.testing.assert_array_equal(xyz, track.xyz)
    np.testing.assert_array_equal(q, track.quat_xyzw)
    for topic in ("/gtrig/pose", "/gtrig/path", "/tf:map.base_link"):
        back = read_bag_trajectory(bag, topic)
        np.testing.assert_array_equal(back.xyz, track.xyz)
        np.testing.assert_array_equal(back.quat_xyzw, track.quat_xyzw)
        np.testing.assert_array_equal(back.integer_stamps_ns(), track.integer_stamps_ns())  # one stamp, one number
        assert (back.frame_id, back.child_frame_id) == ("map", "base_link")
    np.testing.assert_array_equal(read_bag_trajectory(bag, "/gtrig/pose").cov, track.cov)


@pytest.mark.parametrize("kind", ["xyyaw", "xyz"])
def test_planar_and_position_covariances_in_ros_layout(kind: str) -> None:
    track = _track(5, kind)
    C = to_ros(track).reshape(-1, 6, 6)
    idx = (0, 1, 5) if kind == "xyyaw" else (0, 1, 2)
    others = [i for i in range(6) if i not in idx]
    np.testing.assert_array_equal(C[:, np.array(idx)[:, None], np.array(idx)[None, :]], track.cov)
    assert np.all(C[:, others, others] == UNMEASURED_VAR)
    cov, back_kind = from_ros(C.reshape(-1, 36))
    assert back_kind == kind
    np.testing.assert_array_equal(cov, track.cov)
    assert from_ros(np.zeros((4, 36)))[0] is None


def test_bag_errors_are_one_line(tmp_path: Path, shared_dir: Path) -> None:
    fake = tmp_path / "fake.bag"
    fake.write_bytes(b"not a bag at all\n" * 10)
    with pytest.raises(FormatError, match="not a readable ROS 1 or ROS 2 bag") as e:
        read_bag_trajectory(fake, "/x")
    assert "\n" not in str(e.value)
    with pytest.raises(FormatError, match="no such bag"):
        read_bag_trajectory(tmp_path / "missing.bag", "/x")
    real = shared_dir / "data/rosbags/ROS_example.bag"
    with pytest.raises(InputError, match="no topic /nope"):
        read_bag_trajectory(real, "/nope")
    with pytest.raises(InputError, match="no TF chain from map to nowhere"):
        read_bag_trajectory(shared_dir / "data/rosbags/tf_example.bag", "/tf:map.nowhere")
    with pytest.raises(InputError, match="exists; refusing"):
        write_bag_trajectory(_track(3, "se3"), real, 1)


def test_stamps_going_backwards_refused(tmp_path: Path) -> None:
    track = _track(6, "se3")
    bag = tmp_path / "b.bag"
    write_bag_trajectory(track, bag, 1, path_topic=None, tf_topic=None)
    # the receive times increase; make the header stamps run backwards in a second bag
    from gtrig.io.rosbag._bag import BagWriter, header

    bad = tmp_path / "back.bag"
    with BagWriter(bad, 1) as w:
        T = w.ts.types
        for i, t in enumerate([10.0, 11.0, 10.5]):
            pose = T["geometry_msgs/msg/Pose"](position=T["geometry_msgs/msg/Point"](x=0.0, y=0.0, z=0.0),
                                               orientation=T["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0,
                                                                                             w=1.0))
            w.write("/p", 100.0 + i, T["geometry_msgs/msg/PoseStamped"](header=header(w.ts, 1, t, "map"), pose=pose))
    with pytest.raises(FormatError, match="stamps go backwards at message 3"):
        read_bag_trajectory(bad, "/p")
    assert len(read_bag_trajectory(bad, "/p", stamp="receive")) == 3


def test_failed_write_leaves_nothing(tmp_path: Path) -> None:
    track = _track(4, "se3")
    with pytest.raises(InputError):
        write_bag_trajectory(track, tmp_path / "x.bag", 2)  # a ROS 2 bag is not NAME.bag
    assert list(tmp_path.iterdir()) == []
