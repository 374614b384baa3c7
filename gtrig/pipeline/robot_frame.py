"""Stage ``robot-frame``: the markers' robot frame tied to the surveyed one at the validation stops
(gtrig.vision.robot_frame): the anchor's hand-measured pose replaced by what the survey and GTvision
measured."""

from __future__ import annotations

import logging
import math

import numpy as np

from gtrig import geometry as geo
from gtrig.pipeline.context import AccuracyRow, StageInput, StageOutput
from gtrig.pipeline.vision import run_vision

log = logging.getLogger(__name__)


def robot_frame(inp: StageInput) -> StageOutput:
    from gtrig.io.survey_csv import read_table
    from gtrig.rig import load_rig
    from gtrig.vision.robot_frame import fit_validation, rig_tied_to_survey, with_markers_frame_cov

    cal, sv, rig = inp.products.marker_calibration, inp.products.survey, inp.products.rig
    assert cal is not None and sv is not None and rig is not None
    # GTvision's own covariances: the frame error is what the stops are about to measure
    val = run_vision(inp, with_markers_frame_cov(rig, None), "validation")
    names = read_table(inp.rec / "validation" / "poses.csv", ("pose", "start_s", "end_s")).column("pose")
    fit = fit_validation(names, val, sv.poses.names, sv.poses.xytheta, sv.poses_cov_joint())
    rig2 = rig_tied_to_survey(rig, fit)
    log.info("robot frame from %d stops: offset %.2f mm, %.2f mm, %.4f deg (sigma %.2f mm, %.2f mm, %.4f deg), "
             "chi2 %.1f over %d dof", int(fit.used.sum()), *(1000 * fit.d_xytheta[:2]),
             math.degrees(fit.d_xytheta[2]), *(1000 * np.sqrt(np.diag(fit.cov_d)[:2])),
             math.degrees(math.sqrt(fit.cov_d[2, 2])), fit.chi2, fit.dof)
    n_used = int(fit.used.sum())
    chi2_dof = fit.chi2 / fit.dof if fit.dof else math.nan
    stop_nees = fit.stop_nees[np.isfinite(fit.stop_nees)]
    checks = (
        AccuracyRow("robot frame", "stops used", n_used, f"of {len(fit.names)}", "all", n_used == len(fit.names)),
        AccuracyRow("robot frame", "offset from the survey, position", float(np.hypot(*fit.d_xytheta[:2])) * 1000,
                    "mm"),
        AccuracyRow("robot frame", "offset from the survey, yaw", abs(math.degrees(fit.d_xytheta[2])), "deg"),
        AccuracyRow("robot frame", "stops against one offset, chi2 / dof", chi2_dof, "", "0.3-3",
                    0.3 <= chi2_dof <= 3),
        AccuracyRow("robot frame", "stops, mean NEES / dof", float(np.mean(stop_nees)) / 3 if stop_nees.size
                    else math.nan, "", "0.3-3", bool(stop_nees.size) and 0.3 <= float(np.mean(stop_nees)) / 3 <= 3),
    )
    prod = {"vision_validation": val, "frame_fit": fit, "hand_frame_cov": np.asarray(rig.robot.markers_frame_cov,
                                                                                       float), "rig": rig2}
    if not inp.has_truth:
        return StageOutput(prod, checks=checks)
    truth = load_rig(inp.rec / "truth" / "rig.yaml")
    A_true = truth.marker(cal.anchor).T_robot_marker.matrix()
    # the frame the markers realised is the true one moved by A_given A_true^-1: what D should be
    D_true = geo.T_to_se2(rig.marker(cal.anchor).T_robot_marker.matrix() @ np.linalg.inv(A_true))
    e = fit.d_xytheta - D_true
    e[2] = float(geo.wrap_angle(e[2]))
    nees = float(e @ np.linalg.solve(fit.cov_d, e))
    true_m = {m.id: m.T_robot_marker.matrix() for m in truth.robot.markers}
    err = [geo.pose_error(m.T_robot_marker.matrix(), true_m[m.id]) for m in rig2.robot.markers
           if m.id in true_m and m.id in cal.T_robot_marker]
    pos_mm = max(p for p, _ in err) * 1000
    rot_deg = math.degrees(max(r for _, r in err))
    rows = (
        AccuracyRow("robot frame", "offset from the survey, position error", float(np.hypot(*e[:2])) * 1000, "mm"),
        AccuracyRow("robot frame", "offset from the survey, yaw error", abs(math.degrees(e[2])), "deg"),
        AccuracyRow("robot frame", "offset from the survey, NEES / dof", nees / 3, "", "0.5-2"),
        AccuracyRow("markers", "on the robot, surveyed frame, worst position error", pos_mm, "mm", "<= 1",
                    pos_mm <= 1),
        AccuracyRow("markers", "on the robot, surveyed frame, worst orientation error", rot_deg, "deg", "<= 0.1",
                    rot_deg <= 0.1),
    )
    return StageOutput(prod, rows, checks)
