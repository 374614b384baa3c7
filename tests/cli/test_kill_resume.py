"""Fault injection: ``gtrig sim`` and ``gtrig vision`` interrupted by SIGINT, then SIGTERM, then SIGKILL,
each at a deterministic point found by polling the output folder (a step of the simulation recorded as
done, GTvision chunks in the checkpoint); after each kill no pool worker is left running, and after
SIGINT and SIGTERM no temporary file; the last rerun resumes, leaves no temporary behind and writes
outputs byte-identical to an uninterrupted run. ``gtrig run`` (and so ``gtrig demo``) is in
tests/pipeline/test_demo.py on the demo's recording.

These run real subprocesses on a tiny recording (about a minute in all on two loaded cores): marked
``faults``, run in CI with the rest of the suite."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path

import pytest

pytestmark = pytest.mark.faults

REPO = Path(__file__).resolve().parents[2]
TINY = ("run_duration_s: 1.0\nstatic_pose_s: 0.1\nbackground_s: 0.3\nn_intrinsic_views: 3\nn_pair_views: 2\n"
        "n_handheld_views: 2\n")


def gtrig(*args: str) -> subprocess.Popen[str]:
    env = {**os.environ, "PYTHONPATH": str(REPO), "OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1"}
    return subprocess.Popen([sys.executable, "-m", "gtrig", *args], env=env, stdout=subprocess.PIPE,
                            stderr=subprocess.STDOUT, text=True)


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
    out, _ = p.communicate(timeout=300)
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


@pytest.fixture(scope="module")
def tiny(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    """The settings file and an uninterrupted recording made with them."""
    d = tmp_path_factory.mktemp("kill")
    cfg = d / "tiny.yaml"
    cfg.write_text(TINY)
    finish(gtrig("sim", "--quick", "--config", str(cfg), "--out", str(d / "whole"), "--workers", "2"))
    return cfg, d / "whole"


def _done(rec: Path) -> list[str]:
    try:
        return list(json.loads((rec / ".gtrig_sim_state.json").read_text())["done"])
    except (OSError, ValueError, KeyError):
        return []


def test_sim_killed_three_ways_resumes_to_the_same_recording(tiny: tuple[Path, Path], tmp_path: Path) -> None:
    cfg, whole = tiny
    out = tmp_path / "rec"
    args = ("sim", "--quick", "--config", str(cfg), "--out", str(out), "--workers", "2")
    # each kill lands while images are rendered by the pool: after the step before them is recorded
    for sig, after in ((signal.SIGINT, "laser scans"), (signal.SIGTERM, "calibration images"),
                       (signal.SIGKILL, "validation images")):
        interrupt(gtrig(*args), lambda a=after: a in _done(out), sig)
        if sig != signal.SIGKILL:
            assert not temporaries(out), temporaries(out)
    assert "run images" not in _done(out)
    finish(gtrig(*args))
    assert not temporaries(out)
    a, b = files(whole), files(out)
    assert a.keys() == b.keys()
    assert [k for k in a if a[k] != b[k]] == []


def test_vision_killed_three_ways_resumes_to_the_same_track(tiny: tuple[Path, Path], tmp_path: Path) -> None:
    _, rec = tiny
    args = ["vision", "--rig", str(rec / "rig.yaml"), "--recording", str(rec), "--sequence", "validation",
            "--workers", "2", "--detector", "aruco"]
    ref = tmp_path / "ref"
    ref.mkdir()
    finish(gtrig(*args, "--out", str(ref / "v.tum"), "--covariance", str(ref / "v_cov.csv")))
    out = tmp_path / "out"
    out.mkdir()
    ck = out / "v.tum.checkpoint.jsonl"

    def chunks() -> int:
        try:
            return max(0, ck.read_text().count("\n") - 1)
        except OSError:
            return 0

    run = [*args, "--out", str(out / "v.tum"), "--covariance", str(out / "v_cov.csv")]
    for sig, n in ((signal.SIGINT, 1), (signal.SIGTERM, 2), (signal.SIGKILL, 3)):
        interrupt(gtrig(*run), lambda n=n: chunks() >= n, sig)
        if sig != signal.SIGKILL:
            assert not temporaries(out)
        assert not (out / "v.tum").exists()
    log = finish(gtrig(*run))
    assert not temporaries(out) and not ck.exists()
    assert (out / "v.tum").read_bytes() == (ref / "v.tum").read_bytes(), log
    assert (out / "v_cov.csv").read_bytes() == (ref / "v_cov.csv").read_bytes()
