"""Stage ``cameras``: intrinsics, then the joint network calibration anchored on the world board."""

from __future__ import annotations

from gtrig.pipeline.context import AccuracyRow, StageInput, StageOutput


def camera_calibration(inp: StageInput) -> StageOutput:
    from gtrig.calib.recording import calibrate_recording

    rig, report = calibrate_recording(inp.rec, **inp.config.cameras.overrides())
    assert inp.products.rig is not None
    rig2 = inp.products.rig.model_copy(update={"cameras": rig.cameras})
    report.write(inp.out / "calibration")
    net = report.network
    checks = (
        AccuracyRow("calibration", "network, corner RMS", float(net.rms_px), "px", "<= 1", float(net.rms_px) <= 1),
        AccuracyRow("calibration", "network, sigma per dof", float(net.sigma_px), "px"),
    )
    prod = {"rig": rig2, "camera_report": report}
    if not report.truth:
        return StageOutput(prod, checks=checks)
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
    return StageOutput(prod, tuple(rows), checks)
