"""Validation poses from the robot's own scans: every validation stop relative to a reference stop.

The seeds' "LRF frame" (deliverable, "Using the onboard laser range finders"): the robot stands still
at each validation stop; both onboard scanners' scans of the stop are reduced to their per-beam
median (:func:`gtrig.scanmatch.scan.stop_ranges`, people walking through drop out), put in the robot
frame through the rig's mountings and merged into one 360-degree scan; each stop's scan is matched on
the reference stop's (guess: the survey's relative pose when there is one, else the genetic matcher
over the room), refined by point-to-line ICP and judged by the acceptance test.

The pose of stop ``k`` is ``T_ref_k``, the robot frame at stop ``k`` in the robot frame at the
reference stop, with its covariance (statistical, surface bias, floor tilt:
:mod:`gtrig.scanmatch.covariance`).
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
from scipy.stats import chi2

from gtrig.errors import FormatError, InputError
from gtrig.io.scans import read_scans
from gtrig.rig.models import OnboardScanner, Rig
from gtrig.scanmatch import se2
from gtrig.scanmatch.accept import DEFAULT_ACCEPT, AcceptParams, Verdict, judge
from gtrig.scanmatch.covariance import systematic_cov
from gtrig.scanmatch.genetic import DEFAULT_GENETIC, GeneticParams, match_genetic
from gtrig.scanmatch.icp import DEFAULT_ICP, IcpParams, IcpResult, match_icp
from gtrig.scanmatch.scan import PlanarScan, merge, ranges_to_scan, stop_ranges
from gtrig.trajectory import PoseStatus, PoseTrack

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class ErrorModel:
    """The scanners' and the platform's error sizes (metres, radians).

    range_sigma_m : one scan's range noise (SICK LMS291 data sheet: about 1 cm indoors).
    surface_bias_sigma_m : one surface's reflectivity-dependent range bias: the slope of a pulsed
        scanner's range bias with reflectivity (about 8 mm from black to white) times the spread of a
        room's surface reflectivities (about 0.2), 1.5 mm.
    floor_tilt_sigma_rad : the floor's tilt under the robot, one standard deviation per axis (a lab
        floor within 0.5 deg everywhere: about 0.15 deg); with the scanners' height it shifts a scan
        sideways.
    """

    range_sigma_m: float = 0.01
    surface_bias_sigma_m: float = 0.0015
    floor_tilt_sigma_rad: float = float(np.radians(0.15))


def scanner_pose_xyth(sc: OnboardScanner) -> np.ndarray:
    """(3,) the scanner's planar mounting (x, y, yaw) in the robot frame."""
    return se2.from_matrix(sc.T_robot_scanner.matrix())


def scanner_height_m(rig: Rig) -> float:
    """Mean height of the onboard scanners above the robot frame's origin (the floor)."""
    sc = rig.robot.onboard_scanners
    return float(np.mean([s.T_robot_scanner.matrix()[2, 3] for s in sc])) if sc else 0.0


@dataclass(frozen=True)
class StopScans:
    """The validation stops as scans.

    pose_ids : (K,) the stops' numbers (validation/poses.csv).
    stamps_s : (K,) mid-times of the stops.
    merged : K merged 360-degree scans in the robot frame.
    per_scanner : scanner name -> K scans in that scanner's own frame (for mounting calibration).
    """

    pose_ids: np.ndarray
    stamps_s: np.ndarray
    merged: tuple[PlanarScan, ...]
    per_scanner: dict[str, tuple[PlanarScan, ...]] = field(default_factory=dict)


def read_stop_intervals(path: Path) -> tuple[np.ndarray, np.ndarray]:
    """``validation/poses.csv``: (K,) pose numbers and (K, 2) start and end stamps."""
    from gtrig.io.scans import data_lines, parse_numbers

    header, lines, line_no = data_lines(path)
    if [h.strip() for h in header.split(",")] != ["pose", "start_s", "end_s"]:
        raise FormatError(f"{path}: header must be 'pose,start_s,end_s', got {header[:60]!r}")
    a = parse_numbers(path, lines, line_no, 3)
    bad = np.flatnonzero(~(a[:, 2] > a[:, 1]))
    if bad.size:
        raise FormatError(f"{path}:{line_no[int(bad[0])]}: end_s must be after start_s")
    return a[:, 0].astype(int), a[:, 1:]


