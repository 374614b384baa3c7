"""Trajectories in ROS bags: read from pose, odometry, path and TF topics; written as
``geometry_msgs/PoseWithCovarianceStamped``, one ``nav_msgs/Path`` and TF.

Topics read (``topic``):

- ``geometry_msgs/PoseStamped``, ``PoseWithCovarianceStamped``, ``TransformStamped`` and
  ``nav_msgs/Odometry``: one pose per message, with the covariance where the message has one
  (gtrig.io.rosbag.covariance); ``PointStamped``: a position with the identity rotation (as evo);
- ``nav_msgs/Path``: the poses of the topic's last message (a path is republished whole);
- ``/tf:PARENT.CHILD`` (evo's TF trajectory id; any TF topic before the colon): the transform
  ``T_PARENT_CHILD`` through the TF tree (``/tf`` and ``/tf_static``), at the stamps of the chain's
  most frequent moving link, the other moving links interpolated (linear, slerp) between their
  messages; stamps outside another moving link's messages are dropped (tf2 would refuse to
  extrapolate).

Stamps are the header stamps (``stamp="header"``) or the bag's receive times (``"receive"``).
Messages with a stamp equal to the previous one are dropped (the first kept, with a warning); a
stamp going backwards is a :class:`~gtrig.errors.FormatError`.
"""

from __future__ import annotations

import contextlib
import logging
import os
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import Any, Literal

import numpy as np
from scipy.spatial.transform import Rotation, Slerp

from gtrig.errors import FormatError, InputError
from gtrig.io.rosbag import covariance as rcov
from gtrig.io.rosbag._bag import (
    BagWriter,
    RosVersion,
    Storage,
    deserialize,
    header_ns,
    open_bag,
    time_to_ns,
)
from gtrig.io.rosbag.topics import POSE_TYPES, list_topics
from gtrig.stamps import seconds_from_ns
from gtrig.trajectory import PoseTrack

log = logging.getLogger(__name__)

StampSource = Literal["header", "receive"]

TF_TYPE = "tf2_msgs/msg/TFMessage"


def split_tf_id(topic: str) -> tuple[str, str, str] | None:
    """``(tf_topic, parent, child)`` from ``/tf:PARENT.CHILD``, or ``None`` for a plain topic."""
    if ":" not in topic:
        return None
    tf_topic, frames = topic.split(":", 1)
    if "." not in frames:
        raise InputError(f"{topic}: a TF trajectory is named TOPIC:PARENT.CHILD (e.g. /tf:map.base_link)")
    parent, child = frames.split(".", 1)
    return tf_topic, parent.lstrip("/"), child.lstrip("/")


def _pose_of(msg: Any) -> tuple[list[float], list[float], np.ndarray | None]:
    """(xyz, quat_xyzw, covariance (36,) or None) of one message."""
    if hasattr(msg, "transform"):
        t, r = msg.transform.translation, msg.transform.rotation
        return [t.x, t.y, t.z], [r.x, r.y, r.z, r.w], None
    if hasattr(msg, "point"):  # PointStamped: a position only; the identity rotation, as evo reads it
        return [msg.point.x, msg.point.y, msg.point.z], [0.0, 0.0, 0.0, 1.0], None
    pose, cov = msg.pose, None
    if hasattr(pose, "covariance"):  # PoseWithCovariance (in PoseWithCovarianceStamped and Odometry)
        cov = np.asarray(pose.covariance, dtype=float)
        pose = pose.pose
    p, q = pose.position, pose.orientation
    return [p.x, p.y, p.z], [q.x, q.y, q.z, q.w], cov


def _monotonic(stamps_ns: np.ndarray, where: str) -> np.ndarray:
    """Indices to keep: equal stamps dropped (warned), backwards an error."""
    d = np.diff(stamps_ns)
    back = np.flatnonzero(d < 0)
    if back.size:
        from gtrig.stamps import format_seconds

        i = int(back[0]) + 1
        a, b = format_seconds(stamps_ns[i - 1:i + 1], 9)
        raise FormatError(f"{where}: stamps go backwards at message {i + 1} ({a} then {b})")
    keep = np.concatenate([[True], d > 0]) if len(stamps_ns) else np.zeros(0, bool)
    if not np.all(keep):
        log.warning("%s: %d messages repeat the previous stamp (the first of each kept)", where,
                    int(np.sum(~keep)))
    return np.flatnonzero(keep)


