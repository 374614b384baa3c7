"""The natural spread of the accuracy table: a Monte Carlo of the pipeline over draws of the sensor noise.

For each seed, ``--draws K`` recordings of the same scene, rig, paths, stops, clock offsets and odometry
calibration with independent measurement noise (``noise_draw: 1..K`` in the simulator's settings,
docs/simulator.md, "Noise draws"), each run through every stage. Per figure of ``accuracy.csv``: the mean,
the standard deviation and the coefficient of variation over the draws; the chance that two draws'
figures lie within 5 % of each other (what a 5 % tolerance passes when only the noise changes); and,
given the results of another run on the seed's own noise (``--compare``), how many standard deviations
its figure lies from the draws' mean. Then the analytic check of the validation's yaw: each marker's yaw
in the robot frame over the draws against the yaw sigma the marker calibration states (``markers.yaml``),
and the common yaw offset of the validation stops (mean signed yaw error) over the draws. ``--own``
counts the results of the same code on the seed's own recording (draw 0) as one more draw: their z is
then from the other draws.

    python bench/spread.py --out DIR [--seeds 1 2] [--draws 3] [--redrawn all|calibration]
                           [--compare /path/s{seed}/results] [--own /path/s{seed}/results]
                           [--workers 0] [--tabulate-only]

Recordings go to ``DIR/s<seed>/draw<k>/recording`` (``sensors<k>``, ``calibration<k>`` with
``--redrawn``) and results to ``.../results``; finished ones are
reused (the simulator resumes, the pipeline reuses its stages), so the command can be run again after an
interruption or with a larger ``--draws``. ``--tabulate-only`` simulates and runs nothing: it tables the
draws whose ``accuracy.csv`` exists. Markdown on stdout.
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import yaml

from gtrig import geometry as geo
from gtrig.evaluate.truth import truth_xytheta
from gtrig.io.tum import read_tum
from gtrig.pipeline import read_accuracy_csv
from gtrig.rig import load_rig
from gtrig.rig.models import Pose

Figure = tuple[str, str]


@dataclass(frozen=True)
class Draw:
    """One noise draw of a seed: its recording and the pipeline's results on it."""

    seed: int
    draw: int
    recording: Path
    results: Path


def draws_of(out: Path, seed: int, k: int, redrawn: str) -> list[Draw]:
    """Draws 1 to ``k`` of a seed: ``out/s<seed>/draw<d>`` (``sensors<d>``, ``calibration<d>`` for the
    narrower redraws)."""
    prefix = "draw" if redrawn == "all" else redrawn
    folders = [out / f"s{seed}" / f"{prefix}{d}" for d in range(1, k + 1)]
    return [Draw(seed, d, f / "recording", f / "results") for d, f in enumerate(folders, start=1)]


def produce(d: Draw, redrawn: str, workers: int) -> None:
    """Simulate the draw's recording (resuming) and run every stage on it (reusing finished ones)."""
    from gtrig import pipeline
    from gtrig.config import RunConfig
    from gtrig.sim.config import SimConfig
    from gtrig.sim.recording import simulate

    if (d.results / "accuracy.csv").is_file():
        return
    t0 = time.perf_counter()
    cfg = SimConfig.model_validate({"seed": d.seed, "noise_draw": d.draw, "noise_redrawn": redrawn,
                                    "workers": workers})
    simulate(cfg, d.recording)
    t1 = time.perf_counter()
    pipeline.run(d.recording, d.results, config=RunConfig(workers=workers))
    print(f"<!-- seed {d.seed} draw {d.draw}: simulated in {t1 - t0:.0f} s, run in {time.perf_counter() - t1:.0f} s "
          "-->", flush=True)


