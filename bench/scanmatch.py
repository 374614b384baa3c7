"""Onboard scan matching: speed against small_gicp, the genetic matcher's time, the acceptance test
against truth on simulated pairs, and agreement with the CARMEN logs' corrected poses.

    python bench/scanmatch.py record --seed N --out DIR   (a recording without camera images)
    python bench/scanmatch.py speed --recording REC [--pairs 500]
    python bench/scanmatch.py accept --recording REC [--recording REC2 ...] [--pairs 400]
    python bench/scanmatch.py carmen [--every 8] [--perturbed 600]
    python bench/scanmatch.py carmen-figure --out docs/figures/scanmatch_carmen.png
    python bench/scanmatch.py map --recording REC [--recording REC2 ...]

The machine may be loaded: speed figures are printed with the ratio to the peer measured in the same
run. small_gicp (PyPI ``small_gicp``) is the peer; without it the speed section says so.
"""

from __future__ import annotations

import argparse
import os
import time
from pathlib import Path

import numpy as np

from gtrig.io.scans import read_scans
from gtrig.io.tum import read_tum
from gtrig.rig.load import load_rig
from gtrig.scanmatch import se2
from gtrig.scanmatch.accept import AcceptParams
from gtrig.scanmatch.genetic import GeneticParams, match_genetic
from gtrig.scanmatch.icp import evaluate, match_icp
from gtrig.scanmatch.pairs import Guess, candidate_pairs, match_pairs, sequence_scans
from gtrig.scanmatch.scan import ranges_to_scan
from gtrig.scanmatch.validate import ErrorModel, scanner_height_m, scanner_pose_xyth

ROOT = Path(__file__).resolve().parents[1]


def truth_at(rec: Path, stamps: np.ndarray) -> np.ndarray:
    tr = read_tum(rec / "truth" / "run.tum")
    return Guess(tr.stamps_s, se2.from_matrix(tr.matrices())).at(stamps)


def speed(rec: Path, n_pairs: int) -> None:
    rig = load_rig(rec / "rig.yaml")
    sc = rig.robot.onboard_scanners[0]
    lg = read_scans(rec / "run" / "onboard" / f"{sc.name}.csv", sc)
    scans = [ranges_to_scan(r, sc.angles_rad, np.zeros(3), 0.01, sc.range_max_m, t)
             for r, t in zip(lg.ranges_m, lg.stamps_s, strict=True)]
    mount = scanner_pose_xyth(sc)
    robot = truth_at(rec, lg.stamps_s)
    scanner = se2.compose(robot, mount)
    rng = np.random.default_rng(0)
    i = rng.integers(0, len(scans) - 10, n_pairs)
    j = i + rng.integers(1, 10, n_pairs)
    rel = se2.relative(scanner[i], scanner[j])
    guess = rel + np.column_stack([rng.normal(0, 0.03, (n_pairs, 2)), rng.normal(0, np.radians(1.5), n_pairs)])
    match_icp(scans[0], scans[1], np.zeros(3))  # compile
    t = time.perf_counter()
    c = time.process_time()
    ours = np.array([match_icp(scans[a], scans[b], g).pose for a, b, g in zip(i, j, guess, strict=True)])
    t_ours = time.perf_counter() - t
    c_ours = time.process_time() - c
    e = se2.relative(rel, ours)
    print(f"gtrig point-to-line ICP: {n_pairs / t_ours:.0f} matches/s wall, {n_pairs / c_ours:.0f} per CPU second "
          f"({sc.beams} beams, one thread; load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores); "
          f"error median {1000 * np.median(np.hypot(e[:, 0], e[:, 1])):.2f} mm, "
          f"{np.degrees(np.median(np.abs(e[:, 2]))):.3f} deg")
    try:
        import small_gicp
    except ImportError:
        print("small_gicp not installed (pip install small_gicp): no peer")
        return
    pts = [np.column_stack([s.xy, np.zeros(len(s))]) for s in scans]
    for kind in ("ICP", "GICP"):
        t = time.perf_counter()
        c = time.process_time()
        out = []
        for a, b, g in zip(i, j, guess, strict=True):
            T0 = np.eye(4)
            c, s_ = np.cos(g[2]), np.sin(g[2])
            T0[:2, :2] = [[c, -s_], [s_, c]]
            T0[:2, 3] = g[:2]
            r = small_gicp.align(pts[a], pts[b], T0, registration_type=kind, downsampling_resolution=0.01,
                                 max_correspondence_distance=0.5, num_threads=1, max_iterations=40)
            out.append(se2.from_matrix(r.T_target_source))
        t_p = time.perf_counter() - t
        c_p = time.process_time() - c
        e2 = se2.relative(rel, np.array(out))
        print(f"small_gicp {kind}: {n_pairs / t_p:.0f} matches/s wall, {n_pairs / c_p:.0f} per CPU second; "
              f"error median {1000 * np.median(np.hypot(e2[:, 0], e2[:, 1])):.2f} mm, "
              f"{np.degrees(np.median(np.abs(e2[:, 2]))):.3f} deg; "
              f"gtrig / small_gicp: speed x{t_p / t_ours:.2f} wall, x{c_p / c_ours:.2f} CPU; position error x"
              f"{np.median(np.hypot(e[:, 0], e[:, 1])) / np.median(np.hypot(e2[:, 0], e2[:, 1])):.2f}")
    t = time.perf_counter()
    n_ga = 20
    for a, b, g in zip(i[:n_ga], j[:n_ga], guess[:n_ga], strict=True):
        match_genetic(scans[a], scans[b], g, GeneticParams())
    print(f"genetic matcher: {1000 * (time.perf_counter() - t) / n_ga:.0f} ms per pair "
          f"(population 64, 40 generations, 120 points)")


