"""Stages ``sync`` and ``fusion``: each GT source's clock offset to odometry (gtrig.sync.offset), then one
smoothed trajectory from GTvision, GTlaser and odometry (gtrig.fusion), written as the pose track
``gt_fused.tum`` + ``gt_fused_cov.csv`` with ``fusion_report.json`` and ``sync.yaml``."""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import TYPE_CHECKING

from gtrig.pipeline.context import AccuracyRow, StageInput, StageOutput
from gtrig.pipeline.truth import true_odometry_offset

if TYPE_CHECKING:
    from gtrig.io.odometry import OdometryLog
    from gtrig.trajectory import PoseTrack

#: the GT sources fusion takes, by their name in the fusion's report
SOURCES = {"vision": "GTvision/run", "laser": "GTlaser/run"}


def _sources(inp: StageInput) -> dict[str, PoseTrack]:
    return {name: inp.products.tracks[key] for name, key in SOURCES.items() if key in inp.products.tracks}


def _odometry(rec: Path) -> OdometryLog:
    from gtrig.io.odometry import read_odometry

    return read_odometry(rec / "run" / "odometry.csv")


def sync(inp: StageInput) -> StageOutput:
    """Clock offsets of the GT sources to odometry, each with its 95 % interval and verdict."""
    from gtrig.errors import InputError
    from gtrig.fusion.measurements import fixes_from_track
    from gtrig.io.offsets import write_offsets
    from gtrig.memory import release_free_memory
    from gtrig.sync.offset import combine_with_laser_clock, estimate_offset, refine_by_fusion
    from gtrig.sync.sensors import to_reference

    cfg = inp.config.fusion
    tracks = _sources(inp)
    if not tracks:
        raise InputError("sync needs GTvision's or GTlaser's run track")
    odo = _odometry(inp.rec)
    results = {}
    for name, track in tracks.items():
        use = track.usable()
        est = estimate_offset(odo.stamps_s, odo.xytheta[:, 2], use.stamps_s, use.yaw_rad(), name,
                              search_s=cfg.sync_search_s)
        if track.cov is not None and est.verdict == "ok":
            est = refine_by_fusion(est, fixes_from_track(track, name), odo)
        results[name] = est
    release_free_memory()  # the refinements' smoothings, before the per-sensor fits allocate theirs
    sensors, clock = _sensor_offsets(inp, tracks, results, odo) if cfg.sync_per_sensor else ([], (math.nan, math.nan))
    if "vision" in results and "laser" in results:
        # one offset for the GT system: the two sources' estimates made consistent with GTlaser's clock
        # to GTvision's (the scanners'), far better known than either offset to odometry
        results["vision"], results["laser"] = combine_with_laser_clock(results["vision"], results["laser"], *clock)
    doc = {k: v.to_dict() for k, v in results.items()}
    for e in sensors:
        doc[e.source] = to_reference(e, results["vision"])
    write_offsets(inp.out / "sync.yaml", "odometry", doc)
    offsets = {k: float(v.offset_s) for k, v in results.items() if v.verdict == "ok"}
    checks = tuple(AccuracyRow("sync", f"{k} clock offset to odometry ({v.verdict})",
                               1000 * v.offset_s if v.verdict == "ok" else math.nan, "ms",
                               "verdict ok (docs/sync.md)", v.verdict == "ok")
                   for k, v in results.items())
    checks += tuple(AccuracyRow("sync", f"{e.source} clock offset to GTvision's ({e.verdict})",
                                1000 * e.offset_s if e.verdict == "ok" else math.nan, "ms") for e in sensors)
    rows: tuple[AccuracyRow, ...] = ()
    if inp.has_truth:
        true_s = true_odometry_offset(inp.rec)
        # the sources' own clocks (cameras', scanners') carry small offsets too: informational, no target
        rows = tuple(AccuracyRow("sync", f"{k}: offset minus the simulated odometry clock's",
                                 1000 * abs(offsets[k] - true_s), "ms") for k in offsets)
        rows += _sensor_truth_rows(inp.rec, sensors)
    return StageOutput({"clock_offsets": offsets}, rows, checks, ("sync.yaml",))


def _sensor_offsets(inp: StageInput, tracks: dict[str, PoseTrack], results: dict, odo: OdometryLog,  # noqa: ANN001
                    ) -> tuple[list, tuple[float, float]]:
    """Each camera's and scanner's offset to GTvision's clock, when both GT sources and the scanners exist,
    and GTlaser's clock to GTvision's with its sigma (nan when not measured)."""
    from gtrig.pipeline.cache import SCAN_CACHE
    from gtrig.sync.sensors import sensor_offsets_and_laser_clock

    none: tuple[list, tuple[float, float]] = ([], (math.nan, math.nan))
    rig = inp.products.rig
    if rig is None or "vision" not in tracks or "laser" not in tracks or rig.robot.hull is None:
        return none
    if not rig.laser_scanners or "vision" not in results:
        return none
    ck = inp.out / "gt_vision_run.checkpoint"  # GTvision's detections: which camera made each pose
    vis = results["vision"]
    return sensor_offsets_and_laser_clock(inp.rec, rig, tracks["vision"], tracks["laser"],
                                          checkpoint=ck if ck.is_file() else None, odometry=odo,
                                          odometry_offset_s=vis.offset_s if vis.verdict == "ok" else math.nan,
                                          scan_cache=inp.out / SCAN_CACHE)  # GTlaser's parsed logs


