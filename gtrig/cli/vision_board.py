"""``gtrig vision --board``: a ChArUco board tracked in 6-DoF through the videos of calibrated fixed cameras."""

from __future__ import annotations

from pathlib import Path

from gtrig.cli.common import console


def run(board: Path, videos: Path, cameras: Path, out: Path, covariance: Path | None, step: int,
        sigma_px: float, line_delay: bool = False) -> None:
    """Track the board, write its poses (TUM, ``T_world_board``) and covariances, print the shape check and
    the cameras' time offsets (and line delays) from the board's motion."""
    from gtrig.calib.charuco import read_board_file
    from gtrig.calib.video_detect import detect_videos, find_videos
    from gtrig.cli import checks
    from gtrig.io.posetrack import write_pose_track
    from gtrig.vision.board_video import board_body, board_instants, read_cameras
    from gtrig.vision.body import BodyOptions
    from gtrig.vision.body_shape import check_shape
    from gtrig.vision.body_timing import estimate_timing
    from gtrig.vision.body_track import track_body

    checks.input_folder("--videos", videos)
    checks.count("--step", step, lo=1, hi=1000)
    checks.number("--sigma-px", sigma_px, lo=0.0, lo_open=True, hi=100.0, unit="px")
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
    tm = estimate_timing(cams, track.body, track.instants, track.poses, line_delay=line_delay,
                         options=BodyOptions(sigma_px=sigma_px))
    console.print(f"  time offsets from the board's motion ({tm.instants} instants, 95 % intervals; residual RMS "
                  f"{tm.rms_px['stamps']:.3f} px with the frame times, {tm.rms_px['model']:.3f} px with the offsets"
                  f"{' and line delays' if line_delay else ''}):", highlight=False)
    for k, c in enumerate(tm.cameras):
        text = ("reference" if c == tm.reference
                else f"{1000 * tm.offset_s[k]:+.1f} ± {1960 * tm.sigma_offset_s[k]:.1f} ms")
        if line_delay:
            text += f", line delay {1e6 * tm.line_delay_s[k]:+.1f} ± {1.96e6 * tm.sigma_line_delay_s[k]:.1f} us/row"
        console.print(f"    {c}: {text}", highlight=False)
