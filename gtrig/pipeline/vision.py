"""Stage ``vision``: GTvision, robot poses from all markers in all cameras on the calibrated rig, written as pose
tracks ``gt_vision_<sequence>.tum`` + ``_cov.csv``."""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np

from gtrig import geometry as geo
from gtrig.pipeline.context import AccuracyRow, StageInput, StageOutput

if TYPE_CHECKING:
    from gtrig.rig import Rig
    from gtrig.vision.sequence import VisionResult

#: the least share (%) of the instants with a marker in view that GTvision should localize (the others are
#: ambiguous or inconsistent: a warning, see their reasons in the log)
MIN_LOCALIZED_SEEN_PCT = 90.0


def run_vision(inp: StageInput, rig: Rig, sequence: str) -> VisionResult:
    """GTvision over one sequence with ``rig`` and the run's ``vision`` options; each calibrated camera
    and marker in view gets a pose nuisance with the covariance its calibration wrote into the rig
    (``pose_cov``), the others the sigmas of hand measurements. The detections are checkpointed under
    the output folder, so an interrupted run resumes instead of detecting again."""
    from gtrig.config import apply_to_dataclass
    from gtrig.vision.covariance import UNCALIBRATED_MARKERS
    from gtrig.vision.estimate import VisionOptions
    from gtrig.vision.sequence import run_recording

    cfg = inp.config.vision
    opts = apply_to_dataclass(cfg.options, VisionOptions(rig_uncertainty=UNCALIBRATED_MARKERS))
    return run_recording(inp.rec, rig, sequence=sequence, planar=cfg.planar, workers=inp.workers, options=opts,
                         detector=cfg.detector, checkpoint=inp.out / f"gt_vision_{sequence}.checkpoint",
                         chunk_size=cfg.chunk_size, sync_tol_s=cfg.sync_tol_s, estimate_noise=cfg.estimate_noise,
                         stale_checkpoint="restart", executor=inp.executor, progress=inp.progress,
                         track=cfg.track.options())


def _against_survey(inp: StageInput, res: VisionResult) -> list[AccuracyRow]:
    """Each validation stop (in the frame fitted without it) against the survey's pose: what can be
    judged without truth."""
    from gtrig.evaluate.compare import mean_nees_interval
    from gtrig.io.survey_csv import read_table
    from gtrig.vision.covariance import planar_covariance

    sv = inp.products.survey
    if sv is None:
        return []
    names = read_table(inp.rec / "validation" / "poses.csv", ("pose", "start_s", "end_s")).column("pose")
    idx = {n: i for i, n in enumerate(sv.poses.names)}
    d_mm, nees = [], []
    for n, e in zip(names, res.estimates, strict=True):
        if not e.ok or n not in idx or e.T_world_robot is None or e.cov_6x6 is None:
            continue
        z = geo.T_to_se2(e.T_world_robot) - sv.poses.xytheta[idx[n]]
        z[2] = float(geo.wrap_angle(z[2]))
        d_mm.append(1000 * float(np.hypot(*z[:2])))
        nees.append(float(z @ np.linalg.solve(planar_covariance(e.cov_6x6) + sv.poses.cov_xytheta[idx[n]], z)))
    if not d_mm:
        return []
    mean_nees = float(np.mean(nees)) / 3
    # the 0.3-3 row stays as the loose check; this one is what an honest covariance gives for this many stops
    lo, hi = mean_nees_interval(len(nees), 3)
    return [
        AccuracyRow("GTvision", "validation, leave-one-out, mean distance to the survey", float(np.mean(d_mm)), "mm"),
        AccuracyRow("GTvision", "validation, leave-one-out, max distance to the survey", float(np.max(d_mm)), "mm"),
        AccuracyRow("GTvision", "validation, leave-one-out, NEES / dof against the survey", mean_nees, "",
                    "0.3-3", 0.3 <= mean_nees <= 3),
        AccuracyRow("GTvision", "validation, leave-one-out, NEES / dof against the survey, 95 % interval",
                    mean_nees, "", f"{lo:.2f}-{hi:.2f}", lo <= mean_nees <= hi),
    ]