def accept(recs: list[Path], n_pairs: int, ga_pairs: int) -> None:
    tot = {"right0": 0, "wrong0": 0, "wrong0_rej": 0, "right0_rej": 0, "right": 0, "wrong": 0, "right_rej": 0,
           "wrong_rej": 0, "n": 0}
    for s, rec in enumerate(recs):
        rig = load_rig(rec / "rig.yaml")
        sc = rig.robot.onboard_scanners
        logs = {x.name: read_scans(rec / "run" / "onboard" / f"{x.name}.csv", x) for x in sc}
        from gtrig.io.odometry import read_odometry

        od = read_odometry(rec / "run" / "odometry.csv")
        scans = sequence_scans(sc, logs, Guess(od.stamps_s, od.xytheta),
                               {x.name: scanner_pose_xyth(x) for x in sc}, 0.01, every=3)
        truth = truth_at(rec, np.array([x.stamp_s for x in scans]))
        pairs = candidate_pairs(truth, 1.0, np.radians(30), min_index_gap=2)
        rng = np.random.default_rng(s)
        pairs = pairs[rng.choice(len(pairs), min(n_pairs, len(pairs)), replace=False)]
        rel = se2.relative(truth[pairs[:, 0]], truth[pairs[:, 1]])
        r = 0.5 * np.sqrt(rng.uniform(0, 1, len(pairs)))
        a = rng.uniform(0, 2 * np.pi, len(pairs))
        rg = rel + np.column_stack([r * np.cos(a), r * np.sin(a), rng.uniform(-1, 1, len(pairs)) * np.radians(30)])
        gc = np.diag([0.3**2, 0.3**2, np.radians(20) ** 2])
        tilt = scanner_height_m(rig) * ErrorModel().floor_tilt_sigma_rad
        for stage, ga in (("0", None), ("", GeneticParams())):
            # the genetic fallback costs about a second per refused pair: measured on the first ga_pairs
            m = len(pairs) if ga is None else min(ga_pairs, len(pairs))
            R = match_pairs(scans, truth, pairs[:m], tilt_shift_m=tilt, genetic=ga, guess_cov=gc, rel_guesses=rg[:m],
                            accept=AcceptParams())
            E = np.array([se2.relative(rel[n], x.pose) for n, x in enumerate(R)])
            right = (np.hypot(E[:, 0], E[:, 1]) < 0.02) & (np.degrees(np.abs(E[:, 2])) < 0.5)
            acc = np.array([x.verdict.accepted for x in R])
            tot["right" + stage] += int(right.sum())
            tot["wrong" + stage] += int((~right).sum())
            tot["right" + stage + "_rej"] += int((right & ~acc).sum())
            tot["wrong" + stage + "_rej"] += int((~right & ~acc).sum())
        tot["n"] += len(pairs)
        tot["n_ga"] = tot.get("n_ga", 0) + min(ga_pairs, len(pairs))
        print(f"{rec}: {len(pairs)} pairs", {k: v for k, v in tot.items()}, flush=True)
    print(f"candidate pairs: {tot['n']} over {len(recs)} recordings; guesses off by up to 0.5 m and 30 deg")
    print(f"local ICP from the guess: {tot['wrong0']} wrong, {tot['wrong0_rej']} rejected "
          f"({100 * tot['wrong0_rej'] / max(1, tot['wrong0']):.2f} %); {tot['right0']} right, {tot['right0_rej']} "
          f"rejected ({100 * tot['right0_rej'] / max(1, tot['right0']):.2f} %)")
    n_ga = tot["n_ga"]
    print(f"with the genetic fallback ({n_ga} of the pairs): {tot['wrong']} wrong, {tot['wrong_rej']} rejected; "
          f"{tot['right']} right, {tot['right_rej']} rejected ({100 * tot['right_rej'] / max(1, tot['right']):.2f} %); "
          f"accepted {100 * (n_ga - tot['wrong_rej'] - tot['right_rej']) / max(1, n_ga):.1f} % of the pairs")


