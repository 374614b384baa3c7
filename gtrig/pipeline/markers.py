"""Stage ``markers``: the markers' poses on the robot from the hand-held images, anchored on the
dima-marker."""

from __future__ import annotations

import math

from gtrig.pipeline.context import AccuracyRow, StageInput, StageOutput


def marker_calibration(inp: StageInput) -> StageOutput:
    from gtrig.config import Section, apply_to_dataclass
    from gtrig.markers.robotcal import calibrate_markers, marker_errors, specs_from_rig, write_markers_yaml
    from gtrig.markers.robotcal.calibrate import RobotCalOptions
    from gtrig.rig import load_rig
    from gtrig.vision.covariance import hand_placement_frame_covariance
    from gtrig.vision.robot_frame import with_markers_frame_cov

    cfg = inp.config.markers
    rig = inp.products.rig
    assert rig is not None
    options: Section = cfg.options
    opts = apply_to_dataclass(options, RobotCalOptions()) if options.overrides() else None
    rig2, cal = calibrate_markers(inp.rec, rig, cfg.anchor, opts)
    write_markers_yaml(inp.out / "markers.yaml", cal, specs_from_rig(rig))
    # every marker now hangs on the dima-marker's hand-measured pose: its error is common to all
    T_anchor = rig2.marker(cal.anchor).T_robot_marker.matrix()
    rig2 = with_markers_frame_cov(rig2, hand_placement_frame_covariance(T_anchor))
    checks = [
        AccuracyRow("markers", "calibrated", len(cal.T_robot_marker), f"of {len(rig.robot.markers)}"),
        AccuracyRow("markers", "corner RMS", float(cal.rms_px), "px", "<= 1", float(cal.rms_px) <= 1),
        AccuracyRow("markers", "variance factor of the corners", float(cal.variance_factor), "", "<= 4",
                    float(cal.variance_factor) <= 4),
    ]
    prod = {"rig": rig2, "marker_calibration": cal}
    if not inp.has_truth:
        return StageOutput(prod, checks=tuple(checks), outputs=("markers.yaml",))
    truth = load_rig(inp.rec / "truth" / "rig.yaml")
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
    return StageOutput(prod, tuple(rows), tuple(checks), ("markers.yaml",))