def load_stop_scans(rec: str | Path, rig: Rig, model: ErrorModel = ErrorModel()) -> StopScans:
    """Read ``validation/onboard/<scanner>.csv`` and reduce each stop to one low-noise scan per scanner."""
    rec = Path(rec)
    scanners = rig.robot.onboard_scanners
    if not scanners:
        raise InputError(f"{rec}: the rig describes no onboard scanner (robot.onboard_scanners)")
    ids, iv = read_stop_intervals(rec / "validation" / "poses.csv")
    per: dict[str, list[PlanarScan]] = {s.name: [] for s in scanners}
    merged: list[PlanarScan] = []
    logs = {s.name: read_scans(rec / "validation" / "onboard" / f"{s.name}.csv", s) for s in scanners}
    for k, (a, b) in enumerate(iv):
        parts = []
        for sc in scanners:
            lg = logs[sc.name]
            sel = (lg.stamps_s >= a) & (lg.stamps_s <= b)
            if not np.any(sel):
                raise InputError(f"{rec}/validation/onboard/{sc.name}.csv: no scan during stop {ids[k]} "
                                 f"({a:.3f} .. {b:.3f} s)")
            r, s = stop_ranges(lg.ranges_m[sel], model.range_sigma_m)
            if not np.any(np.isfinite(r)):
                raise InputError(f"{rec}/validation/onboard/{sc.name}.csv: stop {ids[k]} has no valid range")
            mid = 0.5 * (a + b)
            per[sc.name].append(ranges_to_scan(r, sc.angles_rad, np.zeros(3), s, sc.range_max_m, mid))
            parts.append(ranges_to_scan(r, sc.angles_rad, scanner_pose_xyth(sc), s, sc.range_max_m, mid))
        merged.append(merge(parts))
    return StopScans(ids, iv.mean(axis=1), tuple(merged), {k: tuple(v) for k, v in per.items()})


@dataclass(frozen=True)
class StopMatch:
    """One stop against the reference: the match, its full covariance and the verdict."""

    pose_id: int
    pose: np.ndarray
    cov: np.ndarray
    icp: IcpResult
    verdict: Verdict
    matcher: str


def match_pair(ref: PlanarScan, cur: PlanarScan, guess: np.ndarray, guess_cov: np.ndarray,
               model: ErrorModel, tilt_shift_m: float, icp: IcpParams = DEFAULT_ICP,
               accept: AcceptParams = DEFAULT_ACCEPT, genetic: GeneticParams | None = DEFAULT_GENETIC,
               ) -> tuple[np.ndarray, np.ndarray, IcpResult, Verdict, str]:
    """Local match from ``guess``; when the acceptance test refuses it, the genetic matcher (seeded
    with the guess) and the local refinement. Returns pose, full covariance, match, verdict, matcher."""
    def local(start: np.ndarray) -> tuple[IcpResult, np.ndarray, Verdict]:
        r = match_icp(ref, cur, start, icp)
        c = r.cov + systematic_cov(r, cur, model.surface_bias_sigma_m, tilt_shift_m)
        v = judge(r, c, guess, guess_cov, accept)
        return r, (degenerate_cov(c, guess_cov) if v.degenerate else c), v

    res, cov, v = local(guess)
    name = "icp"
    if not v.accepted and genetic is not None:
        ga = match_genetic(ref, cur, guess, genetic)
        res2, cov2, v2 = local(ga.pose)
        if v2.accepted or v2.score > v.score:
            res, cov, v, name = res2, cov2, v2, "genetic+icp"
    if v.accepted and accept.probe_m > 0:
        res, cov, v, name = _probe(local, res, cov, v, name, accept)
    return res.pose, cov, res, v, name


