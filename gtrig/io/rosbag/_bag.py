"""Opening and creating ROS bags with the ``rosbags`` library (pure Python; ROS need not be installed).

Everything here maps the library's exceptions to one-line :class:`~gtrig.errors.FormatError` s and
converts ROS time (``sec``, ``nanosec``) to and from float seconds without going through a float
nanosecond count (1.7e18 ns is past float64's 2^53: that would cost 256 ns).
"""

from __future__ import annotations

import contextlib
import os
import shutil
import tempfile
from collections.abc import Iterator, Sequence
from functools import cache
from pathlib import Path
from typing import Any, Literal

import numpy as np

from gtrig.errors import FormatError, GtrigError, InputError

RosVersion = Literal[1, 2]
Storage = Literal["sqlite3", "mcap"]

# tf2_msgs/TFMessage, which rosbags' ROS 1 store lacks (same definition in ROS 1 and ROS 2)
_TFMESSAGE = ("tf2_msgs/msg/TFMessage", "geometry_msgs/TransformStamped[] transforms")


@cache
def typestore(ros_version: RosVersion) -> Any:
    """The message types gtrig writes with: ROS 1 Noetic or ROS 2 Humble (plus TFMessage for ROS 1)."""
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    ts = get_typestore(Stores.ROS1_NOETIC if ros_version == 1 else Stores.ROS2_HUMBLE)
    if _TFMESSAGE[0] not in ts.types:
        ts.register(get_types_from_msg(_TFMESSAGE[1], _TFMESSAGE[0]))
    return ts


def bag_paths(paths: str | os.PathLike[str] | Sequence[str | os.PathLike[str]]) -> list[Path]:
    """The bag paths as a list; a missing one is a :class:`FormatError`."""
    ps = [Path(paths)] if isinstance(paths, (str, os.PathLike)) else [Path(p) for p in paths]
    if not ps:
        raise InputError("no bag given")
    for p in ps:
        if not p.exists():
            raise FormatError(f"{p}: no such bag")
    kinds = {p.suffix == ".bag" for p in ps}
    if len(kinds) > 1:
        raise InputError(f"{ps[0]}: ROS 1 and ROS 2 bags cannot be read together")
    if len(ps) > 1 and ps[0].suffix != ".bag":
        raise InputError(f"{ps[1]}: only ROS 1 bags are read several at once (a ROS 2 bag is one folder)")
    return ps


@contextlib.contextmanager
def open_bag(paths: str | os.PathLike[str] | Sequence[str | os.PathLike[str]]) -> Iterator[Any]:
    """An open ``rosbags.highlevel.AnyReader`` over one ROS 2 bag or several ROS 1 bags.

    Bags without embedded definitions (older ROS 2 sqlite3 bags) are read with the ROS 2 Humble types.
    """
    from rosbags.highlevel import AnyReader, AnyReaderError

    ps = bag_paths(paths)
    try:
        # ROS 1 bags embed their definitions: no default store (building Humble's costs 0.8 s)
        reader = AnyReader(ps, default_typestore=None if ps[0].suffix == ".bag" else typestore(2))
        reader.open()
    except (AnyReaderError, OSError, ValueError, KeyError) as e:
        msg = str(e).splitlines()[0] if str(e) else type(e).__name__
        raise FormatError(f"{ps[0]}: not a readable ROS 1 or ROS 2 bag ({msg})") from None
    except Exception as e:  # the storage plugins raise their own (sqlite3, zstd, mcap) errors
        msg = str(e).splitlines()[0] if str(e) else type(e).__name__
        raise FormatError(f"{ps[0]}: not a readable ROS 1 or ROS 2 bag ({type(e).__name__}: {msg})") from None
    try:
        yield reader
    except GtrigError:
        raise
    except Exception as e:
        # reading messages lazily, the storage layers raise on a corrupt chunk or index; only theirs
        # are the bag's fault (an error of gtrig's own code stays a crash, to be seen and fixed)
        if not _from_storage(e):
            raise
        msg = str(e).splitlines()[0] if str(e) else type(e).__name__
        raise FormatError(f"{ps[0]}: a corrupt part in the bag ({type(e).__name__}: {msg[:120]})") from None
    finally:
        reader.close()


def _from_storage(e: BaseException) -> bool:
    """``e`` comes from reading the bag's bytes: raised inside rosbags or a storage library (whatever
    its type: they raise KeyError and AssertionError on corrupt data too), or a decoding error."""
    import struct

    tb = e.__traceback__
    while tb is not None and tb.tb_next is not None:
        tb = tb.tb_next
    where = tb.tb_frame.f_code.co_filename if tb is not None else ""
    return (any(f"{os.sep}{lib}{os.sep}" in where for lib in ("rosbags", "zstandard", "lz4", "mcap", "ruamel"))
            or type(e).__module__.split(".")[0] in ("rosbags", "sqlite3")
            or isinstance(e, (struct.error, EOFError, OSError, UnicodeDecodeError)))


def deserialize(reader: Any, rawdata: bytes, msgtype: str, where: str) -> Any:
    """One message; a corrupt one is a :class:`FormatError` naming ``where``."""
    try:
        return reader.deserialize(rawdata, msgtype)
    except Exception as e:  # rosbags raises several kinds for truncated data
        raise FormatError(f"{where}: cannot decode a {msgtype} message ({type(e).__name__})") from None


def time_to_s(stamp: Any) -> float:
    """ROS ``Time`` (``sec``, ``nanosec``) as float seconds."""
    return stamp.sec + stamp.nanosec * 1e-9


def ns_to_s(ns: int) -> float:
    """Integer nanoseconds (a bag's receive time) as float seconds, split before converting."""
    return ns // 1_000_000_000 + (ns % 1_000_000_000) * 1e-9


