"""The client's memory does not grow with the recording's length: GTvision's run over a
recording three times longer peaks (tracemalloc, in this process) at about the same memory; so does
GTlaser's, beyond its per-frame result (:func:`test_gtlaser_client_memory_is_flat_in_the_log_length`).

The recordings are made without images being detected: a cycle of synthetic detections (noisy corners
of the markers each camera sees, :func:`gtrig.vision.synthetic.synthetic_observations`) is written to
the detection checkpoint for every row of a ``timestamps.csv`` that repeats the cycle, so the run goes
straight to estimation, the stage whose state grew with the length (every instant's detections and
estimate kept for the flips and the motion compensation). The corner-noise calibration is left out:
its sample is bounded by construction (at most 300 instants with markers, :func:`calibrate_noise`), and
a test long enough to fill it would take minutes."""

from __future__ import annotations

import json
import tracemalloc
from pathlib import Path

import cv2
import numpy as np

from gtrig.io.frames import write_frame_index
from gtrig.rig.load import dump_rig
from gtrig.sim.gtroom import VALIDATION_POSES, make_scene
from gtrig.vision.detect import make_detector
from gtrig.vision.estimate import VisionOptions
from gtrig.vision.sequence import (
    CHECKPOINT_VERSION,
    _key,
    _views_to_json,
    camera_indices,
    detection_chunks,
    detector_label,
    make_instants,
    run_recording,
)
from gtrig.vision.synthetic import CornerNoise, synthetic_observations, visible_views
from gtrig.vision.track import TrackOptions

CYCLE = 24  # distinct instants: the robot creeping past validation pose 4, then out of sight (as a run)
SEEN = 2  # instants of the cycle with markers, seen by two cameras (a run's 30 %: 1/12 keeps the test fast)
CHUNK = 4  # instants per chunk: the short run already fills the client's bounded caches of chunks


def make_recording(out: Path, instants: int, seed: int = 1) -> tuple[Path, object]:
    """A run of ``instants`` instants at 10 Hz (every camera's images one blank file of its size, stamps 1 ms apart
    so that each instant holds all cameras) and its seeded detection checkpoint ``out/ck.jsonl``."""
    scene = make_scene(0)
    rig = scene.rig_true
    rng = np.random.default_rng(seed)
    x, y, th = VALIDATION_POSES[3]
    # the first instants of the cycle in view, moving 2 cm a step; the rest out of sight (no marker)
    poses = [scene.T_world_robot(x + 0.02 * k * np.cos(th), y + 0.02 * k * np.sin(th), th) for k in range(SEEN)]
    cams = [c.name for c in rig.cameras]
    seeing = sorted({c for T in poses for c, _, _ in visible_views(rig, T)})[:2]
    views = {(c, k): _views_to_json(synthetic_observations(rig, poses[k], 0.1 * k, rng, CornerNoise(0.2),
                                                           cameras=(c,)).views) if k < SEEN and c in seeing else []
             for c in cams for k in range(CYCLE)}
    for j, cam in enumerate(rig.cameras):
        folder = out / "run" / "cameras" / cam.name
        folder.mkdir(parents=True)
        cv2.imwrite(str(folder / "blank.png"), np.zeros((cam.resolution[1], cam.resolution[0]), np.uint8))
        write_frame_index(folder, 0.1 * np.arange(instants) + 0.001 * j, ["blank.png"] * instants)
    dump_rig(rig, out / "rig.yaml")
    indices = camera_indices(out, "run", rig)
    det = make_detector(rig, "auto")
    key = _key(rig, "run", detector_label(det.name, det.version, TrackOptions(), CHUNK),
               {n: [ix.source(i) for i in range(len(ix))] for n, ix in indices.items()}, out)
    with open(out / "ck.jsonl", "w", encoding="utf-8") as f:
        f.write(json.dumps({"key": key, "version": CHECKPOINT_VERSION}) + "\n")
        for cam, rows in detection_chunks(make_instants(indices, "run"), indices, CHUNK):
            f.write(json.dumps({"camera": cam, "frames": [[r, views[(cam, r % CYCLE)]] for r in rows]}) + "\n")
    return out, rig


def peak_of_run(rec: Path, rig: object) -> tuple[int, int]:
    """(tracemalloc peak in bytes of one GTvision run in this process, instants)."""
    tracemalloc.start()
    try:
        res = run_recording(rec, rig, "run", True, workers=1, checkpoint=rec / "ck.jsonl",  # type: ignore[arg-type]
                            options=VisionOptions(), chunk_size=CHUNK, estimate_noise=False)
        n = len(res.estimates)
        assert sum(e.ok for e in res.estimates) == n * SEEN // CYCLE
        del res
        return tracemalloc.get_traced_memory()[1], n
    finally:
        tracemalloc.stop()