def degenerate_cov(cov: np.ndarray, guess_cov: np.ndarray) -> np.ndarray:
    """A degenerate match's covariance (3, 3): ``cov`` with the guess's variance along its major position
    axis ``u`` added (``cov + (u^T G u) u u^T``). Along a weakly held direction the local quadratic
    does not bound the error (the scans' few cues there, a door frame, a pillar, can pull the match to
    another place the guess allows); on the CARMEN logs such matches were 8-21 cm off the logs' poses
    with 7-15 mm claimed: NEES/dof 3.0 over 20 pairs against the logs (their 2 cm, 0.5 deg noise
    counted), 1.0 with the guess's variance added."""
    u = np.linalg.eigh(cov[:2, :2])[1][:, -1]
    u3 = np.r_[u, 0.0]
    return cov + float(u3 @ np.asarray(guess_cov, dtype=float) @ u3) * np.outer(u3, u3)


def _probe(local: Callable[[np.ndarray], tuple[IcpResult, np.ndarray, Verdict]], res: IcpResult,
           cov: np.ndarray, v: Verdict, name: str, accept: AcceptParams) -> tuple[IcpResult, np.ndarray, Verdict, str]:
    """The uniqueness check of an accepted match: the local matcher restarted ``accept.probe_m`` either
    side along the match's least determined direction (a corridor's axis).

    A restart that ends on another pose (outside the chi-square(3) ``guess_quantile`` gate of the
    match's covariance), fits within the noise (inlier share, residual spread), agrees with the guess
    and explains at least as many points (within ``probe_margin``) is a second solution that neither
    the scans nor the guess can tell from the first: the match is kept as degenerate with its
    covariance widened by ``d d^T`` (``d`` the perturbation between the two solutions, the covariance's
    frame) when ``accept.degenerate == "report"``, refused otherwise; the other side is then probed
    against the widened covariance. One that explains clearly more and passes the whole test replaces the
    match (the guess led to a local minimum)."""
    u = np.linalg.eigh(cov[:2, :2])[1][:, -1]
    gate = chi2.ppf(accept.guess_quantile, 3)
    best = (res, cov, v)
    for sgn in (1.0, -1.0):
        r2, c2, v2 = local(res.pose + np.r_[sgn * accept.probe_m * u, 0.0])
        d = se2.compose(r2.pose, se2.inverse(res.pose))  # world-frame perturbation, as the covariance's
        if not r2.converged or d @ np.linalg.solve(cov, d) <= gate:
            continue
        if v2.accepted and v2.explained > best[2].explained + accept.probe_margin:
            best = (r2, c2, v2)
        elif (v2.explained >= v.explained - accept.probe_margin and v2.inlier_share >= accept.min_inlier_share
              and v2.s_ratio <= accept.max_s_ratio and v2.mahalanobis2 <= gate):
            why = (f"ambiguous: a second match {1000 * float(np.hypot(d[0], d[1])):.0f} mm away explains "
                   f"{v2.explained:.2f} of the points (this one {v.explained:.2f})")
            if accept.degenerate == "refuse":
                return res, cov, replace(v, accepted=False, reason=why), name
            cov = cov + np.outer(d, d)
            v = replace(v, degenerate=True, reason=why + "; covariance widened to span it",
                        sd_max_m=float(np.sqrt(np.linalg.eigvalsh(cov[:2, :2])[-1])),
                        sd_theta_rad=float(np.sqrt(cov[2, 2])))
            best = (res, cov, v)
    if best[0] is not res:
        return best[0], best[1], best[2], name + "+probe"
    return res, cov, v, name


