"""Evaluation bench: speed against evo on 10^6-pose trajectories, the RAWSEEDS tables, and GT-aware scores on
simulated runs.

    python bench/evaluate.py [--n 1000000] [--skip-evo] [--evo-timeout S] [--recs /work/recs]

Sections (Markdown on stdout):

1. speed: two TUM files of ``--n`` poses (GT at 100 Hz, an estimate stamped 3 ms off with noise) scored end
   to end by the command lines, imports included: ``gtrig evaluate slam --metrics evo`` (APE + RPE,
   translation, rotation and full, SE(3) Umeyama, nearest-stamp association) and evo's ``evo_ape`` +
   ``evo_rpe`` (translation) on the same files; wall and CPU times (the children's user + system) and
   their ratios, measured in the same run;
2. RAWSEEDS Bicocca 2009-02-25b: ATE / RPE of the published solutions against the GROUNDTRUTH and the
   GT-extended, and the GT-extended against the GROUNDTRUTH; the external GT against the GT-extended on
   25a, 25b, 26a (ATE RMSE after the toolkit's 2-D alignment);
3. GT-aware: on the simulated runs in ``--recs`` (``sN/results`` and ``sN/recording/truth``), the truth and a
   1 cm biased truth scored against GTlaser and GTvision with their own covariances.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from gtrig.evaluate.slam import evaluate_slam
from gtrig.io.formats import read_trajectory
from gtrig.io.relations import read_relations
from gtrig.io.tum import write_tum
from gtrig.trajectory import PoseTrack

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT / ".." / "shared" / "data"


def _synthetic(n: int, rng: np.random.Generator) -> tuple[PoseTrack, PoseTrack]:
    t = 1.0e9 + np.arange(n) * 0.01
    s = np.arange(n) * 0.01
    xyz = np.column_stack([5 * np.sin(0.01 * s), 3 * np.sin(0.02 * s), 0.2 * np.sin(0.05 * s)])
    yaw = 0.3 * s
    from scipy.spatial.transform import Rotation

    q = Rotation.from_euler("zyx", np.column_stack([yaw, 0.01 * np.sin(s), 0.01 * np.cos(s)])).as_quat()
    gt = PoseTrack(t, xyz, q)
    dq = Rotation.from_rotvec(rng.normal(0, 0.002, (n, 3)))
    qe = (dq * Rotation.from_quat(q)).as_quat()
    est = PoseTrack(t + 0.003, xyz + rng.normal(0, 0.01, (n, 3)) + [1.0, -2.0, 0.5], qe)
    return gt, est


def _run(cmd: list[str], timeout_s: float) -> tuple[float, float, str | None]:
    """``(wall s, CPU s of the child: user + system, its stdout or None on a timeout)``."""
    r0 = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    try:
        out: str | None = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout_s, check=True,
                                         env={**os.environ, "PYTHONPATH": str(ROOT)}).stdout
    except subprocess.TimeoutExpired:
        out = None
    wall = time.perf_counter() - t0
    r1 = resource.getrusage(resource.RUSAGE_CHILDREN)
    return wall, (r1.ru_utime - r0.ru_utime) + (r1.ru_stime - r0.ru_stime), out


def _evo_rmse(out: str | None) -> float:
    m = re.search(r"^\s*rmse\s+([0-9.eE+-]+)", out or "", re.M)
    return float(m.group(1)) if m else float("nan")


def bench_speed(n: int, skip_evo: bool, evo_timeout_s: float) -> None:
    """The end-to-end CLI calls on two ``n``-pose TUM files (imports, reading, evaluation, printing): ``gtrig
    evaluate slam --metrics evo`` (APE and RPE, translation, rotation and full) against ``evo_ape`` plus
    ``evo_rpe`` (translation only), both SE(3) Umeyama and nearest-stamp pairing within 0.01 s."""
    rng = np.random.default_rng(0)
    with tempfile.TemporaryDirectory() as d:
        gt, est = _synthetic(n, rng)
        pg, pe = Path(d) / "gt.tum", Path(d) / "est.tum"
        write_tum(pg, gt)
        write_tum(pe, est)
        del gt, est
        gtrig = [sys.executable, "-m", "gtrig", "evaluate", "slam", "--metrics", "evo", "--align", "se3",
                 "--max-dt", "0.01", "--format", "json"]
        # one small call first: numba compiles the kernels on a machine's first run and caches them
        small = Path(d) / "small.tum"
        write_tum(small, _synthetic(100, rng)[0])
        _run(gtrig + ["--gt", str(small), "--estimate", str(small)], 600)
        wall, cpu, out = _run(gtrig + ["--gt", str(pg), "--estimate", str(pe)], 600)
        ours = json.loads(out or "{}")["evo"]
        print(f"## speed, {n} poses: the CLIs end to end (machine shared; CPU times and ratios hold)\n")
        print("| command | wall (s) | CPU (s) | APE trans rmse | RPE trans rmse |")
        print("|---|---|---|---|---|")
        print(f"| gtrig evaluate slam --metrics evo | {wall:.2f} | {cpu:.2f} | {ours['APE trans']['rmse']:.6f} | "
              f"{ours['RPE trans']['rmse']:.6f} |")
        # where gtrig's time goes, in this process (imports excluded)
        t0, c0 = time.perf_counter(), time.process_time()
        g, e = read_trajectory(pg), read_trajectory(pe)
        t1, c1 = time.perf_counter(), time.process_time()
        ev = evaluate_slam(g, e, metrics="evo", align="se3", method="nearest", max_dt_s=0.01)
        ev.rows()
        t2, c2 = time.perf_counter(), time.process_time()
        print(f"| (in-process: read both files) | {t1 - t0:.2f} | {c1 - c0:.2f} | | |")
        print(f"| (in-process: evaluate and statistics) | {t2 - t1:.2f} | {c2 - c1:.2f} | | |")
        if skip_evo:
            return
        evo_wall = evo_cpu = 0.0
        evo_rmse = []
        for tool in ("evo_ape", "evo_rpe"):
            cmd = [str(Path(sys.executable).with_name(tool)), "tum", str(pg), str(pe), "-a", "--t_max_diff", "0.01"]
            w, c, o = _run(cmd, evo_timeout_s)
            evo_wall, evo_cpu = evo_wall + w, evo_cpu + c
            evo_rmse.append(_evo_rmse(o))
            done = "" if o is not None else f" (stopped after {evo_timeout_s:g} s)"
            print(f"| {tool} tum -a --t_max_diff 0.01{done} | {w:.2f} | {c:.2f} | "
                  + (f"{evo_rmse[0]:.6f} | |" if tool == "evo_ape" else f"| {evo_rmse[1]:.6f} |"))
            if o is None:
                break
        print(f"\nevo (APE + RPE) / gtrig: {evo_wall / wall:.1f}x wall, {evo_cpu / cpu:.1f}x CPU (same run); "
              f"APE / RPE trans rmse differences "
              f"{abs(evo_rmse[0] - ours['APE trans']['rmse']):.1e} / "
              f"{abs(evo_rmse[-1] - ours['RPE trans']['rmse']) if len(evo_rmse) > 1 else float('nan'):.1e} "
              "(evo prints 6 decimals)")


def _ate_rpe(gt_file: Path, est_file: Path, rel: np.ndarray | None, align: str = "se2") -> tuple[float, ...]:
    g, e = read_trajectory(gt_file), read_trajectory(est_file)
    ev = evaluate_slam(g, e, metrics="rawseeds", align=align, relations=rel)  # type: ignore[arg-type]
    a = ev.rawseeds_ate
    assert a is not None
    r = ev.rawseeds_rpe
    return (*a.ate, a.heading[0], a.rmse_m, len(a.dist_m), *((r.t_rpe_m, r.r_rpe_deg) if r else (np.nan, np.nan)))


def bench_rawseeds() -> None:
    b = DATA / "rawseeds" / "Bicocca_2009-02-25b"
    if not b.is_dir():
        print("\nRAWSEEDS data missing: no table")
        return
    rel = read_relations(b / "Bicocca_2009-02-25b.relations")
    print("\n## RAWSEEDS Bicocca 2009-02-25b (toolkit definitions)\n")
    print("| estimate | GT | ATE mean (m) | ATE std (m) | mean-3std | mean+3std | heading mean (rad) | ATE rmse (m) "
          "| GT samples | T-RPE (m) | R-RPE (deg) |")
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    sols = ("SOLUTION_CI-GRAPH_Stereo", "SOLUTION_GraphSLAM_Laser", "SOLUTION_H-SLAM_Trinocular")
    for gname in ("GROUNDTRUTH", "GT-extended"):
        for s in sols:
            v = _ate_rpe(b / f"Bicocca_2009-02-25b-{gname}.csv", b / f"{s}.csv", rel)
            print(f"| {s[9:]} | {gname} | " + " | ".join(f"{x:.4f}" for x in v[:6]) + f" | {v[6]} | {v[7]:.4f} | "
                  f"{v[8]:.3f} |")
    v = _ate_rpe(b / "Bicocca_2009-02-25b-GROUNDTRUTH.csv", b / "Bicocca_2009-02-25b-GT-extended.csv", rel)
    print("| GT-extended | GROUNDTRUTH | " + " | ".join(f"{x:.4f}" for x in v[:6]) + f" | {v[6]} | {v[7]:.4f} | "
          f"{v[8]:.3f} |")
    print("\n## external GT against GT-extended (2-D alignment, GT samples in the GT-extended's span)\n")
    print("| run | GT samples | ATE rmse (m) | ATE mean (m) | ATE std (m) | heading mean (deg) |")
    print("|---|---|---|---|---|---|")
    for run in ("Bicocca_2009-02-25a", "Bicocca_2009-02-25b", "Bicocca_2009-02-26a"):
        d = DATA / "rawseeds" / run
        v = _ate_rpe(d / f"{run}-GROUNDTRUTH.csv", d / f"{run}-GT-extended.csv", None)
        print(f"| {run} | {v[6]} | {v[5]:.4f} | {v[0]:.4f} | {v[1]:.4f} | {np.degrees(v[4]):.3f} |")


def bench_gt_aware(recs: Path) -> None:
    runs = sorted(p for p in recs.glob("s*") if (p / "DONE").exists())
    if not runs:
        print(f"\nno simulated runs in {recs}: no GT-aware table")
        return
    print("\n## GT-aware: the truth and a 1 cm biased truth against the GT sources of simulated runs\n")
    print("| run | GT | estimate | poses | within GT 95 % | NEES/dof | RMSE vs truth (mm, 95 %) | GT sigma (mm) | "
          "verdict |")
    print("|---|---|---|---|---|---|---|---|---|")
    for run in runs:
        truth = read_trajectory(run / "recording" / "truth" / "run.tum")
        biased = PoseTrack(truth.stamps_s, truth.xyz + [0.01, 0, 0], truth.quat_xyzw)
        for gname in ("gt_laser", "gt_vision_run", "gt_fused"):
            p = run / "results" / f"{gname}.tum"
            if not p.is_file():
                continue
            gt = read_trajectory(p)
            for label, est in (("truth", truth), ("truth + 1 cm", biased)):
                ev = evaluate_slam(gt, est, metrics="evo", align="none", method="interpolate")
                s = ev.gt_aware
                if s is None:
                    continue
                r = s.rmse_trans_m
                print(f"| {run.name} | {gname} | {label} | {s.n} | {100 * s.share_resolved:.1f} % | "
                      f"{s.mean_d2_per_dof:.2f} | {1000 * r.value:.2f} ({1000 * r.low:.2f}..{1000 * r.high:.2f}) | "
                      f"{1000 * s.gt_sigma_trans_m:.2f} | "
                      f"{'indistinguishable' if s.indistinguishable else 'distinguished'} |")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--n", type=int, default=1_000_000)
    ap.add_argument("--skip-evo", action="store_true")
    ap.add_argument("--evo-timeout", type=float, default=1200.0, help="seconds per evo command")
    ap.add_argument("--recs", type=Path, default=ROOT / ".." / "recs")
    ap.add_argument("--only", choices=("speed", "rawseeds", "gt-aware"), default=None)
    a = ap.parse_args()
    if a.only in (None, "speed"):
        bench_speed(a.n, a.skip_evo, a.evo_timeout)
    if a.only in (None, "rawseeds"):
        bench_rawseeds()
    if a.only in (None, "gt-aware"):
        bench_gt_aware(a.recs)


if __name__ == "__main__":
    main()