def _make_track(stamps_ns: np.ndarray, xyz: np.ndarray, quat: np.ndarray, covs: np.ndarray | None, where: str,
                frame_id: str, child_frame_id: str, source: str) -> PoseTrack:
    keep = _monotonic(stamps_ns, where)
    q = quat[keep]
    n = np.linalg.norm(q, axis=1)
    if np.any(np.abs(n - 1) > 1e-3):
        raise FormatError(f"{where}: message {int(keep[np.argmax(np.abs(n - 1) > 1e-3)]) + 1} has a quaternion "
                          f"of norm {n[np.argmax(np.abs(n - 1) > 1e-3)]:.4f}, not a rotation")
    q = np.where(np.abs(n - 1)[:, None] > 1e-12, q / n[:, None], q)
    q[q[:, 3] < 0] *= -1
    cov, kind = rcov.from_ros(covs[keep]) if covs is not None else (None, "se3")
    ns = stamps_ns[keep]
    return PoseTrack(seconds_from_ns(ns), xyz[keep], q, cov, kind, source=source, frame_id=frame_id or "world",
                     child_frame_id=child_frame_id or "base_link", stamps_ns=ns)


def read_bag_trajectory(bag: str | os.PathLike[str] | Sequence[str | os.PathLike[str]], topic: str,
                        stamp: StampSource = "header", child_frame_id: str | None = None) -> PoseTrack:
    """The trajectory on ``topic`` (see the module docstring) as a :class:`PoseTrack`.

    Parameters
    ----------
    bag : a ROS 1 ``.bag`` (or several, read as one), a ROS 2 bag folder or a ``.mcap`` file.
    topic : a pose topic or ``/tf:PARENT.CHILD``.
    stamp : ``"header"`` (the message's stamp) or ``"receive"`` (the bag's record time).
    child_frame_id : the body frame's name when the message does not say (PoseStamped); default
        ``base_link``.
    """
    if stamp not in ("header", "receive"):
        raise InputError(f"stamp must be 'header' or 'receive', got {stamp!r}")
    tf = split_tf_id(topic)
    with open_bag(bag) as reader:
        name = f"{reader.paths[0]}:{topic}"
        if tf is not None:
            return _read_tf(reader, tf, stamp, name)
        conns = [c for c in reader.connections if c.topic == topic]
        if not conns:
            raise InputError(f"{reader.paths[0]}: no topic {topic} (topics: "
                             f"{', '.join(sorted({c.topic for c in reader.connections}))})")
        msgtype = conns[0].msgtype
        if msgtype not in POSE_TYPES:
            raise InputError(f"{name}: a {msgtype} is not a trajectory (readable: {', '.join(POSE_TYPES)}, "
                             "or TF as /tf:PARENT.CHILD)")
        stamps, xyz, quat, covs = [], [], [], []
        frame, child = "", child_frame_id or ""
        last_path = None
        for conn, t_ns, raw in reader.messages(conns):
            msg = deserialize(reader, raw, conn.msgtype, name)
            if msgtype == "nav_msgs/msg/Path":
                last_path = (msg, t_ns)
                continue
            with _standard_fields(name, conn.msgtype):
                stamps.append(time_to_ns(msg.header.stamp) if stamp == "header" else int(t_ns))
                p, q, c = _pose_of(msg)
                frame = frame or str(msg.header.frame_id)
            xyz.append(p)
            quat.append(q)
            covs.append(c)
            if not child:
                child = str(getattr(msg, "child_frame_id", ""))
        if last_path is not None:
            msg, t_ns = last_path
            with _standard_fields(name, msgtype):
                frame = str(msg.header.frame_id)
                for ps in msg.poses:
                    # a path's poses carry their own stamps; the receive time is the path's
                    stamps.append(time_to_ns(ps.header.stamp) if stamp == "header" else int(t_ns))
                    p, q, _ = _pose_of(ps)
                    xyz.append(p)
                    quat.append(q)
                    covs.append(None)
        if not stamps:
            raise InputError(f"{name}: no messages")
        if not child:
            child = _child_from_tf(bag, frame.lstrip("/"))
        cov_arr = np.array(covs, float) if all(c is not None for c in covs) else None
        return _make_track(np.array(stamps, np.int64), np.array(xyz, float), np.array(quat, float), cov_arr, name,
                           frame, child, topic)


