"""The whole job on one recording, as a table of contents: each stage that exists runs in turn.

``run(rec, out)`` reads a recording, runs the stages and, when the recording carries its truth
(simulated), measures every result against it. Each stage writes its outputs under ``out`` and
returns rows of the accuracy table.
"""

from __future__ import annotations

import logging
import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from gtrig import geometry as geo
from gtrig.errors import GtrigError
from gtrig.io.recording import recording_dir

if TYPE_CHECKING:
    from gtrig.rig import Rig
    from gtrig.vision.sequence import VisionResult

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class AccuracyRow:
    """One measured figure: ``stage``, what was measured, the value with its unit, and our target."""

    stage: str
    metric: str
    value: float
    unit: str
    target: str = ""
    ok: bool | None = None


@dataclass
class StageContext:
    """What stages hand on to later ones (the calibrated rig, trajectories...)."""

    rec: Path
    out: Path
    products: dict[str, object] = field(default_factory=dict)


Stage = Callable[[StageContext], list[AccuracyRow]]


def _has_truth(ctx: StageContext) -> bool:
    return (ctx.rec / "truth").is_dir()


def _rig(ctx: StageContext) -> Rig:
    """The rig as calibrated so far (the recording's nominal rig before any calibration stage)."""
    from gtrig.rig import Rig, load_rig

    rig = ctx.products.get("rig")
    return rig if isinstance(rig, Rig) else load_rig(ctx.rec / "rig.yaml")


def _calibrated(ctx: StageContext, rig: Rig) -> None:
    """Hand on a rig with one more part calibrated, and write it as ``out/rig.calibrated.yaml``."""
    from gtrig.rig.load import dump_rig

    ctx.products["rig"] = rig
    dump_rig(rig, ctx.out / "rig.calibrated.yaml")


def survey(ctx: StageContext) -> list[AccuracyRow]:
    """World points and validation poses from the hand-laser distances (issue 3)."""
    from gtrig.survey import compare_to_truth, run_recording_survey

    res = run_recording_survey(ctx.rec, ctx.out / "survey")
    ctx.products["survey"] = res
    if not _has_truth(ctx):
        return []
    s = compare_to_truth(res, ctx.rec).summary()
    return [
        AccuracyRow("survey", "world points, max error", s["world_points_max_mm"], "mm", "<= 2",
                    s["world_points_max_mm"] <= 2.0),
        AccuracyRow("survey", "world points, RMS error", s["world_points_rms_mm"], "mm"),
        AccuracyRow("survey", "validation poses, max position error", s["poses_max_pos_mm"], "mm", "<= 3",
                    s["poses_max_pos_mm"] <= 3.0),
        AccuracyRow("survey", "validation poses, max heading error", s["poses_max_theta_deg"], "deg", "<= 0.1",
                    s["poses_max_theta_deg"] <= 0.1),
        AccuracyRow("survey", "validation poses, mean NEES / dof", s["poses_mean_nees"] / 3, "", "0.7-1.4"),
    ]


def camera_calibration(ctx: StageContext) -> list[AccuracyRow]:
    """Intrinsics, then the joint network calibration anchored on the world board (issue 4)."""
    from gtrig.calib.recording import calibrate_recording

    rig, report = calibrate_recording(ctx.rec)
    _calibrated(ctx, _rig(ctx).model_copy(update={"cameras": rig.cameras}))
    ctx.products["camera_calibration"] = report
    report.write(ctx.out / "calibration")
    if not report.truth:
        return []
    t = report.truth
    worst_mm = max(r["joint_mm"] for r in t.values())
    worst_deg = max(r["joint_deg"] for r in t.values())
    worst_px = max(max(abs(r[k]) for k in ("dfx_px", "dfy_px", "dcx_px", "dcy_px")) for r in t.values())
    last = sorted(t)[-1]
    rows = [
        AccuracyRow("calibration", "cameras, worst position error", worst_mm, "mm", "<= 5", worst_mm <= 5),
        AccuracyRow("calibration", "cameras, worst orientation error", worst_deg, "deg", "<= 0.05", worst_deg <= 0.05),
        AccuracyRow("calibration", "intrinsics, worst f / c error", worst_px, "px", "<= 0.5", worst_px <= 0.5),
    ]
    if "chain_mm" in t[last]:
        ratio = t[last]["chain_mm"] / max(t[last]["joint_mm"], 1e-9)
        rows.append(AccuracyRow("calibration", f"{last}: chain / joint position error", ratio, "x", ">= 2",
                                ratio >= 2))
    return rows