def index_bytes(rec: Path, rig: object) -> int:
    """Bytes held by the recording's index alone: its cameras' frame indices, the instants and the
    detection chunks (read whole before anything runs; the part of the client that still grows)."""
    tracemalloc.start()
    try:
        indices = camera_indices(rec, "run", rig)  # type: ignore[arg-type]
        plan = (indices, make_instants(indices, "run"))
        plan += (detection_chunks(plan[1], indices, CHUNK),)  # type: ignore[assignment]
        return tracemalloc.get_traced_memory()[0]
    finally:
        tracemalloc.stop()


def test_client_memory_is_flat_in_the_recording_length(tmp_path: Path) -> None:
    peak_of_run(*make_recording(tmp_path / "warm", CYCLE))  # imports and first-use caches not measured
    short = make_recording(tmp_path / "short", 120)
    long = make_recording(tmp_path / "long", 360)
    p1, n1 = peak_of_run(*short)
    p3, n3 = peak_of_run(*long)
    i1, i3 = index_bytes(*short), index_bytes(*long)
    print(f"tracemalloc peak: {n1} instants {p1 / 1e6:.3f} MB (index {i1 / 1e6:.3f}), {n3} instants "
          f"{p3 / 1e6:.3f} MB (index {i3 / 1e6:.3f}); {(p3 - p1) / (n3 - n1):.0f} bytes per instant, "
          f"{(p3 - i3 - p1 + i1) / (n3 - n1):.0f} beyond the index")
    assert n3 == 3 * n1
    # beyond the index, the run's own state (detections, estimates, chunks in flight) is flat
    assert p3 - i3 < 1.3 * (p1 - i1)


LASER_CYCLE = 600  # frames of one lap of the simulated robot (8 s at 75 Hz); the long log is three laps


def circle_pose(t: float) -> np.ndarray:
    """The robot of :func:`laser_logs` at ``t`` (s): x, y (m), yaw (rad), world frame; one lap per
    ``LASER_CYCLE`` frames at 75 Hz."""
    w = 2 * np.pi / (LASER_CYCLE / 75.0)
    return np.array([1.2 * np.cos(w * t), 1.2 * np.sin(w * t), w * t + np.pi / 2])


def laser_logs(out: Path, laps: int, background: Path | None = None) -> tuple[Path, object, list]:
    """A robot driving laps of a circle (1.2 m radius, 0.94 m/s) in a rectangular room watched by three
    scanners at 75 Hz: ``out/lasers/<scanner>.csv`` (the first lap's scans repeated with their stamps
    moved on by a lap, so the longer log costs no more to make), the rig and the backgrounds (their scans
    written to ``background/lasers/`` too when given)."""
    from gtrig.io.scans import ScanLog, write_scans
    from gtrig.laser import synth
    from gtrig.laser.background import build_background
    from tests.laser.conftest import make_scanner

    walls = synth.rectangle_segments([[-4, -3], [4, -3], [4, 3], [-4, 3]])
    scs = (make_scanner("a", -3.6, -2.6, np.radians(35)), make_scanner("b", 3.6, -2.2, np.radians(150)),
           make_scanner("c", 3.6, 2.6, np.radians(-145)))
    base = make_scene(0).rig_true
    rig = base.model_copy(update={"laser_scanners": scs})
    hull = rig.robot.hull
    lap_s = LASER_CYCLE / 75.0
    rng = np.random.default_rng(4)
    bst = [np.arange(0, 0.4, 1 / 75) + 0.002 * i for i in range(3)]
    bg = synth.scan_sequence(scs, walls, None, None, bst, rng)
    lap = [np.arange(LASER_CYCLE) / 75.0 + 0.003 * i for i in range(3)]
    run = synth.scan_sequence(scs, walls, hull, circle_pose, lap, rng)
    if background is not None:
        (background / "lasers").mkdir(parents=True)
        for s, t, r in zip(scs, bst, bg, strict=True):
            write_scans(background / "lasers" / f"{s.name}.csv", ScanLog(t, r))
    (out / "lasers").mkdir(parents=True)
    for s, t, r in zip(scs, lap, run, strict=True):
        write_scans(out / "lasers" / f"{s.name}.csv",
                    ScanLog(np.concatenate([t + k * lap_s for k in range(laps)]), np.tile(r, (laps, 1))))
    return out, rig, [build_background(b, s) for b, s in zip(bg, scs, strict=True)]


def laser_peak(seq: Path, rig: object, backgrounds: list) -> tuple[int, int, int]:
    """(tracemalloc peak of one GTlaser run of ``seq`` in this process, its frames, the bytes of its
    result: the per-frame output every run keeps)."""
    import sys

    from gtrig.laser.recording import track_sequence

    tracemalloc.start()
    try:
        res = track_sequence(rig, seq, backgrounds, workers=1)  # type: ignore[arg-type]
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert res.counts()["ok"] > 0.95 * len(res)
    kept = sum(np.asarray(getattr(res, f)).nbytes for f in ("stamps_s", "xytheta", "cov_xytheta", "status",
               "raw_xytheta", "raw_cov_xytheta", "n_points", "n_sides", "rms_m", "track_id", "cov_calibration"))
    return peak, len(res), kept + sum(sys.getsizeof(r) for r in res.reasons)