def _child_from_tf(bag: str | os.PathLike[str] | Sequence[str | os.PathLike[str]], frame: str) -> str:
    """The body frame of a pose message that names none (PoseStamped, PoseWithCovarianceStamped): the one
    child the bag's TF moves under ``frame`` (a bag gtrig wrote publishes ``world -> robot``), else ``""``."""
    from gtrig.io.rosbag.tf_tree import tf_edges

    children = {e.child for e in tf_edges(bag, max_messages=200) if e.parent == frame and not e.static}
    return children.pop() if len(children) == 1 else ""


def trajectory_choices(bag: str | os.PathLike[str] | Sequence[str | os.PathLike[str]]) -> list[tuple[str, str]]:
    """``(topic, what)`` for every trajectory ``bag`` offers: its pose topics (type, message count) and the TF
    chains gtrig.io.rosbag.tf_tree proposes."""
    from gtrig.io.rosbag.tf_tree import propose_tf_trajectories, tf_edges

    out = [(s.topic, f"{s.msgtype.replace('/msg/', '/')}, {s.count}") for s in list_topics(bag)
           if s.msgtype in POSE_TYPES]
    return out + [(t, "TF chain") for t in propose_tf_trajectories(tf_edges(bag))]


def choose_topic(bag: str | os.PathLike[str] | Sequence[str | os.PathLike[str]]) -> str:
    """The trajectory to read when none is named: gtrig's own ``/gtrig/pose`` (with its covariance), or the
    bag's only trajectory; else an InputError that lists them."""
    choices = trajectory_choices(bag)
    topics = [t for t, _ in choices]
    if "/gtrig/pose" in topics:
        return "/gtrig/pose"
    if len(choices) == 1:
        return topics[0]
    first = bag if isinstance(bag, (str, os.PathLike)) else bag[0]
    if not choices:
        raise InputError(f"{first}: no trajectory in the bag (no pose, odometry, path or TF topic)")
    raise InputError(f"{first}: {len(choices)} trajectories; choose one with --topic: "
                     + "; ".join(f"{t} ({w})" for t, w in choices))


@contextlib.contextmanager
def _standard_fields(name: str, msgtype: str) -> Iterator[None]:
    """Reads of a deserialized message's fields: a bag embeds its own message definitions, and one
    that is not the standard type's (a field missing, renamed or of another type) is one refusal
    naming the topic, wherever the first field it lacks is read."""
    try:
        yield
    except (AttributeError, TypeError):
        raise FormatError(f"{name}: the bag's definition of {msgtype} is not the standard one "
                          "(a field is missing or renamed)") from None


