"""The robot pose of one instant from every marker in every camera: initialisation, robust refinement,
outlier views, the consistency test and the covariance.

Steps:

1. both IPPE solutions of every view, candidates refined on all corners, flip picked
   (:mod:`gtrig.vision.init`);
2. one robust fit over all corners of all markers in all cameras (:mod:`gtrig.vision.refine`);
3. a view (one marker in one camera) whose residuals are far beyond its covariance (a wrong ID, an
   occluded corner) is dropped and the fit repeated from the last pose, while more than one view is
   left; after any drop the flip is decided again without the dropped views;
4. the remaining residuals say how noisy this frame's corners are: the frame's variance factor
   (chi-square over redundancy) scales its covariance when above 1 (a posteriori, as in geodetic adjustment); a
   frame whose factor exceeds ``max_variance_factor`` is reported with the reason "inconsistent
   residuals", never silently kept;
5. what the blur's pull on each view's corners towards the marker's centre does to the pose is added to
   the covariance (``VisionOptions.blur_pull``): the pull is common to a marker's four corners, so no
   residual shows it, and a blurred marker seen alone looked farther away than it was.

The corner covariances are the detector's plus an isotropic floor (``corner_floor_px``), times a
variance factor per camera (``VisionOptions.corner_scale``) that :mod:`gtrig.vision.noise` estimates
from the residuals of the whole recording. A detector's covariances are at best right in shape, rarely
in scale, and a test against a wrong scale refuses good frames (scale too small) or lets bad ones
through (too large). The floor keeps one over-confident corner from outweighing a whole camera: the
detector reports a median corner sigma of 0.006 px on simulated images whose corners are
off by about 0.2 px RMS, with a spread of 40 between corners that the residuals do not show.

The per-camera factor is an average: close, motion-blurred or over-exposed markers have noisier
corners than the camera's mean, and a chi-square test at the mean noise refused 15 % of the moving
frames of a simulated run (residual RMS 0.15-0.2 px against 0.1 px) while the accepted ones had a
covariance too small by 2.2 (NEES). Scaling each frame by its own factor keeps those frames with an
honest covariance; frames with few degrees of freedom get a noisy factor, which is why it never
lowers the covariance, and why it is charged only where a chi-square test finds it significant
(``frame_scale_level``): by chance alone half the frames have a factor above 1.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from enum import StrEnum
from typing import Any

import numpy as np
from scipy.special import gammaincinv

from gtrig.vision.covariance import (
    UNCALIBRATED_MARKERS,
    RigUncertainty,
    blur_consider_covariance,
    blur_scale_sigma_px,
    common_whitening,
)
from gtrig.vision.init import InitOptions, PreviousPose, initial_pose, unbeaten_by_views
from gtrig.vision.observations import FrameObservations, MarkerView, StackedCorners, VisionModel, stack_corners
from gtrig.vision.refine import PlanarPrior, RefineOptions, RefineResult, refine_pose

log = logging.getLogger(__name__)


class Status(StrEnum):
    """Outcome of one instant."""

    OK = "ok"
    NO_MARKER = "no marker"
    AMBIGUOUS = "ambiguous"
    INCONSISTENT = "inconsistent residuals"


@dataclass(frozen=True)
class VisionOptions:
    """Everything that changes a GTvision estimate.

    Attributes
    ----------
    planar : bool
        Use the floor prior (``--planar``).
    prior : PlanarPrior
        The floor prior's mean and sigmas.
    rig_uncertainty : RigUncertainty
        The rig's camera and marker pose sigmas (default: calibrated cameras, hand-measured markers,
        :data:`gtrig.vision.covariance.UNCALIBRATED_MARKERS`).
    corner_floor_px : float
        Isotropic sigma added to every corner's covariance before scaling, pixels.
    corner_scale : tuple of (camera, factor)
        Variance factor applied to every (floored) corner covariance of that camera (cameras not
        listed: 1); estimated by :func:`gtrig.vision.noise.estimate_corner_scale`.
    view_gate : float
        A view whose chi-square (4 corners) exceeds this is an outlier candidate.
    max_variance_factor : float
        Largest frame variance factor accepted: 100 means corners ten times noisier than the camera's
        corner model; beyond, "inconsistent residuals". Single markers that are over-exposed and
        motion-blurred at once (a box blur the detector's Gaussian edge model lacks, seen on one side
        of the ramp only) reach 10-45 on a simulated run: their poses are 1-3 cm off with a
        covariance that says so (NEES/dof 1.5 over those frames); with a limit of 9 they were refused
        and 5 % of the run's frames with a visible marker went unlocalized.
    previous_max_gap_s : float
        A previous pose older than this is not used to break flips.
    frame_scale_level : float
        A frame's own variance factor scales its covariance only when it is significantly above 1 at
        this level (chi-square test with the frame's redundancy): by chance a frame whose corners are
        exactly as noisy as its camera's model has a factor above 1 half of the time, and charging
        that to it made the covariances of homogeneous data cautious by 10-40 % (E max(1, F) at 2-10
        dof); 0.5 charges every factor above 1 (the earlier behaviour, kept as an option).
    follow_max_gap_s : float
        :func:`estimate_consecutive`: an instant at most this much later than the last localized one of
        the same list starts its fit from that pose instead of ranking every view's IPPE solutions (the
        search is run when the followed fit moved more than 0.2 m or 10 degrees, did not converge, left
        an inconsistent frame, dropped a view, or when a view's own solution scores better); 0: never.
    rig_variance_component : bool
        The recording's noise calibration splits its residuals between the corners and the rig's
        stated uncertainty (:func:`gtrig.vision.sequence.calibrate_noise` with ``rig_component``),
        so that a rig calibrated better or worse than it says gets the covariance its residuals show
        (static instants seen with several markers per camera: ``tests/vision/test_rig_component.py``).
        Off by default: on a simulated run, whose moving instants mostly show one marker to one camera
        (8 corner coordinates against that camera's 6 pose nuisances), the two components are not
        separable and ran away (seed 0, planar: corner factors 0.05-0.22 instead of 0.5-0.9, NEES/dof 9.5).
    blur_pull : bool
        Add to an OK frame's covariance what the blur's pull on each view's corners towards the marker's
        centre leaves in the pose (:func:`gtrig.vision.covariance.blur_scale_sigma_px`, from the detector's
        fitted blur and the marker's size in the image; views without a fitted blur add nothing). Without
        it, at 1.5 px blur a 47 px marker seen alone was 55 mm off at 6 sigmas.
    common_corners : bool
        Weight each view's eight corner coordinates with their joint covariance in the fit
        (:attr:`MarkerView.corner_common`, a clipped marker's edges offset as one;
        :func:`gtrig.vision.covariance.common_whitening`): a common shrink of the four corners is an error
        of the view, not four errors the pose follows, and the fit's covariance holds it.
    """

    planar: bool = True
    prior: PlanarPrior = PlanarPrior()
    rig_uncertainty: RigUncertainty = UNCALIBRATED_MARKERS
    corner_floor_px: float = 0.1
    corner_scale: tuple[tuple[str, float], ...] = ()
    refine: RefineOptions = RefineOptions()
    init: InitOptions = InitOptions()
    view_gate: float = 60.0
    max_variance_factor: float = 100.0
    previous_max_gap_s: float = 1.0
    frame_scale_level: float = 0.05
    follow_max_gap_s: float = 0.3
    rig_variance_component: bool = False
    blur_pull: bool = True
    common_corners: bool = True

    @property
    def planar_prior(self) -> PlanarPrior | None:
        return self.prior if self.planar else None


@dataclass(frozen=True)
class FrameEstimate:
    """The estimate of one instant.

    Attributes
    ----------
    stamp_s : float
    status : Status
    reason : str
        One line for the log when ``status`` is not OK ("" otherwise).
    T_world_robot : (4, 4) or None
        None only for NO_MARKER. Filled for AMBIGUOUS (the best guess) and INCONSISTENT (the fit)
        so that reports can show them, but such frames are not written to the trajectory.
    cov_6x6 : (6, 6) or None
        Covariance over (x, y, z, rx, ry, rz), world frame, m and rad (:mod:`gtrig.vision.covariance`).
    views : tuple of (camera, marker ID)
        The views used in the final fit.
    rejected : tuple of (camera, marker ID)
        Views dropped as outliers.
    rms_px : float
        RMS reprojection error of the used corners, pixels.
    view_rms_px : tuple of float
        The same per used view (aligned with ``views``).
    chi2, dof : the final fit's chi-square and degrees of freedom.
    flip_margin : float
        Cost of the best distinct alternative minus the chosen one's (inf: none).
    alternatives : tuple of (4, 4)
        For AMBIGUOUS frames: the distinct candidate poses, best first (resolved later by
        :func:`resolve_with_previous`).
    noise : tuple of (camera, chi-square share, dof share)
        The final fit's chi-square and degrees of freedom shared among its cameras in proportion to
        their corners' redundancy numbers (with the covariances as scaled by ``corner_scale``); the
        input of the variance-factor estimate (:mod:`gtrig.vision.noise`).
    variance_factor : float
        The corners' chi-square over their redundancy (``chi2 / dof`` with the share of the dof that
        the corners own); ``cov_6x6`` of an OK frame is the fit's covariance times this factor where
        it is significantly above 1 (``VisionOptions.frame_scale_level``).
    corner_noise : tuple of (camera, chi-square, redundancy)
        The corners' own chi-square and redundancy per camera (the rig's nuisance priors left out).
    rig_noise : (chi-square, redundancy)
        The rig's nuisance priors' (:attr:`gtrig.vision.refine.RefineResult.chi2_rig`): with
        ``corner_noise``, the input of the two-component estimate (:func:`gtrig.vision.sequence.calibrate_noise`).
    """

    stamp_s: float
    status: Status
    reason: str = ""
    T_world_robot: np.ndarray | None = None
    cov_6x6: np.ndarray | None = None
    views: tuple[tuple[str, int], ...] = ()
    rejected: tuple[tuple[str, int], ...] = ()
    rms_px: float = math.nan
    view_rms_px: tuple[float, ...] = ()
    chi2: float = math.nan
    dof: int = 0
    flip_margin: float = math.inf
    alternatives: tuple[np.ndarray, ...] = field(default=(), repr=False)
    noise: tuple[tuple[str, float, float], ...] = ()
    variance_factor: float = math.nan
    corner_noise: tuple[tuple[str, float, float], ...] = ()
    rig_noise: tuple[float, float] = (0.0, 0.0)

    @property
    def ok(self) -> bool:
        return self.status is Status.OK


def _fit(model: VisionModel, views: list[MarkerView], opts: VisionOptions,
         previous: PreviousPose | None):
    sc = stack_corners(model, views)
    # candidates are ranked with the cameras' pose uncertainty only; the lenses' (eight more nuisance
    # parameters per camera) enter the one fit that gives the pose and its covariance
    ru = opts.rig_uncertainty
    init = initial_pose(model, views, sc, opts.planar_prior, previous, opts.init, opts.refine, ru.without_lenses())
    fit = refine_pose(sc, init.best.fit.T_world_robot, opts.planar_prior, opts.refine, ru,
                      view_whitening(sc, views, opts))
    return sc, init, fit


def view_whitening(sc: StackedCorners, views: Sequence[MarkerView], options: VisionOptions
                   ) -> np.ndarray | None:
    """The per-view joint whitening (V, 8, 8) of ``views`` stacked as ``sc`` from their common corner moves
    (:func:`gtrig.vision.covariance.common_whitening`), or None without any (or with
    ``options.common_corners`` off)."""
    if not options.common_corners or all(v.corner_common is None for v in views):
        return None
    scale = dict(options.corner_scale)
    c = np.concatenate([np.zeros((4, 2)) if v.corner_common is None else v.corner_common for v in views])
    s = np.repeat([scale.get(v.camera, 1.0) for v in views], 4)
    return common_whitening(sc.sqrt_info, c, s)


def merge_repeated(views: tuple[MarkerView, ...] | list[MarkerView]) -> list[MarkerView]:
    """One view per (camera, marker): the mean corners of that marker over the camera's images.

    Several images of one camera in one instant happen only while the robot stands still (validation
    intervals). Their corner errors are mostly the same in every image (the detector's bias for that
    geometry, blur and pixel phase); only the sensor noise averages out. Fitting every image as an
    independent measurement would count the same error ten times and make the covariance ten times
    too small, so the images are averaged first and the mean keeps the mean covariance (the
    noise model's factor, estimated over such means, then says how much averaging did gain).
    """
    groups: dict[tuple[str, int], list[MarkerView]] = {}
    for v in views:
        groups.setdefault((v.camera, v.marker_id), []).append(v)
    if all(len(g) == 1 for g in groups.values()):
        return list(views)
    return [g[0] if len(g) == 1 else
            MarkerView(g[0].camera, g[0].marker_id, np.mean([v.corners_px for v in g], axis=0),
                       np.mean([v.corner_cov for v in g], axis=0), g[0].frame, float(np.mean([v.blur_px for v in g])),
                       _mean_common(g))
            for g in groups.values()]


def _mean_common(views: list[MarkerView]) -> np.ndarray | None:
    """The mean common corner move of repeated views (a clipped white level's offset is the same in each
    image of a still robot, as its bias is), or None when none has one."""
    if all(v.corner_common is None for v in views):
        return None
    return np.mean([np.zeros((4, 2)) if v.corner_common is None else v.corner_common for v in views], axis=0)


def scale_views(views: tuple[MarkerView, ...] | list[MarkerView], scale: dict[str, float],
                floor_px: float = 0.0) -> list[MarkerView]:
    """The views with each corner covariance ``(cov + floor_px^2 I) * factor`` of its camera."""
    floor = floor_px**2 * np.eye(2)
    if not scale and floor_px == 0.0:
        return list(views)
    return [replace(v, corner_cov=(v.corner_cov + floor) * scale.get(v.camera, 1.0)) for v in views]


def _followed_fit(model: VisionModel, views: list[MarkerView], options: VisionOptions, follow: FrameEstimate
                  ) -> tuple[StackedCorners, RefineResult] | None:
    """The fit of ``views`` started from the localized pose ``follow`` of an instant just before, or None
    where it is not to be trusted without the full search (:attr:`VisionOptions.follow_max_gap_s`)."""
    assert follow.T_world_robot is not None
    sc = stack_corners(model, views)
    fit = refine_pose(sc, follow.T_world_robot, options.planar_prior, options.refine, options.rig_uncertainty,
                      view_whitening(sc, views, options))
    if not fit.converged or fit.min_depth_m <= 0 or _beyond(PreviousPose(follow.T_world_robot), fit.T_world_robot):
        return None
    red = float(np.sum(fit.redundancy))
    if not (np.isfinite(red) and red > 0.5 and float(np.sum(fit.whitened**2)) <= options.max_variance_factor * red):
        return None
    if not unbeaten_by_views(model, views, sc, fit, options.planar_prior, options.init):
        return None
    return sc, fit


def _beyond(previous: PreviousPose, T: np.ndarray) -> bool:
    """Whether the pose ``T`` (4, 4) lies outside the previous pose's tolerance (its sigmas as one
    ellipse: ``previous.cost(T)`` above 1), without the rotation's logarithm."""
    Tp = previous.T_world_robot
    dt2 = float(np.sum((Tp[:3, 3] - T[:3, 3]) ** 2))
    c = min(1.0, max(-1.0, (float(np.sum(Tp[:3, :3] * T[:3, :3])) - 1.0) / 2.0))  # cos of the relative angle
    return dt2 / previous.sigma_m**2 + math.acos(c) ** 2 / previous.sigma_rad**2 > 1.0


def estimate_consecutive(model: VisionModel, obs: Sequence[FrameObservations],
                         options: VisionOptions = VisionOptions()) -> list[FrameEstimate]:
    """:func:`estimate_frame` of consecutive instants (time order), each that follows a localized one by at
    most ``options.follow_max_gap_s`` started from its pose.

    The first instant, and any after a gap or an instant that was not localized, gets the full search of
    :mod:`gtrig.vision.init`: the estimates depend on the list given (a chunk of a recording's instants),
    never on what was estimated before it.
    """
    out: list[FrameEstimate] = []
    last: FrameEstimate | None = None
    for o in obs:
        near = last is not None and 0.0 <= o.stamp_s - last.stamp_s <= options.follow_max_gap_s
        e = estimate_frame(model, o, options, follow=last if near else None)
        out.append(e)
        if e.ok:
            last = e
    return out


def estimate_frame(model: VisionModel, obs: FrameObservations, options: VisionOptions = VisionOptions(),
                   previous: PreviousPose | None = None, start: FrameEstimate | None = None,
                   follow: FrameEstimate | None = None) -> FrameEstimate:
    """The robot pose of one instant (see the module docstring).

    Parameters
    ----------
    model : the rig geometry (:meth:`VisionModel.from_rig` of the calibrated rig).
    obs : all views of the instant (covariances as the detector gave them).
    options : estimation settings (``options.corner_scale`` is applied here).
    previous : the last pose localized before, to break flips; None for independent frames.
    start : an estimate of this instant whose flip is settled (a second pass with another model of
        the same instant, :func:`gtrig.vision.sequence.compensate_motion`): the fit starts from its pose
        and keeps its flip margin instead of ranking every view's solutions again.
    follow : the localized estimate of an instant just before (:func:`estimate_consecutive`): the fit
        starts from its pose and inherits its flip margin, unless that fit fails the checks of
        :attr:`VisionOptions.follow_max_gap_s`; then, and after a dropped view, the full search runs.
    """
    model.check(obs)
    scale = dict(options.corner_scale)
    views = scale_views(merge_repeated(obs.views), scale, options.corner_floor_px)
    if not views:
        return FrameEstimate(obs.stamp_s, Status.NO_MARKER, "no marker detected in any camera")
    rejected: list[tuple[str, int]] = []

    def fit_views() -> tuple[StackedCorners, float, tuple[np.ndarray, ...], RefineResult]:
        if start is not None and start.T_world_robot is not None:
            sc = stack_corners(model, views)
            return sc, start.flip_margin, (), refine_pose(sc, start.T_world_robot, options.planar_prior,
                                                          options.refine, options.rig_uncertainty,
                                                          view_whitening(sc, views, options))
        sc, init, fit = _fit(model, views, options, previous)
        return sc, init.margin, tuple(c.fit.T_world_robot for c in init.candidates), fit

    followed = None if follow is None or start is not None else _followed_fit(model, views, options, follow)
    alts: tuple[np.ndarray, ...]
    if followed is not None and follow is not None:
        sc, fit = followed
        margin, alts = follow.flip_margin, ()
    else:
        sc, margin, alts, fit = fit_views()
    while len(views) > 1:
        per_view = np.bincount(sc.view, weights=fit.whitened**2, minlength=len(views))
        worst = int(np.argmax(per_view))
        if per_view[worst] <= options.view_gate:
            break
        rejected.append((views[worst].camera, views[worst].marker_id))
        log.debug("t=%.3f: view %s/%d rejected (chi2 %.1f)", obs.stamp_s, *rejected[-1], per_view[worst])
        del views[worst]
        # the flip was settled with every view; one dropped view does not unsettle it: continue
        # from the last pose (a full re-initialisation per dropped view costs O(views^2))
        sc = stack_corners(model, views)
        fit = refine_pose(sc, fit.T_world_robot, options.planar_prior, options.refine,
                          options.rig_uncertainty, view_whitening(sc, views, options))
    if rejected:  # decide the flip again, and its margin, without the dropped views
        sc, margin, alts, fit = fit_views()
    used = tuple((v.camera, v.marker_id) for v in views)
    r2 = np.sum(fit.residuals_px**2, axis=1)
    rms = float(np.sqrt(np.mean(r2)))
    view_rms = tuple(float(np.sqrt(np.mean(r2[sc.view == i]))) for i in range(len(views)))
    # the frame's chi-square and dof shared among its cameras by their corners' redundancy
    red = np.array([np.sum(fit.redundancy[sc.cam == i]) for i in range(len(sc.camera_names))])
    share = red / red.sum() if np.all(np.isfinite(red)) and red.sum() > 0 else np.full(len(red), np.nan)
    noise = tuple((name, float(fit.chi2 * share[i]), float(fit.dof * share[i]))
                  for i, name in enumerate(sc.camera_names))
    corner_noise = tuple((name, float(np.sum(fit.whitened[sc.cam == i] ** 2)), float(red[i]))
                         for i, name in enumerate(sc.camera_names))
    common: dict[str, Any] = dict(
        T_world_robot=fit.T_world_robot, cov_6x6=fit.cov_6x6, views=used, rejected=tuple(rejected), rms_px=rms,
        view_rms_px=view_rms, chi2=fit.chi2, dof=fit.dof, flip_margin=margin, noise=noise,
        corner_noise=corner_noise, rig_noise=(fit.chi2_rig, fit.redundancy_rig))
    if margin < options.init.ambiguity_margin:
        return FrameEstimate(obs.stamp_s, Status.AMBIGUOUS,
                             f"flip ambiguous: runner-up costs only {margin:.1f} more "
                             f"({len(views)} view(s), {len(sc.camera_names)} camera(s))",
                             alternatives=alts, **common)
    # the corners' chi-square over their redundancy (what the corners leave over after the pose, the
    # rig's nuisances and the floor prior took their share): its expectation is 1 for right covariances
    red_sum = float(np.sum(fit.redundancy))
    factor = float(np.sum(fit.whitened**2)) / red_sum if np.isfinite(red_sum) and red_sum > 0.5 else math.inf
    if factor > options.max_variance_factor or fit.min_depth_m <= 0 or not np.all(np.isfinite(fit.cov_6x6)):
        return FrameEstimate(obs.stamp_s, Status.INCONSISTENT,
                             f"variance factor {factor:.1f} > {options.max_variance_factor:g} "
                             f"(rms {rms:.2f} px)", variance_factor=factor, **common)
    common["cov_6x6"] = fit.cov_6x6 * frame_scale(factor, red_sum, options.frame_scale_level)
    if options.blur_pull:
        common["cov_6x6"] = common["cov_6x6"] + blur_covariance(sc, fit, views)
    return FrameEstimate(obs.stamp_s, Status.OK, variance_factor=factor, **common)


def blur_covariance(sc: StackedCorners, fit: RefineResult, views: Sequence[MarkerView]) -> np.ndarray:
    """The pose covariance (6, 6) of the fit ``fit`` of the corners ``sc`` from the blur's pull on each of
    ``views`` (:func:`gtrig.vision.covariance.blur_consider_covariance`); zeros where no view has a blur."""
    blur = np.array([v.blur_px for v in views], float)
    if not np.any(np.isfinite(blur)):
        return np.zeros((6, 6))
    side = np.array([float(np.mean(np.linalg.norm(np.roll(v.corners_px, -1, axis=0) - v.corners_px, axis=1)))
                     for v in views])
    return blur_consider_covariance(fit.J, sc.sqrt_info, fit.weights, sc.view, sc.uv,
                                    blur_scale_sigma_px(side, blur), fit.cov_6x6)


def frame_scale(factor: float, redundancy: float, level: float) -> float:
    """The factor that scales a frame's covariance: its own variance factor where the chi-square test
    (``redundancy`` dof) says its corners are noisier than the camera's model at ``level``, else 1."""
    if factor <= 1.0:
        return 1.0
    # chi2.ppf(q, n) is 2 gammaincinv(n / 2, q), bit for bit (scipy.stats takes a second to import)
    return factor if factor * redundancy > 2.0 * float(gammaincinv(redundancy / 2.0, 1.0 - level)) else 1.0
