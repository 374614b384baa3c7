"""A Dask cluster for the tests as a lab runs one: a ``dask scheduler`` and a ``dask worker`` process
(with its nanny, which replaces a worker that dies), on 127.0.0.1 only; and chunk functions the
workers can import (this module is on their path)."""

from __future__ import annotations

import contextlib
import json
import os
import signal
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
DASK = [sys.executable, "-m", "dask"]  # the `dask` command of this interpreter


def _env() -> dict[str, str]:
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([str(REPO), env.get("PYTHONPATH", "")]).rstrip(os.pathsep)
    env["OMP_NUM_THREADS"] = env["OPENBLAS_NUM_THREADS"] = "1"
    return env


@contextlib.contextmanager
def dask_cluster(folder: Path, nworkers: int = 2, timeout_s: float = 60.0) -> Iterator[str]:
    """Start a scheduler and ``nworkers`` single-threaded worker processes on the loopback interface;
    yields the scheduler's address; stops them all on exit."""
    import distributed

    folder.mkdir(parents=True, exist_ok=True)
    sched_file = folder / "scheduler.json"
    env = _env()
    logs = [open(folder / n, "w") for n in ("scheduler.log", "worker.log")]  # noqa: SIM115
    procs = [subprocess.Popen([*DASK, "scheduler", "--host", "127.0.0.1", "--port", "0",
                               "--no-dashboard", "--scheduler-file", str(sched_file)],
                              stdout=logs[0], stderr=subprocess.STDOUT, env=env, start_new_session=True)]
    try:
        deadline = time.monotonic() + timeout_s
        while not sched_file.is_file() or not sched_file.read_text().strip():
            if time.monotonic() > deadline or procs[0].poll() is not None:
                raise RuntimeError(f"the Dask scheduler did not start: {(folder / 'scheduler.log').read_text()}")
            time.sleep(0.1)
        address = json.loads(sched_file.read_text())["address"]
        assert address.startswith("tcp://127.0.0.1:"), address
        procs.append(subprocess.Popen(
            [*DASK, "worker", address, "--nworkers", str(nworkers), "--nthreads", "1",
             "--host", "127.0.0.1", "--no-dashboard", "--local-directory", str(folder / "workers")],
            stdout=logs[1], stderr=subprocess.STDOUT, env=env, cwd=str(REPO), start_new_session=True))
        with distributed.Client(address, timeout="30s") as c:
            c.wait_for_workers(nworkers, timeout=timeout_s)
        yield address
    finally:
        for p in reversed(procs):  # the whole group of each (a worker's nanny and its child)
            with contextlib.suppress(ProcessLookupError):
                os.killpg(p.pid, signal.SIGTERM)
        for p in reversed(procs):
            try:
                p.wait(timeout=20)
            except subprocess.TimeoutExpired:
                with contextlib.suppress(ProcessLookupError):
                    os.killpg(p.pid, signal.SIGKILL)
                p.wait(timeout=10)
        for f in logs:
            f.close()


# ----------------------------------------------------------------- chunk functions for the workers
def square_or_die(i: int, flag: str) -> tuple[int, int]:
    """``(i * i, pid)``; the first call for ``i == 3`` kills its own process mid-chunk (SIGKILL), once."""
    p = Path(flag)
    if i == 3 and not p.exists():
        p.write_text(str(os.getpid()))
        os.kill(os.getpid(), signal.SIGKILL)
    return i * i, os.getpid()


def fail_on(i: int, bad: int, counts: str | None = None) -> int:
    """``i`` squared, except that chunk ``bad`` always raises (ValueError; with ``counts``, a file to
    count its attempts in, an InputError: bad input)."""
    if i == bad:
        if counts is not None:
            from gtrig.errors import InputError

            with open(counts, "a") as f:
                f.write("x")
            raise InputError(f"image {i}.png: not an image")
        raise ValueError(f"chunk {i} is broken")
    return i * i
