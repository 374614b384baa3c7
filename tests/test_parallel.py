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
