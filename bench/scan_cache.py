"""The scan cache: what parsing a laser log costs against reading its parsed ranges back.

For each ``REC/run/lasers/*.csv``, in this process, CPU seconds (``time.process_time``, so a loaded
machine changes them less than wall time) of:

* ``read_scans``: the whole log parsed at once (the reference reading);
* ``index_scans``: the block-wise validation and index, without a cache folder;
* ``index_scans(cache=)``, building: the same pass writing the parsed ranges (plus the log's hash);
* ``index_scans(cache=)``, reusing: the log hashed and its files found, nothing parsed;
* every window of ``--window`` scans read with ``ScanRows.read``: from the text (what each GTlaser pass
  cost before the cache) and from the binary file.

The cache folder is a temporary one (removed at the end) unless ``--cache`` names one. Every window read
from the binary file is checked equal, bit for bit, to the text's.

    python bench/scan_cache.py --recording REC [--window 256] [--cache DIR]
"""

from __future__ import annotations

import argparse
import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from typing import TypeVar

from gtrig.io.scans import ScanRows, index_scans, read_scans

_T = TypeVar("_T")


def cpu(f: Callable[[], _T]) -> tuple[_T, float]:
    """``f()`` and the CPU seconds it took."""
    c = time.process_time()
    out = f()
    return out, time.process_time() - c


def windows(rows: ScanRows, w: int) -> list[bytes]:
    """Every window of ``w`` scans read through ``rows``."""
    return [rows.read(a, min(a + w, len(rows))).tobytes() for a in range(0, len(rows), w)]


def bench_log(p: Path, cache: Path, w: int) -> dict[str, float]:
    """CPU seconds of each way of reading ``p`` (module docstring); checks the binary file's values."""
    _, t_read = cpu(lambda: read_scans(p))
    plain, t_index = cpu(lambda: index_scans(p))
    built, t_build = cpu(lambda: index_scans(p, cache=cache))
    reused, t_reuse = cpu(lambda: index_scans(p, cache=cache))
    if built.ranges_file is None or reused.ranges_file is None:
        raise SystemExit(f"{cache}: the cache folder could not be written")
    text, t_text = cpu(lambda: windows(plain, w))
    binary, t_bin = cpu(lambda: windows(reused, w))
    if text != binary:
        raise SystemExit(f"{p}: the cached ranges differ from the text's")
    return {"scans": len(plain), "MB": p.stat().st_size / 1e6, "read_scans": t_read, "index": t_index,
            "index_build": t_build, "index_reuse": t_reuse, "windows_text": t_text, "windows_cache": t_bin,
            "cache_MB": built.ranges_file.stat().st_size / 1e6}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--recording", type=Path, required=True, help="a recording with run/lasers/*.csv")
    ap.add_argument("--window", type=int, default=256, help="scans per window read (GTlaser: 256 frames)")
    ap.add_argument("--cache", type=Path, help="cache folder to use (default: a temporary one)")
    a = ap.parse_args()
    logs = sorted((a.recording / "run" / "lasers").glob("*.csv"))
    if not logs:
        raise SystemExit(f"{a.recording}: no run/lasers/*.csv")
    with tempfile.TemporaryDirectory(prefix="gtrig-scan-cache-") as tmp:
        cache = a.cache or Path(tmp)
        rows = [bench_log(p, cache, a.window) for p in logs]
    tot = {k: sum(r[k] for r in rows) for k in rows[0]}
    n = tot["scans"]
    print(f"{len(logs)} logs, {n:.0f} scans, {tot['MB']:.1f} MB of text, {tot['cache_MB']:.1f} MB cached; "
          f"CPU s (scans per CPU second):")
    for k in ("read_scans", "index", "index_build", "index_reuse", "windows_text", "windows_cache"):
        print(f"  {k:14s} {tot[k]:8.3f} s  ({n / max(tot[k], 1e-9):12,.0f} scans/s)")


if __name__ == "__main__":
    main()
