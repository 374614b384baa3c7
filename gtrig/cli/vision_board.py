"""``gtrig vision --board``: a ChArUco board tracked in 6-DoF through the videos of calibrated fixed cameras."""

from __future__ import annotations

import math
from collections.abc import Mapping
from pathlib import Path
from typing import TYPE_CHECKING

from gtrig.cli.common import console

if TYPE_CHECKING:
    from gtrig.vision.body import BodyOptions
    from gtrig.vision.body_track import BodyTrack
    from gtrig.vision.observations import CameraGeometry


def run(board: Path, videos: Path, cameras: Path, out: Path, covariance: Path | None, step: int,
        sigma_px: float, line_delay: bool = False, drift: bool = False, timing_windows: int = 0) -> None:
    """Track the board, write its poses (TUM, ``T_world_board``) and covariances, print the shape check and
    the cameras' time offsets (and drifts, line delays) from the board's motion, with the halves check."""
    from gtrig.calib.charuco import read_board_file
    from gtrig.calib.video_detect import detect_videos, find_videos
    from gtrig.cli import checks
    from gtrig.io.posetrack import write_pose_track
    from gtrig.vision.board_video import board_body, board_instants, read_cameras
    from gtrig.vision.body import BodyOptions
    from gtrig.vision.body_shape import check_shape
    from gtrig.vision.body_track import track_body

    checks.input_folder("--videos", videos)
    checks.count("--step", step, lo=1, hi=1000)
    checks.number("--sigma-px", sigma_px, lo=0.0, lo_open=True, hi=100.0, unit="px")
    checks.count("--timing-windows", timing_windows, lo=0, hi=100)
    checks.outputs([board, cameras], [out, covariance])
    b = read_board_file(board)
    cams = read_cameras(cameras)
    dets = detect_videos(find_videos(videos), b, step)
    missing = sorted(set(dets) - set(cams))
    if missing:
        from gtrig.errors import InputError

        raise InputError(f"{cameras}: no calibration of camera(s) {', '.join(missing)}")
    track = track_body(cams, board_body(b), board_instants(dets), BodyOptions(sigma_px=sigma_px))
    write_pose_track(track.to_pose_track(), out, covariance)
    ok = [p for p in track.poses if p.ok]
    sc = check_shape(cams, track, b.square_m, sigma_px)
    mm, pct = 1000.0, 100.0 / b.square_m
    console.print(f"{out}: board tracked at {len(ok)} of {len(track.poses)} instants ({b.spec()}); covariances "
                  f"scaled by {track.variance_factor:.2f} (camera-split NEES/dof {sc.split_nees:.2f} over "
                  f"{len(track.split_nees)} pairs)", highlight=False)
    console.print(f"  from the tracked poses: square {mm * (b.square_m + sc.pose_edge_mean_m):.3f} mm "
                  f"({pct * sc.pose_edge_mean_m:+.2f} %), edge RMS error {mm * sc.pose_edge_rms_m:.3f} mm, "
                  f"flatness RMS {mm * sc.pose_plane_rms_m:.3f} mm over {sc.pose_points} corners", highlight=False)
    console.print(f"  triangulated per instant: square {mm * (b.square_m + sc.tri_edge_mean_m):.3f} mm "
                  f"({pct * sc.tri_edge_mean_m:+.2f} %), edge RMS error {mm * sc.tri_edge_rms_m:.3f} mm over "
                  f"{sc.tri_edges} edges, flatness RMS {mm * sc.tri_plane_rms_m:.3f} mm over {sc.tri_instants} "
                  f"instants; rigidity NEES/dof {sc.rigidity_nees:.2f}", highlight=False)
    _print_timing(cams, track, BodyOptions(sigma_px=sigma_px), line_delay, drift)
    if timing_windows:
        _print_windows(cams, track, BodyOptions(sigma_px=sigma_px), timing_windows)