def _share(mask: np.ndarray, sel: np.ndarray) -> str:
    return f"{100 * np.mean(mask[sel]):.1f} %" if np.any(sel) else "-"


def _within(a: np.ndarray, b: np.ndarray, m: float, deg: float) -> np.ndarray:
    e = se2.relative(a, b)
    return (np.hypot(e[:, 0], e[:, 1]) < m) & (np.degrees(np.abs(e[:, 2])) < deg)


def _mm(e: np.ndarray, q: float = 50) -> str:
    """Percentile ``q`` of the position part of (P, 3) pose differences, in mm."""
    return f"{1000 * np.percentile(np.hypot(e[:, 0], e[:, 1]), q):.1f} mm"


def _deg(e: np.ndarray) -> str:
    return f"{np.degrees(np.median(np.abs(e[:, 2]))):.3f} deg"


def _carmen_agreement(label: str, logrel: np.ndarray, own: np.ndarray, ours: np.ndarray, acc: np.ndarray) -> None:
    print(f"  {label}within 2 cm and 1 deg of the logs' relative pose: {_share(_within(logrel, ours, .02, 1), acc)}; "
          f"within 5 cm and 1 deg: {_share(_within(logrel, ours, .05, 1), acc)}; within 2 cm and 0.5 deg of the "
          f"scans' own match near the logs' pose: {_share(_within(own, ours, .02, .5), acc)}")


def _carmen_evidence(scans: list, pairs: np.ndarray, ours: np.ndarray, logrel: np.ndarray,  # type: ignore[type-arg]
                     acc: np.ndarray) -> None:
    """The scans' fit at both relative poses, loop closure of ours, and the scanner's mounting in the
    frame of the logs' poses (planar hand-eye: identity when the logs' poses are the scanner's)."""
    from scipy.optimize import least_squares

    from gtrig.scanmatch.carmen import triplet_closures

    s_o = np.array([evaluate(scans[a], scans[b], ours[k]).s_m for k, (a, b) in enumerate(pairs) if acc[k]])
    s_l = np.array([evaluate(scans[a], scans[b], logrel[k]).s_m for k, (a, b) in enumerate(pairs) if acc[k]])
    print(f"  the scans' fit (residual spread, accepted pairs): {1000 * np.median(s_o):.1f} mm at ours, "
          f"{1000 * np.median(s_l):.1f} mm at the logs' (ours lower in {100 * np.mean(s_o < s_l):.1f} %)")
    cl = triplet_closures(pairs[acc], ours[acc])
    e = se2.relative(logrel[acc], ours[acc])
    print(f"  loop closure of {len(cl)} triplets of accepted pairs: median {_mm(cl)} and {_deg(cl)} (p95 "
          f"{_mm(cl, 95)}); ours against the logs' on those pairs: median {_mm(e)} and {_deg(e)} (p95 {_mm(e, 95)})")
    la, oa = logrel[acc], ours[acc]
    m = least_squares(lambda m: se2.relative(se2.compose(se2.compose(se2.inverse(m), la), m), oa).ravel(),
                      np.zeros(3), loss="soft_l1", f_scale=0.01).x
    print(f"  the scanner in the frame of the logs' poses: x {1000 * m[0]:+.1f} mm, y {1000 * m[1]:+.1f} mm, "
          f"yaw {np.degrees(m[2]):+.3f} deg")


