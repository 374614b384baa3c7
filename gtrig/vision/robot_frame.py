"""The robot frame the markers realise, tied to the surveyed robot frame at the validation stops.

Every marker's pose on the robot is calibrated relative to one anchor (the seeds' dima-marker,
:mod:`gtrig.markers.robotcal`), whose own pose on the robot is measured by hand: set square against the
dima, offset taken with a caliper, about 0.3 mm and 0.1 deg. That error moves the robot frame of every
GTvision pose by the same rigid transform, so no averaging over markers, cameras or instants removes it;
at 0.1 deg it is the largest term of a standing robot's yaw error.

The validation stops measure it. At stop ``k`` the hand-laser survey gives the robot frame ``S_k`` from
the robot points drawn under it (:mod:`gtrig.survey`), and GTvision the frame the markers realise,
``V_k``. The offset ``D = V_k^-1 S_k`` is the same at every stop. Its planar part ``d = (x, y, theta)``
(robot axes) is estimated by generalised least squares over all stops, with the survey's joint
covariance (its poses share world points) and GTvision's per-stop covariances; a stop whose offset
disagrees beyond the chi-square bound is named and left out. The markers then move by ``D^-1`` on the
robot (:func:`rig_in_surveyed_frame`), and every later GTvision pose is ``V D``. Height, roll and pitch
of the frame are not seen by a planar survey: they keep the hand measurement's uncertainty.

This is the hand-eye step the seeds did not have (their marker poses on the robot were measured by hand,
deliverable AD2.3, "Robot-frame"); it makes GTvision's robot frame the one the survey and the validation
tables use.
"""

from __future__ import annotations

import logging
from collections.abc import Sequence
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING, Any

import numpy as np
from scipy.linalg import block_diag
from scipy.stats import chi2 as chi2_dist

from gtrig import geometry as geo
from gtrig.errors import InputError
from gtrig.rig.models import Pose, Rig, pose_cov_rows
from gtrig.vision.covariance import PLANAR_INDEX

if TYPE_CHECKING:
    from gtrig.vision.sequence import VisionResult

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class FrameFit:
    """The offset between the markers' robot frame and the surveyed one (:func:`fit_frame_offset`).

    Attributes
    ----------
    names : (K,) the stops given.
    used : (K,) bool, the stops the estimate rests on (False: not localized, or refused as outliers).
    d_xytheta : (3,) the offset ``D`` as x, y (m) and theta (rad), robot axes.
    cov_d : (3, 3) its covariance, scaled by ``variance_factor``.
    chi2, dof : the stops' disagreement with one common offset, and its degrees of freedom.
    variance_factor : ``max(1, chi2 / dof)``, applied to ``cov_d``.
    stop_nees : (K,) each used stop's offset against the estimate, normalised by the residual's
        covariance (nan for stops not used).
    loo_d, loo_cov : (K, 3), (K, 3, 3) the estimate and covariance from all used stops but stop ``k``:
        what an honest check of stop ``k`` corrects it with.
    excluded : the stops refused as outliers, with the reason.
    """

    names: tuple[str, ...]
    used: np.ndarray
    d_xytheta: np.ndarray
    cov_d: np.ndarray
    chi2: float
    dof: int
    variance_factor: float
    stop_nees: np.ndarray
    loo_d: np.ndarray
    loo_cov: np.ndarray
    excluded: tuple[str, ...]

    @property
    def T_markers_surveyed(self) -> np.ndarray:
        """``D`` (4, 4): the surveyed robot frame in the frame the markers realised."""
        return geo.se2_to_T(*self.d_xytheta)


def _rot2(theta: np.ndarray) -> np.ndarray:
    c, s = np.cos(theta), np.sin(theta)
    return np.stack([np.stack([c, -s], -1), np.stack([s, c], -1)], -2)


