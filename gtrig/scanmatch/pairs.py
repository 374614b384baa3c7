"""Relative-pose ground truth from the robot's own scans: candidate scan pairs near a guessed
trajectory, each matched and judged.

The seeds (deliverable, "Using the onboard laser range finders") searched a kd-tree over the guessed
poses for scan pairs close in space, matched each and inspected the matches by eye. Here the pairs
are every two scans whose guessed positions are within ``max_dist_m`` (scipy's cKDTree
``query_pairs``) and headings within ``max_angle_rad``; each is matched from the guess (point-to-line
ICP, the genetic matcher when the acceptance test refuses the local result) and the acceptance test
decides. A relation is the pose of the scan at ``t2`` in the robot frame at ``t1``.

Scans of a moving robot are de-skewed: each beam is placed with the guessed motion at its own firing
instant (the mirror sweeps the beams over part of a revolution), and the rear scanner's nearest scan
joins the front scanner's at the front scan's stamp.
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
from scipy.spatial import cKDTree

from gtrig.errors import InputError
from gtrig.io.scans import ScanLog
from gtrig.rig.models import OnboardScanner
from gtrig.scanmatch import se2
from gtrig.scanmatch.accept import DEFAULT_ACCEPT, AcceptParams, Verdict
from gtrig.scanmatch.genetic import DEFAULT_GENETIC, GeneticParams, pair_seed
from gtrig.scanmatch.icp import DEFAULT_ICP, IcpParams
from gtrig.scanmatch.scan import PlanarScan, merge, ranges_to_scan

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class Guess:
    """A guessed planar trajectory: stamps (N,) and poses (N, 3), theta unwrapped for interpolation."""

    stamps_s: np.ndarray
    xytheta: np.ndarray

    def __post_init__(self) -> None:
        st = np.asarray(self.stamps_s, dtype=float)
        p = np.asarray(self.xytheta, dtype=float).reshape(-1, 3).copy()
        if st.shape != (p.shape[0],) or st.size < 2:
            raise InputError("a guessed trajectory needs at least two poses")
        if np.any(np.diff(st) <= 0):
            raise InputError("the guessed trajectory's stamps must increase strictly")
        p[:, 2] = np.unwrap(p[:, 2])
        object.__setattr__(self, "stamps_s", st)
        object.__setattr__(self, "xytheta", p)

    def at(self, t: np.ndarray) -> np.ndarray:
        """(M, 3) poses at ``t`` (M,), linear interpolation, clamped at the ends."""
        t = np.atleast_1d(np.asarray(t, dtype=float))
        return np.column_stack([np.interp(t, self.stamps_s, self.xytheta[:, k]) for k in range(3)])


def beam_delays_s(sc: OnboardScanner) -> np.ndarray:
    """(B,) firing time of each beam after the scan's stamp: the mirror turns once per period."""
    a = sc.angles_rad
    return np.abs(a - a[0]) / (2 * np.pi) / sc.rate_hz


def sequence_scans(scanners: tuple[OnboardScanner, ...], logs: dict[str, ScanLog], guess: Guess,
                   mounts: dict[str, np.ndarray], range_sigma_m: float, every: int = 1) -> list[PlanarScan]:
    """One merged, de-skewed scan in the robot frame per ``every``-th scan of the first scanner.

    Parameters
    ----------
    scanners : the onboard scanners; the first one's stamps define the merged scans' stamps.
    logs : their scans.
    guess : the motion used for de-skewing (only its local shape matters).
    mounts : scanner name -> (3,) planar mounting in the robot frame.
    range_sigma_m : one scan's range noise.
    """
    lead = scanners[0]
    st = logs[lead.name].stamps_s[::every]
    rows = np.arange(len(logs[lead.name]))[::every]
    out = []
    ref_poses = guess.at(st)
    for i, t0 in enumerate(st):
        parts = []
        for sc in scanners:
            lg = logs[sc.name]
            if sc.name == lead.name:
                k = int(rows[i])
            else:
                k = int(np.argmin(np.abs(lg.stamps_s - t0)))
                if abs(lg.stamps_s[k] - t0) > 1.0 / sc.rate_hz:
                    continue
            tb = lg.stamps_s[k] + beam_delays_s(sc)
            rel = se2.relative(ref_poses[i], guess.at(tb))
            bp = se2.compose(rel, mounts[sc.name])
            parts.append(ranges_to_scan(lg.ranges_m[k], sc.angles_rad, bp, range_sigma_m, sc.range_max_m, t0))
        out.append(merge(parts, stamp_s=float(t0)))
    return out


def candidate_pairs(poses: np.ndarray, max_dist_m: float, max_angle_rad: float,
                    min_index_gap: int = 1) -> np.ndarray:
    """(P, 2) index pairs ``i < j`` of poses (N, 3) within ``max_dist_m`` and ``max_angle_rad``
    (cKDTree over the positions), at least ``min_index_gap`` apart in the sequence."""
    p = np.asarray(poses, dtype=float)
    if len(p) < 2:
        return np.zeros((0, 2), np.int64)
    pairs = cKDTree(p[:, :2]).query_pairs(max_dist_m, output_type="ndarray")
    if not len(pairs):
        return np.zeros((0, 2), np.int64)
    pairs = np.sort(pairs, axis=1)
    dth = np.abs(se2.wrap(p[pairs[:, 1], 2] - p[pairs[:, 0], 2]))
    keep = (dth <= max_angle_rad) & (pairs[:, 1] - pairs[:, 0] >= min_index_gap)
    pairs = pairs[keep]
    return pairs[np.lexsort((pairs[:, 1], pairs[:, 0]))]