def _sensor_truth_rows(rec: Path, sensors: list) -> tuple[AccuracyRow, ...]:  # noqa: ANN001
    """|estimate - truth| of each camera's (truth 0: the simulated cameras are on the GT clock, with
    per-frame jitter) and scanner's (truth/laser_clocks.yaml) offset to GTvision's clock, target 1 ms."""
    from gtrig.io.yamlfile import load_yaml

    p = rec / "truth" / "laser_clocks.yaml"
    doc = load_yaml(p) if p.is_file() else {}
    scan = ((doc or {}).get("run") or {}).get("clock_offsets_s") or {}
    rows = []
    for e in sensors:
        kind, name = e.source.split("/", 1)
        if e.verdict != "ok" or (kind == "laser" and name not in scan):
            continue
        err = 1000 * abs(e.offset_s - (float(scan[name]) if kind == "laser" else 0.0))
        rows.append(AccuracyRow("sync", f"{e.source}: offset to GTvision's minus the simulated one", err, "ms",
                                "<= 1", err <= 1.0))
    return tuple(rows)


#: each source's run-constant error, as its stage writes it beside the track (gtrig.io.biascov)
BIAS_FILES = {"vision": "gt_vision_run_bias.yaml", "laser": "gt_laser_bias.yaml"}


def _bias_covs(out: Path, tracks: dict[str, PoseTrack]) -> dict:
    """Per source fused, its run-constant error's covariance when its stage wrote one (none: nothing)."""
    from gtrig.io.biascov import read_bias_cov

    return {k: read_bias_cov(out / BIAS_FILES[k]) for k in tracks if (out / BIAS_FILES[k]).is_file()}


def fusion(inp: StageInput) -> StageOutput:
    """GTvision and GTlaser smoothed with odometry: one pose per odometry stamp, bridged poses flagged."""
    from gtrig.errors import InputError
    from gtrig.evaluate.truth import score_track
    from gtrig.fusion import FusionOptions, fuse_tracks
    from gtrig.io.posetrack import write_pose_track
    from gtrig.io.tum import read_tum
    from gtrig.sync.offset import offset_sigmas

    cfg = inp.config.fusion
    tracks = _sources(inp)
    if not tracks:
        raise InputError("fusion needs GTvision's or GTlaser's run track")
    offsets = dict(inp.products.clock_offsets or {})
    # the offsets' intervals (sync.yaml, written by the sync stage beside): the fused poses are stamped on
    # the odometry's clock, so an offset's uncertainty is the poses' along-track uncertainty
    sync_yaml = inp.out / "sync.yaml"
    sigmas = offset_sigmas(sync_yaml) if offsets and sync_yaml.is_file() else {}
    opts = FusionOptions(estimator=cfg.estimator, max_gap_s=cfg.max_gap_s, offsets_s=offsets,
                         offsets_sigma_s={k: v for k, v in sigmas.items() if k in offsets},
                         bias_cov=_bias_covs(inp.out, tracks))
    fused, report = fuse_tracks(tracks, _odometry(inp.rec), opts)
    names = ("gt_fused.tum", "gt_fused_cov.csv", "fusion_report.json")
    report_text = json.dumps(report.to_dict(), indent=1, default=float) + "\n"
    write_pose_track(fused, inp.out / names[0], inp.out / names[1], extra={inp.out / names[2]: report_text})
    counts = fused.counts()
    n_out = len(report.outliers)
    checks = (
        AccuracyRow("fusion", "poses", len(fused), ""),
        AccuracyRow("fusion", "poses bridged by odometry", 100 * counts["bridged"] / max(len(fused), 1), "%"),
        AccuracyRow("fusion", "fixes rejected or down-weighted", n_out, ""),
        AccuracyRow("fusion", "odometry jumps (each a new odometry segment)", len(report.odometry_jumps_s), ""),
    )
    prod = {"tracks/fusion/run": fused}
    if not inp.has_truth:
        return StageOutput(prod, checks=checks, outputs=names)
    # the truth read once for the three scores: each reading of an hour's (700,000 poses) left ~130 MB more
    # in the heap under the next
    truth = read_tum(inp.rec / "truth" / "run.tum")
    acc = score_track(fused, truth)
    pos_mm, yaw_deg = acc.mean_pos_m * 1000, math.degrees(acc.mean_abs_yaw_rad)
    rows = [
        AccuracyRow("fusion", "run, mean position error", pos_mm, "mm", "<= 1.0", pos_mm <= 1.0),
        AccuracyRow("fusion", "run, max position error", acc.max_pos_m * 1000, "mm"),
        AccuracyRow("fusion", "run, mean |yaw| error", yaw_deg, "deg", "<= 0.05", yaw_deg <= 0.05),
        AccuracyRow("fusion", "run, mean NEES / dof", acc.mean_nees / acc.nees_dof, "", "0.5-2",
                    0.5 <= acc.mean_nees / acc.nees_dof <= 2),
    ]
    for name, track in tracks.items():
        single = score_track(track.usable(), truth)
        rows.append(AccuracyRow("fusion", f"run, mean position error / {name}'s", pos_mm / max(
            single.mean_pos_m * 1000, 1e-9), "x", "< 1", pos_mm < single.mean_pos_m * 1000))
    return StageOutput(prod, tuple(rows), checks, names)
