"""The global matcher: the seeds' real-coded genetic algorithm over (x, y, theta).

RAWSEEDS deliverable, "Using the onboard laser range finders": three real genes, the fitness of a
candidate pose is the residual of nearest-point association of the current scan on the reference
(here scipy's cKDTree), trimmed to drop the worst residuals (partial overlap), and the population is
seeded with the initial guess. Selection is by tournament, crossover is BLX-alpha (Eshelman and
Schaffer 1993), mutation is Gaussian with a step that shrinks over the generations, and the best
candidates survive (elitism). Deterministic for a given ``seed``. The result is meant to be refined
by the local matcher (:func:`gtrig.scanmatch.icp.match_icp`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from gtrig.scanmatch import se2
from gtrig.scanmatch.scan import PlanarScan


@dataclass(frozen=True)
class GeneticParams:
    """Settings of the genetic matcher.

    half_width : (3,) search box around the guess: metres, metres, radians.
    population, generations, tournament, elite : the usual.
    blx_alpha : BLX crossover's extension of the parents' interval.
    trim : share of the worst residuals each fitness drops.
    clip_m : a residual counts at most this (no neighbour within it).
    max_points : current points used (evenly subsampled) for speed.
    """

    half_width: tuple[float, float, float] = (0.6, 0.6, np.radians(35.0))
    population: int = 64
    generations: int = 40
    tournament: int = 3
    elite: int = 2
    blx_alpha: float = 0.3
    trim: float = 0.2
    clip_m: float = 0.5
    max_points: int = 120
    seed: int = 0


DEFAULT_GENETIC = GeneticParams()


@dataclass(frozen=True)
class GeneticResult:
    """Best pose (3,) (the current frame in the reference frame), its fitness (trimmed mean squared
    nearest-point distance, m^2) and the fitness of the best per generation."""

    pose: np.ndarray
    fitness: float
    history: np.ndarray


def pair_seed(base: int, stamp_a_s: float, stamp_b_s: float) -> int:
    """The genetic matcher's seed for the pair of scans stamped ``stamp_a_s`` and ``stamp_b_s``: derived
    from the pair itself (its stamps to the microsecond) and ``base``, so a pair's match does not depend
    on where it stands in a list, how the list is cut into chunks or which other pairs are matched."""
    us = [int(round(float(t) * 1e6)) for t in (stamp_a_s, stamp_b_s)]
    words = [int(base) & 0xFFFFFFFF] + [w for u in us for w in ((u >> 32) & 0xFFFFFFFF, u & 0xFFFFFFFF)]
    return int(np.random.SeedSequence(words).generate_state(1, np.uint64)[0] >> 1)


def _fitness(tree: cKDTree, pts: np.ndarray, poses: np.ndarray, trim: float, clip: float) -> np.ndarray:
    P = poses.shape[0]
    moved = se2.apply(poses, np.broadcast_to(pts, (P, *pts.shape)))  # (P, N, 2)
    d, _ = tree.query(moved.reshape(-1, 2), k=1, distance_upper_bound=clip)
    d = np.minimum(d, clip).reshape(P, -1) ** 2
    keep = max(1, int(round((1.0 - trim) * d.shape[1])))
    d.partition(keep - 1, axis=1)
    return d[:, :keep].mean(axis=1)


def match_genetic(ref: PlanarScan, cur: PlanarScan, guess: np.ndarray,
                  params: GeneticParams = GeneticParams()) -> GeneticResult:
    """Search (x, y, theta) in ``guess +- half_width`` for the pose putting ``cur`` on ``ref``."""
    rng = np.random.default_rng(params.seed)
    g = np.asarray(guess, dtype=float).reshape(3)
    hw = np.asarray(params.half_width, dtype=float)
    tree = cKDTree(ref.xy)
    step = max(1, int(np.ceil(len(cur) / params.max_points)))
    pts = np.ascontiguousarray(cur.xy[::step])
    P = params.population
    lo, hi = g - hw, g + hw
    pop = rng.uniform(lo, hi, size=(P, 3))
    pop[0] = g  # seeded with the guess
    fit = _fitness(tree, pts, pop, params.trim, params.clip_m)
    history = np.empty(params.generations)
    sigma0 = hw / 4.0
    for gen in range(params.generations):
        order = np.argsort(fit)
        elite = pop[order[: params.elite]]
        # tournament selection of 2 (P - elite) parents
        n_child = P - params.elite
        cand = rng.integers(0, P, size=(2 * n_child, params.tournament))
        winners = cand[np.arange(2 * n_child), np.argmin(fit[cand], axis=1)]
        pa, pb = pop[winners[:n_child]], pop[winners[n_child:]]
        lo_p, hi_p = np.minimum(pa, pb), np.maximum(pa, pb)
        span = hi_p - lo_p
        child = rng.uniform(lo_p - params.blx_alpha * span, hi_p + params.blx_alpha * span)
        # mutation step shrinks linearly to a tenth
        sig = sigma0 * (1.0 - 0.9 * gen / max(1, params.generations - 1))
        mutate = rng.random(child.shape) < 0.3
        child = child + mutate * rng.normal(0.0, 1.0, child.shape) * sig
        child = np.clip(child, lo, hi)
        pop = np.vstack([elite, child])
        fit = np.concatenate([fit[order[: params.elite]], _fitness(tree, pts, child, params.trim, params.clip_m)])
        history[gen] = fit.min()
    best = int(np.argmin(fit))
    pose = pop[best].copy()
    pose[2] = float(se2.wrap(pose[2]))
    return GeneticResult(pose, float(fit[best]), history)
