"""Fault injection helpers shared by tests/cli/test_kill_resume.py and tests/pipeline/test_demo.py: run
``gtrig`` in a subprocess, send it a signal at a deterministic point, and check that no process it
started survives it."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]


def _sigint_default() -> None:
    # a suite started in the background (`cmd &` in a script, nohup) has SIGINT ignored, and an ignored
    # signal stays ignored across exec: the child would then never see the test's SIGINT and run to the end
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def gtrig(*args: str) -> subprocess.Popen[str]:
    env = {**os.environ, "PYTHONPATH": str(REPO), "OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1"}
    return subprocess.Popen([sys.executable, "-m", "gtrig", *args], env=env, stdout=subprocess.PIPE,
                            stderr=subprocess.STDOUT, text=True, preexec_fn=_sigint_default)


def finish(p: subprocess.Popen[str], timeout: float = 900) -> str:
    out, _ = p.communicate(timeout=timeout)
    assert p.returncode == 0, out
    return out


def descendants(pid: int) -> set[int]:
    """Every process under ``pid`` (Linux /proc)."""
    found: set[int] = set()
    todo = [pid]
    while todo:
        p = todo.pop()
        for task in Path(f"/proc/{p}/task").glob("*"):
            try:
                kids = {int(x) for x in (task / "children").read_text().split()}
            except OSError:
                continue
            todo.extend(kids - found)
            found |= kids
    return found


def alive(pid: int) -> bool:
    try:
        return Path(f"/proc/{pid}/stat").read_text().split(") ")[1][0] != "Z"
    except OSError:
        return False


def interrupt(p: subprocess.Popen[str], ready: Callable[[], bool], sig: int, timeout: float = 600) -> None:
    """Send ``sig`` once ``ready()`` holds; then the process ends and no process it started survives it."""
    t0 = time.monotonic()
    while not ready():
        assert p.poll() is None, f"finished before the kill point:\n{p.communicate()[0]}"
        assert time.monotonic() - t0 < timeout, "the kill point never came"
        time.sleep(0.05)
    kids = descendants(p.pid)
    p.send_signal(sig)
    try:
        out, _ = p.communicate(timeout=120)
    except subprocess.TimeoutExpired:
        p.kill()
        raise AssertionError(f"still running 120 s after {signal.Signals(sig).name}: a hang (open)") from None
    assert p.returncode in ({signal.SIGINT: 130, signal.SIGTERM: 128 + signal.SIGTERM}.get(sig, -sig),
                            -sig), (p.returncode, out)
    assert "Traceback" not in out, out
    t0 = time.monotonic()
    while any(alive(k) for k in kids) and time.monotonic() - t0 < 30:
        time.sleep(0.1)
    assert not any(alive(k) for k in kids), f"pool workers left running after {signal.Signals(sig).name}"


def temporaries(folder: Path) -> list[Path]:
    return [p for p in folder.rglob(".*.tmp")]


def files(folder: Path, skip: tuple[str, ...] = ()) -> dict[str, bytes]:
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*"))
            if p.is_file() and not any(s in p.name for s in skip)}
