"""Calibrate fixed cameras from videos of a hand-held ChArUco board or AprilGrid: each lens, then the network.

The steps: frame times read and checked (:mod:`gtrig.io.video`), the board's corners in every ``step``-th
frame (:mod:`gtrig.calib.video_detect`), each camera's lens from its views
(:func:`gtrig.calib.intrinsics.calibrate_point_sets`) unless lenses are given, the cameras' relative poses
from the instants two or more see the board (:mod:`gtrig.calib.video_network`). :func:`write_video_calibration`
writes ``<cam>.yaml`` per camera and ``network.yaml`` (docs/calibrate-from-video.md).
"""

from __future__ import annotations

import logging
import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from gtrig.calib.idboards import IdBoard
from gtrig.calib.intrinsics import PointSetFit, calibrate_point_sets
from gtrig.calib.video_detect import VideoDetections, detect_videos, find_videos
from gtrig.calib.video_network import RelativePose, VideoNetworkResult, calibrate_video_network, relative_poses
from gtrig.calib.view_jackknife import block_jackknife_std, view_jackknife_std
from gtrig.io.atomic import atomic_group, atomic_write_text
from gtrig.io.camfile import CameraIntrinsics, write_cam_yaml
from gtrig.io.video import CameraVideo

log = logging.getLogger(__name__)

#: a view enters a lens's calibration with this many corners or more
MIN_LENS_CORNERS = 6
#: time blocks of the lens's block jackknife, seconds: about the 0.5-1.5 s over which a hand-held
#: board's views (and a webcam's focus) stay correlated, short enough for 4 or more blocks in a 10 s sweep
LENS_BLOCK_S = 1.0


@dataclass(frozen=True)
class VideoCalibration:
    """Everything :func:`calibrate_from_videos` found.

    Attributes
    ----------
    videos : each camera's video and frame timing.
    detections : each camera's board views.
    lenses : each camera's intrinsics (calibrated here, or as given).
    fits : the lenses calibrated here (empty for the given ones).
    network : the cameras' poses in the reference camera's frame, with covariance.
    pairs : every pair's baseline and relative angle with standard deviations.
    """

    videos: dict[str, CameraVideo]
    detections: dict[str, VideoDetections]
    lenses: dict[str, CameraIntrinsics]
    fits: dict[str, PointSetFit]
    network: VideoNetworkResult
    pairs: tuple[RelativePose, ...]


def fit_lens(det: VideoDetections, board: IdBoard, *, estimate_k3: bool = False) -> PointSetFit:
    """A camera's intrinsics from its views with at least :data:`MIN_LENS_CORNERS` corners.

    The lens's ``extra`` holds OpenCV's ``std``, ``std_views`` (the delete-one-view jackknife) and
    ``std_blocks`` (the delete-one-time-block jackknife, blocks of :data:`LENS_BLOCK_S`;
    :mod:`gtrig.calib.view_jackknife`); ``std_honest`` is the largest of the three per parameter.
    """
    P = board.object_points()
    keep = [k for k, v in enumerate(det.views) if len(v.ids) >= MIN_LENS_CORNERS]
    names = [f"{det.camera}@{det.stamps_s[k]:.3f}s" for k in keep]
    fit = calibrate_point_sets([P[det.views[k].ids] for k in keep], [det.views[k].corners_px for k in keep],
                               names, det.image_size, estimate_k3=estimate_k3)
    idx = [keep[names.index(n)] for n in fit.names]
    obj = [P[det.views[k].ids] for k in idx]
    img = [det.views[k].corners_px for k in idx]
    jk = view_jackknife_std(obj, img, fit.camera, estimate_k3=estimate_k3)
    jb = block_jackknife_std(obj, img, fit.camera, det.stamps_s[idx], LENS_BLOCK_S, estimate_k3=estimate_k3)
    std = fit.camera.extra["std"]
    honest = {k: float(np.nanmax([float(std[k]), jk[k], jb[k]])) for k in std}
    cam = replace(fit.camera, extra={**fit.camera.extra, "std_views": jk, "std_blocks": jb, "std_honest": honest})
    return replace(fit, camera=cam)


