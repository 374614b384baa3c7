"""Scan matching on CARMEN logs (the Radish / Freiburg ``*-corrected.log`` files): their scans as
matchable point sets, the raw odometry at the scans, and the two checks of a relative pose that
need no ground truth (the scans' own fit and loop closure).

What the two logs in ``../shared/data/carmen`` hold, measured on the files (docs/scanmatch.md):

- ``FLASER n r_1 .. r_n x y theta odom_x odom_y odom_theta t host t``: intel 180 beams, freiburg-079
  360; the beams cover 180 degrees from the right, beam ``i`` at ``-90 deg + i * 180 deg / n`` (the
  convention of CARMEN's readers; spreading them over ``180 * n / (n - 1)`` degrees fits the scans
  worse in 58-66 % of consecutive pairs). Ranges in metres to the centimetre; a scanner's "no echo" is
  its maximum code, 81.83 m (intel) or 81.91 m (freiburg): nothing lies between 40 m and that code.
- Both pose triples of a FLASER record hold the corrected pose (equal to the last digit), and it is
  the scanner's pose: the planar mounting that best maps the logs' relative poses on our matches is
  within 12 mm and 0.07 deg of the identity (freiburg's ``robot_frontlaser_offset`` of 4 cm is not
  in them). The raw odometry is in the ODOM records (:mod:`gtrig.io.carmen`).
- The two stamps of every record are equal (the logs were re-timed from zero), and each FLASER
  follows a raw ODOM record with its own stamp: the raw odometry at a scan is read, not interpolated.
"""

from __future__ import annotations

import numpy as np

from gtrig.io.carmen import CarmenLog
from gtrig.scanmatch import se2
from gtrig.scanmatch.genetic import GeneticParams
from gtrig.scanmatch.icp import DEFAULT_ICP, IcpParams, match_icp
from gtrig.scanmatch.pairs import Guess
from gtrig.scanmatch.scan import PlanarScan, ranges_to_scan

# Readings at or beyond this are the scanner's "no echo" code (81.83 / 81.91 m), not ranges.
NO_ECHO_M = 80.0
# A SICK LMS's range noise indoors (data sheet: about 1 cm; the logs round to 1 cm).
RANGE_SIGMA_M = 0.01
# The global search for pairs the local matcher refuses: the logs' raw odometry drifts by metres and
# any heading around a loop, so the window spans every heading and 1.5 m either way (a wider one
# holds more look-alike places than 96 x 60 candidates can tell apart).
LOOP_GENETIC = GeneticParams(half_width=(1.5, 1.5, float(np.pi)), population=96, generations=60)


def beam_angles_rad(n_beams: int) -> np.ndarray:
    """(n,) beam angles in the scanner frame: ``-pi/2 + i * pi / n`` (180 degrees from the right)."""
    return -np.pi / 2 + np.arange(n_beams) * np.pi / n_beams


def log_scans(log: CarmenLog, rows: np.ndarray | None = None,
              range_sigma_m: float = RANGE_SIGMA_M) -> list[PlanarScan]:
    """The log's scans (all, or ``rows``) as :class:`PlanarScan` in the scanner frame, no-echo codes dropped."""
    rows = np.arange(len(log.laser_stamps_s)) if rows is None else np.asarray(rows)
    ang = beam_angles_rad(log.laser_ranges.shape[1])
    return [ranges_to_scan(log.laser_ranges[k], ang, np.zeros(3), range_sigma_m, NO_ECHO_M,
                           float(log.laser_stamps_s[k])) for k in rows]


def odometry_at_scans(log: CarmenLog, rows: np.ndarray | None = None) -> np.ndarray:
    """(M, 3) the raw wheel odometry (re-anchorings removed, :meth:`CarmenLog.rebuilt_odometry`) at the
    scans' stamps."""
    rows = np.arange(len(log.laser_stamps_s)) if rows is None else np.asarray(rows)
    t, p = log.rebuilt_odometry()
    return Guess(t, p).at(log.laser_stamps_s[rows])


def odometry_path_m(log: CarmenLog, rows: np.ndarray | None = None) -> np.ndarray:
    """(M,) the distance the raw odometry travelled from the first scan to each scan (metres)."""
    rows = np.arange(len(log.laser_stamps_s)) if rows is None else np.asarray(rows)
    t, p = log.rebuilt_odometry()
    run = np.r_[0.0, np.cumsum(np.hypot(np.diff(p[:, 0]), np.diff(p[:, 1])))]
    return np.interp(log.laser_stamps_s[rows], t, run)


def scans_own_match(scans: list[PlanarScan], poses: np.ndarray, pairs: np.ndarray,
                    icp: IcpParams = DEFAULT_ICP) -> np.ndarray:
    """(P, 3) each pair's match started from the relative pose of ``poses`` (N, 3) (e.g. the logs'
    corrected poses, a few centimetres off): the alignment the two scans themselves define near it.
    A reference for judging matches from poorer guesses, not a ground truth."""
    rel = se2.relative(poses[pairs[:, 0]], poses[pairs[:, 1]])
    return np.array([match_icp(scans[a], scans[b], g, icp).pose for (a, b), g in zip(pairs, rel, strict=True)])


def triplet_closures(pairs: np.ndarray, rel: np.ndarray) -> np.ndarray:
    """(T, 3) loop-closure errors ``rel_ij + rel_jk - rel_ik`` (composed, in the frame of ``i``) over every
    triplet ``i < j < k`` whose three pairs are all in ``pairs`` (P, 2) with relative poses ``rel`` (P, 3).

    Relative poses computed from one set of absolute poses close exactly; independent matches close
    to within their own errors (about sqrt(3) times one match's error per axis).
    """
    index = {(int(a), int(b)): n for n, (a, b) in enumerate(pairs)}
    nbrs: dict[int, list[int]] = {}
    for a, b in index:
        nbrs.setdefault(a, []).append(b)
    out = []
    for (i, j), n_ij in index.items():
        for k in nbrs.get(j, ()):
            n_ik = index.get((i, k))
            if n_ik is not None:
                out.append(se2.relative(rel[n_ik], se2.compose(rel[n_ij], rel[index[(j, k)]])))
    return np.array(out).reshape(-1, 3)
