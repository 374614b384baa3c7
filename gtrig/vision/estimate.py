"""The robot pose of one instant from every marker in every camera: initialisation, robust refinement,
outlier views, the consistency test and the covariance.

Steps (issue 6):

1. both IPPE solutions of every view, candidates refined on all corners, flip picked
   (:mod:`gtrig.vision.init`);
2. one robust fit over all corners of all markers in all cameras (:mod:`gtrig.vision.refine`);
3. a view (one marker in one camera) whose residuals are far beyond its covariance (a wrong ID, an
   occluded corner) is dropped and the fit repeated, while more than one view is left;
4. the remaining residuals must be consistent with their covariances (chi-square test); otherwise the
   frame is reported with the reason "inconsistent residuals", never silently kept.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass, field
from enum import StrEnum

import numpy as np
from scipy.stats import chi2 as chi2_dist

from gtrig.vision.covariance import RigUncertainty
from gtrig.vision.init import InitOptions, PreviousPose, initial_pose
from gtrig.vision.observations import FrameObservations, MarkerView, VisionModel, stack_corners
from gtrig.vision.refine import PlanarPrior, RefineOptions, refine_pose

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
        The calibrated rig's camera and marker pose sigmas.
    view_gate : float
        A view whose chi-square (4 corners) exceeds this is an outlier candidate.
    frame_alpha : float
        Significance of the frame's chi-square test ("inconsistent residuals" below it).
    previous_max_gap_s : float
        A previous pose older than this is not used to break flips.
    """

    planar: bool = True
    prior: PlanarPrior = PlanarPrior()
    rig_uncertainty: RigUncertainty = RigUncertainty()
    refine: RefineOptions = RefineOptions()
    init: InitOptions = InitOptions()
    view_gate: float = 60.0
    frame_alpha: float = 1e-6
    previous_max_gap_s: float = 1.0

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

    @property
    def ok(self) -> bool:
        return self.status is Status.OK


def _fit(model: VisionModel, views: list[MarkerView], opts: VisionOptions,
         previous: PreviousPose | None):
    sc = stack_corners(model, views)
    init = initial_pose(model, views, sc, opts.planar_prior, previous, opts.init, opts.refine,
                        opts.rig_uncertainty)
    fit = init.best.fit
    if not fit.converged:  # candidates get a few iterations only: finish the job
        fit = refine_pose(sc, fit.T_world_robot, opts.planar_prior, opts.refine, opts.rig_uncertainty)
    return sc, init, fit


def estimate_frame(model: VisionModel, obs: FrameObservations, options: VisionOptions = VisionOptions(),
                   previous: PreviousPose | None = None) -> FrameEstimate:
    """The robot pose of one instant (see the module docstring).

    Parameters
    ----------
    model : the rig geometry (:meth:`VisionModel.from_rig` of the calibrated rig).
    obs : all views of the instant.
    options : estimation settings.
    previous : the last pose localized before, to break flips; None for independent frames.
    """
    model.check(obs)
    views = list(obs.views)
    if not views:
        return FrameEstimate(obs.stamp_s, Status.NO_MARKER, "no marker detected in any camera")
    rejected: list[tuple[str, int]] = []
    while True:
        sc, init, fit = _fit(model, views, options, previous)
        if len(views) == 1:
            break
        per_view = np.bincount(sc.view, weights=fit.whitened**2, minlength=len(views))
        worst = int(np.argmax(per_view))
        if per_view[worst] <= options.view_gate:
            break
        rejected.append((views[worst].camera, views[worst].marker_id))
        log.debug("t=%.3f: view %s/%d rejected (chi2 %.1f)", obs.stamp_s, *rejected[-1], per_view[worst])
        del views[worst]
    used = tuple((v.camera, v.marker_id) for v in views)
    r2 = np.sum(fit.residuals_px**2, axis=1)
    rms = float(np.sqrt(np.mean(r2)))
    view_rms = tuple(float(np.sqrt(np.mean(r2[sc.view == i]))) for i in range(len(views)))
    common = dict(T_world_robot=fit.T_world_robot, cov_6x6=fit.cov_6x6, views=used, rejected=tuple(rejected),
                  rms_px=rms, view_rms_px=view_rms, chi2=fit.chi2, dof=fit.dof, flip_margin=init.margin)
    if init.margin < options.init.ambiguity_margin:
        alts = tuple(c.fit.T_world_robot for c in init.candidates)
        return FrameEstimate(obs.stamp_s, Status.AMBIGUOUS,
                             f"flip ambiguous: runner-up costs only {init.margin:.1f} more "
                             f"({len(views)} view(s), {len(sc.camera_names)} camera(s))",
                             alternatives=alts, **common)
    limit = float(chi2_dist.isf(options.frame_alpha, max(fit.dof, 1)))
    if fit.chi2 > limit or fit.min_depth_m <= 0 or not np.all(np.isfinite(fit.cov_6x6)):
        return FrameEstimate(obs.stamp_s, Status.INCONSISTENT,
                             f"chi2 {fit.chi2:.1f} > {limit:.1f} for {fit.dof} dof (rms {rms:.2f} px)",
                             **common)
    return FrameEstimate(obs.stamp_s, Status.OK, **common)
