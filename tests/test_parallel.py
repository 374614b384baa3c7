"""Process pools: workers die with their parent, even on SIGKILL."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    # a zombie is dead for our purpose
    try:
        with open(f"/proc/{pid}/stat") as f:
            return f.read().split()[2] != "Z"
    except OSError:
        return False


def test_workers_die_when_the_parent_is_killed():
    script = """
import os, time
from gtrig.parallel import process_pool
def pid(_):
    return os.getpid()
with process_pool(2) as ex:
    pids = set(ex.map(pid, range(8)))
    print(' '.join(map(str, sorted(pids))), flush=True)
    time.sleep(120)
"""
    p = subprocess.Popen([sys.executable, "-c", script], stdout=subprocess.PIPE, text=True)
    assert p.stdout is not None
    workers = [int(x) for x in p.stdout.readline().split()]
    assert workers and all(_alive(w) for w in workers)
    p.send_signal(signal.SIGKILL)
    p.wait(timeout=30)
    deadline = time.monotonic() + 20
    while any(_alive(w) for w in workers) and time.monotonic() < deadline:
        time.sleep(0.1)
    assert not any(_alive(w) for w in workers)


def test_a_signal_between_the_workers_start_and_their_manager_ends_the_run():
    # The signal is sent right after the pool's workers are forked and before the thread that would tell
    # them to stop exists, by a thread started before the pool (as a progress bar's is): blocking it in
    # the main thread alone did not hold it (the kernel gives it to that thread, and Python then runs the
    # handler in the main thread) and the exit waited for the workers forever.
    script = """
import os, signal, sys, threading
from concurrent.futures import process as cfp
from gtrig.parallel import process_pool

def term(signum, frame):
    raise SystemExit(143)

signal.signal(signal.SIGTERM, term)
go, sent = threading.Event(), threading.Event()

def sender():
    go.wait()
    os.kill(os.getpid(), signal.SIGTERM)
    sent.set()

threading.Thread(target=sender, daemon=True).start()
launch = cfp.ProcessPoolExecutor._launch_processes

def launch_then_signal(self):
    launch(self)
    print(" ".join(str(p) for p in self._processes), flush=True)
    go.set()
    sent.wait()

cfp.ProcessPoolExecutor._launch_processes = launch_then_signal
with process_pool(2) as ex:
    print(sum(ex.map(abs, range(10))), flush=True)
"""
    p = subprocess.Popen([sys.executable, "-c", script], stdout=subprocess.PIPE, text=True)
    try:
        out, _ = p.communicate(timeout=60)
    except subprocess.TimeoutExpired:
        p.kill()
        out, _ = p.communicate()
        raise AssertionError("still running 60 s after SIGTERM: the exit waits for the pool's workers") from None
    workers = [int(x) for x in out.split()[:2]]
    assert p.returncode == 143, out
    assert len(workers) == 2 and not any(_alive(w) for w in workers)
    assert "45" not in out.split()[2:]  # the map never ran to its end