def time_to_ns(stamp: Any) -> int:
    """ROS ``Time`` (``sec``, ``nanosec``) as integer nanoseconds."""
    return int(stamp.sec) * 1_000_000_000 + int(stamp.nanosec)


def s_to_sec_nsec(t: float) -> tuple[int, int]:
    """Float seconds as ROS ``(sec, nanosec)``, rounded to the nearest nanosecond (a sensor's stamp: the
    recording's CSV files print 9 decimals, and read back as the same float). A trajectory is written from
    its integer nanoseconds instead (:meth:`gtrig.trajectory.PoseTrack.integer_stamps_ns`)."""
    sec = int(np.floor(t))
    nsec = int(round((t - sec) * 1e9))  # t - sec is exact for floats of one binade
    if nsec >= 1_000_000_000:
        sec, nsec = sec + 1, nsec - 1_000_000_000
    return sec, nsec


def s_to_ns(t: float) -> int:
    sec, nsec = s_to_sec_nsec(t)
    return sec * 1_000_000_000 + nsec


def ros_time(ts: Any, t: float) -> Any:
    return ros_time_ns(ts, s_to_ns(t))


def ros_time_ns(ts: Any, t_ns: int) -> Any:
    sec, nsec = divmod(int(t_ns), 1_000_000_000)
    return ts.types["builtin_interfaces/msg/Time"](sec=sec, nanosec=nsec)


def header(ts: Any, ros_version: RosVersion, t: float, frame_id: str, seq: int = 0) -> Any:
    return header_ns(ts, ros_version, s_to_ns(t), frame_id, seq)


def header_ns(ts: Any, ros_version: RosVersion, t_ns: int, frame_id: str, seq: int = 0) -> Any:
    """A ``std_msgs/Header`` stamped ``t_ns`` (integer nanoseconds)."""
    H = ts.types["std_msgs/msg/Header"]
    if ros_version == 1:
        return H(seq=seq, stamp=ros_time_ns(ts, t_ns), frame_id=frame_id)
    return H(stamp=ros_time_ns(ts, t_ns), frame_id=frame_id)


def serialize(ts: Any, ros_version: RosVersion, msg: Any) -> bytes:
    if ros_version == 1:
        return bytes(ts.serialize_ros1(msg, msg.__msgtype__))
    return bytes(ts.serialize_cdr(msg, msg.__msgtype__))


class BagWriter:
    """Write one bag all or none: into a temporary sibling, renamed into place when the block ends
    without error (an existing target is replaced only with ``force``).

    ``path``: ``NAME.bag`` (ROS 1), a folder (ROS 2, sqlite3 or MCAP inside) or ``NAME.mcap`` (ROS 2,
    one MCAP file, as ``ros2 bag record -s mcap`` leaves inside its folder).
    """

    def __init__(self, path: str | os.PathLike[str], ros_version: RosVersion, storage: Storage = "sqlite3",
                 force: bool = False) -> None:
        self.path = Path(path)
        self.ros_version = ros_version
        self.storage: Storage = "mcap" if self.path.suffix == ".mcap" else storage
        self.force = force
        self.ts = typestore(ros_version)
        self._conns: dict[str, Any] = {}
        if ros_version == 1 and self.path.suffix != ".bag":
            raise InputError(f"{self.path}: a ROS 1 bag is a file NAME.bag")
        if ros_version == 2 and self.path.suffix == ".bag":
            raise InputError(f"{self.path}: a ROS 2 bag is a folder or NAME.mcap, not NAME.bag")
        if self.path.exists() and not force:
            raise InputError(f"{self.path}: exists; refusing to overwrite it (use --force)")

    def __enter__(self) -> BagWriter:
        from rosbags.rosbag1 import Writer as Writer1
        from rosbags.rosbag2 import StoragePlugin
        from rosbags.rosbag2 import Writer as Writer2

        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._tmpdir = Path(tempfile.mkdtemp(prefix=f".{self.path.name}.", dir=self.path.parent))
        if self.ros_version == 1:
            self._tmp = self._tmpdir / self.path.name
            self._writer: Any = Writer1(self._tmp)
        else:
            self._tmp = self._tmpdir / (self.path.stem if self.path.suffix == ".mcap" else self.path.name)
            plugin = StoragePlugin.MCAP if self.storage == "mcap" else StoragePlugin.SQLITE3
            self._writer = Writer2(self._tmp, version=8, storage_plugin=plugin)
        self._writer.open()
        return self

    def write(self, topic: str, t_receive_s: float, msg: Any) -> None:
        """Serialize ``msg`` on ``topic`` at receive time ``t_receive_s``."""
        self.write_ns(topic, s_to_ns(t_receive_s), msg)

    def write_ns(self, topic: str, t_receive_ns: int, msg: Any) -> None:
        """Serialize ``msg`` on ``topic`` at receive time ``t_receive_ns`` (integer nanoseconds)."""
        conn = self._conns.get(topic)
        if conn is None:
            conn = self._conns[topic] = self._writer.add_connection(topic, msg.__msgtype__, typestore=self.ts)
        self._writer.write(conn, int(t_receive_ns), serialize(self.ts, self.ros_version, msg))

    def __exit__(self, exc_type: Any, exc: Any, tb: Any) -> None:
        try:
            if exc_type is not None:
                with contextlib.suppress(Exception):
                    self._writer.close()
                return
            self._writer.close()
            made = self._tmp
            if self.ros_version == 2 and self.path.suffix == ".mcap":
                made = next(self._tmp.glob("*.mcap"))
            if self.path.exists():  # force: the old bag goes only once the new one is complete
                old = self._tmpdir / ".old"
                os.replace(self.path, old)
            os.replace(made, self.path)
        finally:
            shutil.rmtree(self._tmpdir, ignore_errors=True)