@dataclass(frozen=True)
class StopValidation:
    """Validation poses from the onboard scans.

    track : the stops' poses in the reference stop's robot frame (``frame_id = "stop<ref>"``), planar
        covariance, REJECTED where the acceptance test refused the match.
    matches : one :class:`StopMatch` per stop.
    reference : the reference stop's number.
    survey_rel : (K, 3) the survey's poses relative to the reference stop, or None.
    """

    track: PoseTrack
    matches: tuple[StopMatch, ...]
    reference: int
    survey_rel: np.ndarray | None = None

    def rows(self) -> list[dict[str, Any]]:
        """One row per stop: pose, x, y, theta, standard deviations, verdict, and the survey's pose."""
        out = []
        for i, m in enumerate(self.matches):
            sd = np.sqrt(np.diag(m.cov))
            row: dict[str, Any] = {
                "pose": m.pose_id, "x": m.pose[0], "y": m.pose[1], "theta": m.pose[2],
                "sd_x": sd[0], "sd_y": sd[1], "sd_theta": sd[2],
                "verdict": "accepted" if m.verdict.accepted else "rejected", "reason": m.verdict.reason,
                "matcher": m.matcher, "explained": m.verdict.explained,
            }
            if self.survey_rel is not None:
                e = se2.relative(self.survey_rel[i], m.pose)
                row.update({"survey_x": self.survey_rel[i, 0], "survey_y": self.survey_rel[i, 1],
                            "survey_theta": self.survey_rel[i, 2], "diff_xy_m": float(np.hypot(e[0], e[1])),
                            "diff_theta_rad": float(e[2])})
            out.append(row)
        return out


# Stops lie up to 6 m from the reference: a stop's scan sees parts of the room the reference stop's
# cannot (clutter occludes), so the share of points explained is lower than for neighbouring scans.
STOP_ACCEPT = AcceptParams(min_explained=0.3)


def validate_stops(stops: StopScans, reference: int, rig: Rig, guesses_world: np.ndarray | None = None,
                   guess_cov: np.ndarray | None = None, model: ErrorModel = ErrorModel(),
                   icp: IcpParams = DEFAULT_ICP, accept: AcceptParams = STOP_ACCEPT,
                   seed: int = 0) -> StopValidation:
    """Match every stop on the reference stop.

    Parameters
    ----------
    stops : :func:`load_stop_scans`.
    reference : the reference stop's number.
    guesses_world : (K, 3) rough poses of the stops in any one frame (the survey's), or None: then
        the genetic matcher searches the room (+-4 m, +-180 deg) for each stop.
    guess_cov : (3, 3) covariance of a relative guess; default: 5 cm, 2 deg with guesses, else the
        search box.
    """
    ids = list(int(i) for i in stops.pose_ids)
    if reference not in ids:
        raise InputError(f"reference stop {reference} is not among the validation stops {ids[0]}..{ids[-1]}")
    r = ids.index(reference)
    tilt = scanner_height_m(rig) * model.floor_tilt_sigma_rad
    ref = stops.merged[r]
    matches = []
    survey_rel = None
    if guesses_world is not None:
        g = np.asarray(guesses_world, dtype=float)
        if g.shape != (len(ids), 3):
            raise InputError(f"{g.shape[0]} guesses for {len(ids)} validation stops")
        survey_rel = se2.relative(g[r], g)
        gcov = np.diag([0.05**2, 0.05**2, np.radians(2.0) ** 2]) if guess_cov is None else guess_cov
        ga = GeneticParams(seed=seed)
    else:
        gcov = np.diag([4.0**2, 4.0**2, np.pi**2]) if guess_cov is None else guess_cov
        ga = GeneticParams(half_width=(4.0, 4.0, np.pi), population=200, generations=80, seed=seed)
    for k, pid in enumerate(ids):
        if k == r:
            z = np.zeros(3)
            res = match_icp(ref, ref, z, icp)
            matches.append(StopMatch(pid, z, np.zeros((3, 3)), res, Verdict.reference(), "reference"))
            continue
        if survey_rel is not None:
            pose, cov, res, v, name = match_pair(ref, stops.merged[k], survey_rel[k], gcov, model, tilt, icp, accept,
                                                 GeneticParams(seed=seed + k))
        else:
            gres = match_genetic(ref, stops.merged[k], np.zeros(3), ga)
            pose, cov, res, v, name = match_pair(ref, stops.merged[k], gres.pose, np.diag([0.1, 0.1, 0.05]) ** 2,
                                                 model, tilt, icp, accept, GeneticParams(seed=seed + k))
            name = "genetic+icp"
        matches.append(StopMatch(pid, pose, cov, res, v, name))
    matches = _chain_rejected(stops, matches, r, survey_rel, model, tilt, icp, accept, seed)
    poses = np.array([m.pose for m in matches])
    status = np.array([PoseStatus.OK if m.verdict.accepted else PoseStatus.REJECTED for m in matches], np.uint8)
    track = PoseTrack.from_xytheta(stops.stamps_s, poses, cov=np.array([m.cov for m in matches]),
                                   status=status, reasons=tuple(m.verdict.reason for m in matches),
                                   source="scanmatch", frame_id=f"stop{reference}", child_frame_id="robot")
    return StopValidation(track, tuple(matches), reference, survey_rel)


