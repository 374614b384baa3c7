"""RTK-GPS ground truth, measured (issue 23): the shared Bovisa logs and simulated outdoor runs.

Real logs (``../shared/data/rawseeds/Bovisa_2008-*``): fix-type shares over time, fixes kept by the
default filter (RTK fixed, sigmas < 0.2 m) and by the RAWSEEDS-like one (any fix, sigmas < 0.2 m),
lost-fix intervals, the log clock's offset and drift against GPS time, and how the GST ellipse
agrees with its latitude/longitude sigmas and with the positions' own jitter (the shape likelihood of
the second differences of the positions under each reading of the ellipse's orientation).

Simulated runs (``gtrig.sim.outdoor``, ``--seeds``): fixed-only positions within 3 sigma (each axis)
and NEES / dof against truth; float multipath outliers rejected; the odometry-smoothed trajectory
(fusion) on the lost-fix stretches within 3 sigma, and its NEES / dof.

    python bench/gps_accuracy.py [--seeds 0 1 2] [--duration 420] [--figures DIR]
"""

from __future__ import annotations

import argparse
import json
import tempfile
import time
from pathlib import Path

import numpy as np

from gtrig.gps.filter import FilterOptions
from gtrig.gps.frames import Origin
from gtrig.gps.groundtruth import GpsOptions, gps_ground_truth
from gtrig.gps.nmea import read_nmea
from gtrig.gps.report import gps_report
from gtrig.io.tum import read_tum

SHARED = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "rawseeds"


def ellipse_conventions(path: Path) -> dict[str, float]:
    """Mean log shape likelihood (nats per sample) of the positions' second differences under the
    ellipse read from north clockwise (NMEA), from east counter-clockwise and from east clockwise;
    and the median relative mismatch of the latitude sigma with each reading's north sigma."""
    log = read_nmea(path)
    g, s = log.sentences["GGA"], log.sentences["GST"]
    n = min(len(g), len(s))
    lat, lon, q = g["lat_deg"][:n], g["lon_deg"][:n], g["quality"][:n]
    N = (lat - lat[0]) * 111132.954
    E = (lon - lon[0]) * 111319.49 * np.cos(np.radians(lat[0]))
    a, b, th = s["major_m"][:n], s["minor_m"][:n], np.radians(s["orient_deg"][:n])
    e = np.stack([E[2:] - 2 * E[1:-1] + E[:-2], N[2:] - 2 * N[1:-1] + N[:-2]], 1)
    ok = (q[1:-1] > 0) & (q[2:] > 0) & (q[:-2] > 0) & (np.abs(e).max(1) > 0) & (a[1:-1] > b[1:-1])
    out = {}
    for name, (dE, dN) in {"north_cw (NMEA)": (np.sin(th), np.cos(th)), "east_ccw": (np.cos(th), np.sin(th)),
                           "east_cw": (np.cos(th), -np.sin(th))}.items():
        dE, dN, a2, b2 = dE[1:-1], dN[1:-1], a[1:-1] ** 2, b[1:-1] ** 2
        S = np.empty((dE.size, 2, 2))
        S[:, 0, 0] = a2 * dE**2 + b2 * dN**2
        S[:, 1, 1] = a2 * dN**2 + b2 * dE**2
        S[:, 0, 1] = S[:, 1, 0] = (a2 - b2) * dE * dN
        S = S[ok] / np.trace(S[ok], axis1=1, axis2=2)[:, None, None]
        x = e[ok]
        m = np.einsum("ni,nij,nj->n", x, np.linalg.inv(S), x)
        out[name] = float(np.mean(-0.5 * np.log(np.linalg.det(S)) - np.log(m)))
    vN_nmea = a**2 * np.cos(th) ** 2 + b**2 * np.sin(th) ** 2
    vE_nmea = a**2 * np.sin(th) ** 2 + b**2 * np.cos(th) ** 2
    big = a > 0.05
    sl = s["sigma_lat_m"][:n]
    out["lat_sigma_vs_north_nmea"] = float(np.median(np.abs(np.sqrt(vN_nmea[big]) - sl[big]) / sl[big]))
    out["lat_sigma_vs_east_nmea"] = float(np.median(np.abs(np.sqrt(vE_nmea[big]) - sl[big]) / sl[big]))
    out["samples"] = float(ok.sum())
    return out