@dataclass(frozen=True)
class Relation:
    """One judged scan pair: ``pose`` of the scan at ``t2`` in the robot frame at ``t1``, covariance
    (3, 3), the guess it started from, the matcher used and the acceptance test's verdict."""

    t1: float
    t2: float
    pose: np.ndarray
    cov: np.ndarray
    guess: np.ndarray
    matcher: str
    verdict: Verdict


def guess_cov_for(rel_guess: np.ndarray, dist_sigma_frac: float = 0.1, min_sigma_m: float = 0.05,
                  min_sigma_rad: float = float(np.radians(3.0)), path_m: float | None = None) -> np.ndarray:
    """A wheel-odometry guess's covariance over a relative motion: 10 % of the distance and of the
    turn, not below 5 cm and 3 deg (the slip and scale errors of the seeds' platforms). The distance is
    the path the odometry integrated between the two scans when ``path_m`` is given (a loop's two ends
    are close, but the odometry drifted over the whole loop), else the relative pose's length."""
    d = float(np.hypot(rel_guess[0], rel_guess[1])) if path_m is None else float(path_m)
    s_t = max(min_sigma_m, dist_sigma_frac * d)
    s_r = max(min_sigma_rad, dist_sigma_frac * abs(float(rel_guess[2])) + 0.02 * d)
    return np.diag([s_t**2, s_t**2, s_r**2])


#: scan pairs per chunk of :func:`match_pairs`
PAIRS_PER_CHUNK = 32


def _match_chunk(first: int, items: list[tuple[PlanarScan, PlanarScan, np.ndarray, np.ndarray]],
                 tilt_shift_m: float, surface_bias_m: float, icp: IcpParams, accept: AcceptParams,
                 genetic: GeneticParams | None) -> list[Relation]:
    """Pairs ``first, first + 1, ...``: each ``(scan i, scan j, guess, guess covariance)``."""
    from gtrig.scanmatch.validate import ErrorModel, match_pair

    model = ErrorModel(surface_bias_sigma_m=surface_bias_m)
    out = []
    for a, b, g, gc in items:
        # each pair's own seed, from its scans' stamps: the result depends neither on the pair's place in
        # the list nor on how the pairs are cut into chunks
        gp = None if genetic is None else replace(genetic, seed=pair_seed(genetic.seed, a.stamp_s, b.stamp_s))
        pose, cov, _res, v, name = match_pair(a, b, g, gc, model, tilt_shift_m, icp, accept, gp)
        out.append(Relation(a.stamp_s, b.stamp_s, pose, cov, g, name, v))
    return out


def match_pairs(scans: list[PlanarScan], guesses: np.ndarray, pairs: np.ndarray, tilt_shift_m: float = 0.0,
                surface_bias_m: float = 0.0015, icp: IcpParams = DEFAULT_ICP, accept: AcceptParams = DEFAULT_ACCEPT,
                genetic: GeneticParams | None = DEFAULT_GENETIC, guess_cov: np.ndarray | None = None,
                rel_guesses: np.ndarray | None = None, path_m: np.ndarray | None = None, *, executor: Any = None,
                workers: int = 1, progress: Callable[[int, int], None] | None = None) -> list[Relation]:
    """Match and judge every pair; ``guesses`` (N, 3) are the scans' guessed poses (``rel_guesses``
    (P, 3), when given, replace their relative poses, e.g. perturbed truth in a measurement).
    ``path_m`` (P,): the distance the odometry travelled between each pair's scans, for the guess's
    covariance (:func:`guess_cov_for`) when ``guess_cov`` is not given.

    The pairs run in chunks of :data:`PAIRS_PER_CHUNK` over ``executor`` (:mod:`gtrig.executor`; None:
    ``workers`` local processes, 1 = here); each chunk carries its own scans. The output does not
    depend on them."""
    from gtrig.executor import Chunk, map_chunks

    items = []
    for n, (i, j) in enumerate(pairs):
        g = se2.relative(guesses[i], guesses[j]) if rel_guesses is None else rel_guesses[n]
        gc = guess_cov if guess_cov is not None else guess_cov_for(g, path_m=None if path_m is None else path_m[n])
        items.append((scans[i], scans[j], g, gc))
    chunks = []
    for k in range(0, len(items), PAIRS_PER_CHUNK):
        part = items[k:k + PAIRS_PER_CHUNK]
        chunks.append(Chunk((k, part, tilt_shift_m, surface_bias_m, icp, accept, genetic),
                            f"pairs {k}-{k + len(part) - 1} ({part[0][0].stamp_s:.3f}-{part[-1][1].stamp_s:.3f} s)"))
    done: dict[int, list[Relation]] = {}
    map_chunks(_match_chunk, chunks, done.__setitem__, executor=executor, workers=workers, progress=progress)
    return [r for c in range(len(chunks)) for r in done[c]]