def _carmen_odometry(log, n_max: int = 1500) -> None:  # type: ignore[no-untyped-def]
    """Consecutive scans: the wheel odometry, a third sensor, against our match and the logs' poses."""
    from gtrig.scanmatch.carmen import log_scans, odometry_at_scans

    k = np.arange(len(log.laser_stamps_s) - 1)
    k = k[:: max(1, len(k) // n_max)]
    rows = np.unique(np.r_[k, k + 1])
    pos = {int(r): n for n, r in enumerate(rows)}
    scans, odo = log_scans(log, rows), odometry_at_scans(log, rows)
    ro = se2.relative(odo[[pos[a] for a in k]], odo[[pos[a + 1] for a in k]])
    rl = se2.relative(log.laser_xytheta[k], log.laser_xytheta[k + 1])
    rs = np.array([match_icp(scans[pos[a]], scans[pos[a + 1]], g).pose for a, g in zip(k, ro, strict=True)])
    eo, el = se2.relative(ro, rs), se2.relative(ro, rl)
    print(f"  {len(k)} consecutive scans ({_mm(ro)} median step): wheel odometry against ours {_mm(eo)}, "
          f"{_deg(eo)}; against the logs' {_mm(el)}, {_deg(el)} (medians)")


def _carmen_perturbed(scans: list, cor: np.ndarray, pairs: np.ndarray, own: np.ndarray,  # type: ignore[type-arg]
                      n: int) -> None:
    """The acceptance test's verdicts from guesses off the scans' own match by up to 0.5 m and 30 deg."""
    rng = np.random.default_rng(0)
    sel = rng.choice(len(pairs), min(n, len(pairs)), replace=False)
    r = 0.5 * np.sqrt(rng.uniform(0, 1, len(sel)))
    a = rng.uniform(0, 2 * np.pi, len(sel))
    off = np.column_stack([r * np.cos(a), r * np.sin(a), rng.uniform(-1, 1, len(sel)) * np.radians(30)])
    gc = np.diag([0.3**2, 0.3**2, np.radians(20) ** 2])
    P = match_pairs(scans, cor, pairs[sel], genetic=None, guess_cov=gc, rel_guesses=own[sel] + off)
    right = _within(own[sel], np.array([x.pose for x in P]), 0.02, 0.5)
    acc = np.array([x.verdict.accepted for x in P])
    print(f"  acceptance test on {len(sel)} pairs from guesses off the scans' own match by up to 0.5 m and "
          f"30 deg: {(~right).sum()} wrong (2 cm, 0.5 deg), {(~right & ~acc).sum()} rejected ({_share(~acc, ~right)}); "
          f"{right.sum()} right, {(right & ~acc).sum()} rejected ({_share(~acc, right)})")


def carmen(every_freiburg: int, perturbed: int) -> None:
    """Both CARMEN logs: every pair within 1 m and 30 deg (the logs' corrected poses) among every scan
    (intel) or every ``every_freiburg``-th scan (freiburg), matched from the raw odometry; against the
    logs' poses, against the scans' own match near them, the scans' fit and loop closure at both."""
    from gtrig.io.carmen import read_carmen
    from gtrig.scanmatch.carmen import LOOP_GENETIC, log_scans, odometry_at_scans, odometry_path_m, scans_own_match

    for name, every in (("intel-corrected.log.gz", 1), ("freiburg-079-corrected.log.gz", every_freiburg)):
        log = read_carmen(ROOT / ".." / "shared" / "data" / "carmen" / name)
        rows = np.arange(0, len(log.laser_stamps_s), every)
        scans, odo, cor = log_scans(log, rows), odometry_at_scans(log, rows), log.laser_xytheta[rows]
        pairs = candidate_pairs(cor, 1.0, np.radians(30))
        t = time.process_time()
        R = match_pairs(scans, odo, pairs, genetic=None)
        dt = time.process_time() - t
        ours, acc = np.array([x.pose for x in R]), np.array([x.verdict.accepted for x in R])
        logrel = se2.relative(cor[pairs[:, 0]], cor[pairs[:, 1]])
        own = scans_own_match(scans, cor, pairs)
        reach = _within(own, np.array([x.guess for x in R]), 0.3, 10.0)
        print(f"{name}: {len(scans)} scans ({log.laser_ranges.shape[1]} beams, every {every}), {len(pairs)} pairs "
              f"within 1 m and 30 deg, matched from the raw odometry in {1000 * dt / len(pairs):.2f} ms CPU each; "
              f"accepted {acc.sum()} ({100 * acc.mean():.1f} %): {_share(acc, reach)} of the {reach.sum()} pairs "
              f"whose odometry guess is within 0.3 m and 10 deg, {_share(acc, ~reach)} of the {(~reach).sum()} "
              f"others (metres and up to 180 deg of odometry drift)")
        _carmen_agreement("accepted pairs ", logrel, own, ours, acc)
        # the refused pairs again, with the genetic matcher over +-1.5 m and every heading, the guess's
        # covariance from the path the odometry travelled between the scans
        ref = np.flatnonzero(~acc)
        path = odometry_path_m(log, rows)
        t = time.process_time()
        travelled = np.abs(path[pairs[ref, 1]] - path[pairs[ref, 0]])
        Rg = match_pairs(scans, odo, pairs[ref], genetic=LOOP_GENETIC, path_m=travelled)
        dt = time.process_time() - t
        ag = np.array([x.verdict.accepted for x in Rg])
        ours[ref[ag]], acc[ref[ag]] = np.array([x.pose for x in Rg]).reshape(-1, 3)[ag], True
        print(f"  with the genetic fallback for the {len(ref)} refused pairs ({1000 * dt / max(1, len(ref)):.0f} ms "
              f"CPU each): accepted {acc.sum()} ({100 * acc.mean():.1f} %): {_share(acc, reach)} of the pairs within "
              f"reach, {_share(acc, ~reach)} of the others")
        _carmen_agreement("accepted pairs ", logrel, own, ours, acc)
        _carmen_evidence(scans, pairs, ours, logrel, acc)
        # the verb's own population: pairs within 1 m and 30 deg by the raw odometry itself
        po = candidate_pairs(odo, 1.0, np.radians(30))
        Ro = match_pairs(scans, odo, po, genetic=None)
        ao = np.array([x.verdict.accepted for x in Ro])
        print(f"  pairs within 1 m and 30 deg by the raw odometry instead: {len(po)}, accepted {100 * ao.mean():.1f} %")
        _carmen_agreement("of those ", se2.relative(cor[po[:, 0]], cor[po[:, 1]]), scans_own_match(scans, cor, po),
                          np.array([x.pose for x in Ro]), ao)
        _carmen_odometry(log)
        if perturbed:
            _carmen_perturbed(scans, cor, pairs, own, perturbed)
        print(flush=True)


def carmen_figure(out: Path, n_pairs: int = 3) -> None:
    """Consecutive freiburg-079 scans where our match and the log's relative pose differ by 3-6 cm: the
    second scan drawn on the first under each, zoomed where the two placements differ most."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from gtrig.io.carmen import read_carmen
    from gtrig.scanmatch.carmen import log_scans, odometry_at_scans

    log = read_carmen(ROOT / ".." / "shared" / "data" / "carmen" / "freiburg-079-corrected.log.gz")
    rows = np.arange(0, len(log.laser_stamps_s), 40)
    scans = log_scans(log, np.sort(np.r_[rows, rows + 1]))
    odo, cor = odometry_at_scans(log), log.laser_xytheta
    chosen = []
    for n, k in enumerate(rows):
        a, b = scans[2 * n], scans[2 * n + 1]
        m = match_icp(a, b, se2.relative(odo[k], odo[k + 1]))
        lg = se2.relative(cor[k], cor[k + 1])
        d = float(np.hypot(*se2.relative(lg, m.pose)[:2]))
        if 0.03 < d < 0.06 and m.s_m < 0.012:
            chosen.append((k, a, b, m.pose, lg, d))
        if len(chosen) == n_pairs:
            break
    fig, axs = plt.subplots(len(chosen), 3, figsize=(13, 4.3 * len(chosen)), squeeze=False)
    for r, (k, a, b, ours, lg, d) in enumerate(chosen):
        pa, po, pl = a.xy, se2.apply(ours, b.xy), se2.apply(lg, b.xy)
        # the zoom: where the placements differ most, among points on a wall with neighbours around
        dense = np.array([np.sum(np.linalg.norm(pa - q, axis=1) < 0.2) >= 12 for q in po])
        near = (np.linalg.norm(b.xy, axis=1) < 3.0) & b.normal_ok & dense
        c = po[np.argmax(np.where(near, np.linalg.norm(po - pl, axis=1), -1))]
        s_o, s_l = evaluate(a, b, ours).s_m, evaluate(a, b, lg).s_m
        views = ((axs[r, 1], po, "our match", "r", s_o), (axs[r, 2], pl, "the log's poses", "g", s_l))
        for ax, pts, lab, col, sv in views:
            ax.plot(pa[:, 0], pa[:, 1], "o", ms=6, mfc="none", color="b", label=f"scan {k}")
            ax.plot(pts[:, 0], pts[:, 1], "+", ms=8, color=col, label=f"scan {k + 1}, {lab}")
            ax.set_xlim(c[0] - 0.3, c[0] + 0.3)
            ax.set_ylim(c[1] - 0.3, c[1] + 0.3)
            ax.set_aspect("equal")
            ax.grid(True)
            ax.legend(loc="upper left", fontsize=8)
            ax.set_title(f"{lab}: residual spread {1000 * sv:.1f} mm", fontsize=10)
        ax = axs[r, 0]
        ax.plot(pa[:, 0], pa[:, 1], ".", ms=2, color="b")
        ax.plot(pl[:, 0], pl[:, 1], ".", ms=2, color="g")
        ax.add_patch(plt.Rectangle((c[0] - 0.3, c[1] - 0.3), 0.6, 0.6, fill=False, color="k"))
        ax.set_xlim(-1.0, 6.0)
        ax.set_ylim(-3.5, 3.5)
        ax.set_aspect("equal")
        ax.set_title(f"freiburg-079 scans {k}, {k + 1}: ours and the log's differ by {1000 * d:.0f} mm", fontsize=10)
    fig.tight_layout()
    fig.savefig(out, dpi=70)
    print(f"wrote {out}")


def map_validation(recs: list[Path]) -> None:
    import tempfile

    import yaml

    from gtrig.io.rosmap import read_map
    from gtrig.scanmatch.mapmatch import map_points, match_to_map
    from gtrig.scanmatch.validate import load_stop_scans
    from gtrig.sim.gtroom import make_scene
    from gtrig.sim.map import write_maps

    for rec in recs:
        rig = load_rig(rec / "rig.yaml")
        seed = int(yaml.safe_load((rec / "sim_config.yaml").read_text())["seed"])
        mdir = rec
        if not (rec / "map" / "blueprint.yaml").exists():  # recordings made before the map step
            mdir = Path(tempfile.mkdtemp())
            write_maps(make_scene(seed), mdir)
        err = yaml.safe_load((mdir / "truth" / "map_errors.yaml").read_text())["blueprint"]
        truth = np.loadtxt(rec / "truth" / "validation_poses.csv", delimiter=",", skiprows=1)[:, 1:]
        stops = load_stop_scans(rec, rig)
        rng = np.random.default_rng(seed)
        r = 0.3 * np.sqrt(rng.uniform(0, 1, len(truth)))
        a = rng.uniform(0, 2 * np.pi, len(truth))
        init = truth + np.column_stack([r * np.cos(a), r * np.sin(a), rng.uniform(-1, 1, len(truth)) * np.radians(15)])
        for which in ("gtroom", "blueprint"):
            mp = map_points(read_map(mdir / "map" / f"{which}.yaml"))
            t = time.perf_counter()
            res = match_to_map(mp, list(stops.merged), init,
                               tilt_shift_m=scanner_height_m(rig) * ErrorModel().floor_tilt_sigma_rad)
            e = se2.relative(truth, res.poses)
            fl = "; ".join(f"{f.name()} {1000 * f.offset_m:+.1f} mm (+-{1000 * f.se_m:.1f})" for f in res.flagged)
            print(f"{rec} {which}: {sum(v.accepted for v in res.verdicts)}/{len(truth)} accepted; error max "
                  f"{1000 * np.max(np.hypot(e[:, 0], e[:, 1])):.2f} mm, "
                  f"mean {1000 * np.mean(np.hypot(e[:, 0], e[:, 1])):.2f} mm, "
                  f"max {np.degrees(np.max(np.abs(e[:, 2]))):.3f} deg; flagged: {fl or 'none'}"
                  + (f" (truth: wall {err['wall_from_xy'][0]:.2f}, {err['wall_from_xy'][1]:.2f} - "
                     f"{err['wall_to_xy'][0]:.2f}, {err['wall_to_xy'][1]:.2f} moved {1000 * err['shift_m']:.0f} mm)"
                     if which == "blueprint" else "") + f"; {time.perf_counter() - t:.0f} s", flush=True)


def record(seed: int, out: Path) -> None:
    """A recording for this bench without camera images: the simulator's rig, truth, survey,
    odometry, laser and map steps, then the survey's poses (``OUT/results/survey``)."""
    from gtrig.sim import recording as simrec
    from gtrig.sim.config import SimConfig
    from gtrig.sim.gtroom import make_scene
    from gtrig.survey import run_recording_survey

    rec = out / "recording"
    rec.mkdir(parents=True, exist_ok=True)
    cfg = SimConfig(seed=seed, workers=1)
    scene = make_scene(seed)
    tl = simrec.make_timeline(scene, cfg)
    for name, step in simrec.STEPS:
        if "images" not in name:
            step(scene, tl, rec, cfg)
    run_recording_survey(rec, out / "results" / "survey")
    print(f"wrote {rec} and {out / 'results' / 'survey'}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = ap.add_subparsers(dest="what", required=True)
    a = sub.add_parser("speed")
    a.add_argument("--recording", type=Path, required=True)
    a.add_argument("--pairs", type=int, default=500)
    b = sub.add_parser("accept")
    b.add_argument("--recording", type=Path, action="append", required=True)
    b.add_argument("--pairs", type=int, default=400)
    b.add_argument("--ga-pairs", type=int, default=60, help="pairs also run with the genetic fallback")
    c = sub.add_parser("carmen")
    c.add_argument("--every", type=int, default=8, help="freiburg: every n-th scan (intel: every scan)")
    c.add_argument("--perturbed", type=int, default=600, help="pairs for the acceptance test's verdicts")
    f = sub.add_parser("carmen-figure")
    f.add_argument("--out", type=Path, required=True)
    e = sub.add_parser("record")
    e.add_argument("--seed", type=int, required=True)
    e.add_argument("--out", type=Path, required=True)
    d = sub.add_parser("map")
    d.add_argument("--recording", type=Path, action="append", required=True)
    args = ap.parse_args()
    if args.what == "speed":
        speed(args.recording, args.pairs)
    elif args.what == "accept":
        accept(args.recording, args.pairs, args.ga_pairs)
    elif args.what == "record":
        record(args.seed, args.out)
    elif args.what == "carmen-figure":
        carmen_figure(args.out)
    elif args.what == "map":
        map_validation(args.recording)
    else:
        carmen(args.every, args.perturbed)


if __name__ == "__main__":
    main()
