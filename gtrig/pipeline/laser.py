"""Stage ``laser``: GTlaser, the fixed scanners' calibration then hull tracking over the continuous run, written as
the pose track ``gt_laser.tum`` + ``gt_laser_cov.csv``, and the error its poses
share over the run (the scanners' calibration) as ``gt_laser_bias.yaml`` (gtrig.io.biascov)."""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

from gtrig.pipeline.cache import SCAN_CACHE
from gtrig.pipeline.context import AccuracyRow, StageInput, StageOutput

if TYPE_CHECKING:
    from gtrig.evaluate.truth import TruthScore
    from gtrig.trajectory import PoseTrack



def gtlaser(inp: StageInput) -> StageOutput:
    from gtrig.config import apply_to_dataclass
    from gtrig.evaluate.truth import score_on_recording
    from gtrig.io.biascov import write_bias_cov
    from gtrig.laser.beam_timing import timing_check
    from gtrig.laser.recording import calibrate_recording, check_recording_timing, track_recording
    from gtrig.laser.track import TrackSettings, to_pose_track

    assert inp.products.rig is not None
    rig_scanners, report = calibrate_recording(inp.rec)
    rig = inp.products.rig.model_copy(update={"laser_scanners": rig_scanners.laser_scanners})
    settings = apply_to_dataclass(inp.config.laser.track, TrackSettings())
    res = track_recording(inp.rec, sequence="run", rig=rig, out_tum=inp.out / "gt_laser.tum",
                          out_cov=inp.out / "gt_laser_cov.csv", settings=settings, scanner_cov=report.cov_xytheta,
                          scan_cache=inp.out / SCAN_CACHE, executor=inp.executor, workers=inp.workers,
                          progress=inp.progress)
    track = to_pose_track(res)
    # the beam timing the residuals fit, against the rig's (a wrong one leaves a covariance too confident)
    timing_text, timing_z, timing_ok = timing_check(check_recording_timing(
        inp.rec, res, rig, "run", scan_cache=inp.out / SCAN_CACHE))
    # the scanners' registration error is one draw for the whole run; what every pose shares of it (its
    # mean over the run) fusion considers as a bias rather than averaging it away; the part that changes
    # with the pose stays in each pose's covariance
    write_bias_cov(inp.out / "gt_laser_bias.yaml", "GTlaser",
                   {"scanners' calibration": res.cov_calibration_shared})
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
        AccuracyRow("GTlaser", timing_text, timing_z, "sd off the rig's sweep slope", "< 3", timing_ok),
    )
    # the per-frame result (diagnostics, raw fits) stays here: no later stage reads it, and on an hour's
    # recording (~80 MB) it would stand under the scoring's peak and under every later stage's
    prod = {"rig": rig, "laser_report": report, "tracks/GTlaser/run": track}
    outputs = ("gt_laser.tum", "gt_laser_cov.csv", "gt_laser_bias.yaml")
    stamps_s = res.stamps_s
    del res
    if not inp.has_truth:
        return StageOutput(prod, checks=checks, outputs=outputs)
    acc = score_on_recording(track, inp.rec, "run", expected_stamps_s=stamps_s)
    return StageOutput(prod, _accuracy_rows(acc, "run", localized=True), checks, outputs)


def _accuracy_rows(acc: TruthScore, what: str, localized: bool) -> tuple[AccuracyRow, ...]:
    """GTlaser's rows against truth for the track ``what`` names (``run``, ``run on vision's clock``)."""
    pos_mm, yaw_deg = acc.mean_pos_m * 1000, math.degrees(acc.mean_abs_yaw_rad)
    n_wrong = acc.n_pos_over(0.05)
    rows = [AccuracyRow("GTlaser", f"{what}, mean position error", pos_mm, "mm", "<= 5", pos_mm <= 5),
            AccuracyRow("GTlaser", f"{what}, mean |yaw| error", yaw_deg, "deg", "<= 0.1", yaw_deg <= 0.1)]
    if localized:
        rows.append(AccuracyRow("GTlaser", f"{what}, frames localized", 100 * acc.n_scored / max(acc.n_expected, 1),
                                "%"))
    rows += [AccuracyRow("GTlaser", f"{what}, OK frames off by > 5 cm", n_wrong, "", "0", n_wrong == 0),
             AccuracyRow("GTlaser", f"{what}, mean NEES / dof", acc.mean_nees / 3, "", "0.5-2")]
    return tuple(rows)


