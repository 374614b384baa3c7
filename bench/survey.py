"""Survey benchmark: world points from the seeds' readings, from a network and jointly with the
validation poses, side by side.

Monte-Carlo over simulated surveys of one GT-room scene with its 26 validation stops: every trial redraws
the reference points' true positions (0.5 mm per coordinate, O exact) and the hand-laser noise (0.75 mm).
The same readings are adjusted three times: with the readings to the reference points only (the seeds'
survey, AD2.3), with the readings between world points as well (``gtrig.survey.network``), and with every
reading of the validation stops too (``gtrig.survey.joint``; started from the network's points and the
true poses moved by 3 mm / 3 mrad, as the two stages leave them). Prints errors against truth, the
consistency of the covariances (mean NEES per point, ideal 2; per pose, ideal 3) and the ratios.

    python bench/survey.py [--trials 500] [--scene-seed 0]
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from gtrig import geometry as geo
from gtrig.sim.gtroom import REFERENCE_SIGMA_M, VALIDATION_POSES, make_scene
from gtrig.sim.survey import as_inputs, simulate_survey
from gtrig.survey.joint import adjust_jointly
from gtrig.survey.network import adjust_network


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--trials", type=int, default=500)
    ap.add_argument("--scene-seed", type=int, default=0)
    args = ap.parse_args()
    sc = make_scene(args.scene_seed)
    T = np.array([sc.T_world_robot(*p) for p in VALIDATION_POSES])
    truth = np.array([geo.T_to_se2(t) for t in T])
    nominal = {r.name: r.xy for r in sc.rig_nominal.survey.reference_points}
    rng = np.random.default_rng(11)
    designs = ("seeds", "network", "joint")
    err: dict[str, list[np.ndarray]] = {d: [] for d in designs}
    nees: dict[str, list[float]] = {d: [] for d in designs}
    secs = dict.fromkeys(designs, 0.0)
    pose_err, pose_yaw, pose_nees = [], [], []
    names: list[str] = []
    for _ in range(args.trials):
        ref_true = {
            k: (v[0] + rng.normal(0, REFERENCE_SIGMA_M), v[1] + rng.normal(0, REFERENCE_SIGMA_M)) if k != "O" else v
            for k, v in nominal.items()
        }
        sv = simulate_survey(sc, T, rng, reference_true_xy=ref_true)
        ref, wd, rp, pd = as_inputs(sv)
        names = list(sv.world_names)
        for design, readings in (("seeds", wd.subset(np.isin(np.array(wd.b), ref.names))), ("network", wd)):
            t0 = time.perf_counter()
            r = adjust_network(names, sc.world_points_xy, ref, readings, on_outlier="keep", warnings=[])
            secs[design] += time.perf_counter() - t0
            e = r.xy - sc.world_points_xy
            err[design].append(np.linalg.norm(e, axis=1))
            nees[design].append(float(np.einsum("ni,nij,nj->n", e, np.linalg.inv(r.cov_xy), e).mean()))
        t0 = time.perf_counter()
        start = truth + rng.normal(0, 0.003, truth.shape)
        j = adjust_jointly(names, r.xy, ref, wd, list(sv.pose_names), start, rp, pd, on_outlier="keep", warnings=[])
        secs["joint"] += time.perf_counter() - t0
        e = j.points_xy - sc.world_points_xy
        err["joint"].append(np.linalg.norm(e, axis=1))
        nees["joint"].append(float(np.einsum("ni,nij,nj->n", e, np.linalg.inv(j.points_cov_xy), e).mean()))
        ep = j.poses_xytheta - truth
        ep[:, 2] = geo.wrap_angle(ep[:, 2])
        pose_err.append(np.hypot(ep[:, 0], ep[:, 1]))
        pose_yaw.append(np.degrees(np.abs(ep[:, 2])))
        pose_nees.append(float(np.einsum("pi,pij,pj->p", ep, np.linalg.inv(j.poses_cov), ep).mean()))
    print(f"scene seed {args.scene_seed}, {args.trials} surveys, {len(names)} world points, "
          f"{len(sv.network_pairs)} readings between world points, {len(T)} validation stops "
          f"({pd.distance_m.size} pose readings)")
    print("| survey | error median / 95 % (mm) | worst point median / 95 % (mm) | all within 2 mm | NEES (2) | ms |")
    print("|---|---|---|---|---|---|")
    stats = {}
    for design in designs:
        e = np.array(err[design]) * 1000
        worst = e.max(axis=1)
        stats[design] = (np.sqrt(np.mean(e**2)), np.median(worst))
        print(f"| {design} | {np.median(e):.2f} / {np.percentile(e, 95):.2f} | {np.median(worst):.2f} / "
              f"{np.percentile(worst, 95):.2f} | {100 * np.mean(worst < 2):.0f} % | {np.mean(nees[design]):.2f} | "
              f"{1000 * secs[design] / args.trials:.1f} |")
    for ref_design in ("seeds", "network"):
        print(f"{ref_design} / joint: RMS error {stats[ref_design][0] / stats['joint'][0]:.2f}x, "
              f"median worst point {stats[ref_design][1] / stats['joint'][1]:.2f}x")
    pe, py = np.array(pose_err) * 1000, np.array(pose_yaw)
    print(f"joint, validation poses: worst of a survey median {np.median(pe.max(axis=1)):.2f} mm, "
          f"95 % {np.percentile(pe.max(axis=1), 95):.2f} mm; worst heading median {np.median(py.max(axis=1)):.3f} "
          f"deg, 95 % {np.percentile(py.max(axis=1), 95):.3f} deg; surveys with every pose within 3 mm and "
          f"0.1 deg {100 * np.mean((pe.max(axis=1) < 3) & (py.max(axis=1) < 0.1)):.0f} %; "
          f"NEES (3) {np.mean(pose_nees):.2f}")


if __name__ == "__main__":
    main()