def _read_tf(reader: Any, tf: tuple[str, str, str], stamp: StampSource, name: str) -> PoseTrack:
    """A TF chain's trajectory (see the module docstring)."""
    tf_topic, parent, child = tf
    topics = {tf_topic, "/tf_static"}
    conns = [c for c in reader.connections if c.topic in topics]
    if not any(c.topic == tf_topic for c in conns):
        raise InputError(f"{reader.paths[0]}: no topic {tf_topic}")
    # edges[child] = (parent, static, [stamps in integer ns], [xyz], [quat])
    edges: dict[str, tuple[str, bool, list[int], list[list[float]], list[list[float]]]] = {}
    for conn, t_ns, raw in reader.messages(conns):
        if conn.msgtype != TF_TYPE:
            raise InputError(f"{reader.paths[0]}:{conn.topic}: a {conn.msgtype}, not a {TF_TYPE}")
        msg = deserialize(reader, raw, conn.msgtype, f"{reader.paths[0]}:{conn.topic}")
        static = conn.topic == "/tf_static" and tf_topic != "/tf_static"
        with _standard_fields(f"{reader.paths[0]}:{conn.topic}", conn.msgtype):
            for ts in msg.transforms:
                c, p = ts.child_frame_id.lstrip("/"), ts.header.frame_id.lstrip("/")
                e = edges.setdefault(c, (p, static, [], [], []))
                if e[0] != p:
                    raise FormatError(f"{reader.paths[0]}:{conn.topic}: frame {c} has two parents, {e[0]} and {p}")
                xyz, q, _ = _pose_of(ts)
                e[2].append(time_to_ns(ts.header.stamp) if stamp == "header" else int(t_ns))
                e[3].append(xyz)
                e[4].append(q)

    def up(frame: str) -> list[str]:
        chain = [frame]
        while chain[-1] in edges:
            chain.append(edges[chain[-1]][0])
            if len(chain) > len(edges) + 1:
                raise FormatError(f"{reader.paths[0]}: the TF tree has a loop through {frame}")
        return chain

    a, b = up(child), up(parent)
    common = next((f for f in a if f in b), None)
    if common is None:
        known = sorted(set(edges) | {e[0] for e in edges.values()})
        raise InputError(f"{name}: no TF chain from {parent} to {child} (frames: {', '.join(known)})")
    # T_parent_child = inv(T_common_parent) @ T_common_child; each edge is T_edgeparent_edgechild
    down_child = a[:a.index(common)]  # child ... (frames below common)
    down_parent = b[:b.index(common)]
    moving = [f for f in down_child + down_parent if not edges[f][1]]
    series = {f: _edge_series(edges[f], f, name) for f in down_child + down_parent}
    if moving:
        lead = max(moving, key=lambda f: len(series[f][0]))
        stamps = series[lead][0]
        inside = np.ones(len(stamps), bool)
        for f in moving:
            st = series[f][0]
            inside &= (stamps >= st[0]) & (stamps <= st[-1])
        stamps = stamps[inside]
    else:
        stamps = np.array([series[f][0][-1] for f in down_child + down_parent][:1] or [0], np.int64)
    if not len(stamps):
        raise InputError(f"{name}: the moving links of the chain {parent} -> {child} never overlap in time")

    if down_child == [child] and not down_parent and not edges[child][1]:
        # one moving link: its messages as published (a matrix round trip would cost 1e-16)
        st1, xyz1, q1 = series[child]
        return _make_track(st1, xyz1, q1, None, name, parent, child, f"{tf_topic}:{parent}.{child}")

    def chain_T(frames: list[str]) -> np.ndarray:
        T = np.tile(np.eye(4), (len(stamps), 1, 1))
        for f in frames:  # child-most first: T_common_x = T_edge(k) ... T_edge(0)
            T = _edge_at(series[f], edges[f][1], stamps) @ T
        return T

    T = np.linalg.inv(chain_T(down_parent)) @ chain_T(down_child)
    q = Rotation.from_matrix(T[:, :3, :3]).as_quat()
    return _make_track(stamps, T[:, :3, 3], q, None, name, parent, child, f"{tf_topic}:{parent}.{child}")


