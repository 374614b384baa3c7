"""Stage ``laser``: GTlaser, the fixed scanners' calibration then hull tracking over the continuous run
(issue 7), written as the pose track ``gt_laser.tum`` + ``gt_laser_cov.csv``."""

from __future__ import annotations

import math

from gtrig.pipeline.context import AccuracyRow, StageInput, StageOutput


def gtlaser(inp: StageInput) -> StageOutput:
    from gtrig.config import apply_to_dataclass
    from gtrig.evaluate.truth import score_on_recording
    from gtrig.laser.recording import calibrate_recording, track_recording
    from gtrig.laser.track import TrackSettings, to_pose_track

    assert inp.products.rig is not None
    rig_scanners, report = calibrate_recording(inp.rec)
    rig = inp.products.rig.model_copy(update={"laser_scanners": rig_scanners.laser_scanners})
    settings = apply_to_dataclass(inp.config.laser.track, TrackSettings())
    res = track_recording(inp.rec, sequence="run", rig=rig, out_tum=inp.out / "gt_laser.tum",
                          out_cov=inp.out / "gt_laser_cov.csv", settings=settings, scanner_cov=report.cov_xytheta,
                          executor=inp.executor, workers=inp.workers, progress=inp.progress)
    track = to_pose_track(res)
    counts = res.counts()
    share = 100 * counts["ok"] / max(len(res), 1)
    checks = (
        AccuracyRow("GTlaser", "calibration, overlap RMS", 1000 * report.rms_overlap_m, "mm", "<= 10",
                    1000 * report.rms_overlap_m <= 10),
        AccuracyRow("GTlaser", "calibration, world object RMS", 1000 * report.rms_object_m, "mm", "<= 10",
                    1000 * report.rms_object_m <= 10),
        AccuracyRow("GTlaser", "run, frames localized", share, "%", ">= 50", share >= 50),
        AccuracyRow("GTlaser", "run, frames degenerate", counts["degenerate"], f"of {len(res)}"),
        AccuracyRow("GTlaser", "run, frames ambiguous", counts["ambiguous"], f"of {len(res)}", "0",
                    counts["ambiguous"] == 0),
    )
    prod = {"rig": rig, "laser_report": report, "laser_result": res, "tracks/GTlaser/run": track}
    outputs = ("gt_laser.tum", "gt_laser_cov.csv")
    if not inp.has_truth:
        return StageOutput(prod, checks=checks, outputs=outputs)
    acc = score_on_recording(track, inp.rec, "run", expected_stamps_s=res.stamps_s)
    pos_mm, yaw_deg = acc.mean_pos_m * 1000, math.degrees(acc.mean_abs_yaw_rad)
    n_wrong = acc.n_pos_over(0.05)
    rows = (
        AccuracyRow("GTlaser", "run, mean position error", pos_mm, "mm", "<= 5", pos_mm <= 5),
        AccuracyRow("GTlaser", "run, mean |yaw| error", yaw_deg, "deg", "<= 0.1", yaw_deg <= 0.1),
        AccuracyRow("GTlaser", "run, frames localized", 100 * acc.n_scored / max(acc.n_expected, 1), "%"),
        AccuracyRow("GTlaser", "run, OK frames off by > 5 cm", n_wrong, "", "0", n_wrong == 0),
        AccuracyRow("GTlaser", "run, mean NEES / dof", acc.mean_nees / 3, "", "0.5-2"),
    )
    return StageOutput(prod, rows, checks, outputs)



