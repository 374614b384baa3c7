"""Fuzz run of every reader: any bytes give a result or a GtrigError, never another exception,
a hang or an exhausted memory.

Each reader of ``tests/io/fuzz_cases.py`` gets ``--n`` inputs, in process (no Hypothesis): three in four
are mutations of its valid seed file (1 to 8 edits: bytes flipped, cuts, lines duplicated or dropped,
numbers replaced by nan / inf / huge values, tokens inserted, a splice of the seed into itself), one in
four random bytes. The inputs are files on a RAM disk (``/dev/shm``), so the disk does not set the pace.
Every input has a CPU-time limit (``--limit-s``, ``ITIMER_PROF``: load on the machine does not count)
and the workers an address-space limit (``--max-mem-gib``): a hang or a runaway allocation is a crash.
The work is cut into chunks of ``--chunk`` inputs, interleaved over the readers and mapped over
``--workers`` processes, so a run stopped early has covered every reader alike; ``--progress`` gets the
running totals as JSON after every chunk.

Prints, per reader, inputs tried, accepted, refused with a GtrigError, crashes (any other exception,
hangs included: each distinct one is printed and its input saved under ``--crashes``), and inputs per
second of CPU time in the workers.

    nice -n 19 python bench/fuzz.py [--n 1000000] [--only tum,scans] [--seed 0] [--workers 2]
"""

from __future__ import annotations

import argparse
import json
import logging
import multiprocessing as mp
import os
import random
import resource
import signal
import sys
import tempfile
import time
import traceback
import warnings
from pathlib import Path

# one thread per worker: the CPU-time alarm counts every thread of the process
for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests" / "io"))

from fuzz_cases import READERS, mutate  # noqa: E402

from gtrig.errors import GtrigError  # noqa: E402


class _Hang(BaseException):
    """Raised by the CPU-time alarm: not an Exception, so no reader's ``except Exception`` swallows it."""


def _alarm(signum: int, frame: object) -> None:
    raise _Hang()


_STATE: dict[str, object] = {}


def _init(limit_s: float, max_mem_gib: float, nice: int) -> None:
    """A worker: quiet, niced, bounded in memory, with the per-input CPU alarm; it dies with the parent."""
    from gtrig.parallel import _die_with_parent

    _die_with_parent(os.getppid())
    if nice:
        os.nice(nice)
    logging.disable(logging.CRITICAL)
    warnings.simplefilter("ignore")
    import numpy as np

    np.seterr(all="ignore")
    if max_mem_gib > 0:
        lim = int(max_mem_gib * 2**30)
        resource.setrlimit(resource.RLIMIT_AS, (lim, lim))
    signal.signal(signal.SIGPROF, _alarm)
    root = Path("/dev/shm") if Path("/dev/shm").is_dir() else Path(tempfile.gettempdir())
    _STATE["dir"] = Path(tempfile.mkdtemp(prefix="gtrig_fuzz_", dir=root))
    _STATE["limit_s"] = limit_s
    _STATE["seeds"] = {}


def _input(base: bytes, rnd: random.Random) -> bytes:
    if rnd.random() < 0.25:
        return rnd.randbytes(rnd.randint(0, 1200))
    data = mutate(base, rnd, rnd.randint(1, 8))
    if rnd.random() < 0.1 and data:  # a splice: part of the file repeated elsewhere in it
        i, j, k = sorted(rnd.randrange(len(data) + 1) for _ in range(3))
        data = data[:k] + data[i:j] + data[k:]
    return data


def _chunk(task: tuple[str, int, int, int]) -> dict[str, object]:
    """``n`` inputs of reader ``name``, chunk ``index`` (its own random stream): counts and new crashes."""
    name, index, n, seed = task
    read, valid, suffix = READERS[name]
    seeds: dict[str, bytes] = _STATE["seeds"]  # type: ignore[assignment]
    folder = _STATE["dir"] / name  # type: ignore[operator]
    folder.mkdir(exist_ok=True)
    path = folder / f"in{suffix}"
    if name not in seeds:
        seeds[name] = valid()
        # warm up outside the alarm: the first read imports and loads (or compiles) the reader's numba
        # kernels, seconds of CPU; an alarm inside numba's compiler leaves its dispatcher broken, and every
        # later input of that worker then "crashes" in numba, not in the reader
        path.write_bytes(seeds[name])
        read(path)
    base = seeds[name]
    rnd = random.Random(f"{seed}:{name}:{index}")
    limit = float(_STATE["limit_s"])  # type: ignore[arg-type]
    ok = refused = 0
    crashes: list[tuple[str, str, bytes]] = []
    t0 = time.process_time()
    for _ in range(n):
        data = _input(base, rnd)
        path.write_bytes(data)
        try:
            signal.setitimer(signal.ITIMER_PROF, limit)
            try:
                read(path)
            finally:
                signal.setitimer(signal.ITIMER_PROF, 0)
            ok += 1
        except GtrigError:
            refused += 1
        except _Hang:
            crashes.append(("hang", f"more than {limit:g} s of CPU", data))
        except (Exception, RecursionError, MemoryError) as e:  # a crash: what this run is looking for
            tb = traceback.extract_tb(e.__traceback__)
            where = f"{Path(tb[-1].filename).name}:{tb[-1].lineno}" if tb else "?"
            crashes.append((f"{type(e).__name__}@{where}", " ".join(str(e).split())[:200], data))
    return {"name": name, "n": n, "ok": ok, "refused": refused, "crashes": crashes,
            "cpu_s": time.process_time() - t0}


