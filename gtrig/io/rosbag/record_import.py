"""A ROS bag into the recording layout of docs/formats.md (``gtrig import rosbag``).

topics.yaml (gtrig.io.rosbag.topics) says which topic is which of the rig's sensors. One pass over
the bag in receive-time order:

- ``sensor_msgs/Image`` (encodings :data:`IMAGE_ENCODINGS`; colour converted to grey as OpenCV's
  ``cvtColor`` does) into ``<seq>/cameras/<cam>/<frame>.pgm`` (or PNG, :data:`PNG_PARAMS`: ``image_format``),
  or into one lossless FFV1 ``video.mkv`` per camera (``video=True``); ``CompressedImage`` written as
  its own PNG/JPEG bytes. The frame size must be the rig's resolution (raw images).
- ``sensor_msgs/LaserScan`` into ``<seq>/lasers/<scanner>.csv`` (or ``onboard/``): ``angle_min``,
  ``angle_increment`` (to 1e-5 rad: the message holds float32) and the beam count checked against the
  rig; ranges below ``range_min``, above ``range_max`` or not finite written as no return (``nan``).
- ``nav_msgs/Odometry`` into ``<seq>/odometry.csv``: x, y, yaw (unwrapped: the layout's theta is
  continuous), ``twist.linear.x`` and ``twist.angular.z`` (the twist is in the child frame).
- trajectories (pose topics, TF) into ``<seq>/trajectories/<name>.tum`` + ``<name>_cov.csv``.

Stamps are the header stamps (``stamp="header"``) or the receive times; both are written to
``<seq>/stamps/<kind>-<name>.csv`` (``index,header_s,receive_s``) so that a clock check can compare
them. A stamp that does not increase within one topic is an error. The sequence is written into a
temporary folder and renamed into place at the end: nothing is left half-written.

Throughput (BENCHMARKS.md, "interchange"): images are encoded on a thread pool (OpenCV releases the
GIL), scans are decoded by rosbags and written by the scan CSV writer in one go.
"""

from __future__ import annotations

import contextlib
import logging
import os
import shutil
import tempfile
from collections.abc import Sequence
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

import cv2
import numpy as np

from gtrig.errors import FormatError, InputError
from gtrig.io.atomic import atomic_open
from gtrig.io.frames import write_frame_index
from gtrig.io.odometry import OdometryLog, write_odometry_csv
from gtrig.io.rosbag._bag import deserialize, ns_to_s, open_bag, time_to_s
from gtrig.io.rosbag.topics import IMAGE_TYPES, ODOM_TYPE, SCAN_TYPE, TopicsConfig, load_topics
from gtrig.io.scans import ScanLog, write_scans
from gtrig.rig import load_rig

log = logging.getLogger(__name__)

#: sensor_msgs/Image encodings read (8 bits per channel; colour becomes grey)
IMAGE_ENCODINGS = ("mono8", "8UC1", "bgr8", "rgb8", "bgra8", "rgba8", "8UC3")
_TO_GREY = {"bgr8": cv2.COLOR_BGR2GRAY, "8UC3": cv2.COLOR_BGR2GRAY, "rgb8": cv2.COLOR_RGB2GRAY,
            "bgra8": cv2.COLOR_BGRA2GRAY, "rgba8": cv2.COLOR_RGBA2GRAY}
_CHANNELS = {"mono8": 1, "8UC1": 1, "bgr8": 3, "rgb8": 3, "8UC3": 3, "bgra8": 4, "rgba8": 4}
ANGLE_TOL_RAD = 1e-5

ImageFormat = Literal["png", "pgm"]


@dataclass
class _Stream:
    kind: str  # "camera", "laser", "onboard", "odometry"
    name: str
    topic: str
    header_s: list[float] = field(default_factory=list)
    receive_s: list[float] = field(default_factory=list)
    rows: list[Any] = field(default_factory=list)
    raws: list[bytes] = field(default_factory=list)  # LaserScan messages, decoded in bulk at the end
    msgtype: str = ""
    files: list[str] = field(default_factory=list)
    sensor: Any = None
    writer: Any = None  # cv2.VideoWriter

    def stamp(self, which: str) -> list[float]:
        return self.header_s if which == "header" else self.receive_s


@dataclass(frozen=True)
class ImportReport:
    """What an import wrote: messages per stream, the sequence folder, the trajectories."""

    sequence_dir: Path
    counts: dict[str, int]
    trajectories: tuple[str, ...]