def marker_calibration(ctx: StageContext) -> list[AccuracyRow]:
    """The markers' poses on the robot from the hand-held images, anchored on the dima-marker (issue 5)."""
    from gtrig.markers.robotcal import calibrate_markers, marker_errors, specs_from_rig, write_markers_yaml
    from gtrig.rig import load_rig
    from gtrig.vision.covariance import hand_placement_frame_covariance
    from gtrig.vision.robot_frame import with_markers_frame_cov

    rig = _rig(ctx)
    rig2, cal = calibrate_markers(ctx.rec, rig)
    write_markers_yaml(ctx.out / "markers.yaml", cal, specs_from_rig(rig))
    # every marker now hangs on the dima-marker's hand-measured pose: its error is common to all
    T_anchor = rig2.marker(cal.anchor).T_robot_marker.matrix()
    rig2 = with_markers_frame_cov(rig2, hand_placement_frame_covariance(T_anchor))
    _calibrated(ctx, rig2)
    ctx.products["marker_calibration"] = cal
    if not _has_truth(ctx):
        return []
    truth = load_rig(ctx.rec / "truth" / "rig.yaml")
    rows = []
    # relative to the dima-marker: what the images measured; on the robot: that plus the error of the
    # dima-marker's own measured pose, which every marker inherits
    for what, relative in (("relative to the dima-marker", True), ("on the robot", False)):
        err = marker_errors(cal, truth, relative=relative)
        pos_mm = max(e[0] for e in err.values()) * 1000
        rot_deg = math.degrees(max(e[1] for e in err.values()))
        rows += [
            AccuracyRow("markers", f"{what}, worst position error", pos_mm, "mm", "<= 1", pos_mm <= 1),
            AccuracyRow("markers", f"{what}, worst orientation error", rot_deg, "deg", "<= 0.1", rot_deg <= 0.1),
        ]
    return rows


def gtlaser(ctx: StageContext) -> list[AccuracyRow]:
    """Fixed-scanner calibration, then hull tracking over the continuous run (issue 7)."""
    from gtrig.io.tum import read_tum
    from gtrig.laser import report as laser_report
    from gtrig.laser.recording import calibrate_recording, track_recording

    rig_scanners, report = calibrate_recording(ctx.rec)
    rig = _rig(ctx).model_copy(update={"laser_scanners": rig_scanners.laser_scanners})
    _calibrated(ctx, rig)
    res = track_recording(ctx.rec, sequence="run", rig=rig, out_tum=ctx.out / "gt_laser.tum",
                          out_cov=ctx.out / "gt_laser_cov.csv", scanner_cov=report.cov_xytheta)
    if not _has_truth(ctx):
        return []
    acc = laser_report.accuracy(res, read_tum(ctx.rec / "truth" / "run.tum"))
    pos_mm, yaw_deg = acc.mean_pos_m * 1000, math.degrees(acc.mean_abs_yaw_rad)
    return [
        AccuracyRow("GTlaser", "run, mean position error", pos_mm, "mm", "<= 5", pos_mm <= 5),
        AccuracyRow("GTlaser", "run, mean |yaw| error", yaw_deg, "deg", "<= 0.1", yaw_deg <= 0.1),
        AccuracyRow("GTlaser", "run, frames localized", 100 * acc.n_ok / max(acc.n_frames, 1), "%"),
        AccuracyRow("GTlaser", "run, OK frames off by > 5 cm", acc.n_ok_wrong_5cm, "", "0", acc.n_ok_wrong_5cm == 0),
        AccuracyRow("GTlaser", "run, mean NEES / dof", acc.mean_nees / 3, "", "0.5-2"),
    ]


def _vision(ctx: StageContext, rig: Rig, sequence: str) -> VisionResult:
    """GTvision over one sequence with ``rig``, planar, the rig's calibrated covariances; the detections
    checkpointed, so an interrupted demo resumes instead of detecting again."""
    from gtrig.vision.covariance import UNCALIBRATED_MARKERS
    from gtrig.vision.estimate import VisionOptions
    from gtrig.vision.sequence import run_recording

    # each calibrated camera and marker in view gets a pose nuisance with the covariance its calibration
    # wrote into the rig (pose_cov); the others the sigmas of hand measurements
    return run_recording(ctx.rec, rig, sequence=sequence, planar=True,
                         options=VisionOptions(rig_uncertainty=UNCALIBRATED_MARKERS),
                         checkpoint=ctx.out / f"gt_vision_{sequence}.checkpoint", stale_checkpoint="restart")