def test_gtlaser_client_memory_is_flat_in_the_log_length(tmp_path: Path, monkeypatch) -> None:  # type: ignore[no-untyped-def]
    """GTlaser's client over a log three times longer: its peak beyond the result grows by well under a kB
    a frame (it held every scan, every point and the side-bias pass's arrays of them, ~52 kB a frame,
    before; now a window's, and per frame only the poses, covariances and stamps of the filters).
    The logs are indexed in blocks of 200 lines: a block (2,048 lines, ~8 MB, by default) is bounded by
    construction, and one longer than the short log would be counted as growth."""
    import gtrig.io.scans as scans

    monkeypatch.setattr(scans, "INDEX_BLOCK_LINES", 200, raising=False)  # (raising: the test runs on older code too)
    short, long = laser_logs(tmp_path / "short", 1), laser_logs(tmp_path / "long", 3)
    laser_peak(*short)  # imports and first-use caches not measured
    p1, n1, r1 = laser_peak(*short)
    p3, n3, r3 = laser_peak(*long)
    growth = ((p3 - r3) - (p1 - r1)) / (n3 - n1)
    print(f"GTlaser tracemalloc peak: {n1} frames {p1 / 1e6:.2f} MB (result {r1 / 1e6:.2f}), {n3} frames "
          f"{p3 / 1e6:.2f} MB (result {r3 / 1e6:.2f}); {(p3 - p1) / (n3 - n1):.0f} bytes per frame, {growth:.0f} "
          "beyond the result")
    assert n3 == 3 * n1
    assert growth < 1000


def scanner_sync_peak(rec: Path, rig: object, laps: int) -> tuple[int, int]:
    """(tracemalloc peak of the per-scanner clock fit of ``rec`` in this process, the frames of its logs):
    :func:`gtrig.sync.sensors.sensor_offsets_and_laser_clock` for the scanners only, against a
    GTvision track of the true circle (10 Hz, 1 mm / 1 mrad noise)."""
    from gtrig.io.scans import index_scans
    from gtrig.sync.sensors import sensor_offsets_and_laser_clock
    from gtrig.trajectory import PoseTrack

    t = np.arange(0.0, laps * LASER_CYCLE / 75.0, 0.1)
    z = np.array([circle_pose(x) for x in t]) + np.random.default_rng(5).normal(0, 0.001, (t.size, 3))
    vision = PoseTrack.from_xytheta(t, z, cov=np.tile(np.eye(3) * 1e-6, (t.size, 1, 1)), source="vision")
    tracemalloc.start()
    try:
        est, _ = sensor_offsets_and_laser_clock(rec, rig, vision, cameras=False)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert [e.source for e in est] == ["laser/a", "laser/b", "laser/c"]
    return peak, len(index_scans(rec / "run" / "lasers" / "a.csv").stamps_s)


def test_scanner_sync_client_memory_is_flat_in_the_log_length(tmp_path: Path, monkeypatch) -> None:  # type: ignore[no-untyped-def]
    """The sync stage's per-scanner fit over a log three times longer: its peak grows by well under a kB a
    frame (it held every foreground return and the fit's rows of them, (P, n), 21 kB a frame here,
    before; now a window's, and per frame only its stamp and each scanner's count of returns). The
    fit's windows are made shorter than the short log, so that a window's memory is the same in both."""
    import gtrig.io.scans as scans

    monkeypatch.setattr(scans, "INDEX_BLOCK_LINES", 200, raising=False)
    try:
        import gtrig.sync.returns as returns

        monkeypatch.setattr(returns, "WINDOW_FRAMES", 150)
    except ImportError:  # no windowed returns: the test measures the fit that holds every return
        pass
    runs = {}
    for name, laps in (("short", 1), ("long", 3)):
        rec = tmp_path / name
        _, rig, _ = laser_logs(rec / "run", laps, rec / "background")
        cam = rig.cameras[0].name  # type: ignore[attr-defined]
        folder = rec / "run" / "cameras" / cam
        folder.mkdir(parents=True)
        write_frame_index(folder, 0.1 * np.arange(10), ["blank.png"] * 10)  # the camera stamps it reads
        runs[name] = (rec, rig, laps)
    scanner_sync_peak(*runs["short"])  # imports and first-use caches not measured
    p1, n1 = scanner_sync_peak(*runs["short"])
    p3, n3 = scanner_sync_peak(*runs["long"])
    growth = (p3 - p1) / (n3 - n1)
    print(f"per-scanner sync tracemalloc peak: {n1} frames {p1 / 1e6:.2f} MB, {n3} frames {p3 / 1e6:.2f} MB; "
          f"{growth:.0f} bytes per frame")
    assert n3 == 3 * n1
    assert growth < 1000
