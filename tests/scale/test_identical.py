"""The same bytes whatever runs the chunks: GTvision and GTlaser with ``--workers 1``, ``--workers 2``,
``--dask local:2`` and a Dask cluster of separate scheduler and worker processes on 127.0.0.1; and a
client killed with SIGKILL mid-way resumes from its checkpoint, redoing only the chunks in flight.
(The whole pipeline, fusion included, on the cluster: tests/pipeline/test_demo.py.)"""

from __future__ import annotations

import logging
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from vision_synth import write_rendered_run

from gtrig.executor import open_executor
from gtrig.rig.load import dump_rig
from gtrig.sim.gtroom import VALIDATION_POSES, make_scene
from gtrig.vision.sequence import run_recording, write_pose_track_files
from tests.scale.cluster import REPO, _env, dask_cluster

pytest.importorskip("distributed")

INSTANTS = 6


@pytest.fixture(scope="module")
def run_rec(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, object]:
    """A short run: the robot creeping forward past validation pose 4, every camera that sees it."""
    scene = make_scene(0)
    rig = scene.rig_true
    out = tmp_path_factory.mktemp("rec")
    x, y, th = VALIDATION_POSES[3]
    Ts = [scene.T_world_robot(x + 0.02 * k * np.cos(th), y + 0.02 * k * np.sin(th), th) for k in range(INSTANTS)]
    write_rendered_run(out, rig, Ts, 0.1 * np.arange(INSTANTS), np.random.default_rng(1))
    dump_rig(rig, out / "rig.yaml")
    return out, rig


@pytest.fixture(scope="module")
def executors(tmp_path_factory: pytest.TempPathFactory):
    """``--dask local:2`` and a client of a cluster started as separate processes (2 workers)."""
    with open_executor("local:2") as local, dask_cluster(tmp_path_factory.mktemp("dask"), 2) as address, \
            open_executor(address) as remote:
        yield {"local:2": local, "tcp": remote, "address": address}


def _vision_bytes(res: object, folder: Path, name: str) -> tuple[bytes, bytes]:
    tum, cov = folder / f"{name}.tum", folder / f"{name}_cov.csv"
    write_pose_track_files(res, tum, cov)  # type: ignore[arg-type]
    return tum.read_bytes(), cov.read_bytes()


def test_gtvision_identical_on_every_executor(run_rec, executors, tmp_path: Path) -> None:
    path, rig = run_rec
    kw = {"detector": "aruco", "chunk_size": 2}
    ref = run_recording(path, rig, "run", True, workers=1, **kw)
    assert len(ref.localized()) == INSTANTS, [e.reason for e in ref.estimates]
    want = _vision_bytes(ref, tmp_path, "w1")
    for name, how in (("w2", {"workers": 2}), ("local", {"executor": executors["local:2"]}),
                      ("tcp", {"executor": executors["tcp"]})):
        res = run_recording(path, rig, "run", True, checkpoint=tmp_path / f"{name}.ck", **how, **kw)  # type: ignore[arg-type]
        assert _vision_bytes(res, tmp_path, name) == want, name


