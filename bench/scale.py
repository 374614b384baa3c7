"""Scale benchmark: GTvision over a long recording on the local process pool and on Dask.

A long run is made cheaply from a short one: each camera's images of the short run's ``run/`` are
linked once and repeated through a ``timestamps.csv`` that goes on for ``--minutes`` (stamps of the
short run shifted by its length, cycle after cycle; 10 Hz for the simulator's cameras). The stamps,
not the pixels, set the work: every repeated image is read and detected again.

Measured, each in its own process (so each peak is its own):

* throughput: detection (images read and detected on the workers) and the whole GTvision run, in
  images per second per worker, for the local pool and ``--dask local:N``, with 1 and 2 workers, on
  ``--throughput-seconds`` of the run; with the workers' CPU seconds, since wall time on a loaded
  machine is not the code's (rates per CPU second are what to compare; rerun idle for wall figures);
* Dask's overhead per chunk: a map of empty chunks on the same LocalCluster (round trip per chunk),
  and the wall difference per chunk between Dask and the pool with one worker;
* memory: the client's and a worker's peak RSS for the real-detection runs; then the whole
  ``--minutes`` run end to end from a detection checkpoint filled from one detected cycle (the images
  repeat, so the detections of a repeated image are its first detections, byte for byte): estimation,
  noise, flips, motion compensation and the written track, on ``--minutes`` and on fractions of it to
  show how the client's peak grows with the recording's length.

GTlaser's client memory against the laser log's length (``--laser-minutes``): a full recording's
``run/lasers/*.csv`` repeated, lap after lap, with their stamps moved on by the log's length (the robot
jumps back at each seam: the track is lost and found again), tracked in a process of its own.

The whole pipeline on a long full recording (``--run-minutes``): every sensor of a full recording's run
(cameras through their timestamps files, scanner logs, odometry, the true trajectory) repeated lap after
lap with one period, the rest linked; ``gtrig run --workers N`` in a child process into a copy of the short
run's results (its checkpoints; GTvision's detections seeded from the short run's), sampled every second:
the client's and the workers' RSS and CPU per stage.

Usage::

    python bench/scale.py --source REC --rig RESULTS/rig.calibrated.yaml --minutes 60 --work /tmp/scale
    python bench/scale.py --laser-source REC --rig RESULTS/rig.calibrated.yaml --laser-minutes 5 15 --work W
    python bench/scale.py --run-source REC --run-results RESULTS --run-minutes 5 15 60 --work W
    python bench/scale.py --sync-rerun W/run_10min/recording W/run_10min/results OUT
    python bench/scale.py --run-source REC --run-results RESULTS --tracks-minutes 60 --work W
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]


def make_long(source: Path, out: Path, seconds: float | None, lap: tuple[float, float] | None = None,
              ) -> dict[str, int]:
    """``out/run/cameras/<cam>/``: ``source``'s run images hard-linked once, repeated by a timestamps file
    ``seconds`` long (None: once); ``out/rig.yaml`` copied. Returns the images per camera. ``lap`` =
    (period, start): every camera's stamps moved on by the one ``period`` (s) a lap and cut at ``start +
    seconds`` (as :func:`repeat_stamped`, for a recording whose sensors repeat together); default: each
    camera's own period, a number of images."""
    import shutil

    import numpy as np

    from gtrig.io.frames import read_frame_index, write_frame_index

    counts = {}
    for cam_dir in sorted((source / "run" / "cameras").iterdir()):
        if not cam_dir.is_dir():
            continue
        ix = read_frame_index(cam_dir)
        n = len(ix)
        period = float(ix.stamps_s[-1] - ix.stamps_s[0]) + float(np.median(np.diff(ix.stamps_s)))
        total = n if seconds is None else int(round(seconds / period * n))
        if lap is not None and seconds is not None:
            period = lap[0]
            k = np.arange(n * (int(np.ceil(seconds / period)) + 1))
            total = int(np.sum(ix.stamps_s[k % n] + (k // n) * period < lap[1] + seconds))
        dst = out / "run" / "cameras" / cam_dir.name
        dst.mkdir(parents=True, exist_ok=True)
        for f in ix.files:
            if not (dst / f).exists():
                os.link(cam_dir / f, dst / f)
        k = np.arange(total)
        write_frame_index(dst, ix.stamps_s[k % n] + (k // n) * period, [ix.files[i] for i in k % n])
        counts[cam_dir.name] = total
    shutil.copy(source / "rig.yaml", out / "rig.yaml")
    return counts


def _worker_stats(executor: object) -> dict[str, float]:
    """CPU seconds and peak RSS (MB) of the executor's worker processes."""
    from gtrig.executor import is_dask

    if executor is not None and is_dask(executor):
        got = executor.run(_self_stats)  # type: ignore[attr-defined]
        return {"cpu_s": sum(v["cpu_s"] for v in got.values()), "peak_mb": max(v["peak_mb"] for v in got.values())}
    ch = resource.getrusage(resource.RUSAGE_CHILDREN)
    return {"cpu_s": ch.ru_utime + ch.ru_stime, "peak_mb": ch.ru_maxrss / 1024}


def _self_stats() -> dict[str, float]:
    r = resource.getrusage(resource.RUSAGE_SELF)
    return {"cpu_s": r.ru_utime + r.ru_stime, "peak_mb": r.ru_maxrss / 1024}


def _noop(i: int) -> int:
    return i


def _warm(ctx: object, camera: str, path: str) -> None:
    """Imports, the detector's compiled kernels and one image: what a new worker pays once, kept out of
    the per-image CPU figures."""
    from gtrig.vision.sequence import _process_chunk

    _process_chunk(ctx, camera, [0], [path], [0.0])  # type: ignore[arg-type]


def child_vision(rec: Path, rig_path: Path, mode: str, checkpoint: Path | None) -> dict[str, object]:
    """One GTvision run in this process: ``mode`` ``pool:N``, ``dask:N`` (``--dask local:N``: the
    scheduler in this process) or ``tcp:N`` (a scheduler and N workers started as their own processes on
    127.0.0.1, as on a cluster: this process is only the client)."""
    import contextlib

    from gtrig.executor import Chunk, map_chunks, open_executor
    from gtrig.rig import load_rig
    from gtrig.vision.sequence import run_recording, write_pose_track_files

    kind, n = mode.split(":")
    rig = load_rig(rig_path)
    out: dict[str, object] = {"mode": mode}
    with contextlib.ExitStack() as stack:
        spec = {"dask": f"local:{n}", "pool": None}.get(kind)
        if kind == "tcp":
            sys.path.insert(0, str(REPO))
            from tests.scale.cluster import dask_cluster

            spec = stack.enter_context(dask_cluster(rec.parent / f"{rec.name}_cluster", int(n)))
        ex = stack.enter_context(open_executor(spec))
        from gtrig.vision.sequence import WorkerContext, camera_indices
        from gtrig.vision.track import TrackOptions

        ix = next(iter(camera_indices(rec, "run", rig).values()))
        warm = (WorkerContext.of(rig, "auto", TrackOptions()), ix.camera, ix.source(0))  # run_recording's
        if ex is not None:
            ex.run(_warm, *warm)  # type: ignore[attr-defined]
        _warm(*warm)  # the client (forked into the local pool's workers)
        before, me0 = _worker_stats(ex), _self_stats()
        chunks = [0]
        t0 = time.perf_counter()
        res = run_recording(rec, rig, "run", True, workers=int(n), executor=ex, checkpoint=checkpoint,
                            progress=lambda d, total: chunks.__setitem__(0, total))
        wall = time.perf_counter() - t0
        after, me1 = _worker_stats(ex), _self_stats()
        if kind == "pool" and int(n) == 1:  # in this process: the client is the worker
            before, after = {"cpu_s": me0["cpu_s"]}, {"cpu_s": me1["cpu_s"], "peak_mb": me1["peak_mb"]}
        if ex is not None:  # Dask's own cost per chunk: empty chunks, round trip through the scheduler
            t = time.perf_counter()
            map_chunks(_noop, [Chunk((i,), str(i)) for i in range(200)], lambda i, r: None, executor=ex)
            out["noop_ms_per_chunk"] = 1000 * (time.perf_counter() - t) / 200
    write_pose_track_files(res, rec.parent / f"{rec.name}_{kind}{n}.tum")
    images = sum(res.images_per_camera.values())
    out.update(images=images, instants=len(res.estimates), localized=len(res.localized()), chunks=chunks[0],
               wall_s=wall, detect_s=res.seconds["parallel"], worker_cpu_s=after["cpu_s"] - before["cpu_s"],
               worker_peak_mb=after["peak_mb"], client_peak_mb=_self_stats()["peak_mb"],
               client_cpu_s=_self_stats()["cpu_s"])
    return out


def seed_checkpoint(long_rec: Path, rig_path: Path, cycle_ck: Path, out_ck: Path, chunk_size: int = 16) -> int:
    """A detection checkpoint of the long recording from the detections of its first cycle (the images
    repeat: a repeated image's detections are its first ones). Returns the chunk lines written."""
    from gtrig.rig import load_rig
    from gtrig.vision.detect import make_detector
    from gtrig.vision.sequence import (
        CHECKPOINT_VERSION,
        _key,
        camera_indices,
        detection_chunks,
        detector_label,
        make_instants,
    )
    from gtrig.vision.track import TrackOptions

    rig = load_rig(rig_path)
    first: dict[tuple[str, str], object] = {}
    with open(cycle_ck, encoding="utf-8") as f:
        next(f)
        for line in f:
            d = json.loads(line)
            for row, views in d["frames"]:
                first[(d["camera"], int(row))] = views
    indices = camera_indices(long_rec, "run", rig)
    det = make_detector(rig, "auto")
    paths = {name: [ix.source(i) for i in range(len(ix))] for name, ix in indices.items()}
    key = _key(rig, "run", detector_label(det.name, det.version, TrackOptions(), chunk_size), paths, long_rec)
    instants = make_instants(indices, "run")
    n_lines = 0
    with open(out_ck, "w", encoding="utf-8") as f:
        f.write(json.dumps({"key": key, "version": CHECKPOINT_VERSION}) + "\n")
        for cam, rows in detection_chunks(instants, indices, chunk_size):
            n = len(set(indices[cam].files))
            frames = [[r, first[(cam, r % n)]] for r in rows]
            f.write(json.dumps({"camera": cam, "frames": frames}) + "\n")
            n_lines += 1
    return n_lines


def repeat_stamped(src: Path, dst: Path, period: float, reps: int, end_s: float = float("inf"),
                   decimals: int = 9) -> int:
    """``dst``: the rows of the stamped text file ``src`` (CSV or TUM: the stamp is a row's first field;
    header lines, those whose first field is no number, kept once at the top) repeated ``reps`` times,
    each repeat's stamps moved on by ``period`` s, written with ``decimals`` decimals, rows at or after
    ``end_s`` left out; written under a temporary name and renamed. Returns the rows written."""
    sep = "," if src.suffix == ".csv" else " "
    with open(src, encoding="utf-8") as f:
        lines = f.readlines()
    head = [ln for ln in lines if not _stamp_of(ln, sep)[1]]
    body = [_stamp_of(ln, sep) + (ln,) for ln in lines if _stamp_of(ln, sep)[1]]
    tmp = dst.with_name(dst.name + ".tmp")
    n = 0
    with open(tmp, "w", encoding="utf-8") as g:
        g.writelines(head)
        for k in range(reps):
            for t, _, ln in body:
                if t + k * period >= end_s:
                    break
                g.write(f"{t + k * period:.{decimals}f}{sep}{ln.split(sep, 1)[1]}")
                n += 1
    tmp.rename(dst)
    return n


def _stamp_of(line: str, sep: str) -> tuple[float, bool]:
    """(the stamp of a row, True) or (nan, False) for a header or blank line."""
    try:
        return float(line.split(sep, 1)[0]), True
    except ValueError:
        return float("nan"), False


def make_long_laser(source: Path, out: Path, seconds: float) -> int:
    """``out/run/lasers/<scanner>.csv``: ``source``'s run scans repeated for ``seconds`` (each repeat's
    stamps moved on by the log's length, written with 9 decimals as the simulator does), ``out/background``
    linked to ``source``'s. Returns the repeats."""
    import numpy as np

    from gtrig.io.scans import index_scans

    logs = sorted((source / "run" / "lasers").glob("*.csv"))
    rows = [index_scans(p) for p in logs]
    first = min(float(r.stamps_s[0]) for r in rows)
    last = max(float(r.stamps_s[-1]) for r in rows)
    period = last - first + float(np.median(np.diff(rows[0].stamps_s)))
    reps = max(1, int(round(seconds / period)))
    (out / "run" / "lasers").mkdir(parents=True, exist_ok=True)
    if not (out / "background").exists():
        (out / "background").symlink_to((source / "background").resolve())
    for p in logs:
        dst = out / "run" / "lasers" / p.name
        if not dst.is_file():
            repeat_stamped(p, dst, period, reps)
    return reps


def child_laser(rec: Path, rig_path: Path, mode: str) -> dict[str, object]:
    """GTlaser's run of ``rec`` (``track_recording``) on ``mode`` (pool:N or dask:N), in this process: frames,
    wall, the client's CPU and peak RSS, the pool workers' peak RSS."""
    from gtrig.executor import open_executor
    from gtrig.laser.recording import track_recording
    from gtrig.rig.load import load_rig

    kind, n = mode.split(":")
    t0, c0 = time.time(), time.process_time()
    with open_executor(f"local:{n}" if kind == "dask" else None) as ex:
        res = track_recording(rec, "run", rig=load_rig(rig_path), executor=ex, workers=int(n))
    out = {"mode": mode, "frames": len(res), "ok": res.counts()["ok"], "wall_s": time.time() - t0,
           "client_cpu_s": time.process_time() - c0}
    # (ru_maxrss is in kB here; MB = 1000 kB, as lasermem.py and the GTlaser figures of BENCHMARKS.md)
    out["client_peak_mb"] = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1e3
    out["pool_worker_peak_mb"] = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1e3
    return out


#: a lap of a long full recording lasts a multiple of this (s): of every simulated sensor's period (cameras
#: 10 Hz, scanners 75 Hz, odometry 50 Hz), so each sensor's stamps keep their phase from lap to lap
LAP_GRID_S = 0.2


def lap_of(source: Path) -> tuple[float, float]:
    """(period, start) of ``source``'s run, seconds: the first stamp of any camera, scanner or odometry
    row, and the shortest multiple of :data:`LAP_GRID_S` longer than the span of them all by at least one
    grid step (every sensor then repeats with one period: the sensors stay on their clocks)."""
    import math

    from gtrig.io.frames import read_frame_index
    from gtrig.io.odometry import read_odometry
    from gtrig.io.scans import index_scans

    run = source / "run"
    spans = [index_scans(p).stamps_s for p in sorted((run / "lasers").glob("*.csv"))]
    spans += [read_frame_index(d).stamps_s for d in sorted((run / "cameras").iterdir()) if d.is_dir()]
    spans.append(read_odometry(run / "odometry.csv").stamps_s)
    first, last = min(float(t[0]) for t in spans), max(float(t[-1]) for t in spans)
    return LAP_GRID_S * (math.floor((last - first) / LAP_GRID_S) + 2), first


def make_long_run(source: Path, out: Path, seconds: float) -> tuple[dict[str, int], int, float]:
    """A full recording ``seconds`` long in ``out`` made of laps of ``source``: its cameras' images (through
    their timestamps files, :func:`make_long`), its scanner logs, odometry and true trajectory
    (``truth/run.tum``) repeated with their stamps moved on by one lap period (:func:`lap_of`) and cut at
    the same time; every other entry (survey, calibration, background, validation, the rest of truth/)
    linked to ``source``'s. The robot jumps back to the lap's start at each seam. Returns (images per
    camera, laps begun, the lap's period in seconds)."""
    import math

    period, start = lap_of(source)
    end = start + seconds
    reps = math.ceil(seconds / period)
    out.mkdir(parents=True, exist_ok=True)
    for e in source.iterdir():
        if e.name not in ("run", "truth", "rig.yaml") and not (out / e.name).exists():
            (out / e.name).symlink_to(e.resolve())
    (out / "truth").mkdir(exist_ok=True)
    for e in (source / "truth").iterdir():
        if e.name != "run.tum" and not (out / "truth" / e.name).exists():
            (out / "truth" / e.name).symlink_to(e.resolve())
    todo = [(source / "truth" / "run.tum", out / "truth" / "run.tum", 6),
            (source / "run" / "odometry.csv", out / "run" / "odometry.csv", 9)]
    todo += [(p, out / "run" / "lasers" / p.name, 9) for p in sorted((source / "run" / "lasers").glob("*.csv"))]
    (out / "run" / "lasers").mkdir(parents=True, exist_ok=True)
    for src, dst, decimals in todo:
        if not dst.is_file():
            repeat_stamped(src, dst, period, reps, end, decimals)
    counts = make_long(source, out, seconds, (period, start))
    return counts, reps, period


def _sample_tree(pid: int, records: Path, before: dict[str, float], samples: list[dict[str, object]],
                 stop: object, every_s: float = 1.0, journal: Path | None = None) -> None:
    """Every ``every_s`` until ``stop`` is set: the process ``pid``'s RSS and high-water mark (MB), CPU
    seconds, its descendants' RSS (largest, MB) and CPU seconds (summed over every descendant seen, each
    at its last reading), and the stages finished so far (``records``: ``name.pkl`` written as a stage
    ends; one with its mtime in ``before`` is the copied results' own); each sample also appended to
    ``journal`` (JSON lines) as it is taken, so a run cut short still has its figures."""
    import psutil

    proc = psutil.Process(pid)
    cpu_of: dict[int, float] = {}
    t0 = time.time()
    while not stop.is_set():  # type: ignore[attr-defined]
        try:
            with open(f"/proc/{pid}/status", encoding="ascii") as f:
                st = {ln.split(":")[0]: ln.split()[1] for ln in f if ln.startswith(("VmRSS", "VmHWM"))}
            c = proc.cpu_times()
            kids = proc.children(recursive=True)
        except (psutil.Error, OSError):
            break
        if "VmRSS" not in st:  # exited: a zombie's status has no memory lines
            break
        rss = [0.0]
        for k in kids:
            try:
                rss.append(k.memory_info().rss / 1e6)
                kc = k.cpu_times()
                cpu_of[k.pid] = kc.user + kc.system
            except psutil.Error:
                continue
        done = [p.stem for p in records.glob("*.pkl") if p.stat().st_mtime != before.get(p.stem)]
        samples.append({"t": time.time() - t0, "rss_mb": int(st["VmRSS"]) / 1e3, "hwm_mb": int(st["VmHWM"]) / 1e3,
                        "cpu_s": c.user + c.system, "worker_rss_mb": max(rss), "workers": len(kids),
                        "worker_cpu_s": sum(cpu_of.values()), "done": set(done)})
        if journal is not None:
            with open(journal, "a", encoding="utf-8") as f:
                f.write(json.dumps(dict(samples[-1], done=sorted(done))) + "\n")
        stop.wait(every_s)  # type: ignore[attr-defined]


def run_pipeline(rec: Path, out: Path, workers: int, log: Path) -> dict[str, object]:
    """``gtrig run --recording rec --out out --workers N`` in a child process, sampled (:func:`_sample_tree`)
    while it runs: wall, the child's own peak RSS (its high-water mark, last sample) and, per stage, the
    client's and a worker's largest RSS, CPU seconds and wall (a stage ends when its record is written;
    stages reused from the copied results are not timed). ``log``: the child's output."""
    import threading

    import psutil

    from gtrig.pipeline import STAGES

    env = dict(os.environ, PYTHONPATH=str(REPO), OMP_NUM_THREADS="1", OPENBLAS_NUM_THREADS="1")
    records = out / ".gtrig" / "stages"
    before = {p.stem: p.stat().st_mtime for p in records.glob("*.pkl")} if records.is_dir() else {}
    samples: list[dict[str, object]] = []
    t0 = time.time()
    with open(log, "w", encoding="utf-8") as f:
        child = psutil.Popen([sys.executable, "-m", "gtrig", "run", "--recording", str(rec), "--out", str(out),
                              "--workers", str(workers)], stdout=f, stderr=subprocess.STDOUT, env=env)
        stop = threading.Event()
        th = threading.Thread(target=_sample_tree, args=(child.pid, records, before, samples, stop, 1.0,
                                                         log.with_suffix(".samples.jsonl")), daemon=True)
        th.start()
        _, status, ru = os.wait4(child.pid, 0)
        stop.set()
        th.join()
    fresh = {p.stem for p in records.glob("*.pkl") if p.stat().st_mtime != before.get(p.stem)}
    order = [st.name for st in STAGES if st.name in fresh]
    return {"wall_s": time.time() - t0, "exit": os.waitstatus_to_exitcode(status),
            "tree_maxrss_mb": ru.ru_maxrss / 1e3, "client_hwm_mb": max((x["hwm_mb"] for x in samples), default=0.0),
            "stages": _per_stage(samples, order), "samples": samples}


def _per_stage(samples: list[dict[str, object]], order: list[str]) -> list[dict[str, object]]:
    """Per stage that ran (``order``), from the samples taken after the stage before it had finished and
    before it had: the client's largest RSS, a worker's largest RSS, the client's and the workers' CPU
    seconds and the wall (MB, s)."""
    rows, prev = [], None
    for name in order:
        mine = [x for x in samples if name not in x["done"] and (prev is None or prev in x["done"])]  # type: ignore[operator]
        if mine:
            a, b = mine[0], mine[-1]
            rows.append({"stage": name, "wall_s": b["t"] - a["t"],  # type: ignore[operator]
                         "client_peak_mb": max(x["rss_mb"] for x in mine),  # type: ignore[type-var]
                         "worker_peak_mb": max(x["worker_rss_mb"] for x in mine),  # type: ignore[type-var]
                         "client_cpu_s": b["cpu_s"] - a["cpu_s"],  # type: ignore[operator]
                         "worker_cpu_s": b["worker_cpu_s"] - a["worker_cpu_s"]})  # type: ignore[operator]
        prev = name
    tail = [x for x in samples if prev is not None and prev in x["done"]]  # type: ignore[operator]
    if tail:  # after the last stage: the accuracy tables written and printed
        rows.append({"stage": "(after the stages)", "wall_s": tail[-1]["t"] - tail[0]["t"],  # type: ignore[operator]
                     "client_peak_mb": max(x["rss_mb"] for x in tail),  # type: ignore[type-var]
                     "worker_peak_mb": max(x["worker_rss_mb"] for x in tail),  # type: ignore[type-var]
                     "client_cpu_s": tail[-1]["cpu_s"] - tail[0]["cpu_s"],  # type: ignore[operator]
                     "worker_cpu_s": tail[-1]["worker_cpu_s"] - tail[0]["worker_cpu_s"]})  # type: ignore[operator]
    return rows


def long_run(source: Path, results: Path, work: Path, minutes: float, workers: int) -> dict[str, object]:
    """The whole pipeline on a ``minutes`` long full recording made of laps of ``source``
    (:func:`make_long_run`), into a copy of ``source``'s ``results`` (its checkpoints and stage records)
    whose GTvision run checkpoint is seeded from the short run's detections (:func:`seed_checkpoint`: the
    images repeat); :func:`run_pipeline` measures it. Prints one line per stage and returns the figures
    (also written to ``work/run_<minutes>min.json``)."""
    import shutil

    base = work / f"run_{minutes:g}min"
    rec, out = base / "recording", base / "results"
    t = time.time()
    counts, reps, period = make_long_run(source, rec, 60 * minutes)
    if not out.exists():  # copied and seeded under another name, renamed once complete
        part = out.with_name(out.name + ".partial")
        shutil.rmtree(part, ignore_errors=True)
        shutil.copytree(results, part, symlinks=True)
        lines = seed_checkpoint(rec, results / "rig.calibrated.yaml", results / "gt_vision_run.checkpoint",
                                part / "gt_vision_run.checkpoint")
        part.rename(out)
    else:
        lines = -1  # a rerun: the results (and the seeded checkpoint) of the first attempt
    made_s = time.time() - t
    r = run_pipeline(rec, out, workers, base / "gtrig_run.log")
    r.update(minutes=minutes, images=sum(counts.values()), laps=reps, period_s=period, checkpoint_lines=lines,
             made_s=made_s)
    with open(base.with_suffix(".json"), "w", encoding="utf-8") as f:
        json.dump({k: v for k, v in r.items() if k != "samples"} | {
            "samples": [dict(x, done=sorted(x["done"])) for x in r["samples"]]}, f)  # type: ignore[union-attr]
    print(f"gtrig run on {minutes:g} min ({reps} laps of {period:g} s of {source}; {sum(counts.values())} images, "
          f"{len(counts)} cameras; made in {made_s:.0f} s) --workers {workers}: exit {r['exit']}, "
          f"{r['wall_s']:.0f} s wall; client peak {r['client_hwm_mb']:.0f} MB (its high-water mark), "
          f"process tree ru_maxrss {r['tree_maxrss_mb']:.0f} MB", flush=True)
    for st in r["stages"]:  # type: ignore[union-attr]
        print(f"  {st['stage']}: {st['wall_s']:.0f} s wall, client CPU {st['client_cpu_s']:.0f} s, workers' CPU "
              f"{st['worker_cpu_s']:.0f} s; client peak {st['client_peak_mb']:.0f} MB, worker peak "
              f"{st['worker_peak_mb']:.0f} MB", flush=True)
    return r


def lapped_tracks(source: Path, results: Path, work: Path, minutes: float) -> tuple[Path, Path]:
    """A lapped recording ``minutes`` long (:func:`make_long_run`) with a results folder holding ``results``'
    GTvision and GTlaser tracks of ``source`` lapped the same way (their stamps moved on by the lap's
    period, as the images and scans they come from), the run's detection checkpoint seeded, the rig and the
    bias files copied: what :func:`rerun_sync_fusion` needs, without the hours of GTvision and GTlaser on
    the long recording (their poses on repeated images and scans are the short run's, but at the seams,
    where the long run's tracking starts again). Returns (recording, results)."""
    import shutil

    base = work / f"tracks_{minutes:g}min"
    rec, out = base / "recording", base / "results"
    _, reps, period = make_long_run(source, rec, 60 * minutes)
    end = lap_of(source)[1] + 60 * minutes
    (out / ".gtrig").mkdir(parents=True, exist_ok=True)
    for name in ("gt_vision_run.tum", "gt_vision_run_cov.csv", "gt_laser.tum", "gt_laser_cov.csv"):
        if not (out / name).is_file():
            repeat_stamped(results / name, out / name, period, reps, end, 6)
    for name in ("gt_vision_run_bias.yaml", "gt_laser_bias.yaml", "rig.calibrated.yaml"):
        shutil.copy(results / name, out / name)
    if not (out / "gt_vision_run.checkpoint").is_file():
        seed_checkpoint(rec, results / "rig.calibrated.yaml", results / "gt_vision_run.checkpoint",
                        out / "gt_vision_run.checkpoint")
    return rec, out


#: what :func:`rerun_sync_fusion` links from a results folder into its own
_SYNC_INPUTS = ("gt_vision_run.tum", "gt_vision_run_cov.csv", "gt_vision_run_bias.yaml", "gt_laser.tum",
                "gt_laser_cov.csv", "gt_laser_bias.yaml", "gt_vision_run.checkpoint", ".gtrig/scans")


def rerun_sync_fusion(rec: Path, results: Path, out: Path) -> None:
    """The pipeline's sync and fusion stages again on ``results``' GTvision and GTlaser tracks of ``rec``, into
    ``out`` (the tracks, checkpoint and scan cache linked; ``out/rig.calibrated.yaml`` written): a lapped
    recording's, after a change to either stage, without the hours of the stages before. The rig is
    ``results/rig.calibrated.yaml`` with the fixed scanners calibrated again from ``rec`` as the laser stage
    does (that file holds the recording's nominal scanner poses when a later run of the calibration stages
    alone rewrote it; timed against those, the scanners' offsets come out several milliseconds off)."""
    from gtrig.config import RunConfig
    from gtrig.io.posetrack import read_pose_track
    from gtrig.laser.recording import calibrate_recording
    from gtrig.pipeline.context import Products, StageInput
    from gtrig.pipeline.fusion import fusion, sync
    from gtrig.rig import load_rig
    from gtrig.rig.load import dump_rig

    (out / ".gtrig").mkdir(parents=True, exist_ok=True)
    for name in _SYNC_INPUTS:
        if not (out / name).exists() and (results / name).exists():
            (out / name).symlink_to((results / name).resolve())
    scanners, _ = calibrate_recording(rec)
    rig = load_rig(results / "rig.calibrated.yaml").model_copy(update={"laser_scanners": scanners.laser_scanners})
    dump_rig(rig, out / "rig.calibrated.yaml")
    tracks = {"GTvision/run": read_pose_track(out / "gt_vision_run.tum", out / "gt_vision_run_cov.csv", "vision"),
              "GTlaser/run": read_pose_track(out / "gt_laser.tum", out / "gt_laser_cov.csv", "laser")}
    t = time.time()
    synced = sync(StageInput(rec, out, RunConfig(), Products(rig=rig, tracks=tracks), True, workers=1))
    print(f"sync: {time.time() - t:.0f} s wall", flush=True)
    t = time.time()
    fused = fusion(StageInput(rec, out, RunConfig(), Products(rig=rig, tracks=tracks,
                                                              clock_offsets=synced.products["clock_offsets"]),
                              True, workers=1))
    print(f"fusion: {time.time() - t:.0f} s wall", flush=True)
    for row in synced.rows + synced.checks + fused.rows + fused.checks:
        print(f"  {row.stage} | {row.metric} | {row.value:.4g} {row.unit} | {row.target} | {row.ok}", flush=True)


def _child(args: list[str]) -> dict[str, object]:
    cmd = [sys.executable, __file__, "--child", *args]
    env = dict(os.environ, PYTHONPATH=str(REPO), OMP_NUM_THREADS="1", OPENBLAS_NUM_THREADS="1")
    r = subprocess.run(cmd, capture_output=True, text=True, env=env)
    if r.returncode != 0:
        raise RuntimeError(f"{' '.join(cmd)} failed:\n{r.stderr[-3000:]}")
    return json.loads(r.stdout.strip().splitlines()[-1])


def end_to_end(source: Path, rig: Path, work: Path, minutes: float, mode: str) -> None:
    """The whole ``minutes`` run with every image read and detected on the workers (nothing seeded), then
    estimated and written: the client's and a worker's peak for the real thing. Its detection checkpoint
    is kept, so a rerun after an interruption continues where it stopped."""
    rec = work / f"full_{minutes:g}min"
    counts = make_long(source, rec, 60 * minutes)
    ck = work / f"full_{minutes:g}min_{mode.replace(':', '')}.ck"
    r = _child([str(rec), str(rig), mode, str(ck)])
    n = int(mode.split(":")[1])
    print(f"{minutes:g} min end to end on {mode}: {sum(counts.values())} images ({len(counts)} cameras) detected, "
          f"{r['instants']} instants ({r['localized']} localized), {r['chunks']} chunks; {r['wall_s']:.0f} s wall "
          f"(detection {r['detect_s']:.0f} s = {r['images'] / r['detect_s'] / n:.1f} images/s per worker), client "
          f"CPU {r['client_cpu_s']:.0f} s, workers' CPU {r['worker_cpu_s']:.0f} s = "
          f"{r['images'] / max(float(r['worker_cpu_s']), 1e-9):.1f} images per CPU second; client peak "
          f"{r['client_peak_mb']:.0f} MB, worker peak {r['worker_peak_mb']:.0f} MB", flush=True)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--source", type=Path, help="a short recording (gtrig sim --quick)")
    ap.add_argument("--rig", type=Path, help="its calibrated rig (default: SOURCE/rig.yaml)")
    ap.add_argument("--minutes", type=float, default=60.0)
    ap.add_argument("--fractions", type=float, nargs="*", default=[0.25, 0.5, 1.0],
                    help="lengths of the memory runs, as fractions of --minutes")
    ap.add_argument("--throughput-seconds", type=float, default=24.0)
    ap.add_argument("--modes", nargs="*", default=["pool:1", "dask:1", "pool:2", "dask:2"])
    ap.add_argument("--work", type=Path, default=Path("/tmp/gtrig_scale"))
    ap.add_argument("--memory-mode", default="dask:2",
                    help="executor of the seeded memory runs (--fractions): pool:N, dask:N or tcp:N")
    ap.add_argument("--end-to-end", nargs="*", default=[], metavar="MODE",
                    help="also detect every image of the whole --minutes run (no seeded checkpoint) on each MODE "
                         "(pool:N, dask:N, tcp:N); resumable: rerun to continue from its checkpoint")
    ap.add_argument("--laser-source", type=Path, help="a full recording whose laser logs --laser-minutes repeats")
    ap.add_argument("--laser-minutes", type=float, nargs="*", default=[],
                    help="GTlaser's client memory on laser logs this long (minutes, each in its own process)")
    ap.add_argument("--laser-mode", default="pool:2", help="executor of the GTlaser runs: pool:N or dask:N")
    ap.add_argument("--run-source", type=Path, help="a short full recording that --run-minutes repeats")
    ap.add_argument("--run-results", type=Path, help="its results folder (gtrig run): checkpoints, stage records")
    ap.add_argument("--run-minutes", type=float, nargs="*", default=[],
                    help="gtrig run end to end on a full recording this long (minutes, each in its own process)")
    ap.add_argument("--run-workers", type=int, default=2, help="--workers of those runs")
    ap.add_argument("--sync-rerun", nargs=3, type=Path, metavar=("REC", "RESULTS", "OUT"),
                    help="the sync and fusion stages again on RESULTS' tracks of REC, into OUT (rerun_sync_fusion)")
    ap.add_argument("--tracks-minutes", type=float, default=None,
                    help="with --run-source and --run-results: a lapped recording this long with the short run's "
                         "tracks lapped (lapped_tracks), then --sync-rerun on it into WORK/tracks_<m>min/sync")
    ap.add_argument("--child", nargs="*", help=argparse.SUPPRESS)
    ap.add_argument("--laser-child", nargs=3, help=argparse.SUPPRESS)
    a = ap.parse_args()
    if a.laser_child:
        rec, rig, mode = a.laser_child
        print(json.dumps(child_laser(Path(rec), Path(rig), mode)))
        return
    if a.sync_rerun:
        rerun_sync_fusion(*a.sync_rerun)
        return
    if a.tracks_minutes:
        if a.run_source is None or a.run_results is None:
            ap.error("--tracks-minutes needs --run-source REC and --run-results RESULTS")
        rec, res = lapped_tracks(a.run_source, a.run_results, a.work, a.tracks_minutes)
        rerun_sync_fusion(rec, res, res.parent / "sync")
        return
    if a.run_minutes:
        if a.run_source is None or a.run_results is None:
            ap.error("--run-minutes needs --run-source REC and --run-results RESULTS")
        for minutes in a.run_minutes:
            long_run(a.run_source, a.run_results, a.work, minutes, a.run_workers)
        return
    if a.laser_minutes:
        if a.laser_source is None or a.rig is None:
            ap.error("--laser-minutes needs --laser-source REC and --rig RIG")
        env = dict(os.environ, PYTHONPATH=str(REPO))
        for minutes in a.laser_minutes:
            rec = a.work / f"laser_{minutes:g}min"
            reps = make_long_laser(a.laser_source, rec, 60 * minutes)
            cmd = [sys.executable, __file__, "--laser-child", str(rec), str(a.rig), a.laser_mode]
            r = subprocess.run(cmd, capture_output=True, text=True, env=env)
            if r.returncode != 0:
                raise RuntimeError(f"{' '.join(cmd)} failed:\n{r.stderr[-3000:]}")
            d = json.loads(r.stdout.strip().splitlines()[-1])
            print(f"GTlaser {minutes:g} min ({reps} repeats of {a.laser_source}) on {a.laser_mode}: "
                  f"{d['frames']} frames ({d['ok']} OK), {d['wall_s']:.0f} s wall, client CPU "
                  f"{d['client_cpu_s']:.0f} s; client peak "
                  f"{d['client_peak_mb']:.0f} MB, pool worker peak {d['pool_worker_peak_mb']:.0f} MB", flush=True)
        return
    if a.child:
        rec, rig, mode, ck = a.child
        print(json.dumps(child_vision(Path(rec), Path(rig), mode, Path(ck) if ck != "-" else None)))
        return
    if a.source is None:
        ap.error("--source REC is needed")
    rig = a.rig or a.source / "rig.yaml"
    a.work.mkdir(parents=True, exist_ok=True)
    rows = []
    short = a.work / "short"
    make_long(a.source, short, a.throughput_seconds)
    print(f"throughput on {a.throughput_seconds:g} s of the run ({short}); loaded machine: compare the per "
          "CPU-second rates, rerun idle for wall-clock figures", flush=True)
    for mode in a.modes:
        r = _child([str(short), str(rig), mode, "-"])
        rows.append(r)
        n = int(mode.split(":")[1])
        print(f"  {mode}: {r['images']} images, {r['chunks']} chunks; detection {r['detect_s']:.1f} s wall = "
              f"{r['images'] / r['detect_s'] / n:.1f} images/s per worker; whole run {r['wall_s']:.1f} s; "
              f"worker CPU {r['worker_cpu_s']:.1f} s = {r['images'] / max(r['worker_cpu_s'], 1e-9):.1f} images "
              f"per CPU second; client peak {r['client_peak_mb']:.0f} MB, worker peak {r['worker_peak_mb']:.0f} MB"
              + (f"; empty chunk round trip {r['noop_ms_per_chunk']:.1f} ms" if "noop_ms_per_chunk" in r else ""),
              flush=True)
    by = {r["mode"]: r for r in rows}
    for n in (1, 2):
        p, d = by.get(f"pool:{n}"), by.get(f"dask:{n}")
        if p and d:
            per = (float(d["detect_s"]) - float(p["detect_s"])) / max(int(d["chunks"]), 1)  # type: ignore[arg-type]
            print(f"  {n} worker(s): Dask / pool detection rate {float(p['detect_s']) / float(d['detect_s']):.2f} "
                  f"(wall), {float(p['worker_cpu_s']) / float(d['worker_cpu_s']):.2f} (CPU); Dask's wall overhead "
                  f"{1000 * per:.0f} ms per chunk", flush=True)
    for mode in a.end_to_end:
        end_to_end(a.source, rig, a.work, a.minutes, mode)
    if not a.fractions:
        return
    # memory over the long run: detections of one cycle checkpointed, repeated through the hour
    cycle_ck = a.work / "cycle.ck"
    cyc = a.work / "cycle"
    make_long(a.source, cyc, None)  # one cycle: every image once
    _child([str(cyc), str(rig), "pool:2", str(cycle_ck)])
    for frac in a.fractions:
        minutes = a.minutes * frac
        rec = a.work / f"long_{minutes:g}min"
        counts = make_long(a.source, rec, 60 * minutes)
        ck = a.work / f"long_{minutes:g}min.ck"
        lines = seed_checkpoint(rec, rig, cycle_ck, ck)
        r = _child([str(rec), str(rig), a.memory_mode, str(ck)])
        print(f"{minutes:g} min on {a.memory_mode}: {sum(counts.values())} images ({len(counts)} cameras), "
              f"{r['instants']} instants, "
              f"{lines} detection chunks from the checkpoint; end to end {r['wall_s']:.0f} s wall, client CPU "
              f"{r['client_cpu_s']:.0f} s, workers' CPU {r['worker_cpu_s']:.0f} s; client peak "
              f"{r['client_peak_mb']:.0f} MB, worker peak {r['worker_peak_mb']:.0f} MB", flush=True)


if __name__ == "__main__":
    main()