def calibrate_from_videos(
    videos_dir: str | os.PathLike[str],
    board: IdBoard,
    *,
    step: int = 1,
    lenses: Mapping[str, CameraIntrinsics] | None = None,
    reference: str | None = None,
    estimate_k3: bool = False,
    mirrored: Sequence[str] = (),
) -> VideoCalibration:
    """Calibrate the cameras whose videos are in ``videos_dir`` (module docstring).

    Parameters
    ----------
    videos_dir : ``<cam>.mp4`` videos with their frame-time files (:func:`gtrig.calib.video_detect.find_videos`).
    board : the ChArUco board or AprilGrid (its corners found by its own detector).
    step : read every ``step``-th frame.
    lenses : intrinsics to hold instead of calibrating them, by camera name (all or some).
    reference : the camera whose frame is the world (default: the first by name).
    mirrored : cameras whose videos are left-right mirrored (a webcam's mirror mode).
    """
    vids = {v.camera: v for v in find_videos(videos_dir)}
    dets = detect_videos(list(vids.values()), board, step, mirrored)
    given = dict(lenses or {})
    fits = {c: fit_lens(d, board, estimate_k3=estimate_k3) for c, d in dets.items() if c not in given}
    cams = {c: given[c] if c in given else fits[c].camera for c in dets}
    net = calibrate_video_network(dets, cams, board, reference)
    return VideoCalibration(vids, dets, cams, fits, net, tuple(relative_poses(net)))


def network_document(cal: VideoCalibration) -> dict[str, Any]:
    """``network.yaml``: the reference, each camera's pose and sigmas, the pairs, the frames' timing."""
    net = cal.network
    sig = np.sqrt(np.clip(np.diag(net.cov), 0, None))
    cams: dict[str, Any] = {}
    for c, T in net.T_ref_cam.items():
        d: dict[str, Any] = {"T_ref_cam": np.round(T, 9).tolist(), "rms_px": round(net.rms_px.get(c, float("nan")), 4)}
        if c in net.order:
            k = 6 * net.order.index(c)
            d["sigma_rot_deg"] = np.round(np.degrees(sig[k: k + 3]), 4).tolist()
            d["sigma_pos_mm"] = np.round(1000 * sig[k + 3: k + 6], 3).tolist()
        v, det = cal.videos[c], cal.detections[c]
        d["frames"] = {"stamped": len(v), "read": det.n_frames_read, "with_board": len(det.views),
                       "frames_per_s": round(1.0 / v.timing.period_s, 4), "dropped": v.timing.n_dropped,
                       "duplicated": v.timing.n_duplicated}
        cams[c] = d
    pairs = [{"cameras": [p.cam_a, p.cam_b], "baseline_mm": round(1000 * p.baseline_m, 2),
              "sigma_baseline_mm": round(1000 * p.sigma_baseline_m, 2), "angle_deg": round(p.angle_deg, 3),
              "sigma_angle_deg": round(p.sigma_angle_deg, 3)} for p in cal.pairs]
    return {"reference": net.reference, "rms_px": round(net.rms_px_all, 4), "instants": net.n_instants,
            "corners": net.n_corners, "cameras": cams, "pairs": pairs}


def write_video_calibration(out_dir: str | os.PathLike[str], cal: VideoCalibration) -> list[Path]:
    """Write ``<cam>.yaml`` per camera and ``network.yaml`` into ``out_dir`` as one atomic group."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    paths = [out / f"{c}.yaml" for c in cal.lenses] + [out / "network.yaml"]
    with atomic_group(*paths) as tmp:
        for p, (_c, lens) in zip(tmp, cal.lenses.items(), strict=False):
            write_cam_yaml(p, lens)
        atomic_write_text(tmp[-1], yaml.safe_dump(network_document(cal), sort_keys=False, default_flow_style=None))
    return paths
