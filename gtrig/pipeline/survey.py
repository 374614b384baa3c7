"""Stage ``survey``: world points and validation poses from the hand-laser distances."""

from __future__ import annotations

import numpy as np

from gtrig.pipeline.context import AccuracyRow, StageInput, StageOutput


def survey(inp: StageInput) -> StageOutput:
    from gtrig.survey import compare_to_truth, run_recording_survey

    res = run_recording_survey(inp.rec, inp.out / "survey", **inp.config.survey.overrides())
    sd_mm = 1000 * np.sqrt(np.max(res.poses.cov_xytheta[:, [0, 1], [0, 1]], axis=1)) if len(res.poses.names) \
        else np.zeros(0)
    checks = [
        AccuracyRow("survey", "world points", len(res.points.names), ""),
        AccuracyRow("survey", "validation poses", len(res.poses.names), ""),
    ]
    if sd_mm.size:
        worst = float(sd_mm.max())
        checks.append(AccuracyRow("survey", "validation poses, worst position sigma", worst, "mm", "<= 3",
                                  worst <= 3.0))
    outputs = ("survey/world_points.csv", "survey/validation_poses.csv")
    if not inp.has_truth:
        return StageOutput({"survey": res}, checks=tuple(checks), outputs=outputs)
    s = compare_to_truth(res, inp.rec).summary()
    rows = (
        AccuracyRow("survey", "world points, max error", s["world_points_max_mm"], "mm", "<= 2",
                    s["world_points_max_mm"] <= 2.0),
        AccuracyRow("survey", "world points, RMS error", s["world_points_rms_mm"], "mm"),
        AccuracyRow("survey", "validation poses, max position error", s["poses_max_pos_mm"], "mm", "<= 3",
                    s["poses_max_pos_mm"] <= 3.0),
        AccuracyRow("survey", "validation poses, max heading error", s["poses_max_theta_deg"], "deg", "<= 0.1",
                    s["poses_max_theta_deg"] <= 0.1),
        AccuracyRow("survey", "validation poses, mean NEES / dof", s["poses_mean_nees"] / 3, "", "0.7-1.4"),
    )
    return StageOutput({"survey": res}, rows, tuple(checks), outputs)
