"""Any pose track against the truth of a simulated recording: written once, for every GT source.

A :class:`~gtrig.trajectory.PoseTrack`'s usable poses (OK and FLAGGED) inside the truth's time span
are compared with the truth interpolated at their stamps:

* a planar track (``cov_kind="xyyaw"``, GTlaser) with the truth's planar projection: x, y linear,
  heading unwrapped and linear; errors ``(dx, dy, wrap(dheading))``;
* a 6-DoF track (``"se3"``, GTvision) with the truth interpolated linearly in position and by slerp in
  rotation; errors the world-frame perturbation of gtrig.trajectory, ``xi = (t_est - t_true,
  Log(R_est R_true^T))``; ``dof="planar"`` scores NEES on its x, y, yaw block (a planar estimate whose
  roll and pitch come from a floor prior), ``"full"`` on all six.

Position error is horizontal (x, y), yaw error the absolute wrapped difference of headings (the body x
axis projected on the floor), NEES ``e^T C^-1 e`` per pose (mean = dof when the covariances are right).
Evaluation only: the estimators never read the truth.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Literal

import numpy as np
from scipy.spatial.transform import Rotation, Slerp

from gtrig import geometry as geo
from gtrig.io.tum import Trajectory, read_tum
from gtrig.trajectory import PLANAR_INDEX, PoseTrack

if TYPE_CHECKING:
    from gtrig.rig import Rig


@dataclass(frozen=True)
class TruthScore:
    """Errors of one pose track against truth.

    Attributes
    ----------
    source : the track's source.
    n_expected : stamps the source was asked for inside the truth's span (frames, instants); the
        denominator of :attr:`localized_fraction`.
    stamps_s : (n,) the usable poses scored (inside the span).
    pos_err_m : (n,) horizontal position errors, metres.
    yaw_err_rad : (n,) absolute heading errors, radians.
    nees : (n,) NEES per pose (empty when the track has no covariance).
    nees_dof : degrees of freedom of ``nees``.
    """

    source: str
    n_expected: int
    stamps_s: np.ndarray
    pos_err_m: np.ndarray
    yaw_err_rad: np.ndarray
    nees: np.ndarray
    nees_dof: int

    @property
    def n_scored(self) -> int:
        return int(self.stamps_s.size)

    @property
    def localized_fraction(self) -> float:
        return self.n_scored / self.n_expected if self.n_expected else math.nan

    @property
    def mean_pos_m(self) -> float:
        return _mean(self.pos_err_m)

    @property
    def max_pos_m(self) -> float:
        return _max(self.pos_err_m)

    @property
    def mean_abs_yaw_rad(self) -> float:
        return _mean(self.yaw_err_rad)

    @property
    def max_abs_yaw_rad(self) -> float:
        return _max(self.yaw_err_rad)

    @property
    def mean_nees(self) -> float:
        return _mean(self.nees)

    def n_pos_over(self, limit_m: float) -> int:
        """Usable poses off by more than ``limit_m`` (silent failures)."""
        return int(np.sum(self.pos_err_m > limit_m))


def _mean(a: np.ndarray) -> float:
    return float(np.mean(a)) if a.size else math.nan


def _max(a: np.ndarray) -> float:
    return float(np.max(a)) if a.size else math.nan


def truth_xytheta(truth: Trajectory | PoseTrack, stamps_s: np.ndarray) -> np.ndarray:
    """True planar poses (N, 3) at ``stamps_s``: x, y and the unwrapped heading interpolated linearly."""
    yaw = np.unwrap(truth.yaw_rad())
    return np.column_stack([np.interp(stamps_s, truth.stamps_s, truth.xyz[:, 0]),
                            np.interp(stamps_s, truth.stamps_s, truth.xyz[:, 1]),
                            np.interp(stamps_s, truth.stamps_s, yaw)])


def truth_matrices(truth: Trajectory | PoseTrack, stamps_s: np.ndarray) -> np.ndarray:
    """True poses (M, 4, 4) at ``stamps_s``: linear in position, slerp in rotation, clamped to the span."""
    t = np.clip(np.asarray(stamps_s, dtype=float), truth.stamps_s[0], truth.stamps_s[-1])
    xyz = np.column_stack([np.interp(t, truth.stamps_s, truth.xyz[:, k]) for k in range(3)])
    R = Slerp(truth.stamps_s, Rotation.from_quat(truth.quat_xyzw))(t).as_matrix()
    T = np.tile(np.eye(4), (len(t), 1, 1))
    T[:, :3, :3] = R
    T[:, :3, 3] = xyz
    return T


def pose_error_xi(T_est: np.ndarray, T_true: np.ndarray) -> np.ndarray:
    """The world-frame perturbation (6,) taking ``T_true`` to ``T_est`` (gtrig.trajectory's convention):
    ``t_est - t_true`` and ``Log(R_est R_true^T)``."""
    dt = T_est[:3, 3] - T_true[:3, 3]
    dphi = Rotation.from_matrix(T_est[:3, :3] @ T_true[:3, :3].T).as_rotvec()
    return np.r_[dt, dphi]


def score_track(track: PoseTrack, truth: Trajectory | PoseTrack, *,
                expected_stamps_s: np.ndarray | None = None, T_true_body: np.ndarray | None = None,
                dof: Literal["planar", "full"] = "planar") -> TruthScore:
    """Score the usable poses of ``track`` against ``truth`` (module docstring).

    Parameters
    ----------
    track : the GT source's poses.
    truth : the true trajectory (``truth/run.tum``, ``truth/validation.tum``).
    expected_stamps_s : the stamps the source was asked for (every frame, every instant); default the
        track's own stamps.
    T_true_body : (4, 4) compare with ``T_true @ T_true_body`` instead of the true robot frame (the frame
        a marker calibration realised: ``A_true @ inv(A_given)`` for an anchor given at ``A_given``).
    dof : NEES of a 6-DoF track on its x, y, yaw block (``"planar"``) or on all six axes.
    """
    lo, hi = truth.stamps_s[0], truth.stamps_s[-1]
    expected = track.stamps_s if expected_stamps_s is None else np.asarray(expected_stamps_s, float)
    n_expected = int(np.sum((expected >= lo) & (expected <= hi)))
    use = track.ok & (track.stamps_s >= lo) & (track.stamps_s <= hi)
    t = track.stamps_s[use]
    if track.cov_kind == "xyyaw" and T_true_body is None:
        est = track.xytheta()[use]
        tr = truth_xytheta(truth, t)
        z = est - tr
        z[:, 2] = geo.wrap_angle(z[:, 2])
        pos = np.hypot(z[:, 0], z[:, 1])
        yaw = np.abs(z[:, 2])
        cov = None if track.cov is None else track.cov[use]
        nees = np.einsum("ni,nij,nj->n", z, np.linalg.inv(cov), z) if cov is not None and len(t) else np.zeros(0)
        return TruthScore(track.source, n_expected, t, pos, yaw, nees if cov is not None else np.zeros(0), 3)
    T_est = track.matrices()[use]
    T_true = truth_matrices(truth, t) if len(t) else np.zeros((0, 4, 4))
    if T_true_body is not None:
        T_true = T_true @ np.asarray(T_true_body, dtype=float)
    pos_l, yaw_l, nees_l = [], [], []
    k = 3 if dof == "planar" or track.cov_kind != "se3" else 6
    for i, (Te, Tt) in enumerate(zip(T_est, T_true, strict=True)):
        err = pose_error_xi(Te, Tt)
        pos_l.append(float(np.linalg.norm(err[:2])))
        yaw_l.append(abs(float(geo.wrap_angle(geo.T_to_se2(Te)[2] - geo.T_to_se2(Tt)[2]))))
        if track.cov is None:
            continue
        c = track.cov[np.flatnonzero(use)[i]]
        if track.cov_kind == "se3":
            idx = np.array(PLANAR_INDEX) if k == 3 else np.arange(6)
            e, c = err[idx], c[np.ix_(idx, idx)]
        elif track.cov_kind == "xyyaw":
            e = err[np.array(PLANAR_INDEX)]
        else:
            e = err[:3]
        nees_l.append(float(e @ np.linalg.solve(c, e)))
    return TruthScore(track.source, n_expected, t, np.array(pos_l), np.array(yaw_l), np.array(nees_l), k)


def score_on_recording(track: PoseTrack, rec_dir: str | os.PathLike[str], sequence: str, **kw: object) -> TruthScore:
    """:func:`score_track` against ``rec_dir/truth/<sequence>.tum``."""
    return score_track(track, read_tum(Path(rec_dir) / "truth" / f"{sequence}.tum"), **kw)  # type: ignore[arg-type]


def visible_localized(localized_frames: set[tuple[str, int]], frame_stamps: dict[str, np.ndarray],
                      truth: Trajectory | PoseTrack, rig_true: Rig) -> tuple[int, int]:
    """``(images in which a marker is fully visible at the true pose, those whose instant was
    localized)``: ``localized_frames`` holds ``(camera, image row)`` of the localized instants'
    images, ``frame_stamps`` each camera's image stamps (GTvision's run acceptance)."""
    from gtrig.vision.synthetic import visible_views

    n_vis = n_vis_ok = 0
    for cam, stamps in frame_stamps.items():
        for i, T in enumerate(truth_matrices(truth, stamps)):
            if any(c == cam for c, _, _ in visible_views(rig_true, T)):
                n_vis += 1
                n_vis_ok += (cam, i) in localized_frames
    return n_vis, n_vis_ok
