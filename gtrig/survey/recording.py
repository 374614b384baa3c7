"""The survey of one recording: read ``REC/survey/*.csv``, estimate world points and validation poses, and
compare with ``REC/truth/`` (simulator only)."""

from __future__ import annotations

import logging
import os
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from gtrig.errors import FormatError, InputError
from gtrig.io.survey_csv import (
    Distances,
    NamedPoints,
    read_pose_distances,
    read_pose_table,
    read_reference_points,
    read_robot_points,
    read_table,
    read_world_distances,
    write_points,
    write_poses,
)
from gtrig.survey.joint import JointResult, adjust_jointly
from gtrig.survey.points import WorldPointsResult, estimate_world_points
from gtrig.survey.poses import PosesResult, estimate_poses
from gtrig.survey.robust import BadReading

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class SurveyResult:
    """World points and validation poses of one recording.

    With the joint adjustment (``joint``), ``points`` and ``poses`` hold its coordinates and covariances
    (and its exclusions and warnings added); their per-point and per-pose details (basins, chi-square)
    are those of the two stages it started from.
    """

    points: WorldPointsResult
    poses: PosesResult
    joint: JointResult | None = None

    def poses_cov_joint(self) -> np.ndarray:
        """(3P, 3P) joint covariance of the validation poses: the joint adjustment's, or the per-pose
        blocks alone when it did not run."""
        if self.joint is not None:
            return self.joint.poses_cov_joint
        from scipy.linalg import block_diag

        return block_diag(*self.poses.cov_xytheta)


@dataclass(frozen=True)
class SurveyAccuracy:
    """Survey against truth. Position errors in metres, angles in radians.

    Attributes
    ----------
    point_err_m : (N,) Euclidean errors of the world points.
    pose_pos_err_m, pose_theta_err_rad : (P,) of the validation poses (theta wrapped).
    point_nees, pose_nees : (N,), (P,) normalized estimation error squared (dof 2 and 3).
    """

    point_names: tuple[str, ...]
    point_err_m: np.ndarray
    point_nees: np.ndarray
    pose_names: tuple[str, ...]
    pose_pos_err_m: np.ndarray
    pose_theta_err_rad: np.ndarray
    pose_nees: np.ndarray

    def summary(self) -> dict[str, float]:
        """Max and RMS errors (mm, deg) and mean NEES, for printing."""
        return {
            "world_points_max_mm": float(self.point_err_m.max() * 1000),
            "world_points_rms_mm": float(np.sqrt(np.mean(self.point_err_m**2)) * 1000),
            "poses_max_pos_mm": float(self.pose_pos_err_m.max() * 1000),
            "poses_rms_pos_mm": float(np.sqrt(np.mean(self.pose_pos_err_m**2)) * 1000),
            "poses_max_theta_deg": float(np.degrees(np.abs(self.pose_theta_err_rad).max())),
            "world_points_mean_nees": float(self.point_nees.mean()),
            "poses_mean_nees": float(self.pose_nees.mean()),
        }


def _rig_sigma(rec: Path) -> float | None:
    rig = rec / "rig.yaml"
    if not rig.exists():
        return None
    from gtrig.rig import load_rig

    return float(load_rig(rig).survey.hand_laser_sigma_m)


def run_survey(
    references: NamedPoints,
    world_distances: Distances,
    robot_points: NamedPoints,
    pose_distances: Distances,
    joint: bool = True,
    **kwargs: Any,
) -> SurveyResult:
    """World points, then validation poses with the world points' joint covariance propagated, then
    (``joint``) all of them adjusted together from every reading (:mod:`gtrig.survey.joint`).

    ``kwargs`` (``multistart``, ``on_ambiguity``, ``on_outlier``, ``alpha``) go to the estimators.
    """
    pts = estimate_world_points(references, world_distances, **kwargs)
    poses = estimate_poses(
        (pts.names, pts.xy, pts.cov_xy), robot_points, pose_distances, cov_world_joint=pts.cov_joint, **kwargs
    )
    if not joint or pose_distances.distance_m.size == 0:
        return SurveyResult(pts, poses)
    warnings: list[str] = []
    jr = adjust_jointly(
        list(pts.names), pts.xy, references, world_distances, list(poses.names), poses.xytheta, robot_points,
        pose_distances, world_active=_kept(world_distances, pts.excluded),
        pose_active=_kept(pose_distances, poses.excluded), warnings=warnings,
        **{k: v for k, v in kwargs.items() if k in ("alpha", "on_outlier")},
    )
    on_poses = tuple(b for b in jr.excluded if b.kind == "pose")
    on_points = tuple(b for b in jr.excluded if b.kind != "pose")
    pts = replace(pts, xy=jr.points_xy, cov_xy=jr.points_cov_xy, cov_joint=jr.points_cov_joint,
                  excluded=pts.excluded + on_points, warnings=pts.warnings + tuple(warnings))
    poses = replace(poses, xytheta=jr.poses_xytheta, cov_xytheta=jr.poses_cov,
                    excluded=poses.excluded + on_poses, warnings=poses.warnings + tuple(warnings))
    return SurveyResult(pts, poses, jr)


