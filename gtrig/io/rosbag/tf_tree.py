"""The TF tree a bag holds, and the robot trajectories it offers (``/tf:PARENT.CHILD``).

:func:`tf_edges` reads the first TF messages of a bag (``/tf`` and ``/tf_static``) into the tree's edges;
:func:`propose_tf_trajectories` names the robot's body frame in it (the first of :data:`BODY_FRAMES`
present, else the child of the most published moving edge) and offers one trajectory from each frame above
it whose chain to the body moves (``map`` -> ``base_link`` and ``odom`` -> ``base_link`` for a Nav2 robot;
``world`` -> ``robot`` for a bag gtrig wrote).
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from dataclasses import dataclass

from gtrig.io.rosbag._bag import deserialize, open_bag

#: body frame names, most likely first (REP 105's, then gtrig's own)
BODY_FRAMES = ("base_link", "base_footprint", "robot", "base")
TF_TOPICS = ("/tf", "/tf_static")


@dataclass(frozen=True)
class TfEdge:
    """One transform of the tree: ``parent -> child``, how many messages carried it, static or not."""

    parent: str
    child: str
    count: int
    static: bool


def tf_edges(bag: str | os.PathLike[str] | Sequence[str | os.PathLike[str]], max_messages: int = 5000
             ) -> list[TfEdge]:
    """The edges of the TF tree in the first ``max_messages`` TF messages of ``bag`` (none without TF)."""
    seen: dict[tuple[str, str], list[int]] = {}
    with open_bag(bag) as r:
        conns = [c for c in r.connections if c.topic in TF_TOPICS and c.msgtype == "tf2_msgs/msg/TFMessage"]
        if not conns:
            return []
        for k, (conn, _, raw) in enumerate(r.messages(conns)):
            if k >= max_messages:
                break
            msg = deserialize(r, raw, conn.msgtype, f"{r.paths[0]}:{conn.topic}")
            for ts in msg.transforms:
                key = (str(ts.header.frame_id).lstrip("/"), str(ts.child_frame_id).lstrip("/"))
                entry = seen.setdefault(key, [0, 1])
                entry[0] += 1
                entry[1] &= int(conn.topic == "/tf_static")
    return [TfEdge(p, c, n, bool(s)) for (p, c), (n, s) in seen.items()]


def _body_frame(edges: list[TfEdge]) -> str | None:
    children = {e.child for e in edges}
    frames = children | {e.parent for e in edges}
    for name in BODY_FRAMES:
        if name in frames:
            return name
    moving = [e for e in edges if not e.static]
    return max(moving, key=lambda e: e.count).child if moving else None


def propose_tf_trajectories(edges: list[TfEdge]) -> list[str]:
    """``/tf:PARENT.BODY`` for each frame above the body frame whose chain to it holds a moving edge,
    the top of the tree first (module docstring)."""
    body = _body_frame(edges)
    if body is None:
        return []
    parent_of = {e.child: e for e in edges}
    out: list[str] = []
    frame, moving = body, False
    while frame in parent_of and len(out) <= len(edges):
        e = parent_of[frame]
        moving |= not e.static
        if moving:
            out.append(f"/tf:{e.parent}.{body}")
        frame = e.parent
    return out[::-1]
