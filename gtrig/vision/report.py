"""What a GTvision run did (poses localized, coverage per camera, residuals, failures by reason) and,
on a simulated recording, how accurate it is against the truth."""

from __future__ import annotations

import math
import os
from collections import Counter
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from gtrig.io.tum import Trajectory
from gtrig.rig.models import Rig
from gtrig.vision.sequence import VisionResult


@dataclass(frozen=True)
class CameraCoverage:
    """Per camera: images read, images with at least one marker, views used in localized poses,
    views rejected as outliers, and the RMS reprojection error of its used views (px)."""

    camera: str
    images: int
    images_with_markers: int
    views_used: int
    views_rejected: int
    rms_px: float


@dataclass(frozen=True)
class VisionReport:
    """Summary of a :class:`~gtrig.vision.sequence.VisionResult`."""

    instants: int
    localized: int
    failures: dict[str, int]
    cameras: tuple[CameraCoverage, ...]
    rms_px: float
    median_views: float
    fused_cameras: dict[int, int]


def summarize(result: VisionResult) -> VisionReport:
    """Poses localized, coverage per camera, residuals and failures by reason."""
    ok = result.localized()
    fail = Counter(e.status.value for e in result.estimates if not e.ok)
    cams = []
    for name in sorted(result.images_per_camera):
        with_m = len({(o.stamp_s, v.frame) for o in result.observations for v in o.views if v.camera == name})
        used = [r for e in ok for (c, _), r in zip(e.views, e.view_rms_px, strict=True) if c == name]
        rej = sum(1 for e in result.estimates for c, _ in e.rejected if c == name)
        rms = float(np.sqrt(np.mean(np.square(used)))) if used else math.nan
        cams.append(CameraCoverage(name, result.images_per_camera[name], int(with_m), len(used), rej, rms))
    all_r = [r for e in ok for r in e.view_rms_px]
    fused = Counter(len({c for c, _ in e.views}) for e in ok)
    return VisionReport(len(result.estimates), len(ok), dict(fail), tuple(cams),
                        float(np.sqrt(np.mean(np.square(all_r)))) if all_r else math.nan,
                        float(np.median([len(e.views) for e in ok])) if ok else 0.0,
                        dict(sorted(fused.items())))


def interpolate_truth(truth: Trajectory, stamps_s: np.ndarray) -> np.ndarray:
    """Truth poses (M, 4, 4) at ``stamps_s`` (:func:`gtrig.evaluate.truth.truth_matrices`)."""
    from gtrig.evaluate.truth import truth_matrices

    return truth_matrices(truth, stamps_s)


@dataclass(frozen=True)
class VisionAccuracy:
    """GTvision against the truth.

    Attributes
    ----------
    instants, localized : counts over the sequence's instants.
    pos_err_mean_m, pos_err_max_m : horizontal position error of the localized poses, metres.
    yaw_err_mean_rad : mean absolute yaw error, radians.
    nees_mean : mean NEES of the localized poses, with ``nees_dof`` degrees of freedom (3 planar, else 6).
    frames_visible : camera images in which at least one marker is fully visible (truth).
    frames_visible_localized : those of them whose instant was localized.
    """

    instants: int
    localized: int
    pos_err_mean_m: float
    pos_err_max_m: float
    yaw_err_mean_rad: float
    nees_mean: float
    nees_dof: int
    frames_visible: int
    frames_visible_localized: int

    @property
    def visible_localized_fraction(self) -> float:
        return self.frames_visible_localized / self.frames_visible if self.frames_visible else math.nan


def accuracy_on_recording(result: VisionResult, rec_dir: str | os.PathLike[str],
                          T_true_robot_frame: np.ndarray | None = None) -> VisionAccuracy:
    """:func:`accuracy` of a simulated recording's sequence against its truth (``truth/<sequence>.tum``,
    ``truth/rig.yaml``) and, for the run, the images in which a marker is fully visible at the true pose.

    Evaluation only: the truth is read here, never by the estimator. ``T_true_robot_frame`` as in
    :func:`accuracy`.
    """
    from gtrig.io.frames import read_frame_index
    from gtrig.io.tum import read_tum
    from gtrig.rig import load_rig

    rec = Path(rec_dir)
    truth = read_tum(rec / "truth" / f"{result.sequence}.tum")
    if result.sequence != "run":
        return accuracy(result, truth, T_true_robot_frame=T_true_robot_frame)
    stamps = {c: read_frame_index(rec / "run" / "cameras" / c).stamps_s for c in result.images_per_camera}
    return accuracy(result, truth, load_rig(rec / "truth" / "rig.yaml"), stamps, T_true_robot_frame)


def accuracy(result: VisionResult, truth: Trajectory, rig_true: Rig | None = None,
             frame_stamps: dict[str, np.ndarray] | None = None,
             T_true_robot_frame: np.ndarray | None = None) -> VisionAccuracy:
    """Errors of the localized poses against ``truth`` (``truth/run.tum`` or ``truth/validation.tum``),
    scored by :func:`gtrig.evaluate.truth.score_track` on the result's pose track.

    With ``rig_true`` and the per-camera image stamps (``frame_stamps``), also counts the images in which
    a marker is fully visible at the true pose and how many of them were localized (run acceptance).
    ``T_true_robot_frame`` (4, 4): compare with the robot frame the markers realise rather than the true
    one, ``T_true @ T_true_robot_frame``; for markers calibrated relative to an anchor whose given pose is
    ``A`` and true pose ``A_true`` that is ``A_true @ inv(A)`` (the anchor's own error taken out).
    """
    from gtrig.evaluate.truth import score_track, visible_localized

    sc = score_track(result.to_pose_track(), truth, T_true_body=T_true_robot_frame,
                     dof="planar" if result.planar else "full")
    n_vis = n_vis_ok = 0
    if rig_true is not None and frame_stamps is not None:
        ok_frames = {f for o, e in zip(result.observations, result.estimates, strict=True) if e.ok
                     for f in o.frames}
        n_vis, n_vis_ok = visible_localized(ok_frames, frame_stamps, truth, rig_true)
    return VisionAccuracy(len(result.estimates), len(result.localized()), sc.mean_pos_m, sc.max_pos_m,
                          sc.mean_abs_yaw_rad, sc.mean_nees, sc.nees_dof, n_vis, n_vis_ok)
