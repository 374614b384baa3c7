"""Summaries of GTlaser results: calibration tables and accuracy against a true trajectory."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from gtrig.io.tum import Trajectory
from gtrig.laser.calibrate import CalibrationReport
from gtrig.laser.track import AMBIGUOUS, DEGENERATE, LOST, OK, TrackResult, to_pose_track


@dataclass(frozen=True)
class TrackAccuracy:
    """GTlaser against truth (simulator), over the frames inside the truth's time span.

    Attributes
    ----------
    n_frames, n_ok, n_degenerate, n_lost, n_ambiguous : frame counts.
    mean_pos_m, max_pos_m : position error of ``OK`` frames (smoothed output).
    mean_abs_yaw_rad, max_abs_yaw_rad : absolute heading error of ``OK`` frames.
    raw_mean_pos_m, raw_mean_abs_yaw_rad : the same for the per-frame ICP poses before smoothing.
    mean_nees : mean normalised estimation error squared of ``OK`` frames (3 if the covariance is right).
    n_ok_wrong_5cm : ``OK`` frames more than 5 cm off (silent failures).
    n_degenerate_wrong_5cm : flagged degenerate frames more than 5 cm off (allowed, reported).
    """

    n_frames: int
    n_ok: int
    n_degenerate: int
    n_lost: int
    n_ambiguous: int
    mean_pos_m: float
    max_pos_m: float
    mean_abs_yaw_rad: float
    max_abs_yaw_rad: float
    raw_mean_pos_m: float
    raw_mean_abs_yaw_rad: float
    mean_nees: float
    n_ok_wrong_5cm: int
    n_degenerate_wrong_5cm: int


def truth_xytheta(truth: Trajectory, stamps_s: np.ndarray) -> np.ndarray:
    """True planar poses (N, 3) at ``stamps_s`` (:func:`gtrig.evaluate.truth.truth_xytheta`)."""
    from gtrig.evaluate.truth import truth_xytheta as planar

    return planar(truth, stamps_s)


def accuracy(result: TrackResult, truth: Trajectory) -> TrackAccuracy:
    """A :class:`TrackResult` against a dense true trajectory (``truth/run.tum``) over the frames inside
    its time span, scored by :func:`gtrig.evaluate.truth.score_track`: the smoothed ``OK`` poses (the
    track GTlaser writes), the same frames before smoothing, and the degenerate ones (flagged, allowed
    to be off, counted)."""
    from gtrig.evaluate.truth import score_track
    from gtrig.trajectory import PoseTrack

    t = result.stamps_s
    inside = (t >= truth.stamps_s[0]) & (t <= truth.stamps_s[-1])
    ok = result.status == OK
    deg = result.status == DEGENERATE
    smoothed = score_track(to_pose_track(result).usable(), truth, expected_stamps_s=t)

    def planar(idx: np.ndarray, poses: np.ndarray) -> PoseTrack:
        idx = idx & np.isfinite(poses[:, 0])
        return PoseTrack.from_xytheta(t[idx], poses[idx], source="GTlaser")

    raw = score_track(planar(ok, result.raw_xytheta), truth)
    degenerate = score_track(planar(deg, result.xytheta), truth)
    return TrackAccuracy(
        n_frames=int(inside.sum()),
        n_ok=smoothed.n_scored,
        n_degenerate=degenerate.n_scored,
        n_lost=int(np.sum(inside & (result.status == LOST))),
        n_ambiguous=int(np.sum(inside & (result.status == AMBIGUOUS))),
        mean_pos_m=smoothed.mean_pos_m,
        max_pos_m=smoothed.max_pos_m,
        mean_abs_yaw_rad=smoothed.mean_abs_yaw_rad,
        max_abs_yaw_rad=smoothed.max_abs_yaw_rad,
        raw_mean_pos_m=raw.mean_pos_m,
        raw_mean_abs_yaw_rad=raw.mean_abs_yaw_rad,
        mean_nees=smoothed.mean_nees,
        n_ok_wrong_5cm=smoothed.n_pos_over(0.05),
        n_degenerate_wrong_5cm=degenerate.n_pos_over(0.05),
    )


def accuracy_lines(acc: TrackAccuracy) -> list[str]:
    """A few human-readable lines."""
    return [
        f"frames {acc.n_frames}: ok {acc.n_ok}, degenerate {acc.n_degenerate}, lost {acc.n_lost}, "
        f"ambiguous {acc.n_ambiguous}",
        f"position error mean {1000 * acc.mean_pos_m:.2f} mm (max {1000 * acc.max_pos_m:.1f}); "
        f"yaw error mean {np.degrees(acc.mean_abs_yaw_rad):.3f} deg "
        f"(max {np.degrees(acc.max_abs_yaw_rad):.3f})",
        f"before smoothing: {1000 * acc.raw_mean_pos_m:.2f} mm, "
        f"{np.degrees(acc.raw_mean_abs_yaw_rad):.3f} deg; "
        f"mean NEES {acc.mean_nees:.2f} (3 = consistent); ok frames off by > 5 cm: {acc.n_ok_wrong_5cm}",
    ]


def calibration_lines(report: CalibrationReport) -> list[str]:
    """One line per scanner: calibrated pose, change from nominal, standard deviations, residuals."""
    out = [
        f"{report.iterations} iterations; overlap RMS {1000 * report.rms_overlap_m:.2f} mm, "
        f"world object RMS {1000 * report.rms_object_m:.2f} mm"
    ]
    for c in report.scanners:
        out.append(
            f"{c.name}: x {c.xytheta[0]:.4f} y {c.xytheta[1]:.4f} m, yaw {np.degrees(c.xytheta[2]):.3f} deg "
            f"(moved {1000 * np.hypot(*c.delta_xytheta[:2]):.1f} mm, "
            f"{np.degrees(c.delta_xytheta[2]):+.2f} deg; "
            f"std {1000 * c.std_xytheta[0]:.1f}, {1000 * c.std_xytheta[1]:.1f} mm, "
            f"{np.degrees(c.std_xytheta[2]):.3f} deg); overlap {c.n_overlap} pts RMS "
            f"{1000 * c.rms_overlap_m:.2f} mm, object {c.n_object} pts RMS {1000 * c.rms_object_m:.2f} mm"
        )
    return out