@dataclass(frozen=True)
class Spread:
    """One figure over the draws."""

    n: int
    mean: float
    sd: float

    @property
    def cv(self) -> float:
        """Standard deviation over the absolute mean (NaN for a zero mean)."""
        return self.sd / abs(self.mean) if self.mean else math.nan

    def p_within(self, tolerance: float) -> float:
        """The chance that two draws' figures differ by less than ``tolerance`` of the mean (0.05 for 5 %):
        their difference has a standard deviation of sqrt(2) sd."""
        return math.erf(tolerance / (2 * self.cv)) if self.cv > 0 else math.nan

    def z(self, value: float) -> float:
        """How many standard deviations ``value`` lies from the mean."""
        return (value - self.mean) / self.sd if self.sd > 0 else math.nan


def spreads(tables: list[dict[Figure, float]]) -> dict[Figure, Spread]:
    """Mean and sample standard deviation (ddof 1) of every figure measured in every draw."""
    out: dict[Figure, Spread] = {}
    for fig in tables[0]:
        v = np.array([t.get(fig, math.nan) for t in tables], float)
        v = v[np.isfinite(v)]
        if v.size:
            out[fig] = Spread(int(v.size), float(v.mean()), float(v.std(ddof=1)) if v.size > 1 else math.nan)
    return out


def units_of(path: Path) -> dict[Figure, str]:
    import csv

    with open(path, newline="") as f:
        return {(r["stage"], r["metric"]): r["unit"] for r in csv.DictReader(f)}


def table(seed: int, done: list[Draw], compare: Path | None) -> None:
    """The figures' spread over the finished draws of one seed, and the compared run's z-scores (from the
    other draws' mean and standard deviation when it is one of the draws)."""
    tables = [read_accuracy_csv(d.results / "accuracy.csv") for d in done]
    units = units_of(done[0].results / "accuracy.csv")
    today = read_accuracy_csv(compare / "accuracy.csv") if compare and (compare / "accuracy.csv").is_file() else {}
    others = spreads([t for d, t in zip(done, tables, strict=True) if d.results != compare])
    print(f"\n### seed {seed}: {len(done)} noise draws (draws {', '.join(str(d.draw) for d in done)})\n")
    name = f"value in {compare}" if today else "compared value"
    print(f"| figure | unit | mean | sd | CV % | two draws within 5 % | {name} | z |\n"
          "|---|---|---|---|---|---|---|---|")
    for fig, s in spreads(tables).items():
        v = today.get(fig, math.nan)
        z = others[fig].z(v) if fig in others else math.nan
        print(f"| {fig[0]}: {fig[1]} | {units.get(fig, '')} | {s.mean:.4g} | {s.sd:.2g} | {100 * s.cv:.1f} | "
              f"{100 * s.p_within(0.05):.0f} % | {v:.4g} | {z:+.1f} |")


def marker_yaws(d: Draw) -> dict[int, tuple[float, float]]:
    """Per marker: its estimated yaw in the robot frame minus the true one, and the yaw sigma the marker
    calibration states (degrees); the anchor marker, taken as given, is left out."""
    doc = yaml.safe_load((d.results / "markers.yaml").read_text())
    truth = load_rig(d.recording / "truth" / "rig.yaml")
    out: dict[int, tuple[float, float]] = {}
    for m in doc["markers"]:
        if m["id"] == doc.get("anchor"):
            continue
        R_est = Pose(**m["T_robot_marker"]).matrix()[:3, :3]
        R_true = truth.marker(m["id"]).T_robot_marker.matrix()[:3, :3]
        d_yaw = math.degrees(math.atan2(*(R_est @ R_true.T)[[1, 0], 0]))
        cov = np.asarray(m["covariance"], float)
        out[int(m["id"])] = (d_yaw, math.degrees(math.sqrt(max(cov[5, 5], 0.0))))
    return out


def common_yaw_offset_deg(d: Draw) -> float:
    """The validation stops' mean signed yaw error (GTvision against truth), degrees."""
    est = read_tum(d.results / "gt_vision_validation.tum")
    truth = read_tum(d.recording / "truth" / "validation.tum")
    yaw_true = truth_xytheta(truth, est.stamps_s)[:, 2]
    return math.degrees(float(np.mean(geo.wrap_angle(est.yaw_rad() - yaw_true))))