def compose_cov(a: np.ndarray, b: np.ndarray, cov_a: np.ndarray, cov_b: np.ndarray) -> np.ndarray:
    """(3, 3) covariance of ``a (+) b`` for independent ``a`` and ``b`` (first-order)."""
    c, s = np.cos(a[2]), np.sin(a[2])
    Ja = np.array([[1.0, 0.0, -s * b[0] - c * b[1]], [0.0, 1.0, c * b[0] - s * b[1]], [0.0, 0.0, 1.0]])
    Jb = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    return Ja @ cov_a @ Ja.T + Jb @ cov_b @ Jb.T


def _chain_rejected(stops: StopScans, matches: list[StopMatch], r: int, guess_rel: np.ndarray | None,
                    model: ErrorModel, tilt: float, icp: IcpParams, accept: AcceptParams,
                    seed: int) -> list[StopMatch]:
    """A stop whose direct match was refused (too far from the reference: too little in common) is
    matched on the nearest accepted stop instead and its pose composed through it (one link)."""
    out = list(matches)
    est = np.array([m.pose for m in matches]) if guess_rel is None else guess_rel
    for k, m in enumerate(matches):
        if m.verdict.accepted:
            continue
        cands = [a for a, ma in enumerate(matches) if ma.verdict.accepted and a not in (k, r)]
        cands.sort(key=lambda a: float(np.hypot(*(est[a, :2] - est[k, :2]))))
        for a in cands[:3]:
            g = se2.relative(out[a].pose, est[k])
            gc = np.diag([0.05**2, 0.05**2, np.radians(2.0) ** 2])
            pose, cov, res, v, name = match_pair(stops.merged[a], stops.merged[k], g, gc, model, tilt, icp, accept,
                                                 GeneticParams(seed=seed + 1000 + k))
            if v.accepted:
                p = se2.compose(out[a].pose, pose)
                out[k] = StopMatch(m.pose_id, p, compose_cov(out[a].pose, pose, out[a].cov, cov), res, v,
                                   f"{name} via stop {matches[a].pose_id}")
                break
    return out


def validate_recording(rec: str | Path, rig: Rig | None = None, reference: int = 1,
                       survey_poses: np.ndarray | None = None, model: ErrorModel = ErrorModel(),
                       seed: int = 0) -> StopValidation:
    """The pipeline's entry point for "scanmatch validate": the recording's validation stops from its
    onboard scans, relative to stop ``reference``; ``survey_poses`` (K, 3) world poses of the stops
    (e.g. ``results/survey/validation_poses.csv``) seed the matches and are reported beside them."""
    from gtrig.rig.load import load_rig

    rec = Path(rec)
    rig = rig if rig is not None else load_rig(rec / "rig.yaml")
    stops = load_stop_scans(rec, rig, model)
    return validate_stops(stops, reference, rig, survey_poses, model=model, seed=seed)