def test_gtlaser_identical_on_every_executor(executors, monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    """GTlaser's whole result is the same bits on every executor, cut into time windows or not, and read
    from the logs on disk a window at a time (the workers reading theirs) as from all scans in memory."""
    import dataclasses

    import gtrig.laser.track as track
    from gtrig.io.scans import ScanLog, index_scans, read_scans, write_scans
    from gtrig.laser import synth
    from gtrig.laser.background import build_background
    from gtrig.laser.foreground import foreground_mask, foreground_threshold
    from gtrig.laser.fuse import frame_layout, frame_points
    from gtrig.laser.hull_icp import HullModel
    from gtrig.laser.recording import LoggedFrames
    from tests.laser.conftest import make_scanner

    walls = synth.rectangle_segments([[-4, -3], [4, -3], [4, 3], [-4, 3]])
    scs = (make_scanner("a", -3.6, -2.6, np.radians(35)), make_scanner("b", 3.6, -2.2, np.radians(150)),
           make_scanner("c", 3.6, 2.6, np.radians(-145)))
    from gtrig.rig.models import Hull

    hull = Hull(length_m=0.78, width_m=0.57, z_min_m=0.05, z_max_m=0.55)
    rng = np.random.default_rng(2)
    bst = [np.arange(0, 0.4, 1 / 75) + 0.002 * i for i in range(3)]
    bg = synth.scan_sequence(scs, walls, None, None, bst, rng)
    st = [np.arange(0, 1.2, 1 / 75) + 0.003 * i for i in range(3)]
    run = synth.scan_sequence(scs, walls, hull, lambda t: np.array([-1 + 0.3 * t, 0.2 * t, 0.3 + 0.1 * t]), st, rng)
    # the run as logs on disk, read back (the written ranges are rounded to 0.1 mm)
    for s, t, r in zip(scs, st, run, strict=True):
        write_scans(tmp_path / f"{s.name}.csv", ScanLog(t, r))
    logs = [read_scans(tmp_path / f"{s.name}.csv", s) for s in scs]
    st, run = [g.stamps_s for g in logs], [g.ranges_m for g in logs]
    thresholds = [foreground_threshold(build_background(b, s)) for b, s in zip(bg, scs, strict=True)]
    masks = [foreground_mask(r, th) for r, th in zip(run, thresholds, strict=True)]
    fp = frame_points(scs, st, run, masks)
    rows = tuple(index_scans(tmp_path / f"{s.name}.csv", s) for s in scs)
    logged = LoggedFrames(scs, rows, tuple(thresholds), frame_layout(scs, [r.stamps_s for r in rows]))
    # ... and from the binary copy of the parsed ranges (index_scans(cache=)), which the workers read
    cached = dataclasses.replace(logged, rows=tuple(index_scans(tmp_path / f"{s.name}.csv", s, cache=tmp_path / "cache")
                                        for s in scs))
    assert all(r.ranges_file is not None for r in cached.rows)
    cal = np.diag(np.tile([1e-6, 1e-6, np.radians(0.02) ** 2], len(scs)))
    model = HullModel.from_hull(hull)

    def fields(r: object) -> list[bytes]:
        """Every field's bytes, nested records (the side bias) field by field: an object's own bytes
        would be its address."""
        out: list[bytes] = []
        for f in dataclasses.fields(r):  # type: ignore[arg-type]
            v = getattr(r, f.name)
            out.extend(fields(v) if dataclasses.is_dataclass(v) else [np.asarray(v).tobytes()])
        return out

    monkeypatch.setattr(track, "COVARIANCE_WINDOW_FRAMES", 10**9)
    ref = track.track_frames(fp, model, scanner_cov=cal)
    assert (ref.status == track.OK).mean() > 0.9
    monkeypatch.setattr(track, "COVARIANCE_WINDOW_FRAMES", 16)  # cut in time windows, in the client
    for how in ({"workers": 1}, {"workers": 2}, {"executor": executors["local:2"]}, {"executor": executors["tcp"]}):
        assert fields(track.track_frames(fp, model, scanner_cov=cal, **how)) == fields(ref), how  # type: ignore[arg-type]
        assert fields(track.track_frames(logged, model, scanner_cov=cal, **how)) == fields(ref), ("logged", how)  # type: ignore[arg-type]
        assert fields(track.track_frames(cached, model, scanner_cov=cal, **how)) == fields(ref), ("cached", how)  # type: ignore[arg-type]


RESUMABLE = """
import sys, time
from pathlib import Path
from gtrig.executor import open_executor
from gtrig.rig.load import load_rig
from gtrig.vision.sequence import run_recording
rec, ck, dask = Path(sys.argv[1]), Path(sys.argv[2]), (sys.argv[3] if len(sys.argv) > 3 else None)
def stall(done, total):
    if done >= 3:  # three chunks checkpointed: say so, then wait to be killed
        print("ready", flush=True)
        time.sleep(300)
with open_executor(dask) as ex:
    run_recording(rec, load_rig(rec / "rig.yaml"), "run", True, workers=2, detector="aruco", chunk_size=1,
                  checkpoint=ck, progress=stall, executor=ex)
"""


@pytest.mark.parametrize("where", ["local", "tcp"])
def test_client_killed_mid_run_resumes_redoing_only_chunks_in_flight(run_rec, executors, where: str, tmp_path: Path,
                                                                     caplog: pytest.LogCaptureFixture) -> None:
    path, rig = run_rec
    ck = tmp_path / "det.ck"
    args = [sys.executable, "-c", RESUMABLE, str(path), str(ck)] + ([executors["address"]] if where == "tcp" else [])
    p = subprocess.Popen(args, stdout=subprocess.PIPE, text=True, env=_env(), cwd=str(REPO))
    assert p.stdout is not None
    deadline = time.monotonic() + 120
    line = ""
    while "ready" not in line and time.monotonic() < deadline and p.poll() is None:
        line = p.stdout.readline()
    assert "ready" in line
    p.send_signal(signal.SIGKILL)
    p.wait(timeout=30)
    kept = len(ck.read_text().splitlines()) - 1  # the header, then one line per finished chunk
    assert kept >= 3
    with caplog.at_level(logging.INFO, logger="gtrig.vision.sequence"):
        res = run_recording(path, rig, "run", True, workers=1, detector="aruco", chunk_size=1, checkpoint=ck)
    # every chunk that finished before the kill is reused; only those still in flight are detected again
    assert f"resuming: {kept} of " in caplog.text
    ref = run_recording(path, rig, "run", True, workers=1, detector="aruco", chunk_size=1)
    assert _vision_bytes(res, tmp_path, "resumed") == _vision_bytes(ref, tmp_path, "whole")
    assert os.path.getsize(ck) > 0