def _scans(s: _Stream, reader: Any, where: str) -> np.ndarray:
    """Decode a scan stream (its header stamps into ``s.header_s``), check every message's geometry
    against the rig, and return the (K, beams) ranges with no return as ``nan``."""
    from gtrig.io.rosbag.scan_decode import decode_scans

    b = decode_scans(s.raws, bool(reader.is2), lambda raw: deserialize(reader, raw, s.msgtype, where))
    s.raws = []
    s.header_s = b.stamps_s.tolist()
    sc = s.sensor
    bad = np.flatnonzero(b.beams != sc.beams)
    if bad.size:
        raise InputError(f"{where}: message {bad[0] + 1} has {b.beams[bad[0]]} beams, the rig's {sc.name} has "
                         f"{sc.beams}")
    amin, inc = b.geometry[:, 0].astype(float), b.geometry[:, 2].astype(float)
    bad = np.flatnonzero(np.abs(amin - sc.angle_min_rad) > ANGLE_TOL_RAD)
    if bad.size:
        raise InputError(f"{where}: message {bad[0] + 1}: angle_min {amin[bad[0]]:.6f} rad, the rig's {sc.name} "
                         f"has {sc.angle_min_rad:.6f}")
    bad = np.flatnonzero(np.abs(inc - sc.angle_increment_rad) > ANGLE_TOL_RAD / max(sc.beams, 1))
    if bad.size:
        raise InputError(f"{where}: message {bad[0] + 1}: angle_increment {inc[bad[0]]:.8f} rad, the rig's "
                         f"{sc.name} has {sc.angle_increment_rad:.8f}")
    r = b.ranges.astype(np.float64)
    rmin, rmax = b.geometry[:, 5:6].astype(float), b.geometry[:, 6:7].astype(float)
    with np.errstate(invalid="ignore"):
        r[~np.isfinite(r) | (r < rmin) | (r > rmax)] = np.nan
    return r


def _image(msg: Any, where: str, n: int) -> np.ndarray:
    enc = msg.encoding
    if enc not in _CHANNELS:
        raise InputError(f"{where}: image encoding {enc!r} is not supported (supported: {', '.join(IMAGE_ENCODINGS)})")
    ch = _CHANNELS[enc]
    row = int(msg.width) * ch
    data = np.frombuffer(msg.data, dtype=np.uint8)
    if int(msg.step) < row or data.size < int(msg.step) * int(msg.height):
        raise FormatError(f"{where}: message {n}: {data.size} bytes for a {msg.width}x{msg.height} {enc} image "
                          f"of step {msg.step}")
    img = data[: int(msg.step) * int(msg.height)].reshape(int(msg.height), int(msg.step))[:, :row]
    if ch == 1:
        return np.ascontiguousarray(img)
    return cv2.cvtColor(np.ascontiguousarray(img).reshape(int(msg.height), int(msg.width), ch), _TO_GREY[enc])


def _png_params() -> list[int]:
    """OpenCV's fastest lossless PNG that compresses: deflate level 1 with Huffman coding only (no string
    matching) over the SUB filter (each byte minus its left neighbour: what makes a camera image
    compressible). On 1024 x 768 camera frames it encodes about twice as fast as level 1 with OpenCV's
    adaptive filters, to files of about the same size (bench/interchange.py). The filter option exists
    from OpenCV 4.11."""
    params = [cv2.IMWRITE_PNG_COMPRESSION, 1, cv2.IMWRITE_PNG_STRATEGY, cv2.IMWRITE_PNG_STRATEGY_HUFFMAN_ONLY]
    if hasattr(cv2, "IMWRITE_PNG_FILTER"):
        params += [cv2.IMWRITE_PNG_FILTER, cv2.IMWRITE_PNG_FILTER_SUB]
    return params


#: the PNG encoder settings of an import (:func:`_png_params`)
PNG_PARAMS = _png_params()


def _write_png(path: Path, img: np.ndarray, fmt: ImageFormat) -> None:
    params = PNG_PARAMS if fmt == "png" else []
    if not cv2.imwrite(str(path), img, params):
        raise FormatError(f"{path}: cannot write the image")


def _write_bytes(path: Path, data: Any) -> None:
    path.write_bytes(bytes(data))