#: CPU microseconds per input measured on this machine (bench/fuzz.py --n 20000): the order of a run
_COST = {"carmen": 28, "world_distances": 35, "reference_points": 37, "pose_distances": 36, "robot_points": 36,
         "pose_covariance": 44, "odometry": 45, "scans": 45, "tum": 52, "rtklib_pos": 65, "frame_index": 59,
         "rawseeds": 85, "euroc": 88, "camera_yaml": 87, "kitti": 100, "trajectory_csv": 140, "rosbag1": 457,
         "rosbag2_mcap": 406, "rig_yaml": 777, "nmea": 736}


def _table(totals: dict[str, dict[str, float]]) -> str:
    rows = [f"{'reader':16s} {'inputs':>9s} {'accepted':>9s} {'refused':>9s} {'crashes':>8s} {'inputs/cpu-s':>12s}"]
    for name, t in sorted(totals.items()):
        rate = t["n"] / t["cpu_s"] if t["cpu_s"] else 0.0
        rows.append(f"{name:16s} {int(t['n']):9d} {int(t['ok']):9d} {int(t['refused']):9d} {int(t['crashes']):8d} "
                    f"{rate:12.0f}")
    return "\n".join(rows)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--n", type=int, default=1_000_000, help="inputs per reader")
    ap.add_argument("--only", default="", help="comma-separated readers (default: all)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--chunk", type=int, default=5000, help="inputs per task")
    ap.add_argument("--limit-s", type=float, default=2.0, help="CPU seconds one input may take")
    ap.add_argument("--max-mem-gib", type=float, default=2.0, help="address space of a worker (0: no limit)")
    ap.add_argument("--nice", type=int, default=0, help="niceness added in the workers")
    ap.add_argument("--crashes", type=Path, default=Path(tempfile.gettempdir()) / "gtrig_fuzz_crashes")
    ap.add_argument("--order", choices=("equal-cpu", "even"), default="equal-cpu",
                    help="equal-cpu: every reader gets the same CPU time until it reaches --n; even: the same "
                    "number of inputs, all readers in step")
    ap.add_argument("--progress", type=Path, default=None, help="running totals as JSON after every chunk")
    a = ap.parse_args()
    names = [x for x in a.only.split(",") if x] or sorted(READERS)
    unknown = set(names) - set(READERS)
    if unknown:
        ap.error(f"unknown readers: {', '.join(sorted(unknown))}")
    n_chunks = -(-a.n // a.chunk)
    if a.order == "even":
        # chunk i of every reader before chunk i + 1 of any: a stopped run has covered all readers alike
        tasks = [(name, i, min(a.chunk, a.n - i * a.chunk), a.seed) for i in range(n_chunks) for name in names]
    else:
        # equal CPU time per reader: the next chunk is always the one of the reader that has had the least
        # (by _COST); a run stopped early has brought the cheap readers to --n and covered the dear ones
        spent = {name: 0.0 for name in names}
        left = {name: n_chunks for name in names}
        tasks = []
        while any(left.values()):
            name = min((x for x in names if left[x]), key=lambda x: spent[x])
            i = n_chunks - left[name]
            tasks.append((name, i, min(a.chunk, a.n - i * a.chunk), a.seed))
            spent[name] += _COST.get(name, 100) * a.chunk
            left[name] -= 1
    totals = {name: {"n": 0, "ok": 0, "refused": 0, "crashes": 0, "cpu_s": 0.0} for name in names}
    seen: set[str] = set()
    t_wall = time.perf_counter()
    with mp.get_context("fork").Pool(a.workers, _init, (a.limit_s, a.max_mem_gib, a.nice)) as pool:
        for res in pool.imap_unordered(_chunk, tasks):
            t = totals[res["name"]]  # type: ignore[index]
            for k in ("n", "ok", "refused", "cpu_s"):
                t[k] += res[k]  # type: ignore[operator]
            for kind, msg, data in res["crashes"]:  # type: ignore[attr-defined]
                t["crashes"] += 1
                key = f"{res['name']}:{kind}"
                if key not in seen:
                    seen.add(key)
                    a.crashes.mkdir(parents=True, exist_ok=True)
                    (a.crashes / f"{res['name']}_{len(seen)}.bin").write_bytes(data)
                    print(f"  crash {key}: {msg}", flush=True)
            if a.progress is not None:
                a.progress.write_text(json.dumps({"wall_s": time.perf_counter() - t_wall, "totals": totals},
                                                 indent=1))
    print(_table(totals))
    total_crashes = sum(int(t["crashes"]) for t in totals.values())
    print(f"crashes in all: {total_crashes}; wall {time.perf_counter() - t_wall:.0f} s")
    sys.exit(1 if total_crashes else 0)


if __name__ == "__main__":
    main()