def _gls(d: np.ndarray, Sigma: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
    """One common (3,) mean of K stacked (3,) offsets ``d`` (3K,) with joint covariance ``Sigma``."""
    K = d.size // 3
    H = np.tile(np.eye(3), (K, 1))
    L = np.linalg.cholesky(Sigma)
    Hw = np.linalg.solve(L, H)
    dw = np.linalg.solve(L, d)
    N = Hw.T @ Hw
    cov = np.linalg.inv(N)
    est = cov @ (Hw.T @ dw)
    r = dw - Hw @ est
    return est, 0.5 * (cov + cov.T), float(r @ r)


def fit_frame_offset(names: Sequence[str], xytheta_markers: np.ndarray, cov_markers: np.ndarray,
                     xytheta_survey: np.ndarray, cov_survey: np.ndarray, *, alpha: float = 0.001,
                     max_excluded: int | None = None) -> FrameFit:
    """Estimate the offset ``D`` between the robot frame the markers realise and the surveyed one.

    Parameters
    ----------
    names : (K,) the stops.
    xytheta_markers : (K, 3) GTvision's poses of the stops (world frame; m, rad); a row of nan: not
        localized.
    cov_markers : (K, 3, 3) their covariances over x, y, yaw, without the anchor's own placement error
        (that is what is estimated here).
    xytheta_survey : (K, 3) the surveyed poses of the same stops.
    cov_survey : (3K, 3K) their joint covariance (x1, y1, theta1, x2, ...), or (K, 3, 3) when the
        poses are independent.
    alpha : a stop whose offset disagrees with the others beyond the chi-square (3 dof) quantile
        ``1 - alpha / K`` (its residual normalised by the residual's own covariance) is refused, worst
        first, at most ``max_excluded`` of them (default a quarter).

    Returns
    -------
    FrameFit
    """
    V = np.asarray(xytheta_markers, float).reshape(-1, 3)
    S = np.asarray(xytheta_survey, float).reshape(-1, 3)
    K = len(names)
    if V.shape[0] != K or S.shape[0] != K:
        raise InputError(f"frame offset: {K} stops but {V.shape[0]} GTvision and {S.shape[0]} surveyed poses")
    Cs = np.asarray(cov_survey, float)
    if Cs.shape == (K, 3, 3):
        Cs = block_diag(*Cs)
    if Cs.shape != (3 * K, 3 * K):
        raise InputError(f"frame offset: survey covariance of shape {Cs.shape}, expected ({3 * K}, {3 * K})")
    Cv = np.asarray(cov_markers, float).reshape(K, 3, 3)
    # the offset seen at each stop, in the markers' robot axes: d_k = (R_k^T (s_k - v_k), s_k - v_k)
    Rt = np.swapaxes(_rot2(V[:, 2]), -1, -2)
    d = np.concatenate([np.einsum("kij,kj->ki", Rt, S[:, :2] - V[:, :2]),
                        geo.wrap_angle(S[:, 2] - V[:, 2])[:, None]], axis=1)
    Jk = np.zeros((K, 3, 3))
    Jk[:, :2, :2] = np.nan_to_num(Rt)
    Jk[:, 2, 2] = 1.0
    J = block_diag(*Jk)
    # a stop GTvision did not localize has no covariance: zero, it is left out below
    Cv_full = block_diag(*np.nan_to_num(Cv))
    # the survey's error and GTvision's are independent; J rotates both into the markers' robot axes
    Sigma_all = J @ (Cs + Cv_full) @ J.T
    used = np.all(np.isfinite(d), axis=1) & np.all(np.isfinite(Cv.reshape(K, 9)), axis=1)
    if used.sum() < 2:
        raise InputError(f"frame offset: {int(used.sum())} stop(s) with both a survey and a GTvision pose; "
                         "at least 2 are needed")
    limit = max(1, K // 4) if max_excluded is None else max_excluded
    # the largest of K normalised offsets is tested: the level shared among the stops (Bonferroni)
    bound = float(chi2_dist.ppf(1 - alpha / K, 3))
    excluded: list[str] = []

    def solve(mask: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
        rows = np.repeat(mask, 3)
        return _gls(d[mask].ravel(), Sigma_all[np.ix_(rows, rows)])

    while True:
        est, cov, chi2 = solve(used)
        nees = np.full(K, np.nan)
        for k in map(int, np.flatnonzero(used)):
            r = d[k] - est
            r[2] = geo.wrap_angle(r[2])
            # a residual's own covariance: its stop's, less what the common estimate took from it
            nees[k] = float(r @ np.linalg.solve(Sigma_all[3 * k:3 * k + 3, 3 * k:3 * k + 3] - cov, r))
        worst = int(np.nanargmax(nees))
        if nees[worst] <= bound or len(excluded) >= limit or used.sum() <= 3:
            break
        msg = (f"frame offset: stop {names[worst]} disagrees with the others (NEES {nees[worst]:.1f} > "
               f"{bound:.1f}: offset {1000 * d[worst, 0]:.2f} mm, {1000 * d[worst, 1]:.2f} mm, "
               f"{np.degrees(d[worst, 2]):.3f} deg against {1000 * est[0]:.2f}, {1000 * est[1]:.2f}, "
               f"{np.degrees(est[2]):.3f}); left out")
        log.warning(msg)
        excluded.append(names[worst])
        used = used.copy()
        used[worst] = False
    dof = 3 * int(used.sum()) - 3
    vf = max(1.0, chi2 / dof) if dof > 0 else 1.0
    loo_d = np.full((K, 3), np.nan)
    loo_cov = np.full((K, 3, 3), np.nan)
    for k in range(K):
        mask = used.copy()
        mask[k] = False
        if mask.sum() < 1:
            continue
        e_k, c_k, chi2_k = solve(mask)
        dof_k = 3 * int(mask.sum()) - 3
        loo_d[k] = e_k
        loo_cov[k] = c_k * (max(1.0, chi2_k / dof_k) if dof_k > 0 else vf)
    return FrameFit(tuple(names), used, est, cov * vf, chi2, dof, vf, nees, loo_d, loo_cov, tuple(excluded))


def frame_error_covariance(cov_d: np.ndarray, cov_frame_hand_6x6: np.ndarray) -> np.ndarray:
    """The robot frame's common error (6, 6) over (dt, dphi), robot axes, once the survey fixed its planar
    part: ``cov_d`` (x, y, yaw) where the fit measured it, the hand measurement's
    (:func:`gtrig.vision.covariance.anchor_frame_covariance`) for height, roll and pitch."""
    C = np.array(cov_frame_hand_6x6, dtype=float)
    i = np.array(PLANAR_INDEX)
    C[i, :] = 0.0
    C[:, i] = 0.0
    C[np.ix_(i, i)] = np.asarray(cov_d, float)
    return C


def correct_pose(T_world_markers: np.ndarray, cov_6x6: np.ndarray, D: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """A GTvision pose in the surveyed robot frame: ``T D`` and its covariance (world-frame (dt, dphi)).

    A world-frame perturbation ``(dt, dphi)`` of ``T`` moves ``T D``'s origin by ``dt - [R d_t]x dphi``
    and its orientation by ``dphi``.
    """
    T = np.asarray(T_world_markers, float)
    Rd = T[:3, :3] @ D[:3, 3]
    A = np.eye(6)
    A[:3, 3:] = -np.array([[0.0, -Rd[2], Rd[1]], [Rd[2], 0.0, -Rd[0]], [-Rd[1], Rd[0], 0.0]])
    return T @ D, A @ np.asarray(cov_6x6, float) @ A.T


def rig_in_surveyed_frame(rig: Rig, D: np.ndarray) -> Rig:
    """``rig`` with every marker moved to the surveyed robot frame: ``T_robot_marker <- D^-1 T_robot_marker``
    (all markers hang on the anchor, so all move), their ``pose_cov`` rotated with the frame."""
    Dinv = geo.inv_T(D)
    B = np.kron(np.eye(2), Dinv[:3, :3])
    new = []
    for m in rig.robot.markers:
        upd: dict[str, object] = {"T_robot_marker": Pose.from_matrix(Dinv @ m.T_robot_marker.matrix())}
        if m.pose_cov is not None:
            upd["pose_cov"] = pose_cov_rows(B @ np.asarray(m.pose_cov, float) @ B.T)
        new.append(m.model_copy(update=upd))
    return rig.model_copy(update={"robot": rig.robot.model_copy(update={"markers": tuple(new)})})


def in_surveyed_frame(result: VisionResult, D: Sequence[np.ndarray], cov_frame_6x6: Sequence[np.ndarray]
                      ) -> VisionResult:
    """A new result in the surveyed robot frame: estimate ``i`` becomes ``T D[i]`` (:func:`correct_pose`)
    and its covariance gains the frame's common error ``cov_frame_6x6[i]`` (robot axes; see
    :func:`frame_error_covariance`). One ``D`` per estimate, so that each validation stop can be
    corrected with the offset fitted without it (``FrameFit.loo_d``)."""
    from gtrig.vision.covariance import add_robot_frame_covariance

    if len(D) != len(result.estimates) or len(cov_frame_6x6) != len(result.estimates):
        raise InputError(f"{len(result.estimates)} estimates but {len(D)} offsets and {len(cov_frame_6x6)} "
                         "covariances")
    ests = []
    for e, Di, Ci in zip(result.estimates, D, cov_frame_6x6, strict=True):
        if e.T_world_robot is None or e.cov_6x6 is None or not np.all(np.isfinite(Di)):
            ests.append(e)
            continue
        T, C = correct_pose(e.T_world_robot, e.cov_6x6, Di)
        ests.append(replace(e, T_world_robot=T, cov_6x6=add_robot_frame_covariance(T, C, Ci)))
    return replace(result, estimates=tuple(ests))


def fit_validation(stop_names: Sequence[str], validation: VisionResult, survey_names: Sequence[str],
                   survey_xytheta: np.ndarray, survey_cov_joint: np.ndarray, **kwargs: Any) -> FrameFit:
    """:func:`fit_frame_offset` from GTvision's validation result and the survey's poses.

    Parameters
    ----------
    stop_names : (K,) the stops of ``validation/poses.csv``, in the order of ``validation.estimates``.
    validation : GTvision over the validation sequence, with its own covariances (without the markers'
        common frame error: that is what is fitted).
    survey_names, survey_xytheta, survey_cov_joint : the survey's pose names (P,), poses (P, 3) and
        joint covariance (3P, 3P) (:meth:`gtrig.survey.SurveyResult.poses_cov_joint`).
    kwargs : to :func:`fit_frame_offset`.
    """
    from gtrig.vision.covariance import planar_covariance

    if len(stop_names) != len(validation.estimates):
        raise InputError(f"{len(stop_names)} validation stops but {len(validation.estimates)} GTvision instants")
    missing = [n for n in stop_names if n not in survey_names]
    if missing:
        raise InputError(f"validation stop(s) {', '.join(missing)} not in the survey")
    iv = [list(survey_names).index(n) for n in stop_names]
    rows = np.concatenate([np.arange(3 * i, 3 * i + 3) for i in iv])
    nan3, nan33 = np.full(3, np.nan), np.full((3, 3), np.nan)
    V = np.array([geo.T_to_se2(e.T_world_robot) if e.ok and e.T_world_robot is not None else nan3
                  for e in validation.estimates])
    Cv = np.array([planar_covariance(e.cov_6x6) if e.ok and e.cov_6x6 is not None else nan33
                   for e in validation.estimates])
    return fit_frame_offset(stop_names, V, Cv, np.asarray(survey_xytheta, float)[iv],
                            np.asarray(survey_cov_joint, float)[np.ix_(rows, rows)], **kwargs)


def with_markers_frame_cov(rig: Rig, cov_6x6: np.ndarray | None) -> Rig:
    """``rig`` whose ``robot.markers_frame_cov`` is ``cov_6x6`` (None: no common frame error)."""
    cov = None if cov_6x6 is None else pose_cov_rows(cov_6x6)
    return rig.model_copy(update={"robot": rig.robot.model_copy(update={"markers_frame_cov": cov})})


def rig_tied_to_survey(rig: Rig, fit: FrameFit) -> Rig:
    """The rig in the surveyed robot frame: markers moved by the fitted offset, and the common frame
    error the fit leaves (:func:`frame_error_covariance`) in place of the rig's own; the rig must give
    that own one (``robot.markers_frame_cov``, the anchor's hand measurement) for height, roll and pitch."""
    if rig.robot.markers_frame_cov is None:
        raise InputError("the rig gives no covariance of the markers' frame (robot.markers_frame_cov)")
    hand = np.asarray(rig.robot.markers_frame_cov, float)
    return with_markers_frame_cov(rig_in_surveyed_frame(rig, fit.T_markers_surveyed),
                                  frame_error_covariance(fit.cov_d, hand))