def _check_increasing(s: _Stream, which: str, where: str) -> None:
    st = s.stamp(which)
    if len(st) > 1 and st[-1] <= st[-2]:
        raise FormatError(f"{where}: {which} stamps do not increase at message {len(st)} ({st[-2]:.9f} then "
                          f"{st[-1]:.9f})")


def import_bag(bag: str | os.PathLike[str] | Sequence[str | os.PathLike[str]],
               topics: str | os.PathLike[str] | dict[str, Any] | TopicsConfig, out: str | os.PathLike[str], *,
               rig_path: str | os.PathLike[str] | None = None, stamp: str | None = None, video: bool = False,
               image_format: ImageFormat = "pgm", force: bool = False, workers: int = 2) -> ImportReport:
    """Import ``bag`` into the recording ``out`` (see the module docstring).

    Parameters
    ----------
    bag : a ROS 1 ``.bag`` (or several), a ROS 2 bag folder or ``.mcap``.
    topics : topics.yaml (path, mapping or :class:`TopicsConfig`).
    out : the recording folder; its ``rig.yaml`` is the rig checked against (``rig_path`` is copied
        there when given). A topics.yaml of odometry and trajectories only needs no rig.
    stamp : ``"header"`` or ``"receive"``; default topics.yaml's.
    video : one FFV1 ``video.mkv`` per camera (lossless) instead of image files.
    image_format : ``"pgm"`` (uncompressed: the import runs at the speed of the bag's reading) or
        ``"png"`` (:data:`PNG_PARAMS`: about 40 % of the disk, at about a tenth of PGM's speed).
    force : replace an existing sequence folder.
    workers : image-encoding threads.
    """
    cfg = topics if isinstance(topics, TopicsConfig) else load_topics(topics)
    which = stamp or cfg.stamp
    if which not in ("header", "receive"):
        raise InputError(f"stamp must be 'header' or 'receive', got {which!r}")
    root = Path(out)
    rig_file = Path(rig_path) if rig_path is not None else root / "rig.yaml"
    sensors = bool(cfg.cameras or cfg.lasers or cfg.onboard)
    if not rig_file.is_file() and (sensors or rig_path is not None):
        raise InputError(f"{rig_file}: no rig (give --rig RIG, or import into a recording that has rig.yaml; "
                         "odometry and trajectories alone need none)")
    rig = load_rig(rig_file) if rig_file.is_file() else None
    seq_dir = root / cfg.sequence
    if seq_dir.exists() and not force:
        raise InputError(f"{seq_dir}: exists; refusing to overwrite it (use --force)")
    if rig_path is not None and (root / "rig.yaml").exists() and not force and \
            (root / "rig.yaml").read_bytes() != rig_file.read_bytes():
        raise InputError(f"{root / 'rig.yaml'}: exists and differs from {rig_file} (use --force)")
    cams = {c.name: c for c in rig.cameras} if rig is not None else {}
    fixed = {s.name: s for s in rig.laser_scanners} if rig is not None else {}
    onboard = {s.name: s for s in rig.robot.onboard_scanners} if rig is not None else {}
    streams: dict[str, _Stream] = {}
    for kind, mapping, known in (("camera", cfg.cameras, cams), ("laser", cfg.lasers, fixed),
                                 ("onboard", cfg.onboard, onboard)):
        for name, topic in mapping.items():
            if name not in known:
                raise InputError(f"topics: {kind} {name!r} is not in the rig ({', '.join(known) or 'none'})")
            if topic in streams:
                raise InputError(f"topics: {topic} is mapped twice")
            streams[topic] = _Stream(kind, name, topic, sensor=known[name])
    if cfg.odometry:
        streams[cfg.odometry] = _Stream("odometry", "odometry", cfg.odometry)
    created_root = not root.exists()
    root.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=f".{cfg.sequence}.import.", dir=root))
    try:
        counts = _import_streams(bag, streams, tmp, which, video, image_format, workers)
        names = _import_trajectories(bag, cfg, tmp, which)
        if rig_path is not None and rig_file.resolve() != (root / "rig.yaml").resolve():
            shutil.copyfile(rig_file, tmp / ".rig.yaml")
        # all or none: the sequence (and the rig) appear only now
        if seq_dir.exists():
            old = root / f".{cfg.sequence}.old.{os.getpid()}"
            os.replace(seq_dir, old)
            shutil.rmtree(old, ignore_errors=True)
        if (tmp / ".rig.yaml").exists():
            os.replace(tmp / ".rig.yaml", root / "rig.yaml")
        os.replace(tmp, seq_dir)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        if created_root:  # a failed import into a new folder leaves no folder
            with contextlib.suppress(OSError):
                root.rmdir()
        raise
    return ImportReport(seq_dir, counts, names)


