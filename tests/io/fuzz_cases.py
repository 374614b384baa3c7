"""Every reader of gtrig with a small valid input, and byte-level mutations: shared by
tests/io/test_readers_fuzz.py and bench/fuzz.py."""

from __future__ import annotations

import gzip
import random
from collections.abc import Callable
from pathlib import Path

import numpy as np


def _tum() -> bytes:
    rows = [f"{t:.6f} {t:.3f} 0.5 0 0 0 {np.sin(t / 2):.9f} {np.cos(t / 2):.9f}" for t in np.arange(1, 6)]
    return ("# timestamp tx ty tz qx qy qz qw\n" + "\n".join(rows) + "\n").encode()


def _cov() -> bytes:
    head = "# gtrig pose covariance v1; source=x\nstamp_s,status,reason," + ",".join(
        f"cov_{a}_{b}" for a in ("x", "y", "yaw") for b in ("x", "y", "yaw"))
    rows = [f"{t:.6f},ok,," + ",".join(str(v) for v in np.eye(3).ravel() * 1e-6) for t in np.arange(1, 6)]
    return (head + "\n" + "\n".join(rows) + "\n").encode()


def _scans() -> bytes:
    return ("timestamp," + ",".join(f"r_{i}" for i in range(5)) + "\n"
            + "".join(f"{t:.6f},1.0,2.0,nan,3.5,4.25\n" for t in np.arange(0, 1, 0.1))).encode()


def _odometry() -> bytes:
    return ("stamp_s,x,y,theta,v,omega\n"
            + "".join(f"{t:.3f},{t:.3f},0,0.1,0.5,0.01\n" for t in np.arange(0, 1, 0.1))).encode()


def _frames() -> bytes:
    return b"frame,stamp_s,file\n0,0.000000,0.png\n1,0.100000,1.png\n2,0.200000,2.png\n"


def _reference_points() -> bytes:
    return b"name,x,y,sigma\nO,0,0,0.0005\nA,0,2.5,0.0005\nB,2.5,0,0.0005\n"


def _world_distances() -> bytes:
    return b"point,reference,distance,sigma\n1,O,2.74,0.00075\n1,A,5.19,0.00075\n1,B,3.16,0.00075\n"


def _pose_distances() -> bytes:
    return b"pose,robot_point,world_point,distance,sigma\n1,O,1,1.55,0.00075\n1,X,2,1.10,0.00075\n"


def _robot_points() -> bytes:
    return b"name,x,y\nO,0,0\nX,0.5,0\nY,0,0.5\n"


def _cam() -> bytes:
    return (b"image_size: [1600, 1200]\ncamera_matrix: [[1500.0, 0.0, 800.0], [0.0, 1500.0, 600.0], "
            b"[0.0, 0.0, 1.0]]\ndist_coeffs: [0.01, -0.02, 0.0, 0.0, 0.0]\nrms_px: 0.2\n")


def _rig() -> bytes:
    import yaml

    from gtrig.rig.load import rig_to_dict
    from gtrig.sim.gtroom import make_scene

    return yaml.safe_dump(rig_to_dict(make_scene(0).rig_nominal), sort_keys=False).encode()


def _carmen() -> bytes:
    lines = ["# CARMEN", "PARAM robot_use_laser on 1.0 host 1.0"]
    for i in range(5):
        t = 1.0 + i
        lines.append(f"ODOM {0.1 * i} 0 0 0.1 0 0 {t} host {t}")
        lines.append("FLASER 4 1.0 1.1 1.2 1.3 " + f"{0.1 * i} 0 0 {0.1 * i} 0 0 {t} host {t}")
        lines.append(f"ODOM {0.1 * i} 0 0 0 0 0 0 host 0")
    return gzip.compress(("\n".join(lines) + "\n").encode(), mtime=0)


def _track() -> object:
    from gtrig.trajectory import PoseTrack

    t = np.arange(1.0, 6.0)
    q = np.c_[np.zeros((5, 2)), np.sin(t / 4), np.cos(t / 4)]
    cov = np.tile(np.diag([1e-6, 2e-6, 3e-6]), (5, 1, 1))
    return PoseTrack(t, np.c_[t, 0.5 * t, np.zeros(5)], q, cov, "xyyaw", source="fuzz")


def _written(fmt: str, name: str, pick: str = "", **options: object) -> Callable[[], bytes]:
    """The bytes of a small track written by gtrig in ``fmt`` (``pick``: which of the files written)."""
    def make() -> bytes:
        import tempfile

        from gtrig.io.formats import write_trajectory

        with tempfile.TemporaryDirectory() as d:
            paths = write_trajectory(_track(), Path(d) / name, fmt, **options)  # type: ignore[arg-type]
            return next(q for q in paths if q.name.endswith(pick or name.rsplit("/", 1)[-1])).read_bytes()
    return make


def _nmea() -> bytes:
    def cs(body: str) -> str:
        x = 0
        for ch in body.encode():
            x ^= ch
        return f"${body}*{x:02X}"

    lines = []
    for i in range(4):
        t = f"1355{10 + i:02d}.00"
        lines += [cs(f"GPGGA,{t},4530.36844637,N,00909.97033083,E,4,8,0.9,129.085,M,48.022,M,1.0,0000"),
                  cs(f"GPGST,{t},0.02,0.020,0.010,30.0,0.018,0.013,0.030"),
                  cs(f"GPRMC,{t},A,4530.36844637,N,00909.97033083,E,0.1,45.0,041008,,,R")]
    return ("\r\n".join(lines) + "\r\n").encode()


