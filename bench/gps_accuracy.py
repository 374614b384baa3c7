"""RTK-GPS ground truth, measured: the shared Bovisa logs and simulated outdoor runs.

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
    print("| log | lines | epochs | RTK fixed | RTK float | DGPS | single | no fix | kept (default) "
          "| kept (`--fix any`) | kept (`--fix any --no-outlier-test`) "
          "| lost-fix intervals (default) | log - UTC | log clock drift |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    for p in sorted(SHARED.glob("Bovisa_2008-*/*-GPS.csv")):
        t = time.perf_counter()
        res = gps_ground_truth(p)
        dt = time.perf_counter() - t
        rep = gps_report(res)
        any_fix = gps_ground_truth(p, GpsOptions(filter=FilterOptions(fix="any")))
        like = gps_ground_truth(p, GpsOptions(frame="utm", filter=FilterOptions(fix="any", outlier_gate=None)))
        sh = rep["fix_share_time"]
        lost = rep["lost_fix_intervals"]
        off = rep["clock_offset_log_minus_utc_s"]
        print(f"| {p.parent.name} | {rep['lines']['total']} | {rep['epochs']} | {sh.get('rtk_fixed', 0):.1%} | "
              f"{sh.get('rtk_float', 0):.1%} | {sh.get('dgps', 0):.1%} | {sh.get('single', 0):.1%} | "
              f"{sh.get('no_fix', 0):.1%} | {rep['kept']} | {len(any_fix.track)} | {len(like.track)} | "
              f"{lost['count']} ({lost['total_s']:.0f} s, "
              f"longest {lost['longest_s']:.0f} s) | {off['median']:.3f} s | {off['drift'] * 1e6:.0f} ppm |")
        print(f"  ({dt:.2f} s for the whole verb's pipeline)")
        if figures is not None:
            from gtrig.gps.plots import coverage_map

            coverage_map(res, figures / f"gps_coverage_{p.parent.name}.png", ellipse_every=100,
                         title=f"{p.parent.name} (kept: RTK fixed, sigmas < 0.2 m)")
    print("\nGST ellipse conventions (positions' jitter shape likelihood, nats/sample; higher is better):")
    for p in sorted(SHARED.glob("Bovisa_2008-*/*-GPS.csv")):
        c = ellipse_conventions(p)
        print(f"  {p.parent.name}: " + ", ".join(f"{k} {v:.3f}" for k, v in c.items()))


def _fixed_only(tr, ant, stamps_utc: np.ndarray, tau_s: float) -> dict[str, object]:
    """The kept RTK-fixed positions against the antenna's truth under each 3-sigma test, with the rate
    a correct covariance gives and its 95 % spreads (independent fixes: binomial; errors wandering
    with the simulator's time constant: Monte Carlo)."""
    from gtrig.evaluate.within import binomial_interval, correlated_rates, expected_rate, mahalanobis2, within

    e = tr.xyz - np.column_stack([np.interp(tr.stamps_s, ant.stamps_s, ant.xyz[:, k]) for k in range(3)])
    C = tr.cov
    out: dict[str, object] = {"n": len(tr), "nees": mahalanobis2(e, C), "err_h": np.linalg.norm(e[:, :2], axis=1)}
    for test in ("region", "axes", "d3"):
        w = within(e, C, test)  # type: ignore[arg-type]
        p = expected_rate(C, test)  # type: ignore[arg-type]
        rates = correlated_rates(stamps_utc, C, tau_s, test)  # type: ignore[arg-type]
        lo, hi = np.quantile(rates, [0.025, 0.975])
        out[test] = (w, p, binomial_interval(len(tr), p), (lo, hi), float(np.mean(rates <= w.mean())))
    hz = within(e[:, :2], C[:, :2, :2], "d3")
    out["d3_2d"] = (hz, expected_rate(C[:, :2, :2], "d3"))
    return out


def simulated(seeds: list[int], duration: float) -> None:
    from gtrig.evaluate.within import mahalanobis2, within
    from gtrig.gps.smooth import smooth_with_odometry
    from gtrig.io.odometry import read_odometry
    from gtrig.sim.outdoor import OutdoorParams, simulate_outdoor

    prm = OutdoorParams(duration_s=duration)
    print(f"\n## Simulated outdoor runs ({duration:.0f} s each)")
    print("\nFixed-only positions against truth (3-D). 'region': inside the 99.73 % ellipsoid (d^2 <= 14.16); "
          "'axes': E, N, U each within 3 sigma; 'd <= 3': Mahalanobis distance. Each cell: observed "
          "(expected for a correct covariance; 95 % spread for independent fixes | for errors correlated "
          f"over tau = {prm.tau_s:g} s, and the share of those correlated runs at or below the observed rate)")
    print("| seed | fixed kept | NEES/dof | region | axes | d <= 3 | d <= 3 (2-D) | 95 % horiz. err |")
    print("|---|---|---|---|---|---|---|---|")
    pool: dict[str, list[np.ndarray]] = {k: [] for k in ("region", "axes", "d3", "d3_2d", "nees", "out", "good",
                                                           "bw", "bwa", "snees", "bnees")}
    rows_b = []
    for seed in seeds:
        with tempfile.TemporaryDirectory() as tmp:
            rec = Path(tmp)
            simulate_outdoor(rec, seed=seed, params=prm)
            meta = json.loads((rec / "truth" / "outdoor.json").read_text())
            o = Origin(**meta["origin"])
            res = gps_ground_truth(rec / "gps" / "gps.log", GpsOptions(clock="utc", origin=o))
            tr = res.track
            fx = _fixed_only(tr, read_tum(rec / "truth" / "antenna.tum"), tr.stamps_s, prm.tau_s)
            cells = []
            for test in ("region", "axes", "d3"):
                w, p, (blo, bhi), (clo, chi), pval = fx[test]  # type: ignore[misc]
                pool[test].append(w)
                cells.append(f"{w.mean():.2%} ({p:.2%}; {blo:.1%}-{bhi:.1%} | {clo:.1%}-{chi:.1%}, "
                             f"P(<=) {pval:.2f})")
            hz, ph = fx["d3_2d"]  # type: ignore[misc]
            pool["d3_2d"].append(hz)
            pool["nees"].append(fx["nees"])  # type: ignore[arg-type]
            print(f"| {seed} | {fx['n']} | {np.mean(fx['nees']) / 3:.2f} | " + " | ".join(cells)  # type: ignore
                  + f" | {hz.mean():.2%} ({ph:.2%}) | {np.percentile(fx['err_h'], 95) * 100:.1f} cm |")  # type: ignore
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
            bw, bwa = within(es, cs, "region")[br], within(es, cs, "axes")[br]
            snees = mahalanobis2(es, cs)
            for k, v in zip(("out", "good", "bw", "bwa", "snees", "bnees"), (rej[out], rej[good], bw, bwa, snees,
                                                                             snees[br]), strict=True):
                pool[k].append(v)
            # a run whose fixes never break (or that has a single stretch of them) bridges nothing
            b_cells = (f"{bw.mean():.2%} | {bwa.mean():.2%} | {snees[br].mean() / 2:.2f}" if br.any() else "- | - | -")
            max_br = f"{np.linalg.norm(es[br], axis=1).max() * 100:.0f} cm" if br.any() else "-"
            rows_b.append(f"| {seed} | {share[0]:.0%} / {share[1]:.0%} / {share[2]:.0%} | {rej[out].sum()} / "
                          f"{out.sum()} | {rej[good].sum()} / {good.sum()} | {br.sum()} | {b_cells} | "
                          f"{snees.mean() / 2:.2f} | {max_br} |")
    cat = {k: np.concatenate(v) for k, v in pool.items()}
    print(f"| all | {cat['region'].size} | {cat['nees'].mean() / 3:.2f} | {cat['region'].mean():.2%} | "
          f"{cat['axes'].mean():.2%} | {cat['d3'].mean():.2%} | {cat['d3_2d'].mean():.2%} | |")
    print("\nFloat outliers and the odometry-smoothed trajectory (bridged: poses in a lost-fix gap, 2-D x, y)")
    print("| seed | fixed / float / none | outliers rejected | good float rejected | bridged poses "
          "| bridged in region | bridged, axes | bridged NEES/dof | smoothed NEES/dof | max bridged err |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    print("\n".join(rows_b))
    print(f"| all | | {cat['out'].mean():.1%} | {cat['good'].mean():.1%} | {cat['bw'].size} | {cat['bw'].mean():.2%} | "
          f"{cat['bwa'].mean():.2%} | {cat['bnees'].mean() / 2:.2f} | {cat['snees'].mean() / 2:.2f} | |")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    ap.add_argument("--duration", type=float, default=420.0)
    ap.add_argument("--figures", type=Path, default=None)
    ap.add_argument("--no-real", action="store_true", help="only the simulated runs")
    args = ap.parse_args()
    if SHARED.is_dir() and not args.no_real:
        real_logs(args.figures)
    simulated(args.seeds, args.duration)


if __name__ == "__main__":
    main()