def real_logs(figures: Path | None) -> None:
    print("## Bovisa logs (RTK-GPS, Trimble 5700 rover)")
    print("| log | lines | epochs | RTK fixed | RTK float | DGPS | single | no fix | kept (fixed) "
          "| kept (RAWSEEDS-like) "
          "| lost-fix intervals (fixed) | log - UTC | clock drift |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    for p in sorted(SHARED.glob("Bovisa_2008-*/*-GPS.csv")):
        t = time.perf_counter()
        res = gps_ground_truth(p)
        dt = time.perf_counter() - t
        rep = gps_report(res)
        like = gps_ground_truth(p, GpsOptions(frame="utm", filter=FilterOptions(fix="any", outlier_gate=None)))
        sh = rep["fix_share_time"]
        lost = rep["lost_fix_intervals"]
        off = rep["clock_offset_log_minus_utc_s"]
        print(f"| {p.parent.name} | {rep['lines']['total']} | {rep['epochs']} | {sh.get('rtk_fixed', 0):.1%} | "
              f"{sh.get('rtk_float', 0):.1%} | {sh.get('dgps', 0):.1%} | {sh.get('single', 0):.1%} | "
              f"{sh.get('no_fix', 0):.1%} | {rep['kept']} | {len(like.track)} | "
              f"{lost['count']} ({lost['total_s']:.0f} s, "
              f"longest {lost['longest_s']:.0f} s) | {off['median']:.3f} s | {off['drift'] * 1e6:.0f} ppm |")
        print(f"  ({dt:.2f} s for the whole verb's pipeline)")
        if figures is not None:
            from gtrig.gps.plots import coverage_map

            coverage_map(res, figures / f"gps_coverage_{p.parent.name}.png", ellipse_every=100,
                         title=f"{p.parent.name}: fix type per epoch; kept: RTK fixed, sigmas < 0.2 m; "
                               "1-sigma x10")
    print("\nGST ellipse conventions (positions' jitter shape likelihood, nats/sample; higher is better):")
    for p in sorted(SHARED.glob("Bovisa_2008-*/*-GPS.csv")):
        c = ellipse_conventions(p)
        print(f"  {p.parent.name}: " + ", ".join(f"{k} {v:.3f}" for k, v in c.items()))


def simulated(seeds: list[int], duration: float) -> None:
    from gtrig.gps.smooth import smooth_with_odometry
    from gtrig.io.odometry import read_odometry
    from gtrig.sim.outdoor import OutdoorParams, simulate_outdoor

    print(f"\n## Simulated outdoor runs ({duration:.0f} s each)")
    print("| seed | fixed / float / none | fixed kept | within 3 sigma | NEES/dof | 95 % horiz. err "
          "| outliers rejected "
          "| good float rejected | bridged poses | bridged within 3 sigma | smoothed NEES/dof | max bridged err |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|")
    pool: dict[str, list[np.ndarray]] = {k: [] for k in ("w", "nees", "out", "good", "bw", "snees")}
    for seed in seeds:
        with tempfile.TemporaryDirectory() as tmp:
            rec = Path(tmp)
            simulate_outdoor(rec, seed=seed, params=OutdoorParams(duration_s=duration))
            meta = json.loads((rec / "truth" / "outdoor.json").read_text())
            o = Origin(**meta["origin"])
            res = gps_ground_truth(rec / "gps" / "gps.log", GpsOptions(clock="utc", origin=o))
            ant = read_tum(rec / "truth" / "antenna.tum")
            tr = res.track
            e = tr.xyz - np.column_stack([np.interp(tr.stamps_s, ant.stamps_s, ant.xyz[:, k]) for k in range(3)])
            sig = np.sqrt(np.diagonal(tr.cov, axis1=1, axis2=2))
            w = np.all(np.abs(e) <= 3 * sig, axis=1)
            nees = np.einsum("ni,ni->n", e, np.linalg.solve(tr.cov, e[..., None])[..., 0])
            gt = np.loadtxt(rec / "truth" / "gps_truth.csv", delimiter=",", skiprows=1)
            share = [np.mean(gt[:, 2] == q) for q in (4, 5, 0)]
            float_opts = GpsOptions(clock="utc", origin=o, filter=FilterOptions(fix="float", max_sigma_m=None))
            rf = gps_ground_truth(rec / "gps" / "gps.log", float_opts)
            i = np.searchsorted(np.round(gt[:, 0], 3), np.round(rf.epochs.utc_s, 3))
            out = gt[i, 3] > 0
            rej = rf.all_epochs.status == 3
            good = ~out & (rf.epochs.quality == 5)
            sm = smooth_with_odometry(res, read_odometry(rec / "odometry" / "odometry.csv"), tuple(meta["lever_arm_m"]))
            robot = read_tum(rec / "truth" / "robot.tum")
            es = sm.xyz[:, :2] - np.column_stack([np.interp(sm.stamps_s, robot.stamps_s, robot.xyz[:, k])
                                                   for k in range(2)])
            cs = sm.cov_xytheta()[:, :2, :2]
            br = sm.status == 2
            bw = np.all(np.abs(es) <= 3 * np.sqrt(np.diagonal(cs, axis1=1, axis2=2)), axis=1)[br]
            snees = np.einsum("ni,ni->n", es, np.linalg.solve(cs, es[..., None])[..., 0])
            for k, v in zip(pool, (w, nees, rej[out], rej[good], bw, snees), strict=True):
                pool[k].append(v)
            print(f"| {seed} | {share[0]:.0%} / {share[1]:.0%} / {share[2]:.0%} | {len(tr)} | {w.mean():.2%} | "
                  f"{nees.mean() / 3:.2f} | {np.percentile(np.linalg.norm(e[:, :2], axis=1), 95) * 100:.1f} cm | "
                  f"{rej[out].sum()} / {out.sum()} | {rej[good].sum()} / {good.sum()} | {br.sum()} | "
                  f"{bw.mean():.2%} | {snees.mean() / 2:.2f} | {np.linalg.norm(es[br], axis=1).max() * 100:.0f} cm |")
    cat = {k: np.concatenate(v) for k, v in pool.items()}
    print(f"| all | | {cat['w'].size} | {cat['w'].mean():.2%} | {cat['nees'].mean() / 3:.2f} | | "
          f"{cat['out'].mean():.1%} | {cat['good'].mean():.1%} | {cat['bw'].size} | {cat['bw'].mean():.2%} | "
          f"{cat['snees'].mean() / 2:.2f} | |")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    ap.add_argument("--duration", type=float, default=420.0)
    ap.add_argument("--figures", type=Path, default=None)
    args = ap.parse_args()
    if SHARED.is_dir():
        real_logs(args.figures)
    simulated(args.seeds, args.duration)


if __name__ == "__main__":
    main()