def _rtklib() -> bytes:
    head = ("%  GPST                  latitude(deg) longitude(deg)  height(m)   Q  ns   sdn(m)   sde(m)   sdu(m)"
            "  sdne(m)  sdeu(m)  sdun(m) age(s)  ratio")
    rows = [f"2008/10/04 13:55:{52 + 0.2 * i:06.3f}   45.50617412{i}    9.16670663{i}   186.527{i}   1   9   0.0068"
            "   0.0052   0.0155   -0.0021   0.0010  -0.0042   0.60   12.3" for i in range(4)]
    return ("\n".join(["% program   : RTKPOST ver.2.4.3", head, *rows]) + "\n").encode()


def _read_traj(fmt: str, name: str, **options: object) -> Callable[[Path], object]:
    """The trajectory front door on a file named ``name`` (the name selects the format)."""
    def read(p: Path) -> object:
        from gtrig.io.formats import read_trajectory

        target = p.parent / name
        target.parent.mkdir(parents=True, exist_ok=True)
        target.write_bytes(p.read_bytes())
        return read_trajectory(target, fmt, **options)
    return read


def _read_cov(p: Path) -> object:
    from gtrig.io.posetrack import read_covariance_csv

    return read_covariance_csv(p)


def _read_frames(p: Path) -> object:
    from gtrig.io.frames import read_frame_index

    # the index is found by folder: the fuzzed bytes are the folder's timestamps.csv
    target = p.parent / "timestamps.csv"
    target.write_bytes(p.read_bytes())
    return read_frame_index(p.parent)


def _lazy(module: str, name: str) -> Callable[[Path], object]:
    def read(p: Path) -> object:
        import importlib

        return getattr(importlib.import_module(module), name)(p)

    return read


#: name -> (reader of a path, a valid input's bytes, the file suffix)
READERS: dict[str, tuple[Callable[[Path], object], Callable[[], bytes], str]] = {
    "tum": (_lazy("gtrig.io.tum", "read_tum"), _tum, ".tum"),
    "pose_covariance": (_read_cov, _cov, ".csv"),
    "scans": (_lazy("gtrig.io.scans", "read_scans"), _scans, ".csv"),
    "odometry": (_lazy("gtrig.io.odometry", "read_odometry"), _odometry, ".csv"),
    "frame_index": (_read_frames, _frames, ".csv"),
    "reference_points": (_lazy("gtrig.io.survey_csv", "read_reference_points"), _reference_points, ".csv"),
    "world_distances": (_lazy("gtrig.io.survey_csv", "read_world_distances"), _world_distances, ".csv"),
    "pose_distances": (_lazy("gtrig.io.survey_csv", "read_pose_distances"), _pose_distances, ".csv"),
    "robot_points": (_lazy("gtrig.io.survey_csv", "read_robot_points"), _robot_points, ".csv"),
    "camera_yaml": (_lazy("gtrig.io.camfile", "read_cam_yaml"), _cam, ".yaml"),
    "rig_yaml": (_lazy("gtrig.rig.load", "load_rig"), _rig, ".yaml"),
    "carmen": (_lazy("gtrig.io.carmen", "read_carmen"), _carmen, ".log.gz"),
    "nmea": (_lazy("gtrig.gps.nmea", "read_nmea"), _nmea, ".nmea"),
    "rtklib_pos": (_lazy("gtrig.gps.rtklib", "read_rtklib_pos"), _rtklib, ".pos"),
    "kitti": (_read_traj("kitti", "t.kitti"), _written("kitti", "t.kitti"), ".kitti"),
    "euroc": (_read_traj("euroc", "state_groundtruth_estimate0/data.csv"),
              _written("euroc", "state_groundtruth_estimate0/data.csv"), ".csv"),
    "rawseeds": (_read_traj("rawseeds", "t-GROUNDTRUTH.csv"), _written("rawseeds", "t-GROUNDTRUTH.csv"), ".csv"),
    "trajectory_csv": (_read_traj("csv", "t.csv"), _written("csv", "t.csv"), ".csv"),
    "rosbag1": (_read_traj("rosbag1", "t.bag", topic="/gt"), _written("rosbag1", "t.bag", topic="/gt"), ".bag"),
    "rosbag2_mcap": (_read_traj("rosbag2", "t.mcap", topic="/gt"), _written("rosbag2", "t.mcap", topic="/gt"),
                     ".mcap"),
}

_TOKENS = [b"nan", b"inf", b"-inf", b"1e308", b"-1e400", b"", b",", b"\n", b"\x00", b"\xff\xfe", b"*", b"&a",
           b"[", b"{", b"'", b'"', b"-", b"0", b"99999999999999999999", b"ok", b"\t", b"#"]


def mutate(data: bytes, rnd: random.Random, n: int = 1) -> bytes:
    """``data`` with ``n`` random edits: a byte flipped, a cut, a line duplicated or dropped, a number
    replaced by a special token, a token inserted."""
    b = bytearray(data)
    for _ in range(n):
        kind = rnd.randrange(6)
        if not b:
            b += rnd.choice(_TOKENS)
            continue
        i = rnd.randrange(len(b))
        if kind == 0:
            b[i] = rnd.randrange(256)
        elif kind == 1:
            del b[i:]
        elif kind in (2, 3):
            lines = bytes(b).split(b"\n")
            j = rnd.randrange(len(lines))
            lines = lines[:j] + ([lines[j]] * 2 if kind == 2 else []) + lines[j + 1:]
            b = bytearray(b"\n".join(lines))
        elif kind == 4:
            j = i
            while j < len(b) and (chr(b[j]).isdigit() or b[j] in b".-e"):
                j += 1
            b[i:j] = rnd.choice(_TOKENS)
        else:
            b[i:i] = rnd.choice(_TOKENS)
    return bytes(b)