def _write_run_bias(inp: StageInput, frame_cov_6x6: np.ndarray) -> None:
    """``gt_vision_run_bias.yaml``: the robot frame's fit (where the markers put the robot frame, the same
    error on every pose of the run, robot axes) as fusion's considered bias, averaged over the heading.
    The cameras' calibration is common to the run too, but GTvision marginalises it per pose without
    keeping its share, so it is not in the file (docs/fusion.md)."""
    from gtrig.fusion.bias import heading_averaged
    from gtrig.io.biascov import write_bias_cov
    from gtrig.vision.covariance import PLANAR_INDEX

    planar = frame_cov_6x6[np.ix_(PLANAR_INDEX, PLANAR_INDEX)]
    write_bias_cov(inp.out / "gt_vision_run_bias.yaml", "GTvision", {"robot frame": heading_averaged(planar)})


def gtvision(inp: StageInput) -> StageOutput:
    from gtrig.evaluate.truth import score_on_recording, visible_localized
    from gtrig.io.frames import read_frame_index
    from gtrig.io.posetrack import write_pose_track
    from gtrig.io.tum import read_tum
    from gtrig.rig import load_rig
    from gtrig.vision.estimate import Status
    from gtrig.vision.report import summarize
    from gtrig.vision.robot_frame import frame_error_covariance, in_surveyed_frame, with_markers_frame_cov
    from gtrig.vision.sequence import file_track, with_robot_frame_uncertainty

    p = inp.products
    rig, cal, fit = p.rig, p.marker_calibration, p.frame_fit
    assert rig is not None
    rows: list[AccuracyRow] = []
    checks: list[AccuracyRow] = []
    prod: dict[str, object] = {}
    outputs: list[str] = []
    for seq in ("validation", "run"):
        static = seq == "validation"
        res_eval = res_own = None
        if static and fit is not None:
            # the stops measured the frame: the file gets the offset of every stop, the accuracy rows
            # check each stop corrected with the offset fitted from the other stops
            val, cov_hand = p.vision_validation, p.hand_frame_cov
            assert val is not None and cov_hand is not None
            n = len(val.estimates)
            res = in_surveyed_frame(val, [fit.T_markers_surveyed] * n,
                                    [frame_error_covariance(fit.cov_d, cov_hand)] * n)
            res_eval = in_surveyed_frame(val, [geo.se2_to_T(*d) for d in fit.loo_d],
                                         [frame_error_covariance(c, cov_hand) for c in fit.loo_cov])
        elif static:
            frame = rig.robot.markers_frame_cov
            res_own = run_vision(inp, with_markers_frame_cov(rig, None), "validation")
            res = res_own if frame is None else with_robot_frame_uncertainty(res_own, np.asarray(frame, float))
        else:
            # the rig's markers_frame_cov (the survey's offset, or the hand's) enters every pose
            res = run_vision(inp, rig, seq)
        track = file_track(res)
        write_pose_track(track, inp.out / f"gt_vision_{seq}.tum", inp.out / f"gt_vision_{seq}_cov.csv")
        outputs += [f"gt_vision_{seq}.tum", f"gt_vision_{seq}_cov.csv"]
        if not static and rig.robot.markers_frame_cov is not None:
            _write_run_bias(inp, np.asarray(rig.robot.markers_frame_cov, float))
            outputs.append("gt_vision_run_bias.yaml")
        elif not static:
            # no frame covariance now: an earlier run's file must not reach fusion
            (inp.out / "gt_vision_run_bias.yaml").unlink(missing_ok=True)
        prod[f"tracks/GTvision/{seq}"] = res.to_pose_track()
        rep = summarize(res)
        # an instant without any marker in view (the robot outside the cameras' fields) is not a failure:
        # the share that says how GTvision does is of the instants where a camera saw a marker
        unseen = rep.failures.get(Status.NO_MARKER.value, 0)
        seen = rep.instants - unseen
        share = 100 * rep.localized / seen if seen else math.nan  # no marker ever in view: said above
        checks += [
            AccuracyRow("GTvision", f"{seq}, poses localized", rep.localized, f"of {rep.instants}",
                        "all" if static else "", rep.localized == rep.instants if static else None),
            AccuracyRow("GTvision", f"{seq}, instants with no marker in view", unseen, f"of {rep.instants}"),
            AccuracyRow("GTvision", f"{seq}, instants with a marker in view, localized", share, "%",
                        f">= {MIN_LOCALIZED_SEEN_PCT:g}", bool(share >= MIN_LOCALIZED_SEEN_PCT) if seen else None),
            AccuracyRow("GTvision", f"{seq}, corner residual RMS", rep.rms_px, "px", "<= 1",
                        bool(rep.rms_px <= 1)),
        ]
        if res_eval is not None:
            checks += _against_survey(inp, res_eval)
        if not inp.has_truth:
            continue
        scored = res_eval or res
        score = score_on_recording(scored.to_pose_track(), inp.rec, seq,
                                   expected_stamps_s=np.array([e.stamp_s for e in scored.estimates]))
        n_ok, n_all = len(scored.localized()), len(scored.estimates)
        mean_cm, max_cm = score.mean_pos_m * 100, score.max_pos_m * 100
        yaw = math.degrees(score.mean_abs_yaw_rad)
        nees_dof = score.mean_nees / score.nees_dof
        rows += [
            AccuracyRow("GTvision", f"{seq}, poses localized", n_ok, f"of {n_all}", "all" if static else "",
                        n_ok == n_all if static else None),
            AccuracyRow("GTvision", f"{seq}, mean position error", mean_cm, "cm", "<= 1.0", mean_cm <= 1.0),
            AccuracyRow("GTvision", f"{seq}, max position error", max_cm, "cm", "<= 3", max_cm <= 3.0),
            AccuracyRow("GTvision", f"{seq}, mean |yaw| error", yaw, "deg", "<= 0.2", yaw <= 0.2),
            AccuracyRow("GTvision", f"{seq}, mean NEES / dof", nees_dof, "", "0.5-2", 0.5 <= nees_dof <= 2),
        ]
        if res_own is not None and cal is not None:
            # the dima-marker's given pose against its true one: one error shared by every pose, so one
            # recording's NEES follows that one draw (a correct covariance gives 0.3-2.3 in nine of ten);
            # without it, what GTvision itself estimated
            A_true = load_rig(inp.rec / "truth" / "rig.yaml").marker(cal.anchor).T_robot_marker.matrix()
            F = A_true @ np.linalg.inv(rig.marker(cal.anchor).T_robot_marker.matrix())
            own_score = score_on_recording(res_own.to_pose_track(), inp.rec, seq, T_true_body=F)
            own = own_score.mean_nees / own_score.nees_dof
            rows.append(AccuracyRow("GTvision", f"{seq}, mean NEES / dof in the dima-marker's frame", own, "",
                                    "0.5-2", 0.5 <= own <= 2))
        if not static:
            ok_frames = {f for o, e in zip(res.observations, res.estimates, strict=True) if e.ok for f in o.frames}
            stamps = {c: read_frame_index(inp.rec / "run" / "cameras" / c).stamps_s for c in res.images_per_camera}
            n_vis, n_vis_ok = visible_localized(ok_frames, stamps, read_tum(inp.rec / "truth" / "run.tum"),
                                                load_rig(inp.rec / "truth" / "rig.yaml"))
            frac = 100 * (n_vis_ok / n_vis if n_vis else math.nan)
            rows.append(AccuracyRow("GTvision", "run, images with a fully visible marker localized", frac, "%",
                                    ">= 99", frac >= 99))
    return StageOutput(prod, tuple(rows), tuple(checks), tuple(outputs))
