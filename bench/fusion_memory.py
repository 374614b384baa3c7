"""Peak memory of the two smoothings with odometry against the recording's length.

The sync stage's joint camera fit smooths GTvision and GTlaser with odometry
(:func:`gtrig.sync.joint_cameras.joint_reference`, 1 + C + 3 times a run), and the fusion stage
smooths them again (:func:`gtrig.fusion.fuse_tracks`, with the offsets' sigmas and the sources' bias
covariances, as ``gtrig.pipeline.fusion`` calls it). Both estimate the odometry calibration over the
whole run: one batch. Here each runs on a synthetic run at a recording's rates
(``tests/fusion_synth.py: long_run``: odometry 50 Hz, GTlaser 75 Hz, GTvision ``--vision-hz``),
each length in a child process of its own, after a one-minute warm-up call (numba's caches, lazy imports),
measured twice:

* RSS: the peak resident set of the call over the resident set before it (``/proc/self/clear_refs``
  resets the high-water mark, VmHWM), without tracemalloc;
* tracemalloc's peak of a second call (Python's and numpy's allocations; numba's work arrays are numpy's).

Usage::

    python bench/fusion_memory.py --minutes 5 15 30 60            # both calls
    python bench/fusion_memory.py --minutes 5 15 --calls fusion --json out.json
"""

from __future__ import annotations

import argparse
import gc
import json
import subprocess
import sys
import time
import tracemalloc
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "tests"))

#: the pipeline's two smoothings with odometry, by name
CALLS = ("joint", "fusion")
#: the per-source run-constant errors' covariances (x, y, yaw; m^2, rad^2), of the size the stages write
BIAS = {"vision": np.diag([0.07e-3, 0.07e-3, 1e-4]) ** 2, "laser": np.diag([1.0e-3, 0.95e-3, 3.8e-4]) ** 2}


def smoothing(call: str, minutes: float, vision_hz: float, seed: int = 0) -> object:
    """One call of ``call`` (:data:`CALLS`) on a synthetic run of ``minutes``; returns its result."""
    from fusion_synth import long_run

    from gtrig.fusion import FusionOptions, fuse_tracks
    from gtrig.sync.joint_cameras import joint_reference

    odo, vision, laser = long_run(minutes, vision_hz=vision_hz, seed=seed)
    return _call(call, odo, vision, laser, joint_reference, fuse_tracks, FusionOptions)


def _call(call: str, odo, vision, laser, joint_reference, fuse_tracks, FusionOptions) -> object:  # noqa: ANN001, N803
    if call == "joint":
        return joint_reference(vision, laser, odo, 0.0)
    off = {"vision": 0.0, "laser": 0.0}
    opts = FusionOptions(offsets_s=off, offsets_sigma_s={"vision": 2e-4, "laser": 3e-4}, bias_cov=BIAS)
    return fuse_tracks({"vision": vision, "laser": laser}, odo, opts)


def _status_mb(key: str) -> float:
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith(key + ":"):
            return float(line.split()[1]) / 1024.0
    return float("nan")


def child(call: str, minutes: float, vision_hz: float) -> dict[str, float]:
    """In this process: warm up, then the RSS peak and tracemalloc's peak of ``call`` on ``minutes``."""
    from fusion_synth import long_run

    from gtrig.fusion import FusionOptions, fuse_tracks
    from gtrig.sync.joint_cameras import joint_reference

    fns = (joint_reference, fuse_tracks, FusionOptions)
    _call(call, *long_run(1.0, vision_hz=vision_hz, seed=1), *fns)  # warm-up: compiled caches, imports
    odo, vision, laser = long_run(minutes, vision_hz=vision_hz)
    gc.collect()
    Path("/proc/self/clear_refs").write_text("5")  # reset VmHWM to the current RSS
    rss0 = _status_mb("VmRSS")
    t = time.perf_counter()
    res = _call(call, odo, vision, laser, *fns)
    wall = time.perf_counter() - t
    rss_peak = _status_mb("VmHWM")
    del res
    gc.collect()
    tracemalloc.start()
    try:
        _call(call, odo, vision, laser, *fns)
        _, traced = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    return {"call": call, "minutes": minutes, "nodes": len(odo), "vision": len(vision), "laser": len(laser),
            "rss_before_mb": rss0, "rss_peak_mb": rss_peak, "rss_growth_mb": rss_peak - rss0,
            "traced_peak_mb": traced / 2**20, "seconds": wall}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--minutes", type=float, nargs="+", default=[5.0, 15.0, 30.0, 60.0])
    ap.add_argument("--calls", nargs="+", choices=CALLS, default=list(CALLS))
    ap.add_argument("--vision-hz", type=float, default=10.0, help="GTvision's poses per second")
    ap.add_argument("--json", type=Path, help="write the rows here")
    ap.add_argument("--child", nargs=2, metavar=("CALL", "MINUTES"), help=argparse.SUPPRESS)
    a = ap.parse_args(argv)
    if a.child:
        print(json.dumps(child(a.child[0], float(a.child[1]), a.vision_hz)))
        return 0
    rows = []
    for call in a.calls:
        for m in a.minutes:
            out = subprocess.run([sys.executable, __file__, "--child", call, str(m), "--vision-hz", str(a.vision_hz)],
                                 check=True, capture_output=True, text=True)
            rows.append(json.loads(out.stdout.strip().splitlines()[-1]))
            r = rows[-1]
            print(f"{call:6s} {m:5.0f} min  {r['nodes']:7d} nodes  RSS +{r['rss_growth_mb']:7.1f} MB "
                  f"(peak {r['rss_peak_mb']:7.1f})  traced peak {r['traced_peak_mb']:7.1f} MB  {r['seconds']:6.1f} s",
                  flush=True)
    for call in a.calls:
        rr = [r for r in rows if r["call"] == call]
        if len(rr) >= 2:
            m = np.array([r["minutes"] for r in rr])
            for key in ("rss_growth_mb", "traced_peak_mb"):
                slope, icpt = np.polyfit(m, [r[key] for r in rr], 1)
                print(f"{call:6s} {key}: {slope:.2f} MB per minute (+{icpt:.1f} MB); "
                      f"60 min: {icpt + 60 * slope:.0f} MB")
    if a.json:
        a.json.write_text(json.dumps(rows, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
