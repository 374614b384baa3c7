"""A recording's sensor data (docs/formats.md) written into a ROS bag, as a ROS user would record it.

Per sequence (``run``, ``validation`` or ``background``):

- ``/<cam>/image_raw``: ``sensor_msgs/Image`` mono8, one per frame, header stamp = the frame's stamp,
  ``frame_id`` the camera's name;
- ``/<scanner>/scan`` (fixed) and ``/onboard/<scanner>/scan``: ``sensor_msgs/LaserScan`` with the rig's
  geometry (``angle_min``, ``angle_increment``, ``angle_max`` of the last beam, ``range_max``), no
  return as ``+inf`` (REP 117);
- ``/odom``: ``nav_msgs/Odometry`` (``odom`` -> ``base_link``; x, y, yaw; v along x; omega about z).

Receive time = header stamp. Returns the topics.yaml mapping that imports the bag back
(gtrig.io.rosbag.record_import).
"""

from __future__ import annotations

import os
from typing import Any

import numpy as np

from gtrig.io.frames import read_frame_index
from gtrig.io.odometry import read_odometry
from gtrig.io.recording import recording_dir
from gtrig.io.rosbag._bag import BagWriter, RosVersion, Storage, header
from gtrig.io.scans import read_scans
from gtrig.rig import load_rig


def _quat_z(theta: float) -> tuple[float, float, float, float]:
    return 0.0, 0.0, float(np.sin(theta / 2)), float(np.cos(theta / 2))


def export_recording(rec: str | os.PathLike[str], bag: str | os.PathLike[str], ros_version: RosVersion = 2, *,
                     sequence: str = "run", storage: Storage = "sqlite3", force: bool = False) -> dict[str, Any]:
    """Write ``rec``'s ``sequence`` (images, fixed and onboard scans, odometry) into a new bag.

    Messages are written in time order (a bag is read in receive-time order). Returns the topics.yaml
    mapping (``sequence``, ``cameras``, ``lasers``, ``onboard``, ``odometry``).
    """
    root = recording_dir(rec)
    rig = load_rig(root / "rig.yaml")
    seq = root / sequence
    events: list[tuple[float, int, str, Any]] = []  # (stamp, order, kind, payload)
    topics: dict[str, Any] = {"sequence": sequence, "stamp": "header", "cameras": {}, "lasers": {}, "onboard": {}}
    for cam in rig.cameras:
        folder = seq / "cameras" / cam.name
        if folder.is_dir():
            idx = read_frame_index(folder)
            topics["cameras"][cam.name] = f"/{cam.name}/image_raw"
            events += [(float(t), 0, "image", (cam.name, idx, i)) for i, t in enumerate(idx.stamps_s)]
    for group, scanners, sub, prefix in (("lasers", rig.laser_scanners, "lasers", ""),
                                         ("onboard", rig.robot.onboard_scanners, "onboard", "/onboard")):
        for sc in scanners:
            f = seq / sub / f"{sc.name}.csv"
            if f.is_file():
                log = read_scans(f, sc)
                topics[group][sc.name] = f"{prefix}/{sc.name}/scan"
                events += [(float(t), 1, "scan", (topics[group][sc.name], sc, log, i))
                           for i, t in enumerate(log.stamps_s)]
    odo_path = seq / "odometry.csv"
    if odo_path.is_file():
        odo = read_odometry(odo_path)
        topics["odometry"] = "/odom"
        events += [(float(t), 2, "odom", (odo, i)) for i, t in enumerate(odo.stamps_s)]
    events.sort(key=lambda e: (e[0], e[1]))
    with BagWriter(bag, ros_version, storage, force) as w:
        T = w.ts.types
        seqno: dict[str, int] = {}
        for t, _, kind, payload in events:
            if kind == "image":
                name, idx, i = payload
                img = idx.read(i)
                n = seqno[name] = seqno.get(name, -1) + 1
                w.write(topics["cameras"][name], t, T["sensor_msgs/msg/Image"](
                    header=header(w.ts, ros_version, t, name, n), height=img.shape[0], width=img.shape[1],
                    encoding="mono8", is_bigendian=0, step=img.shape[1],
                    data=np.ascontiguousarray(img, dtype=np.uint8).reshape(-1)))
            elif kind == "scan":
                topic, sc, log, i = payload
                r = np.asarray(log.ranges_m[i], dtype=np.float32)
                r = np.where(np.isnan(r), np.float32(np.inf), r)
                n = seqno[topic] = seqno.get(topic, -1) + 1
                w.write(topic, t, T["sensor_msgs/msg/LaserScan"](
                    header=header(w.ts, ros_version, t, sc.name, n), angle_min=sc.angle_min_rad,
                    angle_max=sc.angle_min_rad + (sc.beams - 1) * sc.angle_increment_rad,
                    angle_increment=sc.angle_increment_rad, time_increment=0.0,
                    scan_time=1.0 / sc.rate_hz, range_min=0.0, range_max=sc.range_max_m, ranges=r,
                    intensities=np.zeros(0, np.float32)))
            else:
                odo, i = payload
                x, y, th = (float(v) for v in odo.xytheta[i])
                qx, qy, qz, qw = _quat_z(th)
                n = seqno["/odom"] = seqno.get("/odom", -1) + 1
                pose = T["geometry_msgs/msg/PoseWithCovariance"](
                    pose=T["geometry_msgs/msg/Pose"](
                        position=T["geometry_msgs/msg/Point"](x=x, y=y, z=0.0),
                        orientation=T["geometry_msgs/msg/Quaternion"](x=qx, y=qy, z=qz, w=qw)),
                    covariance=np.zeros(36))
                V3 = T["geometry_msgs/msg/Vector3"]
                twist = T["geometry_msgs/msg/TwistWithCovariance"](
                    twist=T["geometry_msgs/msg/Twist"](linear=V3(x=float(odo.v_mps[i]), y=0.0, z=0.0),
                                                       angular=V3(x=0.0, y=0.0, z=float(odo.omega_radps[i]))),
                    covariance=np.zeros(36))
                w.write("/odom", t, T["nav_msgs/msg/Odometry"](header=header(w.ts, ros_version, t, "odom", n),
                                                              child_frame_id="base_link", pose=pose, twist=twist))
    return topics
