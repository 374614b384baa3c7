"""Initial robot pose: both planar-PnP solutions of every marker view, and the flip resolved.

A square seen by one camera has, near fronto-parallel or from far away, two poses that fit its four
corners almost equally well (the "flip": the plane mirrored about the line of sight). IPPE
(Collins and Bartoli, "Infinitesimal plane-based pose estimation", IJCV 109, 2014), through
``cv2.solvePnPGeneric(..., flags=cv2.SOLVEPNP_IPPE_SQUARE)``, returns both. The seeds used
Schweighofer and Pinz ("Robust pose estimation from a planar target", PAMI 28, 2006/2008), which also
looks at both minima but keeps one per marker, and lost poses to wrong picks.

Here every solution of every view becomes a candidate robot pose; candidates that agree are merged;
each distinct candidate is refined against *all* corners of *all* cameras (and the floor prior in
planar mode); the candidates are then ranked by their robust cost plus, when given, their distance
to the previous pose. The runner-up's cost margin says how sure the pick is: below
``ambiguity_margin`` the frame is reported ambiguous rather than guessed.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np

from gtrig import geometry as geo
from gtrig.vision.covariance import RigUncertainty
from gtrig.vision.observations import MarkerView, StackedCorners, VisionModel, marker_corners_marker
from gtrig.vision.refine import PlanarPrior, RefineOptions, RefineResult, refine_pose


@dataclass(frozen=True)
class ViewSolutions:
    """Both IPPE solutions of one marker view.

    Attributes
    ----------
    T_cam_marker : (2, 4, 4) the two poses (best reprojection first)
    rms_px : (2,) reprojection RMS of each, pixels
    T_world_robot : (2, 4, 4) the robot poses they imply through the rig
    """

    view: MarkerView
    T_cam_marker: np.ndarray
    rms_px: np.ndarray
    T_world_robot: np.ndarray


def ippe_view(model: VisionModel, view: MarkerView) -> ViewSolutions:
    """Both IPPE solutions for one marker view (Collins and Bartoli 2014), as marker and robot poses."""
    cam = model.cameras[view.camera]
    obj = marker_corners_marker(model.side_m[view.marker_id])
    n, rvecs, tvecs, errs = cv2.solvePnPGeneric(
        obj, view.corners_px.reshape(4, 1, 2), cam.K, cam.dist, flags=cv2.SOLVEPNP_IPPE_SQUARE)
    T_cm = []
    for rv, tv in zip(rvecs[:n], tvecs[:n], strict=True):
        T_cm.append(geo.make_T(cv2.Rodrigues(rv)[0], tv.ravel()))
    err = np.asarray(errs, dtype=float).ravel()[:n] if errs is not None else np.zeros(n)
    if n == 1:  # degenerate: IPPE returns one solution; keep the shape
        T_cm.append(T_cm[0])
        err = np.r_[err, err]
    T_cm_a = np.stack(T_cm[:2])
    T_rm_inv = geo.inv_T(model.T_robot_marker[view.marker_id])
    T_wr = cam.T_world_cam @ T_cm_a @ T_rm_inv
    return ViewSolutions(view, T_cm_a, err[:2], T_wr)


@dataclass(frozen=True)
class PreviousPose:
    """The last pose localized before this instant, used to break flips: ``T_world_robot`` and the
    tolerance of the comparison (how far the robot may have moved since), metres and radians."""

    T_world_robot: np.ndarray
    sigma_m: float = 0.2
    sigma_rad: float = math.radians(10.0)

    def cost(self, T: np.ndarray) -> float:
        dt, dr = geo.pose_error(T, self.T_world_robot)
        return (dt / self.sigma_m) ** 2 + (dr / self.sigma_rad) ** 2


@dataclass(frozen=True)
class InitOptions:
    """Flip resolution settings.

    Attributes
    ----------
    merge_m, merge_rad : candidates closer than this are one (before refinement).
    distinct_m, distinct_rad : refined candidates closer than this are the same solution.
    ambiguity_margin : the runner-up must cost at least this much more (chi-square units) for a pick.
    refine_iter : Gauss-Newton iterations per candidate.
    screen_cap : per-corner cap of the raw score; only the two best raw candidates and those within
        ``4 screen_cap`` (one wholly wrong view) of the best are refined.
    """

    merge_m: float = 0.05
    merge_rad: float = math.radians(3.0)
    distinct_m: float = 0.01
    distinct_rad: float = math.radians(0.5)
    ambiguity_margin: float = 9.0
    refine_iter: int = 6
    screen_cap: float = 25.0


@dataclass(frozen=True)
class Candidate:
    """A refined candidate: ``fit`` and its total ``score`` (robust cost + previous-pose term)."""

    fit: RefineResult
    score: float
    sources: int


@dataclass(frozen=True)
class InitResult:
    """The ranked candidates: ``best`` and ``margin`` (score of the best distinct runner-up minus the
    best's; ``inf`` when there is none). ``candidates`` holds the distinct ones, best first."""

    best: Candidate
    margin: float
    candidates: tuple[Candidate, ...]
    solutions: tuple[ViewSolutions, ...]


def _close(Ta: np.ndarray, Tb: np.ndarray, m: float, rad: float) -> bool:
    if np.sum((Ta[:3, 3] - Tb[:3, 3]) ** 2) >= m * m:
        return False
    c = (np.sum(Ta[:3, :3] * Tb[:3, :3]) - 1.0) / 2.0  # cos of the relative angle
    return bool(c > math.cos(rad))


def _raw_score(sc: StackedCorners, T: np.ndarray, prior: PlanarPrior | None, cap: float) -> float:
    """Cheap score of an unrefined candidate: per-corner chi-square capped at ``cap`` (a bad view
    costs at most ``4 cap``), plus the floor prior."""
    from gtrig.vision.projection import project_pose, whiten
    from gtrig.vision.refine import prior_residuals

    uv, z, _ = project_pose(sc, T, jacobian=False)
    e2 = np.sum(whiten(sc, uv - sc.uv) ** 2, axis=1)
    e2 = np.where(z > 0, np.minimum(e2, cap), cap)
    out = float(np.sum(e2))
    if prior is not None:
        rp, _ = prior_residuals(T, prior)
        out += float(rp @ rp)
    return out


def initial_pose(model: VisionModel, views: tuple[MarkerView, ...] | list[MarkerView], sc: StackedCorners,
                 prior: PlanarPrior | None = None, previous: PreviousPose | None = None,
                 options: InitOptions = InitOptions(),
                 refine_options: RefineOptions | None = None,
                 rig: RigUncertainty | None = None) -> InitResult:
    """Candidate robot poses from every view's two IPPE solutions, refined on all corners and ranked.

    Parameters
    ----------
    model : the rig geometry.
    views : the views of the instant (at least one); ``sc`` their stacked corners.
    prior : the planar prior (planar mode), which alone usually breaks flips: a flipped marker on a
        level plate implies a robot tilted by tens of degrees.
    previous : the previous pose, or None.
    rig : the rig's uncertainty (see :func:`gtrig.vision.refine.refine_pose`).
    """
    refine_options = refine_options or RefineOptions()
    sols = tuple(ippe_view(model, v) for v in views)
    raw: list[np.ndarray] = []
    for s in sols:
        raw.extend([s.T_world_robot[0], s.T_world_robot[1]])
    groups: list[tuple[np.ndarray, int]] = []
    for T in raw:
        for i, (G, n) in enumerate(groups):
            if _close(T, G, options.merge_m, options.merge_rad):
                groups[i] = (G, n + 1)
                break
        else:
            groups.append((T, 1))
    ropt = RefineOptions(huber_k=refine_options.huber_k, max_iter=options.refine_iter,
                         step_tol=refine_options.step_tol)
    # screen: refine the two best raw candidates and any within one bad view of the best
    raw_scores = [_raw_score(sc, G, prior, options.screen_cap) for G, _ in groups]
    order = np.argsort(raw_scores, kind="stable")
    best_raw = raw_scores[order[0]]
    keep = [int(i) for j, i in enumerate(order)
            if j < 2 or raw_scores[i] <= best_raw + 4 * options.screen_cap]
    cands: list[Candidate] = []
    for G, n in (groups[i] for i in keep):
        fit = refine_pose(sc, G, prior, ropt, rig)
        if fit.min_depth_m <= 0:
            continue
        score = fit.robust_cost + (previous.cost(fit.T_world_robot) if previous is not None else 0.0)
        cands.append(Candidate(fit, score, n))
    if not cands:  # every candidate put a corner behind a camera: keep the raw best for the report
        fit = refine_pose(sc, groups[0][0], prior, ropt, rig)
        cands = [Candidate(fit, math.inf, groups[0][1])]
    cands.sort(key=lambda c: c.score)
    distinct: list[Candidate] = []
    for c in cands:
        if not any(_close(c.fit.T_world_robot, d.fit.T_world_robot, options.distinct_m, options.distinct_rad)
                   for d in distinct):
            distinct.append(c)
    margin = distinct[1].score - distinct[0].score if len(distinct) > 1 else math.inf
    return InitResult(distinct[0], float(margin), tuple(distinct), sols)


def unbeaten_by_views(model: VisionModel, views: tuple[MarkerView, ...] | list[MarkerView], sc: StackedCorners,
                      fit: RefineResult, prior: PlanarPrior | None = None,
                      options: InitOptions = InitOptions()) -> bool:
    """Whether a fit started elsewhere (the previous instant's pose) holds against the candidates
    :func:`initial_pose` would rank: no IPPE solution of any view that is distinct from the fit's pose
    scores, unrefined, below the fit's robust cost (refining a candidate only lowers its cost, so such a
    candidate could win the search). A one-sided test: True does not prove the search would pick the
    fit, only that no view's own solution says otherwise.
    """
    T_fit = fit.T_world_robot
    for v in views:
        for T in ippe_view(model, v).T_world_robot:
            if _close(T, T_fit, options.merge_m, options.merge_rad):
                continue
            if _raw_score(sc, T, prior, options.screen_cap) < fit.robust_cost:
                return False
    return True