def _import_streams(bag: Any, streams: dict[str, _Stream], seq: Path, which: str, video: bool,
                    image_format: ImageFormat, workers: int) -> dict[str, int]:
    """Read the messages of ``streams`` (by topic) from ``bag`` into the sequence folder ``seq``: images
    written as they come (``workers`` threads), scans decoded in bulk after the pass, odometry kept as
    rows; then each stream's files and stamps. Returns the messages per stream."""
    with open_bag(bag) as reader, ThreadPoolExecutor(max(1, workers)) as pool:
        _check_topics(reader, streams)
        conns = [c for c in reader.connections if c.topic in streams]
        pending: list[Future[None]] = []
        for conn, t_ns, raw in reader.messages(conns):
            s = streams[conn.topic]
            if s.kind in ("laser", "onboard"):  # decoded in bulk after the pass (scan_decode)
                s.raws.append(raw)
                s.receive_s.append(ns_to_s(t_ns))
                s.msgtype = conn.msgtype
                continue
            where = f"{reader.paths[0]}:{conn.topic}"
            msg = deserialize(reader, raw, conn.msgtype, where)
            s.header_s.append(time_to_s(msg.header.stamp))
            s.receive_s.append(ns_to_s(t_ns))
            _check_increasing(s, which, where)
            if s.kind == "camera":
                _camera_message(s, msg, conn.msgtype, seq, where, video, image_format, pool, pending, workers)
            else:
                q = msg.pose.pose.orientation
                yaw = np.arctan2(2.0 * (q.w * q.z + q.x * q.y), 1.0 - 2.0 * (q.y * q.y + q.z * q.z))
                s.rows.append((msg.pose.pose.position.x, msg.pose.pose.position.y, yaw,
                               msg.twist.twist.linear.x, msg.twist.twist.angular.z))
        for f in pending:
            f.result()
        for s in streams.values():
            if s.kind in ("laser", "onboard") and s.raws:
                _decode_scans(s, reader, which)
    return _write_streams(streams, seq, which)


def _check_topics(reader: Any, streams: dict[str, _Stream]) -> None:
    """Every topic of ``streams`` is in the bag, of a message type its sensor kind reads."""
    by_topic = {c.topic: c for c in reader.connections}
    for topic, s in streams.items():
        c = by_topic.get(topic)
        if c is None:
            raise InputError(f"{reader.paths[0]}: no topic {topic} (topics: {', '.join(sorted(by_topic))})")
        want = {"camera": IMAGE_TYPES, "laser": (SCAN_TYPE,), "onboard": (SCAN_TYPE,),
                "odometry": (ODOM_TYPE,)}[s.kind]
        if c.msgtype not in want:
            raise InputError(f"{reader.paths[0]}:{topic}: a {c.msgtype}, but {s.kind} {s.name} needs "
                             f"{' or '.join(want)}")


def _camera_message(s: _Stream, msg: Any, msgtype: str, seq: Path, where: str, video: bool,
                    image_format: ImageFormat, pool: ThreadPoolExecutor, pending: list[Future[None]],
                    workers: int) -> None:
    """Camera ``s``'s latest image message (its stamps already appended) into the video or an image file
    of ``seq/cameras/NAME``: a compressed image's own bytes, a raw one encoded (checked against the rig's
    resolution) by ``pool``, at most ``4 workers`` writes pending."""
    n = len(s.header_s)
    folder = seq / "cameras" / s.name
    if n == 1:
        folder.mkdir(parents=True, exist_ok=True)
    if msgtype == IMAGE_TYPES[1]:  # CompressedImage: its own bytes
        if video:
            img = cv2.imdecode(np.frombuffer(msg.data, np.uint8), cv2.IMREAD_GRAYSCALE)
            if img is None:
                raise FormatError(f"{where}: message {n}: cannot decode the {msg.format!r} image")
            _video_write(s, folder, img, where)
            return
        ext = ".png" if "png" in msg.format.lower() else ".jpg"
        name = f"{n - 1:06d}{ext}"
        s.files.append(name)
        pending.append(pool.submit(_write_bytes, folder / name, msg.data))
        return
    img = _image(msg, where, n)
    w, h = s.sensor.resolution
    if img.shape != (h, w):
        raise InputError(f"{where}: message {n} is {img.shape[1]}x{img.shape[0]}, the rig's {s.name} "
                         f"is {w}x{h}")
    if video:
        _video_write(s, folder, img, where)
        return
    name = f"{n - 1:06d}.{image_format}"
    s.files.append(name)
    pending.append(pool.submit(_write_png, folder / name, img, image_format))
    if len(pending) > 4 * max(1, workers):  # bounded memory: wait for the oldest
        pending.pop(0).result()