def _edge_series(e: tuple[str, bool, list[int], list[list[float]], list[list[float]]], frame: str,
                 name: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(stamps (n,) int64 ns, xyz (n, 3), quat_xyzw (n, 4)) of one TF edge, sorted, repeats dropped."""
    st = np.array(e[2], np.int64)
    xyz = np.array(e[3], float)
    q = np.array(e[4], float)
    order = np.argsort(st, kind="stable")  # several publishers interleave on /tf: sort, then dedupe
    st, xyz, q = st[order], xyz[order], q[order]
    keep = np.concatenate([[True], np.diff(st) > 0])
    q = q[keep]
    n = np.linalg.norm(q, axis=1)[:, None]
    return st[keep], xyz[keep], np.where(np.abs(n - 1) > 1e-12, q / n, q)


def _edge_at(s: tuple[np.ndarray, np.ndarray, np.ndarray], static: bool, stamps_ns: np.ndarray) -> np.ndarray:
    """(n, 4, 4) the edge at ``stamps_ns`` (int64): its message at an equal stamp, else interpolated."""
    st_ns, xyz, q = s
    T = np.tile(np.eye(4), (len(stamps_ns), 1, 1))
    if static or len(st_ns) == 1:
        T[:, :3, :3] = Rotation.from_quat(q[-1]).as_matrix()
        T[:, :3, 3] = xyz[-1]
        return T
    exact = np.searchsorted(st_ns, stamps_ns)
    hit = (exact < len(st_ns)) & (st_ns[np.minimum(exact, len(st_ns) - 1)] == stamps_ns)
    # seconds from the first message: float64 keeps nanoseconds over a few months
    st = (st_ns - st_ns[0]).astype(float) * 1e-9
    t = (stamps_ns - st_ns[0]).astype(float) * 1e-9
    rot = Slerp(st, Rotation.from_quat(q))(np.clip(t, st[0], st[-1])).as_matrix()
    pos = np.column_stack([np.interp(t, st, xyz[:, k]) for k in range(3)])
    # at a message's own stamp use it as published (slerp would round it by 1e-16)
    idx = np.minimum(exact, len(st_ns) - 1)[hit]
    rot[hit] = Rotation.from_quat(q[idx]).as_matrix()
    pos[hit] = xyz[idx]
    T[:, :3, :3] = rot
    T[:, :3, 3] = pos
    return T


def write_bag_trajectory(track: PoseTrack, path: str | os.PathLike[str], ros_version: RosVersion = 2, *,
                         storage: Storage = "sqlite3", force: bool = False, frame_id: str | None = None,
                         child_frame_id: str | None = None, topic: str = "/gtrig/pose",
                         path_topic: str | None = "/gtrig/path", tf_topic: str | None = "/tf") -> list[Path]:
    """Write ``track`` into a new bag: ``topic`` (PoseWithCovarianceStamped, one per pose, covariance
    by gtrig.io.rosbag.covariance), ``path_topic`` (one nav_msgs/Path of every pose, at the last stamp)
    and ``tf_topic`` (TFMessage ``frame_id -> child_frame_id`` per pose). Stamps: header and receive
    time both the pose's. ``None`` leaves a topic out. All or none; returns ``[path]``."""
    frame = frame_id or track.frame_id
    child = child_frame_id or track.child_frame_id
    C = rcov.to_ros(track)
    with BagWriter(path, ros_version, storage, force) as w:
        T = w.ts.types
        poses = []
        stamps_ns = track.integer_stamps_ns()
        for i in range(len(track)):
            t = int(stamps_ns[i])
            h = header_ns(w.ts, ros_version, t, frame, seq=i)
            x, y, z = (float(v) for v in track.xyz[i])
            qx, qy, qz, qw = (float(v) for v in track.quat_xyzw[i])
            pose = T["geometry_msgs/msg/Pose"](position=T["geometry_msgs/msg/Point"](x=x, y=y, z=z),
                                               orientation=T["geometry_msgs/msg/Quaternion"](x=qx, y=qy, z=qz, w=qw))
            w.write_ns(topic, t, T["geometry_msgs/msg/PoseWithCovarianceStamped"](
                header=h, pose=T["geometry_msgs/msg/PoseWithCovariance"](pose=pose, covariance=C[i].copy())))
            if path_topic:
                poses.append(T["geometry_msgs/msg/PoseStamped"](header=h, pose=pose))
            if tf_topic:
                tr = T["geometry_msgs/msg/Transform"](
                    translation=T["geometry_msgs/msg/Vector3"](x=x, y=y, z=z),
                    rotation=T["geometry_msgs/msg/Quaternion"](x=qx, y=qy, z=qz, w=qw))
                w.write_ns(tf_topic, t, T["tf2_msgs/msg/TFMessage"](transforms=[
                    T["geometry_msgs/msg/TransformStamped"](header=h, child_frame_id=child, transform=tr)]))
        if path_topic and len(track):
            t_last = int(stamps_ns[-1])
            w.write_ns(path_topic, t_last, T["nav_msgs/msg/Path"](
                header=header_ns(w.ts, ros_version, t_last, frame), poses=poses))
    return [Path(path)]