def _kept(readings: Distances, excluded: tuple[BadReading, ...]) -> np.ndarray:
    """(K,) readings not among ``excluded`` (matched by file and line, ends and value)."""
    bad = {(b.source, b.distance_m) for b in excluded}
    return np.array([(readings.source[k], float(readings.distance_m[k])) not in bad
                     for k in range(readings.distance_m.size)], dtype=bool)


def run_recording_survey(
    rec_dir: str | os.PathLike[str], out_dir: str | os.PathLike[str] | None = None, **kwargs: Any
) -> SurveyResult:
    """Read ``rec_dir/survey/*.csv`` (sigma default: the rig's hand-laser sigma), estimate world points and
    validation poses; with ``out_dir`` write ``world_points.csv`` and ``validation_poses.csv`` there."""
    rec = Path(rec_dir)
    sv = rec / "survey"
    if not sv.is_dir():
        raise InputError(f"{rec}: no survey/ folder")
    sigma = _rig_sigma(rec)
    res = run_survey(
        read_reference_points(sv / "reference_points.csv"),
        read_world_distances(sv / "world_distances.csv", sigma),
        read_robot_points(sv / "robot_points.csv"),
        read_pose_distances(sv / "pose_distances.csv", sigma),
        **kwargs,
    )
    if out_dir is not None:
        out = Path(out_dir)
        write_points(out / "world_points.csv", res.points.names, res.points.xy, res.points.cov_xy)
        write_poses(out / "validation_poses.csv", res.poses.names, res.poses.xytheta, res.poses.cov_xytheta)
    return res


def accuracy(
    result: SurveyResult, true_points: dict[str, np.ndarray], true_poses: dict[str, np.ndarray]
) -> SurveyAccuracy:
    """Errors and NEES of a survey against true world points (name -> (2,)) and poses (name -> (3,))."""
    pn = tuple(n for n in result.points.names if n in true_points)
    if not pn:
        raise InputError("no surveyed world point has a true position")
    ip = [result.points.names.index(n) for n in pn]
    e = result.points.xy[ip] - np.array([true_points[n] for n in pn])
    nees_p = np.einsum("ni,nij,nj->n", e, np.linalg.inv(result.points.cov_xy[ip]), e)
    qn = tuple(n for n in result.poses.names if n in true_poses)
    if not qn:
        raise InputError("no surveyed pose has a true pose")
    iq = [result.poses.names.index(n) for n in qn]
    eq = result.poses.xytheta[iq] - np.array([true_poses[n] for n in qn])
    eq[:, 2] = (eq[:, 2] + np.pi) % (2 * np.pi) - np.pi
    nees_q = np.einsum("ni,nij,nj->n", eq, np.linalg.inv(result.poses.cov_xytheta[iq]), eq)
    return SurveyAccuracy(
        pn, np.linalg.norm(e, axis=1), nees_p, qn, np.linalg.norm(eq[:, :2], axis=1), eq[:, 2], nees_q
    )


def compare_to_truth(result: SurveyResult, rec_dir: str | os.PathLike[str]) -> SurveyAccuracy:
    """Compare with ``rec_dir/truth/world_points.csv`` (name,x,y) and ``truth/validation_poses.csv``
    (pose,x,y,theta)."""
    truth = Path(rec_dir) / "truth"
    t = read_table(truth / "world_points.csv", ("name", "x", "y"))
    try:
        pts = {
            r[t.header.index("name")]: np.array(
                [float(r[t.header.index("x")]), float(r[t.header.index("y")])]
            )
            for r in t.rows
        }
    except ValueError:
        raise FormatError(f"{t.path}: x and y must be numbers") from None
    q = read_pose_table(truth / "validation_poses.csv")
    poses = {n: q.xytheta[i] for i, n in enumerate(q.names)}
    return accuracy(result, pts, poses)