def _decode_scans(s: _Stream, reader: Any, which: str) -> None:
    """Scanner ``s``'s raw messages decoded into its rows, their ``which`` stamps checked to increase."""
    where = f"{reader.paths[0]}:{s.topic}"
    s.rows = [_scans(s, reader, where)]
    st = np.array(s.stamp(which))
    back = np.flatnonzero(np.diff(st) <= 0)
    if back.size:
        i = int(back[0]) + 1
        raise FormatError(f"{where}: {which} stamps do not increase at message {i + 1} "
                          f"({st[i - 1]:.9f} then {st[i]:.9f})")


def _write_streams(streams: dict[str, _Stream], seq: Path, which: str) -> dict[str, int]:
    """Each stream's frame index, scan log or odometry CSV and its stamps file in ``seq``; returns the
    messages per stream (a stream without any is an error)."""
    counts = {}
    for s in streams.values():
        counts[f"{s.kind} {s.name}"] = len(s.header_s)
        if not s.header_s:
            raise InputError(f"{s.topic}: no messages in the bag")
        st = np.array(s.stamp(which))
        if s.kind == "camera":
            if s.writer is not None:
                s.writer.release()
                write_frame_index(seq / "cameras" / s.name, st, [""] * len(st))
            else:
                write_frame_index(seq / "cameras" / s.name, st, s.files)
        elif s.kind in ("laser", "onboard"):
            sub = "lasers" if s.kind == "laser" else "onboard"
            (seq / sub).mkdir(parents=True, exist_ok=True)
            write_scans(seq / sub / f"{s.name}.csv", ScanLog(st, np.vstack(s.rows)))
        else:
            a = np.array(s.rows, float)
            write_odometry_csv(seq / "odometry.csv",
                               OdometryLog(st, np.column_stack([a[:, :2], np.unwrap(a[:, 2])]), a[:, 3], a[:, 4]))
        _write_stamps(seq / "stamps" / f"{s.kind}-{s.name}.csv", s)
    return counts


def _video_write(s: _Stream, folder: Path, img: np.ndarray, where: str) -> None:
    if s.writer is None:
        h, w = img.shape
        rate = float(getattr(s.sensor, "rate_hz", 10.0))
        s.writer = cv2.VideoWriter(str(folder / "video.mkv"), cv2.VideoWriter_fourcc(*"FFV1"), rate, (w, h),  # type: ignore[attr-defined]
                                   isColor=False)
        if not s.writer.isOpened():
            raise InputError(f"{where}: this OpenCV cannot write FFV1 video (import to images instead)")
    s.writer.write(img)


def _write_stamps(path: Path, s: _Stream) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    rows = "".join(f"{i},{h:.9f},{r:.9f}\n" for i, (h, r) in enumerate(zip(s.header_s, s.receive_s, strict=True)))
    with atomic_open(path, "w", encoding="utf-8", newline="\n") as f:
        f.write("index,header_s,receive_s\n" + rows)


def _import_trajectories(bag: Any, cfg: TopicsConfig, seq: Path, which: str) -> tuple[str, ...]:
    from gtrig.io.formats.tum import write_tum_track
    from gtrig.io.rosbag.trajectory import read_bag_trajectory

    for name, topic in cfg.trajectories.items():
        track = read_bag_trajectory(bag, topic, stamp=which)  # type: ignore[arg-type]
        (seq / "trajectories").mkdir(parents=True, exist_ok=True)
        with contextlib.suppress(FileNotFoundError):
            (seq / "trajectories" / f"{name}.tum").unlink()
        write_tum_track(track, seq / "trajectories" / f"{name}.tum", pair=True)
    return tuple(cfg.trajectories)
