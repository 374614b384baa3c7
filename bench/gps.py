"""RTK-GPS reader benchmark: gtrig's reader against pynmea2 + pyproj on the same log.

The logs: the three shared RAWSEEDS Bovisa logs with their prefixes stripped and full two-digit
checksums restored (so pynmea2 verifies every checksum, as gtrig does), and one simulated outdoor
run (GGA/GST/RMC at 5 Hz) long enough to bring the total to about ``--sentences`` sentences. Both
sides do the same job, timed
from the file on disk to local ENU positions of the GGA fixes with their GST sigmas:

- gtrig: ``read_nmea`` -> ``epochs_from_nmea`` -> ``frames.to_local`` (the verb's pipeline minus the
  filter and the writing);
- peer: ``pynmea2.parse`` per line (checksums checked), the GGA's latitude/longitude/altitude and
  the GST's sigmas collected per sentence, then one vectorized pyproj transform to the same ENU.

The two must agree on the positions (to 1 mm) before any figure is printed. On a loaded machine
read the ratio, not the absolute rates.

    python bench/gps.py [--sentences 300000] [--repeat 3]
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np

from gtrig.gps.epochs import epochs_from_nmea
from gtrig.gps.frames import Origin, to_local
from gtrig.gps.nmea import read_nmea

SHARED = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "rawseeds"


def _full_checksum(body: str) -> str:
    x = 0
    for ch in body.encode():
        x ^= ch
    return f"${body}*{x:02X}"


def make_logs(folder: Path, n_target: int) -> list[tuple[Path, int]]:
    """Write the benchmark logs (each one a valid log on its own); returns (path, sentences) per log."""
    out = []
    for d in sorted(SHARED.glob("Bovisa_2008-*/*-GPS.csv")):
        lines = []
        for ln in d.read_text().splitlines():
            i = ln.find("$")
            if i >= 0:
                lines.append(_full_checksum(ln[i + 1:ln.rindex("*")]))
        p = folder / (d.stem + ".nmea")
        p.write_text("\n".join(lines) + "\n")
        out.append((p, len(lines)))
    from gtrig.sim.outdoor import OutdoorParams, simulate_outdoor

    rest = max(n_target - sum(n for _, n in out), 30_000)
    sim = folder / "sim"
    simulate_outdoor(sim, seed=0, params=OutdoorParams(duration_s=rest / 3 / 5.0))
    lines = [ln[ln.find("$"):] for ln in (sim / "gps" / "gps.log").read_text().splitlines()]
    p = folder / "outdoor_sim.nmea"
    p.write_text("\n".join(lines) + "\n")
    out.append((p, len(lines)))
    return out


def run_gtrig(path: Path) -> np.ndarray:
    log = read_nmea(path)
    ep = epochs_from_nmea(log)
    o = Origin(float(ep.lat_deg[0]), float(ep.lon_deg[0]), float(ep.h_m[0]))
    xyz, _ = to_local(ep.lat_deg, ep.lon_deg, ep.h_m, o, "enu", ep.cov_enu)
    return xyz


def run_peer(path: Path) -> np.ndarray:
    import pynmea2
    from pyproj import Transformer

    lat, lon, h, sig = [], [], [], []
    last_t = None
    with open(path, encoding="ascii") as f:
        for ln in f:
            try:
                msg = pynmea2.parse(ln.strip(), check=True)
            except (pynmea2.ParseError, pynmea2.ChecksumError, AttributeError, ValueError):
                continue
            kind = msg.sentence_type
            if kind == "GGA":
                # the same epochs gtrig keeps: a fix, a position, and a new time
                if not msg.gps_qual or not msg.lat or msg.timestamp == last_t:
                    continue
                last_t = msg.timestamp
                lat.append(msg.latitude)
                lon.append(msg.longitude)
                h.append(float(msg.altitude) + float(msg.geo_sep or 0.0))
            elif kind == "GST":
                sig.append((float(msg.std_dev_latitude or "nan"), float(msg.std_dev_longitude or "nan")))
    la, lo, hh = np.array(lat), np.array(lon), np.array(h)
    tr = Transformer.from_pipeline(
        f"+proj=pipeline +step +proj=cart +ellps=WGS84 +step +proj=topocentric +ellps=WGS84 "
        f"+lat_0={float(la[0])!r} +lon_0={float(lo[0])!r} +h_0={float(hh[0])!r}")
    e, n, u = tr.transform(lo, la, hh)
    return np.column_stack([e, n, u])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sentences", type=int, default=300_000)
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args()
    try:
        import pynmea2  # noqa: F401

        have_peer = True
    except ImportError:
        have_peer = False
    with tempfile.TemporaryDirectory() as tmp:
        logs = make_logs(Path(tmp), args.sentences)
        n = sum(k for _, k in logs)
        size = sum(p.stat().st_size for p, _ in logs) / 1e6
        for p, _ in logs:
            run_gtrig(p)  # compile and warm the caches once
        runs = [sum(_timed(run_gtrig, p) for p, _ in logs) for _ in range(args.repeat)]
        t_ours = min(runs, key=lambda r: r[1])
        print(f"logs: {', '.join(f'{p.name} ({k})' for p, k in logs)}: {n} sentences, {size:.1f} MB")
        print(f"gtrig (read_nmea + epochs + ENU):   {_rates(n, t_ours)}")
        if not have_peer:
            print("pynmea2 not installed (pip install -e '.[bench]'): no peer figure")
            return
        # the best of as many runs as gtrig's: on a loaded machine both sides get their quietest pass
        t_peer = min((sum(_timed(run_peer, p) for p, _ in logs) for _ in range(args.repeat)), key=lambda r: r[1])
        worst, fixes = 0.0, 0
        for p, _ in logs:
            a, b = run_gtrig(p), run_peer(p)
            if a.shape != b.shape:
                raise SystemExit(f"{p.name}: gtrig has {len(a)} fixes, the peer {len(b)}")
            worst, fixes = max(worst, float(np.abs(a - b).max())), fixes + len(a)
        if worst > 1e-3:
            raise SystemExit(f"the two disagree by {worst:.3g} m")
        print(f"pynmea2 + pyproj (same job):       {_rates(n, t_peer)}")
        print(f"ratio (CPU): {t_peer[1] / t_ours[1]:.1f}x, (wall): {t_peer[0] / t_ours[0]:.1f}x; "
              f"the same {fixes} fixes, positions agree to {worst * 1e3:.2g} mm")


def _rates(n: int, t: np.ndarray) -> str:
    return (f"wall {t[0]:7.3f} s {n / t[0]:11,.0f} sentences/s;  CPU {t[1]:7.3f} s {n / t[1]:11,.0f} sentences/s")


def _timed(fn, path: Path) -> np.ndarray:
    """(wall, CPU) seconds: on a shared machine the process's CPU time is the closer to an idle wall time."""
    t, c = time.perf_counter(), time.process_time()
    fn(path)
    return np.array([time.perf_counter() - t, time.process_time() - c])


if __name__ == "__main__":
    main()