def robot_frame(ctx: StageContext) -> list[AccuracyRow]:
    """The markers' robot frame tied to the surveyed one at the validation stops (gtrig.vision.robot_frame):
    the anchor's hand-measured pose replaced by what the survey and GTvision measured."""
    from gtrig.io.survey_csv import read_table
    from gtrig.markers.robotcal import RobotCalibration
    from gtrig.rig import load_rig
    from gtrig.survey import SurveyResult
    from gtrig.vision.robot_frame import fit_validation, rig_tied_to_survey, with_markers_frame_cov

    cal = ctx.products.get("marker_calibration")
    sv = ctx.products.get("survey")
    if not isinstance(cal, RobotCalibration) or not isinstance(sv, SurveyResult):
        raise GtrigError("needs the marker calibration and the survey's validation poses")
    rig = _rig(ctx)
    # GTvision's own covariances: the frame error is what the stops are about to measure
    val = _vision(ctx, with_markers_frame_cov(rig, None), "validation")
    names = read_table(ctx.rec / "validation" / "poses.csv", ("pose", "start_s", "end_s")).column("pose")
    fit = fit_validation(names, val, sv.poses.names, sv.poses.xytheta, sv.poses_cov_joint())
    rig2 = rig_tied_to_survey(rig, fit)
    ctx.products.update(vision_validation=val, frame_fit=fit,
                        hand_frame_cov=np.asarray(rig.robot.markers_frame_cov, float))
    _calibrated(ctx, rig2)
    log.info("robot frame from %d stops: offset %.2f mm, %.2f mm, %.4f deg (sigma %.2f mm, %.2f mm, %.4f deg), "
             "chi2 %.1f over %d dof", int(fit.used.sum()), *(1000 * fit.d_xytheta[:2]),
             math.degrees(fit.d_xytheta[2]), *(1000 * np.sqrt(np.diag(fit.cov_d)[:2])),
             math.degrees(math.sqrt(fit.cov_d[2, 2])), fit.chi2, fit.dof)
    if not _has_truth(ctx):
        return []
    truth = load_rig(ctx.rec / "truth" / "rig.yaml")
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
    return [
        AccuracyRow("robot frame", "offset from the survey, position error", float(np.hypot(*e[:2])) * 1000, "mm"),
        AccuracyRow("robot frame", "offset from the survey, yaw error", abs(math.degrees(e[2])), "deg"),
        AccuracyRow("robot frame", "offset from the survey, NEES / dof", nees / 3, "", "0.5-2"),
        AccuracyRow("markers", "on the robot, surveyed frame, worst position error", pos_mm, "mm", "<= 1",
                    pos_mm <= 1),
        AccuracyRow("markers", "on the robot, surveyed frame, worst orientation error", rot_deg, "deg", "<= 0.1",
                    rot_deg <= 0.1),
    ]


