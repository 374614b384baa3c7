"""One stamp, one number: ``gtrig export`` writes the same digits for a pose's stamp in TUM, KITTI times,
EuRoC, gtrig's CSV, RAWSEEDS and bags, the digits it read (integer nanoseconds end to end)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from gtrig.cli.main import app
from gtrig.io.formats import read_trajectory
from gtrig.io.posetrack import write_pose_track
from gtrig.stamps import format_seconds, ns_from_decimals, ns_from_seconds, seconds_from_ns
from gtrig.trajectory import PoseTrack

runner = CliRunner()


def _data_lines(p: Path) -> list[str]:
    return [ln for ln in p.read_text().splitlines() if ln and not ln.startswith("#")]


def _exported_stamps_ns(src: Path, tmp: Path) -> dict[str, np.ndarray]:
    """The stamps of every export of ``src``, each read back from the written text (or bag) as integers."""
    out: dict[str, np.ndarray] = {}
    for fmt, name in (("tum", "t.tum"), ("kitti", "k.kitti"), ("euroc", "e.csv"), ("csv", "c.csv"),
                      ("rawseeds", "r.csv"), ("rosbag2", "b.mcap"), ("rosbag1", "b.bag")):
        res = runner.invoke(app, ["export", str(src), "--to", fmt, "--out", str(tmp / name)])
        assert res.exit_code == 0, res.output
        p = tmp / name
        if fmt == "tum":
            out[fmt] = ns_from_decimals([ln.split()[0] for ln in _data_lines(p)])
        elif fmt == "kitti":
            out[fmt] = ns_from_decimals(_data_lines(tmp / "k_times.txt"))
        elif fmt == "euroc":
            out[fmt] = np.array([int(ln.split(",")[0]) for ln in _data_lines(p)], np.int64)
        elif fmt == "csv":
            out[fmt] = ns_from_decimals([ln.split(",")[0] for ln in _data_lines(p)[1:]])
        elif fmt == "rawseeds":
            out[fmt] = ns_from_decimals([ln.split(",")[0] for ln in _data_lines(p)])
        else:
            from rosbags.highlevel import AnyReader

            with AnyReader([p]) as r:
                conns = [c for c in r.connections if c.topic == "/gtrig/pose"]
                out[fmt] = np.array([int(r.deserialize(raw, c.msgtype).header.stamp.sec) * 10**9
                                     + int(r.deserialize(raw, c.msgtype).header.stamp.nanosec)
                                     for c, _, raw in r.messages(conns)], np.int64)
    return out


def test_float_stamps_export_as_one_number(tmp_path: Path) -> None:
    """A track computed in floats (1700000300.02 is 1700000300.0199999809... as a double): every format
    writes 1700000300.020000, nowhere ...019999981."""
    t = 1700000300.0 + np.arange(50) * 0.02
    xy = np.column_stack([np.cos(t - t[0]), np.sin(t - t[0]), t - t[0]])
    src = tmp_path / "src.tum"
    write_pose_track(PoseTrack.from_xytheta(t, xy), src)
    got = _exported_stamps_ns(src, tmp_path)
    want = 1_700_000_300_000_000_000 + np.arange(50, dtype=np.int64) * 20_000_000
    for fmt, ns in got.items():
        assert np.array_equal(ns, want), fmt
    assert _data_lines(src)[1].split()[0] == "1700000300.020000"
    assert "019999981" not in (tmp_path / "k_times.txt").read_text()


def test_nanosecond_stamps_survive_every_export(tmp_path: Path) -> None:
    """A TUM file with nanosecond digits (a bag's stamps printed to 9 decimals, which a double cannot hold
    at this epoch): each export keeps all nine."""
    ns = 1_700_000_300_000_000_000 + np.arange(40, dtype=np.int64) * 33_333_333 + 19
    src = tmp_path / "src.tum"
    src.write_text("".join(f"{s} {k * 0.01:.9f} 0 0 0 0 0 1\n" for k, s in enumerate(format_seconds(ns, 9))))
    track = read_trajectory(src)
    assert track.stamps_ns is not None and np.array_equal(track.stamps_ns, ns)
    got = _exported_stamps_ns(src, tmp_path)
    for fmt, back in got.items():
        if fmt == "rawseeds":  # 6 decimals, the published layout: the nearest microsecond
            assert np.array_equal(back, (ns + 500) // 1000 * 1000), fmt
        else:
            assert np.array_equal(back, ns), fmt
    for name in ("t.tum", "e.csv", "c.csv", "b.mcap", "b.bag"):  # read back: the same integers
        assert np.array_equal(read_trajectory(tmp_path / name, **({"topic": "/gtrig/pose"} if name.startswith("b.")
                                                                   else {})).integer_stamps_ns(), ns), name


@pytest.mark.parametrize("t,ns", [(1700000300.02, 1_700_000_300_020_000_000), (12.3456789, 12_345_678_900),
                                  (1700000100.1 + 1.2, 1_700_000_101_300_000_000), (1 / 30, 33_333_333),
                                  (1235604664.443286, 1_235_604_664_443_286_000), (-0.5, -500_000_000)])
def test_ns_of_float_seconds_is_the_shortest_decimal(t: float, ns: int) -> None:
    assert int(ns_from_seconds(np.array([t]))[0]) == ns


def test_pose_track_keeps_ns_while_they_agree() -> None:
    ns = 10**18 + np.arange(3, dtype=np.int64) * 1_000_000 + 7  # 7 ns past the millisecond: no double holds it
    tr = PoseTrack(seconds_from_ns(ns), np.zeros((3, 3)), np.tile([0, 0, 0, 1.0], (3, 1)), stamps_ns=ns)
    assert np.array_equal(tr.select([0, 2]).stamps_ns, ns[[0, 2]])
    assert np.array_equal(tr.shifted(1.0).stamps_ns, ns + 10**9)
    from dataclasses import replace

    assert replace(tr, stamps_s=tr.stamps_s + 0.5).stamps_ns is None  # new stamps: the old integers dropped
    plain = PoseTrack(np.array([0.1, 0.2]), np.zeros((2, 3)), np.tile([0, 0, 0, 1.0], (2, 1)))
    assert plain.stamps_ns is None and list(plain.integer_stamps_ns()) == [100_000_000, 200_000_000]
