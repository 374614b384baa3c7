"""Survey benchmark (issue 3): world points from the seeds' readings and from a network, side by side.

Monte-Carlo over simulated surveys of one GT-room scene: every trial redraws the reference points' true
positions (0.5 mm per coordinate, O exact) and the hand-laser noise (0.75 mm). The same readings are
adjusted twice: with the readings to the reference points only (the seeds' survey, AD2.3) and with the
readings between world points as well (``gtrig.survey.network``). Prints errors against truth, the
consistency of the covariance (mean NEES per point, ideal 2) and the ratios.

    python bench/survey.py [--trials 500] [--scene-seed 0]
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from gtrig.sim.gtroom import REFERENCE_SIGMA_M, make_scene
from gtrig.sim.survey import as_inputs, simulate_survey
from gtrig.survey.network import adjust_network


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--trials", type=int, default=500)
    ap.add_argument("--scene-seed", type=int, default=0)
    args = ap.parse_args()
    sc = make_scene(args.scene_seed)
    T = sc.T_world_robot(0.0, 0.0, 0.0)[None]
    nominal = {r.name: r.xy for r in sc.rig_nominal.survey.reference_points}
    rng = np.random.default_rng(11)
    err: dict[str, list[np.ndarray]] = {"seeds": [], "network": []}
    nees: dict[str, list[float]] = {"seeds": [], "network": []}
    secs = {"seeds": 0.0, "network": 0.0}
    names: list[str] = []
    for _ in range(args.trials):
        ref_true = {
            k: (v[0] + rng.normal(0, REFERENCE_SIGMA_M), v[1] + rng.normal(0, REFERENCE_SIGMA_M)) if k != "O" else v
            for k, v in nominal.items()
        }
        sv = simulate_survey(sc, T, rng, reference_true_xy=ref_true)
        ref, wd, _, _ = as_inputs(sv)
        names = list(sv.world_names)
        for design, readings in (("seeds", wd.subset(np.isin(np.array(wd.b), ref.names))), ("network", wd)):
            t0 = time.perf_counter()
            r = adjust_network(names, sc.world_points_xy, ref, readings, on_outlier="keep", warnings=[])
            secs[design] += time.perf_counter() - t0
            e = r.xy - sc.world_points_xy
            err[design].append(np.linalg.norm(e, axis=1))
            nees[design].append(float(np.einsum("ni,nij,nj->n", e, np.linalg.inv(r.cov_xy), e).mean()))
    print(f"scene seed {args.scene_seed}, {args.trials} surveys, {len(names)} world points, "
          f"{len(sv.network_pairs)} readings between world points")
    print("| survey | error median / 95 % (mm) | worst point median / 95 % (mm) | all within 2 mm | NEES (2) | ms |")
    print("|---|---|---|---|---|---|")
    stats = {}
    for design in ("seeds", "network"):
        e = np.array(err[design]) * 1000
        worst = e.max(axis=1)
        stats[design] = (np.sqrt(np.mean(e**2)), np.median(worst))
        print(f"| {design} | {np.median(e):.2f} / {np.percentile(e, 95):.2f} | {np.median(worst):.2f} / "
              f"{np.percentile(worst, 95):.2f} | {100 * np.mean(worst < 2):.0f} % | {np.mean(nees[design]):.2f} | "
              f"{1000 * secs[design] / args.trials:.1f} |")
    print(f"seeds / network: RMS error {stats['seeds'][0] / stats['network'][0]:.2f}x, "
          f"median worst point {stats['seeds'][1] / stats['network'][1]:.2f}x")


if __name__ == "__main__":
    main()