def gtvision(ctx: StageContext) -> list[AccuracyRow]:
    """Robot poses from all markers in all cameras, on the calibrated rig (issue 6)."""
    from gtrig.io.tum import write_tum
    from gtrig.markers.robotcal import RobotCalibration
    from gtrig.rig import load_rig
    from gtrig.vision import report as vision_report
    from gtrig.vision.robot_frame import FrameFit, frame_error_covariance, in_surveyed_frame, with_markers_frame_cov
    from gtrig.vision.sequence import VisionResult, with_robot_frame_uncertainty, write_covariance_csv

    rig = _rig(ctx)
    cal = ctx.products.get("marker_calibration")
    fit = ctx.products.get("frame_fit")
    fit = fit if isinstance(fit, FrameFit) else None
    rows: list[AccuracyRow] = []
    for seq in ("validation", "run"):
        static = seq == "validation"
        res_eval = res_own = None
        if static and fit is not None:
            # the stops measured the frame: the file gets the offset of every stop, the accuracy rows
            # check each stop corrected with the offset fitted from the other stops
            val, cov_hand = ctx.products["vision_validation"], ctx.products["hand_frame_cov"]
            assert isinstance(val, VisionResult) and isinstance(cov_hand, np.ndarray)
            n = len(val.estimates)
            res = in_surveyed_frame(val, [fit.T_markers_surveyed] * n,
                                    [frame_error_covariance(fit.cov_d, cov_hand)] * n)
            res_eval = in_surveyed_frame(val, [geo.se2_to_T(*d) for d in fit.loo_d],
                                         [frame_error_covariance(c, cov_hand) for c in fit.loo_cov])
        elif static:
            frame = rig.robot.markers_frame_cov
            res_own = _vision(ctx, with_markers_frame_cov(rig, None), "validation")
            res = res_own if frame is None else with_robot_frame_uncertainty(res_own, np.asarray(frame, float))
        else:
            # the rig's markers_frame_cov (the survey's offset, or the hand's) enters every pose
            res = _vision(ctx, rig, seq)
        write_tum(ctx.out / f"gt_vision_{seq}.tum", res.trajectory())
        write_covariance_csv(ctx.out / f"gt_vision_{seq}_cov.csv", res)
        if not _has_truth(ctx):
            continue
        acc = vision_report.accuracy_on_recording(res_eval or res, ctx.rec)
        mean_cm, max_cm = acc.pos_err_mean_m * 100, acc.pos_err_max_m * 100
        yaw = math.degrees(acc.yaw_err_mean_rad)
        rows += [
            AccuracyRow("GTvision", f"{seq}, poses localized", acc.localized, f"of {acc.instants}",
                        "all" if static else "", acc.localized == acc.instants if static else None),
            AccuracyRow("GTvision", f"{seq}, mean position error", mean_cm, "cm", "<= 1.0", mean_cm <= 1.0),
            AccuracyRow("GTvision", f"{seq}, max position error", max_cm, "cm", "<= 3", max_cm <= 3.0),
            AccuracyRow("GTvision", f"{seq}, mean |yaw| error", yaw, "deg", "<= 0.2", yaw <= 0.2),
            AccuracyRow("GTvision", f"{seq}, mean NEES / dof", acc.nees_mean / acc.nees_dof, "", "0.5-2",
                        0.5 <= acc.nees_mean / acc.nees_dof <= 2),
        ]
        if res_own is not None and isinstance(cal, RobotCalibration):
            # the dima-marker's given pose against its true one: one error shared by every pose, so one
            # recording's NEES follows that one draw (a correct covariance gives 0.3-2.3 in nine of ten);
            # without it, what GTvision itself estimated
            A_true = load_rig(ctx.rec / "truth" / "rig.yaml").marker(cal.anchor).T_robot_marker.matrix()
            F = A_true @ np.linalg.inv(rig.marker(cal.anchor).T_robot_marker.matrix())
            own = vision_report.accuracy_on_recording(res_own, ctx.rec, T_true_robot_frame=F).nees_mean / acc.nees_dof
            rows.append(AccuracyRow("GTvision", f"{seq}, mean NEES / dof in the dima-marker's frame", own, "",
                                    "0.5-2", 0.5 <= own <= 2))
        if not static:
            frac = 100 * acc.visible_localized_fraction
            rows.append(AccuracyRow("GTvision", "run, images with a fully visible marker localized", frac, "%",
                                    ">= 99", frac >= 99))
    return rows


def _stages() -> list[tuple[str, Stage]]:
    return [
        ("survey", survey),
        ("camera calibration", camera_calibration),
        ("marker calibration", marker_calibration),
        ("robot frame", robot_frame),
        ("GTlaser", gtlaser),
        ("GTvision", gtvision),
    ]


@dataclass(frozen=True)
class PipelineResult:
    rows: tuple[AccuracyRow, ...]
    seconds: dict[str, float]
    skipped: dict[str, str]


def run(rec: str | Path, out: str | Path, on_stage: Callable[[str], None] | None = None) -> PipelineResult:
    """Run every available stage on the recording ``rec``, writing under ``out``."""
    ctx = StageContext(recording_dir(rec), Path(out))
    ctx.out.mkdir(parents=True, exist_ok=True)
    rows: list[AccuracyRow] = []
    seconds: dict[str, float] = {}
    skipped: dict[str, str] = {}
    for name, stage in _stages():
        if on_stage:
            on_stage(name)
        t = time.perf_counter()
        try:
            rows.extend(stage(ctx))
        except GtrigError as e:
            # one stage's refusal (too few views, no markers...) must not hide the others' results
            log.warning("%s: %s", name, e)
            skipped[name] = str(e)
        seconds[name] = time.perf_counter() - t
    if rows:
        write_accuracy_csv(ctx.out / "accuracy.csv", rows)
    return PipelineResult(tuple(rows), seconds, skipped)


def write_accuracy_csv(path: Path, rows: list[AccuracyRow]) -> None:
    """``stage,metric,value,unit,target,ok``: the accuracy table, one measured figure a row."""
    from gtrig.io.atomic import atomic_write_text

    def cell(v: object) -> str:
        return f'"{v}"' if "," in str(v) else str(v)

    lines = ["stage,metric,value,unit,target,ok"]
    lines += [",".join(cell(v) for v in (r.stage, r.metric, f"{r.value:.6g}", r.unit, r.target,
                                         "" if r.ok is None else int(r.ok))) for r in rows]
    atomic_write_text(path, "\n".join(lines) + "\n")


def read_accuracy_csv(path: Path) -> dict[tuple[str, str], float]:
    """{(stage, metric): value} from :func:`write_accuracy_csv`."""
    import csv

    with open(path, newline="") as f:
        return {(r["stage"], r["metric"]): float(r["value"]) for r in csv.DictReader(f)}