def _print_timing(cams: Mapping[str, CameraGeometry], track: BodyTrack, options: BodyOptions, line_delay: bool,
                  drift: bool) -> None:
    """Print each camera's offset (at the recording's midpoint and its drift with ``drift``; line delay with
    ``line_delay``), 95 % intervals, then how well the recording's halves agree on them."""
    from gtrig.vision.body_timing import estimate_timing
    from gtrig.vision.body_timing_halves import timing_halves

    args = (cams, track.body, track.instants, track.poses)
    tm = estimate_timing(*args, line_delay=line_delay, drift=drift, options=options)
    what = " and line delays" if line_delay else ""
    where = (f" at the recording's midpoint ({tm.mid_s:.2f} s on the frame times) and their drifts" if drift
             else "")
    console.print(f"  time offsets{where} from the board's motion ({tm.instants} instants, 95 % intervals; residual "
                  f"RMS {tm.rms_px['stamps']:.3f} px with the frame times, {tm.rms_px['model']:.3f} px with the "
                  f"offsets{' and drifts' if drift else ''}{what}):", highlight=False)
    for k, c in enumerate(tm.cameras):
        text = ("reference" if c == tm.reference
                else f"{1000 * tm.offset_s[k]:+.1f} ± {1960 * tm.sigma_offset_s[k]:.1f} ms"
                if math.isfinite(tm.sigma_offset_s[k]) else "not determined")
        if drift and c != tm.reference and math.isfinite(tm.sigma_drift_s_per_s[k]):
            text += (f", drift {1000 * tm.drift_s_per_s[k]:+.2f} ± {1960 * tm.sigma_drift_s_per_s[k]:.2f} ms/s "
                     f"({1e6 * tm.drift_s_per_s[k]:+.0f} ± {1.96e6 * tm.sigma_drift_s_per_s[k]:.0f} ppm)")
        if line_delay:
            text += f", line delay {1e6 * tm.line_delay_s[k]:+.1f} ± {1.96e6 * tm.sigma_line_delay_s[k]:.1f} us/row"
        console.print(f"    {c}: {text}", highlight=False)
    h = timing_halves(*args, line_delay=line_delay, drift=drift, options=options)
    others = [k for k, c in enumerate(tm.cameras) if c != tm.reference]
    cams_txt = ", ".join(tm.cameras[k] for k in others)
    which = "offsets at the midpoint" if drift else "offsets"
    ratios = ", ".join(_ratio_text(h.offset_ratio[k]) for k in others)
    text = f"  halves (before and after the midpoint, fitted apart): {which} of {cams_txt} differ by {ratios}"
    if drift:
        text += f", drifts by {', '.join(_ratio_text(h.drift_ratio[k]) for k in others)}"
    console.print(text + " of their combined 95 % intervals (above 1: the model does not hold over the recording)",
                  highlight=False)


def _ratio_text(r: float) -> str:
    """A halves ratio, or "-" where a half does not determine it."""
    return f"{r:.2f}" if math.isfinite(r) else "-"


def _print_windows(cams: Mapping[str, CameraGeometry], track: BodyTrack, options: BodyOptions, parts: int) -> None:
    """Print the constant offsets of ``parts`` equal spans of the recording, each fitted apart: the offsets
    against time."""
    from gtrig.vision.body_timing_halves import timing_windows

    fits = timing_windows(cams, track.body, track.instants, track.poses, parts=parts, options=options)
    console.print(f"  offsets in {parts} equal spans of the recording, each fitted apart (95 % intervals):",
                  highlight=False)
    for tm in fits:
        if not tm.instants:
            continue
        text = "; ".join(f"{c} {1000 * o:+.1f} ± {1960 * s:.1f} ms" if math.isfinite(s) else f"{c} not seen"
                         for c, o, s in zip(tm.cameras, tm.offset_s, tm.sigma_offset_s, strict=True)
                         if c != tm.reference)
        console.print(f"    {tm.span_s[0] - tm.mid_s:+.2f} to {tm.span_s[1] - tm.mid_s:+.2f} s from the midpoint "
                      f"({tm.instants} instants): {text}", highlight=False)
