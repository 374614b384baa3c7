"""Fuzz run of every reader (issue 17): any bytes give a result or a GtrigError, never another exception.

Each reader of ``tests/io/fuzz_cases.py`` gets ``--n`` inputs: half mutations of a valid file (bytes
flipped, cuts, lines duplicated or dropped, numbers replaced by nan / inf / huge values, tokens
inserted), half random bytes. Prints, per reader, inputs tried, accepted, refused with a GtrigError, and
crashes (any other exception: each distinct one is printed with its input, saved under ``--crashes``),
and the rate in inputs per second.

    python bench/fuzz.py [--n 1000000] [--only tum,scans] [--seed 0] [--crashes /tmp/gtrig_crashes]
"""

from __future__ import annotations

import argparse
import random
import sys
import tempfile
import time
import traceback
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests" / "io"))

from fuzz_cases import READERS, mutate  # noqa: E402

from gtrig.errors import GtrigError  # noqa: E402


def fuzz_one(name: str, n: int, seed: int, crash_dir: Path) -> tuple[int, int, int, int, float]:
    read, valid, suffix = READERS[name]
    base = valid()
    rnd = random.Random(seed)
    seen: set[str] = set()
    ok = refused = crashes = 0
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / f"in{suffix}"
        t0 = time.perf_counter()
        for i in range(n):
            data = mutate(base, rnd, rnd.randint(1, 4)) if i % 2 == 0 else rnd.randbytes(rnd.randint(0, 600))
            path.write_bytes(data)
            try:
                read(path)
                ok += 1
            except GtrigError:
                refused += 1
            except Exception as e:  # a crash: what this run is looking for
                crashes += 1
                key = f"{type(e).__name__}:{traceback.extract_tb(e.__traceback__)[-1].lineno}"
                if key not in seen:
                    seen.add(key)
                    crash_dir.mkdir(parents=True, exist_ok=True)
                    (crash_dir / f"{name}_{len(seen)}{suffix}").write_bytes(data)
                    print(f"  {name}: {type(e).__name__}: {e}".splitlines()[0][:200], flush=True)
        return ok, refused, crashes, n, time.perf_counter() - t0


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--n", type=int, default=1_000_000, help="inputs per reader")
    ap.add_argument("--only", default="", help="comma-separated readers (default: all)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--crashes", type=Path, default=Path(tempfile.gettempdir()) / "gtrig_fuzz_crashes")
    a = ap.parse_args()
    names = [x for x in a.only.split(",") if x] or sorted(READERS)
    print(f"{'reader':18s} {'inputs':>9s} {'accepted':>9s} {'refused':>9s} {'crashes':>8s} {'inputs/s':>9s}")
    total_crashes = 0
    for name in names:
        ok, refused, crashes, n, dt = fuzz_one(name, a.n, a.seed, a.crashes)
        total_crashes += crashes
        print(f"{name:18s} {n:9d} {ok:9d} {refused:9d} {crashes:8d} {n / dt:9.0f}", flush=True)
    print(f"crashes in all: {total_crashes}")
    sys.exit(1 if total_crashes else 0)


if __name__ == "__main__":
    main()