def frame_yaw_sigma_deg(results: Path) -> float:
    """The yaw sigma of the markers' robot frame the run states once the survey tied it
    (``rig.calibrated.yaml``, ``robot.markers_frame_cov`` over (dt, dphi)), degrees; NaN without it."""
    p = results / "rig.calibrated.yaml"
    cov = load_rig(p).robot.markers_frame_cov if p.is_file() else None
    return math.degrees(math.sqrt(np.asarray(cov, float)[5, 5])) if cov is not None else math.nan


def yaw_check(seed: int, done: list[Draw], compare: Path | None) -> None:
    """Each marker's yaw over the draws against its stated sigma; the common yaw offset over the draws."""
    per = [marker_yaws(d) for d in done]
    # each marker's error holds the anchor's hand placement (the same in every draw): the spread is the noise's
    print(f"\n#### seed {seed}: marker yaw (robot frame, against truth) over the draws\n")
    print("| marker | yaw error per draw, deg | sd over the draws, deg | stated sigma (median), deg |\n"
          "|---|---|---|---|")
    for mid in per[0]:
        e = np.array([p[mid][0] for p in per])
        s = np.median([p[mid][1] for p in per])
        sd = f"{e.std(ddof=1):.4f}" if e.size > 1 else "-"
        print(f"| {mid} | {', '.join(f'{x:+.4f}' for x in e)} | {sd} | {s:.4f} |")
    off = np.array([common_yaw_offset_deg(d) for d in done])
    sig = np.median([frame_yaw_sigma_deg(d.results) for d in done])
    line = (f"\ncommon yaw offset of the validation stops per draw: {', '.join(f'{x:+.4f}' for x in off)} deg; "
            f"mean {off.mean():+.4f}, sd {off.std(ddof=1) if off.size > 1 else math.nan:.4f} deg; the robot "
            f"frame's stated yaw sigma (median) {sig:.4f} deg")
    if compare is not None and compare not in {d.results for d in done} and \
            (compare / "gt_vision_validation.tum").is_file():
        line += f"; {compare}: {common_yaw_offset_deg(Draw(seed, 0, done[0].recording, compare)):+.4f} deg"
    print(line)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, required=True, help="folder of the draws' recordings and results")
    ap.add_argument("--seeds", type=int, nargs="+", default=[1, 2])
    ap.add_argument("--draws", type=int, default=3)
    ap.add_argument("--redrawn", choices=["all", "sensors", "calibration"], default="all",
                    help="the simulator's noise_redrawn")
    ap.add_argument("--compare", default=None, help="results on the seed's own noise, '{seed}' replaced")
    ap.add_argument("--own", default=None, help="results of the same code and run settings on the seed's own "
                    "recording (draw 0), '{seed}' replaced: counted as one more draw")
    ap.add_argument("--workers", type=int, default=0)
    ap.add_argument("--tabulate-only", action="store_true")
    a = ap.parse_args()
    if a.draws < 2:
        ap.error("--draws: at least 2 for a standard deviation")
    all_draws = {s: draws_of(a.out, s, a.draws, a.redrawn) for s in a.seeds}
    if not a.tabulate_only:
        for s in a.seeds:
            for d in all_draws[s]:
                produce(d, a.redrawn, a.workers)
    for s in a.seeds:
        done = [d for d in all_draws[s] if (d.results / "accuracy.csv").is_file()]
        compare = Path(a.compare.format(seed=s)) if a.compare else None
        if a.own and done:
            done.insert(0, Draw(s, 0, done[0].recording, Path(a.own.format(seed=s))))
        if len(done) < 2:
            print(f"\nseed {s}: {len(done)} finished draw(s), fewer than 2: no spread")
            continue
        table(s, done, compare)
        yaw_check(s, done, compare)
    return 0


if __name__ == "__main__":
    sys.exit(main())