def gtlaser_clock(inp: StageInput) -> StageOutput:
    """GTlaser fitted again with each scanner's stamps on one clock (gtrig.laser.clock): the offsets the
    sync stage measured (``sync.yaml``: each scanner against GTvision's smoothed track), the track written
    as ``gt_laser_synced.tum`` + ``gt_laser_synced_cov.csv`` (the product ``tracks/GTlaser-synced/run``), with
    its offset to odometry measured on it (:func:`_offset_to_odometry`) as a check. Fusion keeps GTlaser's
    own track and the sync stage's offset for it: fed the synced track instead, the fused track moved by
    -0.023, +0.014 and 0.000 mm on three recordings, a wash, because the
    fused clock is set by the sources' offsets to odometry, which odometry's slip dominates."""
    from gtrig.config import apply_to_dataclass
    from gtrig.io.yamlfile import load_yaml
    from gtrig.laser.clock import clocks_from_sync
    from gtrig.laser.recording import track_recording
    from gtrig.laser.track import TrackSettings, to_pose_track
    from gtrig.memory import release_free_memory

    clock = inp.config.laser.clock
    p = inp.out / "sync.yaml"
    doc = load_yaml(p) if p.is_file() else None
    sources = doc.get("sources") if isinstance(doc, dict) else None
    clocks = clocks_from_sync(sources, clock) if isinstance(sources, dict) else {}
    rig, report = inp.products.rig, inp.products.laser_report
    if clock == "scanners" or not clocks or rig is None or report is None:
        why = ("laser.clock is 'scanners'" if clock == "scanners" else
               f"no scanner offset to {clock}'s clock in sync.yaml" if not clocks else "no scanner calibration")
        return StageOutput(checks=(AccuracyRow("GTlaser", f"track on {clock}'s clock: not made ({why})", math.nan,
                                               "", "made from the scanners' offsets", clock == "scanners"),))
    settings = apply_to_dataclass(inp.config.laser.track, TrackSettings())
    res = track_recording(inp.rec, sequence="run", rig=rig, out_tum=inp.out / "gt_laser_synced.tum",
                          out_cov=inp.out / "gt_laser_synced_cov.csv", settings=settings,
                          scanner_cov=report.cov_xytheta, clocks=clocks, scan_cache=inp.out / SCAN_CACHE,
                          executor=inp.executor, workers=inp.workers, progress=inp.progress)
    track = to_pose_track(res)
    stamps_s = res.stamps_s
    del res  # ~80 MB on an hour's recording, under the offset's and the scoring's peaks otherwise
    # and the tracking's freed heap with it: on an hour this stage's end (the offset's smoothings, the
    # scoring) peaked at 1,077 MB on top of it, the client's highest
    release_free_memory()
    est = _offset_to_odometry(inp, track)
    missing = [s.name for s in rig.laser_scanners if s.name not in clocks]
    checks = (AccuracyRow("GTlaser", f"track on {clock}'s clock: scanners without a measured offset",
                          len(missing), f"of {len(rig.laser_scanners)}", "0", not missing),
              AccuracyRow("sync", f"laser on {clock}'s clock: offset to odometry",
                          math.nan if est is None else 1000 * est, "ms", "", est is not None))
    prod = {"tracks/GTlaser-synced/run": track}
    outputs = ("gt_laser_synced.tum", "gt_laser_synced_cov.csv")
    if not inp.has_truth:
        return StageOutput(prod, checks=checks, outputs=outputs)
    from dataclasses import replace

    from gtrig.evaluate.truth import score_on_recording
    from gtrig.pipeline.truth import true_odometry_offset

    # the truth is on the GT clock; odometry's clock is off it by the simulated robot clock's offset
    shift = -true_odometry_offset(inp.rec) if clock == "odometry" else 0.0
    acc = score_on_recording(replace(track, stamps_s=track.stamps_s - shift), inp.rec, "run",
                             expected_stamps_s=stamps_s - shift)
    return StageOutput(prod, _accuracy_rows(acc, f"run on {clock}'s clock", localized=False), checks, outputs)


def _offset_to_odometry(inp: StageInput, track: PoseTrack) -> float | None:
    """The track's clock offset to odometry, seconds, measured as the sync stage measures a source's
    (heading correlation refined by the fusion's fit, :mod:`gtrig.sync.offset`); None when not ``ok``.
    On GTvision's clock it is another estimate of GTvision's offset (``sync.yaml``, ``vision``), from the
    same odometry."""
    from gtrig.fusion.measurements import fixes_from_track
    from gtrig.io.odometry import read_odometry
    from gtrig.sync.offset import estimate_offset, refine_by_fusion

    p = inp.rec / "run" / "odometry.csv"
    if not p.is_file():
        return None
    odo = read_odometry(p)
    use = track.usable()
    est = estimate_offset(odo.stamps_s, odo.xytheta[:, 2], use.stamps_s, use.yaw_rad(), "laser",
                          search_s=inp.config.fusion.sync_search_s)
    if est.verdict == "ok" and track.cov is not None:
        est = refine_by_fusion(est, fixes_from_track(track, "laser"), odo)
    return float(est.offset_s) if est.verdict == "ok" else None
