"""What a bag holds, and the topics.yaml that maps its topics to a rig's sensors.

topics.yaml (``gtrig import rosbag --topics``)::

    sequence: run          # the recording sequence to fill: run, validation or background
    stamp: header          # header (the message's stamp) or receive (the bag's record time)
    cameras:               # rig camera name: sensor_msgs/Image or CompressedImage topic
      cam0: /cam0/image_raw
    lasers:                # rig fixed scanner name: sensor_msgs/LaserScan topic
      laser0: /laser0/scan
    onboard:               # rig onboard scanner name: sensor_msgs/LaserScan topic
      sick_front: /onboard/sick_front/scan
    odometry: /odom        # nav_msgs/Odometry
    trajectories:          # a name: a pose topic or /tf:PARENT.CHILD (gtrig.io.rosbag.trajectory)
      amcl: /amcl_pose
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, Literal

import yaml
from pydantic import BaseModel, ConfigDict, Field, ValidationError

from gtrig.errors import ConfigError
from gtrig.io.rosbag._bag import open_bag
from gtrig.io.text import read_text
from gtrig.io.yamlfile import safe_load

IMAGE_TYPES = ("sensor_msgs/msg/Image", "sensor_msgs/msg/CompressedImage")
SCAN_TYPE = "sensor_msgs/msg/LaserScan"
ODOM_TYPE = "nav_msgs/msg/Odometry"
#: the messages a trajectory is read from
POSE_TYPES = ("geometry_msgs/msg/PoseStamped", "geometry_msgs/msg/PointStamped",
              "geometry_msgs/msg/PoseWithCovarianceStamped", "geometry_msgs/msg/TransformStamped",
              "nav_msgs/msg/Odometry", "nav_msgs/msg/Path")


class TopicsConfig(BaseModel):
    """topics.yaml (see the module docstring)."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    sequence: Literal["run", "validation", "background"] = "run"
    stamp: Literal["header", "receive"] = "header"
    cameras: dict[str, str] = Field(default_factory=dict)
    lasers: dict[str, str] = Field(default_factory=dict)
    onboard: dict[str, str] = Field(default_factory=dict)
    odometry: str | None = None
    trajectories: dict[str, str] = Field(default_factory=dict)


def load_topics(path: str | os.PathLike[str] | dict[str, Any]) -> TopicsConfig:
    """Read and check topics.yaml (or a mapping); one-line :class:`ConfigError` naming the field."""
    where = "topics" if isinstance(path, dict) else str(path)
    if isinstance(path, dict):
        doc: Any = path
    else:
        try:
            doc = safe_load(read_text(path, "YAML file"))
        except FileNotFoundError:
            raise ConfigError(f"{path}: no such file") from None
        except yaml.YAMLError as e:
            mark = getattr(e, "problem_mark", None)
            line = f":{mark.line + 1}" if mark is not None else ""
            raise ConfigError(f"{path}{line}: not valid YAML") from None
    if not isinstance(doc, dict):
        raise ConfigError(f"{where}: expected a mapping (sequence, cameras, lasers, onboard, odometry, ...)")
    try:
        return TopicsConfig.model_validate(doc)
    except ValidationError as e:
        err = e.errors()[0]
        field = ".".join(str(x) for x in err["loc"])
        raise ConfigError(f"{where}: {field}: {err['msg']}") from None


@dataclass(frozen=True)
class TopicSummary:
    """One topic of a bag: its type, message count, mean rate (Hz) over the bag, and the bag's first and
    last receive times (s)."""

    topic: str
    msgtype: str
    count: int
    rate_hz: float
    first_s: float
    last_s: float


def list_topics(bag: str | os.PathLike[str] | Sequence[str | os.PathLike[str]]) -> list[TopicSummary]:
    """Every topic of ``bag`` with its type, count and mean rate over the bag's span, from the bag's
    index (no message is read: instant on a 100 GB bag)."""
    out = []
    with open_bag(bag) as r:
        by_topic: dict[str, list[Any]] = {}
        for c in r.connections:
            by_topic.setdefault(c.topic, []).append(c)
        first, last = r.start_time * 1e-9, r.end_time * 1e-9
        span = last - first
        for topic, conns in sorted(by_topic.items()):
            count = sum(int(c.msgcount) for c in conns)
            rate = (count - 1) / span if count > 1 and span > 0 else 0.0
            out.append(TopicSummary(topic, conns[0].msgtype, count, rate, first, last))
    return out


def topics_template(summaries: Sequence[TopicSummary], rig: Any = None, tf_trajectories: Sequence[str] = ()
                    ) -> str:
    """A topics.yaml to start from, valid as it is: every image, scan and odometry topic under a guessed
    sensor name (the rig's name when the topic contains it), the pose topics as trajectories, and the TF
    chains ``tf_trajectories`` (gtrig.io.rosbag.tf_tree.propose_tf_trajectories) as trajectories too."""

    def name_for(topic: str, names: Sequence[str], prefix: str, k: int) -> str:
        for n in names:
            if n and n in topic:
                return n
        return f"{prefix}{k}"

    cams = [c.name for c in rig.cameras] if rig is not None else []
    scs = [s.name for s in rig.laser_scanners] if rig is not None else []
    onb = [s.name for s in rig.robot.onboard_scanners] if rig is not None else []
    doc: dict[str, Any] = {"sequence": "run", "stamp": "header", "cameras": {}, "lasers": {}, "onboard": {},
                           "odometry": None, "trajectories": {}}
    for s in summaries:
        if s.msgtype in IMAGE_TYPES:
            doc["cameras"][name_for(s.topic, cams, "cam", len(doc["cameras"]))] = s.topic
        elif s.msgtype == SCAN_TYPE:
            onboard = any(n in s.topic for n in onb if n) or "onboard" in s.topic
            key = "onboard" if onboard else "lasers"
            doc[key][name_for(s.topic, onb if onboard else scs, "laser", len(doc[key]))] = s.topic
        elif s.msgtype == ODOM_TYPE and doc["odometry"] is None:
            doc["odometry"] = s.topic
        elif s.msgtype in POSE_TYPES and s.msgtype != ODOM_TYPE:
            doc["trajectories"][s.topic.strip("/").replace("/", "_") or "pose"] = s.topic
    for tf_id in tf_trajectories:
        parent, child = tf_id.split(":", 1)[1].split(".", 1)
        doc["trajectories"][f"tf_{parent}_{child}".replace("/", "_")] = tf_id
    lines = ["# gtrig import rosbag --topics: map the bag's topics to the rig's sensors (docs/interchange.md)"]
    text = yaml.safe_dump({k: v for k, v in doc.items() if v not in ({}, None)}, sort_keys=False)
    return "\n".join(lines) + "\n" + text
