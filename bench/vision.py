"""GTvision benchmark: our joint estimate against the seeds' method, side by side, on the simulated GT room.

Levels
------
``corners``: synthetic corners (true corners through the true cameras plus Gaussian noise of known
    covariance), estimated with a "calibrated" rig: the true rig with every camera and marker pose
    perturbed by the sigmas GTvision is told (RigUncertainty). Static validation intervals of 1 s
    (10 images per camera), and the continuous run (one instant per camera image).
``images``: a small recording rendered with :func:`gtrig.vision.synthetic.render_markers` (not the
    simulator's renderer), detected with the available detector, through :func:`run_recording`.
``recording``: a full simulated recording (``gtrig sim``) and its calibrated rig, both sequences,
    exactly as ``gtrig vision`` runs them; accuracy against the recording's truth, the run's frames
    with a fully visible marker that were localized, the seeds' method on the same detections and on
    OpenCV's ArUco subpixel corners (as the seeds ran it), and
    the throughput (images of 1024 x 768 per second, reading, detection, noise calibration and
    estimation included). This is the acceptance measurement.
``tracking``: one sequence of a full simulated recording (``--sequence``, default run) with the markers
    tracked from image to image (:mod:`gtrig.vision.track`) and with every image searched whole, in the same
    run: the whole GTvision stage's images per second (reading, detection, noise calibration, estimation;
    wall, and CPU per image, this process's and its workers', a figure a loaded machine disturbs less,
    split into reading, detection and estimation, with the images per second that CPU allows on the
    workers' cores with and without the reading: an 8-bit 1024 x 768 PNG costs about 2 ms to decode
    through :mod:`gtrig.io.png`, 6 ms through OpenCV),
    the localized share and the accuracy against the truth of both, beside OpenCV's bare whole-image
    detection of the same images (``cv2.aruco.ArucoDetector`` with its default parameters and threads, a
    dictionary of the rig's markers; reading not counted). With ``--split``, the tracked detection pass again
    in this process, its CPU split by part (reading, the change test, OpenCV's candidates, the edge fits, ID
    verification, corners and covariances to raw pixels, markers cut by the image's edge, lens maps, the
    rest: tracking, windows, crops, duplicates and records).

``consistency``: the validation poses rendered by the test renderer at three grey-level noises and two
    blurs, the rig stated exactly (sigmas 1e-6): NEES/dof with 95 % intervals in 6-DoF and planar, the
    corner variance factors the recording's residuals gave, each axis's mean squared z-score and the stops
    left with one marker view.

Usage: ``python bench/vision.py [--seeds 0 1 2] [--level corners images] [--workers 2]``;
``python bench/vision.py --level consistency --seeds 0 [--noise-grey 0.5 1.5 4] [--blur-px 0.5 1.5]
[--stop-images 2] [--corner-floor-px 0.1]``;
``python bench/vision.py --level recording --recording REC --rig REC_OUT/rig.calibrated.yaml --workers 2``;
``python bench/vision.py --level tracking --recording REC --rig RIG --workers 2 [--sequence run] [--split]``
"""

from __future__ import annotations

import argparse
import csv
import math
import os
import tempfile
import time
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from gtrig import geometry as geo
from gtrig.io.frames import write_frame_index
from gtrig.io.tum import Trajectory
from gtrig.rig.models import Pose, Rig
from gtrig.sim.gtroom import VALIDATION_POSES, continuous_path, make_scene
from gtrig.vision.baseline import as_rigid, seeds_frame_pose
from gtrig.vision.covariance import PLANAR_INDEX, RigUncertainty, nees, pose_error_xi
from gtrig.vision.estimate import VisionOptions, estimate_frame
from gtrig.vision.observations import FrameObservations, VisionModel
from gtrig.vision.synthetic import CornerNoise, render_markers, synthetic_observations, visible_views


def perturbed_rig(rig: Rig, ru: RigUncertainty, rng: np.random.Generator) -> Rig:
    cams = tuple(c.model_copy(update={"T_world_cam": Pose.from_matrix(
        geo.T_from_xyz_rpy(rng.normal(0, ru.camera_xyz_m, 3), np.zeros(3)) @ c.T_world_cam.matrix()
        @ geo.T_from_xyz_rpy(np.zeros(3), rng.normal(0, ru.camera_rot_rad, 3)))}) for c in rig.cameras)
    mks = tuple(m.model_copy(update={"T_robot_marker": Pose.from_matrix(
        m.T_robot_marker.matrix() @ geo.T_from_xyz_rpy(rng.normal(0, ru.marker_xyz_m, 3),
                                                       rng.normal(0, ru.marker_rot_rad, 3)))})
        for m in rig.robot.markers)
    return rig.model_copy(update={"cameras": cams, "robot": rig.robot.model_copy(update={"markers": mks})})


def _errors(T_est: np.ndarray, T_true: np.ndarray) -> tuple[float, float]:
    e = pose_error_xi(as_rigid(T_est), T_true)
    yaw = abs(float(geo.wrap_angle(geo.T_to_se2(T_est)[2] - geo.T_to_se2(T_true)[2])))
    return float(np.linalg.norm(e[:2])), yaw


def _row(name: str, pos: list[float], yaw: list[float], n_ok: int, n: int, ne: list[float] | None) -> str:
    p = np.array(pos) * 100
    ne_s = f"{np.mean(ne):6.2f}" if ne else "     -"
    return (f"| {name:<28} | {p.mean():6.2f} | {p.max():6.2f} | {np.degrees(np.mean(yaw)):7.3f} | "
            f"{n_ok:3d}/{n:<3d} | {ne_s} |")


HEADER = ("| method                       | mean cm | max cm | |yaw| deg | localized | NEES |\n"
          "|------------------------------|--------:|-------:|---------:|----------:|-----:|")


def bench_corners(seeds: list[int], noise_px: float) -> None:
    ru = RigUncertainty()
    noise = CornerNoise(sigma_px=noise_px)
    acc: dict[str, tuple[list[float], list[float], list[int], list[float]]] = {
        k: ([], [], [0, 0], []) for k in ("gtvision planar", "gtvision 6-DoF", "seeds")}
    run_vis = run_ok = 0
    t_est = 0.0
    n_est = 0
    for seed in seeds:
        scene = make_scene(seed)
        rng = np.random.default_rng(1000 + seed)
        model = VisionModel.from_rig(perturbed_rig(scene.rig_true, ru, rng))
        for k, p in enumerate(VALIDATION_POSES):
            T = scene.T_world_robot(*p)
            views = []
            for f in range(10):  # 1 s at 10 Hz, every camera
                o = synthetic_observations(scene.rig_true, T, k, rng, noise)
                views.extend(replace(v, frame=f) for v in o.views)
            obs = FrameObservations(float(k), tuple(views))
            for name, planar in (("gtvision planar", True), ("gtvision 6-DoF", False)):
                est = estimate_frame(model, obs, VisionOptions(planar=planar, rig_uncertainty=ru,
                                                               corner_floor_px=0.0))
                a = acc[name]
                a[2][1] += 1
                if est.ok:
                    a[2][0] += 1
                    pe, ye = _errors(est.T_world_robot, T)
                    a[0].append(pe)
                    a[1].append(ye)
                    err = pose_error_xi(est.T_world_robot, T)
                    i = np.array(PLANAR_INDEX) if planar else np.arange(6)
                    a[3].append(nees(err[i], est.cov_6x6[np.ix_(i, i)]))
            Ts = seeds_frame_pose(model, obs)
            a = acc["seeds"]
            a[2][1] += 1
            if Ts is not None:
                a[2][0] += 1
                pe, ye = _errors(Ts, T)
                a[0].append(pe)
                a[1].append(ye)
        # the run: one instant per camera image, 10 Hz
        _, xyth = continuous_path(rate_hz=10.0)
        for i, p in enumerate(xyth[::2]):
            T = scene.T_world_robot(*p)
            for cam in scene.rig_true.cameras:
                o = synthetic_observations(scene.rig_true, T, float(i), rng, noise, cameras=(cam.name,))
                if not o.views:
                    continue
                run_vis += 1
                t0 = time.process_time()
                est = estimate_frame(model, o, VisionOptions(planar=True, rig_uncertainty=ru, corner_floor_px=0.0))
                t_est += time.process_time() - t0
                n_est += 1
                run_ok += est.ok
    print(f"\n### Synthetic corners (sigma {noise_px} px), seeds {seeds}, calibrated-rig emulation "
          f"(cameras {ru.camera_xyz_m * 1e3:g} mm / {math.degrees(ru.camera_rot_rad):g} deg, markers "
          f"{ru.marker_xyz_m * 1e3:g} mm / {math.degrees(ru.marker_rot_rad):g} deg)\n")
    print("Static validation poses (26 per seed), 10 images per camera each:\n")
    print(HEADER)
    for name, (pos, yaw, (n_ok, n), ne) in acc.items():
        print(_row(name, pos, yaw, n_ok, n, ne if ne else None))
    dof = {"gtvision planar": 3, "gtvision 6-DoF": 6}
    print("\nNEES / dof: " + ", ".join(f"{k} {np.mean(v[3]) / dof[k]:.2f}" for k, v in acc.items() if v[3]))
    print(f"\nRun: {run_ok}/{run_vis} camera images with a fully visible marker localized "
          f"({100 * run_ok / max(run_vis, 1):.2f} %); estimation {1e3 * t_est / max(n_est, 1):.2f} ms CPU "
          "per image with markers (planar)")


def bench_images(seed: int, workers: int, frames: int) -> None:
    from gtrig.io.tum import read_tum, write_tum
    from gtrig.vision.report import accuracy
    from gtrig.vision.sequence import run_recording

    scene = make_scene(seed)
    rig = scene.rig_true  # rendered with the truth; the estimate uses the same (no calibration error here)
    rng = np.random.default_rng(seed)
    with tempfile.TemporaryDirectory() as d:
        rec = Path(d)
        Ts = [scene.T_world_robot(*p) for p in VALIDATION_POSES]
        t_render = time.perf_counter()
        intervals = [(10.0 * i, 10.0 * i + 1.0) for i in range(len(Ts))]
        n_img = 0
        for cam in rig.cameras:
            folder = rec / "validation" / "cameras" / cam.name
            folder.mkdir(parents=True)
            stamps, files = [], []
            for T, (t0, _) in zip(Ts, intervals, strict=True):
                seen = any(c == cam.name for c, _, _ in visible_views(rig, T))
                for f in range(frames):
                    name = f"{len(files):06d}.png"
                    img = render_markers(rig, cam.name, T, rng) if seen else \
                        np.clip(rng.normal(90, 1.5, (768, 1024)), 0, 255).astype(np.uint8)
                    cv2.imwrite(str(folder / name), img, [cv2.IMWRITE_PNG_COMPRESSION, 1])
                    stamps.append(t0 + 0.05 + 0.1 * f)
                    files.append(name)
                    n_img += 1
            write_frame_index(folder, np.array(stamps), files)
        with open(rec / "validation" / "poses.csv", "w", newline="") as f:
            w = csv.writer(f)
            w.writerow(["pose", "start_s", "end_s"])
            w.writerows([i + 1, a, b] for i, (a, b) in enumerate(intervals))
        write_tum(rec / "validation.tum", Trajectory.from_matrices(
            np.array([0.5 * (a + b) for a, b in intervals]), np.stack(Ts)))
        t_render = time.perf_counter() - t_render
        res = run_recording(rec, rig, "validation", planar=True, workers=workers)
        acc = accuracy(res, read_tum(rec / "validation.tum"))
        model = VisionModel.from_rig(rig)
        seeds_pos, seeds_yaw, seeds_ok = [], [], 0
        for o, T in zip(res.observations, Ts, strict=True):
            Tsd = seeds_frame_pose(model, o)
            if Tsd is not None:
                seeds_ok += 1
                pe, ye = _errors(Tsd, T)
                seeds_pos.append(pe)
                seeds_yaw.append(ye)
        print(f"\n### Rendered images (test renderer), seed {seed}, {frames} images per camera per pose, "
              f"detector {res.detector}, true rig\n")
        print(HEADER)
        print(f"| {'gtvision planar':<28} | {100 * acc.pos_err_mean_m:6.2f} | "
              f"{100 * acc.pos_err_max_m:6.2f} | "
              f"{math.degrees(acc.yaw_err_mean_rad):7.3f} | {acc.localized:3d}/{acc.instants:<3d} | "
              f"{acc.nees_mean:6.2f} |")
        print(_row("seeds (same corners)", seeds_pos, seeds_yaw, seeds_ok, len(Ts), None))
        t = res.seconds["total"]
        print(f"\nthroughput: {n_img} images of 1024 x 768 in {t:.1f} s with {workers or 'all'} worker(s): "
              f"{n_img / t:.1f} images/s, reading, detection, noise calibration and estimation included "
              f"(rendering took {t_render:.0f} s, not counted)")


def bench_recording(rec: Path, rig_path: Path, workers: int) -> None:
    from gtrig.io.tum import read_tum
    from gtrig.rig import load_rig
    from gtrig.vision.covariance import hand_placement_frame_covariance
    from gtrig.vision.report import accuracy_on_recording, interpolate_truth, summarize
    from gtrig.vision.sequence import run_recording, with_robot_frame_uncertainty

    rig = load_rig(rig_path)
    model = VisionModel.from_rig(rig)
    # the markers' common frame error comes with a calibrated rig (robot.markers_frame_cov, which
    # run_recording adds); an older rig: the dima-marker's (14) hand placement, as gtrig.pipeline had it
    cov_frame = None if rig.robot.markers_frame_cov is not None else hand_placement_frame_covariance(
        rig.marker(14).T_robot_marker.matrix())
    print(f"\n### {rec} (rig {rig_path}), {workers or 'all'} worker(s)\n")
    if cov_frame is None:
        print("(the rig's markers were tied to the survey at these validation stops: the validation rows\n"
              "are not an independent check; gtrig.pipeline checks each stop in the frame of the others)\n")
    print(HEADER)
    lines = []
    for seq in ("validation", "run"):
        res = run_recording(rec, rig, seq, planar=True, workers=workers)
        if cov_frame is not None:
            res = with_robot_frame_uncertainty(res, cov_frame)
        acc = accuracy_on_recording(res, rec)
        rep = summarize(res)
        print(f"| {'gtvision planar, ' + seq:<28} | {100 * acc.pos_err_mean_m:6.2f} | "
              f"{100 * acc.pos_err_max_m:6.2f} | {math.degrees(acc.yaw_err_mean_rad):7.3f} | "
              f"{acc.localized:3d}/{acc.instants:<3d} | {acc.nees_mean / acc.nees_dof:6.2f} |")
        truth = read_tum(rec / "truth" / f"{seq}.tum")
        # the seeds' method on our corners, then as the seeds ran it: on OpenCV's ArUco subpixel corners
        t_cv = time.perf_counter()
        res_cv = run_recording(rec, rig, seq, planar=True, workers=workers, detector="aruco")
        t_cv = time.perf_counter() - t_cv
        for label, r in (("same corners", res), ("ArUco subpix", res_cv)):
            Tt = interpolate_truth(truth, np.array([o.stamp_s for o in r.observations]))
            pos, yaw, n_ok = [], [], 0
            for o, T in zip(r.observations, Tt, strict=True):
                Ts = seeds_frame_pose(model, o) if o.views else None
                if Ts is not None:
                    n_ok += 1
                    pe, ye = _errors(Ts, T)
                    pos.append(pe)
                    yaw.append(ye)
            if pos:
                print(_row(f"seeds ({label}), {seq}", pos, yaw, n_ok, len(Tt), None))
        lines.append(f"{seq}: ArUco detection and the seeds' method took {t_cv:.1f} s")
        n_img = sum(res.images_per_camera.values())
        sec = res.seconds
        lines.append(f"{seq}: {', '.join(f'{k} {v:.1f} s' for k, v in sec.items())}; {n_img} images: "
                     f"{n_img / sec['total']:.1f} images/s; corner variance factors "
                     f"{', '.join(f'{c} {f:.3g}' for c, f in res.corner_scale)}; failures {rep.failures}")
        if seq == "run":
            lines.append(f"run: {acc.frames_visible_localized}/{acc.frames_visible} images with a fully "
                         f"visible marker localized ({100 * acc.visible_localized_fraction:.2f} %)")
    print("\nNEES column: mean NEES / dof (x, y, yaw)\n")
    print("\n".join(lines))


def _cpu_s() -> float:
    """CPU seconds of this process and of its finished children (the workers of a run, once it returns)."""
    import resource

    a, b = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    return a.ru_utime + a.ru_stime + b.ru_utime + b.ru_stime


#: What the detection pass's CPU is split into (``--split``): (module, attribute, part), each function's own
#: CPU (process time, its helper threads included while the caller waits on them), nested calls to the
#: other listed ones taken out; what is left of the pass is its glue (tracking, windows, crops, duplicates,
#: the detections' records)
_DETECTION_PARTS = (
    ("gtrig.vision.sequence", "read_image", "reading"),
    ("gtrig.vision.track", "cell_means", "change test (cell means)"),
    ("gtrig.markers.detect.peers", "opencv_candidates", "OpenCV candidates"),
    ("gtrig.markers.detect", "refine_quads", "edge fits"),
    ("gtrig.markers.detect", "read_whiteness", "ID verification"),
    ("gtrig.markers.detect", "read_whiteness_plain", "ID verification"),
    ("gtrig.markers.detect", "verify_ids", "ID verification"),
    ("gtrig.markers.detect.MarkerDetector", "_accepted", "corners and covariances to raw pixels"),
    ("gtrig.vision.siblings", "cut_siblings", "markers cut by the edge (robot pose, prediction)"),
    ("gtrig.vision.detect.GtrigDetector", "prepare_lens_maps", "lens maps (once per camera and process)"),
)


def _resolve(path: str) -> object:
    import importlib

    try:
        return importlib.import_module(path)
    except ModuleNotFoundError:
        mod, _, name = path.rpartition(".")
        return getattr(importlib.import_module(mod), name)


def detection_split(rec: Path, rig: Rig, sequence: str) -> tuple[int, float, dict[str, float]]:
    """The tracked detection pass of ``sequence`` run in this process (one worker), its CPU split by part
    (:data:`_DETECTION_PARTS`): ``(images, CPU seconds of the pass, {part: own CPU seconds})``, the glue
    under "rest"."""
    from gtrig.vision import sequence as seq
    from gtrig.vision.track import TrackOptions

    own: dict[str, float] = {}
    stack: list[float] = []
    saved = []

    def timed(fn: Callable[..., Any], part: str) -> Callable[..., Any]:
        def run(*a: Any, **k: Any) -> Any:
            c0 = time.process_time()
            stack.append(0.0)
            try:
                return fn(*a, **k)
            finally:
                d, inner = time.process_time() - c0, stack.pop()
                own[part] = own.get(part, 0.0) + d - inner
                if stack:
                    stack[-1] += d
        return run

    for path, name, part in (*_DETECTION_PARTS, ("gtrig.vision.sequence", "_detect_all", "rest")):
        owner = _resolve(path)
        saved.append((owner, name, owner.__dict__[name]))
        setattr(owner, name, timed(getattr(owner, name), part))
    try:
        with tempfile.TemporaryDirectory() as d:
            res = seq.run_recording(rec, rig, sequence, planar=True, workers=1, track=TrackOptions(),
                                    checkpoint=Path(d) / "detections.checkpoint", estimate_noise=False)
    finally:
        for owner, name, fn in reversed(saved):
            setattr(owner, name, fn)
    return sum(res.images_per_camera.values()), sum(own.values()), own


def bench_tracking(rec: Path, rig_path: Path, workers: int, sequence: str, split: bool = False) -> None:
    from gtrig.io.frames import read_image
    from gtrig.rig import load_rig
    from gtrig.vision.detect import aruco_for_rig
    from gtrig.vision.report import accuracy_on_recording
    from gtrig.vision.sequence import camera_indices, run_recording
    from gtrig.vision.track import TrackOptions

    rig = load_rig(rig_path)
    print(f"\n### Tracking, {rec} {sequence} (rig {rig_path}), {workers or 'all'} worker(s)\n")
    # OpenCV's bare detection first: it also brings the images into the page cache for both stage runs
    cv = aruco_for_rig(rig, subpix=False)
    cpu_read = t_read = t_cv = 0.0
    n_cv = found = 0
    for ix in camera_indices(rec, sequence, rig).values():
        for i in range(len(ix)):
            c0, t0 = time.process_time(), time.perf_counter()
            img = read_image(ix.source(i))
            c1, t1 = time.process_time(), time.perf_counter()
            _, ids, _ = cv.detectMarkers(img)
            t_cv += time.perf_counter() - t1
            t_read += t1 - t0
            cpu_read += c1 - c0
            n_cv += 1
            found += 0 if ids is None else len(ids)
    read_ms = 1e3 * cpu_read / max(n_cv, 1)
    cores = workers or (os.cpu_count() or 1)
    rows = []
    for label, track in (("whole images", TrackOptions(enabled=False)), ("tracked", TrackOptions())):
        with tempfile.TemporaryDirectory() as d:
            ck = Path(d) / "detections.checkpoint"
            cpu0 = _cpu_s()
            res = run_recording(rec, rig, sequence, planar=True, workers=workers, track=track, checkpoint=ck)
            cpu = _cpu_s() - cpu0
            # the same again from the detections just checkpointed: what the estimation side costs alone
            cpu0 = _cpu_s()
            run_recording(rec, rig, sequence, planar=True, workers=workers, track=track, checkpoint=ck)
            cpu_est = _cpu_s() - cpu0
        acc = accuracy_on_recording(res, rec)
        n_img = sum(res.images_per_camera.values())
        sec = res.seconds
        share = (f"{acc.frames_visible_localized}/{acc.frames_visible} "
                 f"({100 * acc.visible_localized_fraction:.2f} %)" if sequence == "run" else "")
        est_ms, all_ms = 1e3 * cpu_est / n_img, 1e3 * cpu / n_img
        det_ms = all_ms - est_ms - read_ms
        rows.append(f"| {label:<12} | {n_img / sec['total']:7.1f} | {n_img / sec['parallel']:7.1f} | "
                    f"{sec['total']:6.1f} | {acc.localized:4d}/{acc.instants:<4d} | {share:>18} | "
                    f"{100 * acc.pos_err_mean_m:.3f} / {100 * acc.pos_err_max_m:.2f} | "
                    f"{math.degrees(acc.yaw_err_mean_rad):.4f} | {acc.nees_mean / acc.nees_dof:.2f} | "
                    f"{all_ms:.1f} | {read_ms:.1f} / {det_ms:.1f} / {est_ms:.1f} | "
                    f"{1e3 * cores / all_ms:.0f} / {1e3 * cores / (all_ms - read_ms):.0f} |")
    print("| search       | images/s (stage) | images/s (detection pass) | stage s | localized | "
          "visible-marker images localized | mean / max position cm | mean abs yaw deg | NEES/dof | "
          f"CPU ms per image | of it read / detect / estimate | images/s on {cores} cores at that CPU: "
          "with / without reading |")
    print("|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
    print("\n".join(rows))
    print("\n(images/s: wall, this machine as loaded; CPU per image: this process's and its workers'; read: "
          "gtrig.io.frames.read_image of each image in this process; estimate: the stage run again from its "
          "checkpointed detections (noise calibration, estimation, flips, motion); detect: the rest)")
    print(f"\nOpenCV ArucoDetector (defaults, its own threads), the same {n_cv} images: {n_cv / t_cv:.1f} images/s "
          f"of detection ({1e3 * t_cv / n_cv:.2f} ms per image, {found} markers; reading the images, not counted: "
          f"{1e3 * t_read / n_cv:.2f} ms per image, {read_ms:.2f} ms CPU)")
    if split:
        n_pass, cpu_pass, parts = detection_split(rec, rig, sequence)
        print(f"\nThe tracked detection pass in one process (reading included), {1e3 * cpu_pass / n_pass:.2f} ms CPU "
              "per image, by part (each part's own CPU, ms per image):\n")
        print("| part | ms CPU per image | share |\n|---|---:|---:|")
        for part, part_s in sorted(parts.items(), key=lambda kv: -kv[1]):
            print(f"| {part} | {1e3 * part_s / n_pass:.3f} | {100 * part_s / cpu_pass:.1f} % |")


def _render_validation(rec: Path, rig: Rig, Ts: list[np.ndarray], rng: np.random.Generator, frames: int,
                       blur_px: float, noise_grey: float) -> None:
    """The validation sequence of ``rec`` rendered with the test renderer: ``frames`` images per camera
    at each of the poses ``Ts`` (one static interval each), blur and grey-level noise as given."""
    intervals = [(10.0 * i, 10.0 * i + 1.0) for i in range(len(Ts))]
    for cam in rig.cameras:
        folder = rec / "validation" / "cameras" / cam.name
        folder.mkdir(parents=True)
        stamps, files = [], []
        for T, (t0, _) in zip(Ts, intervals, strict=True):
            seen = any(c == cam.name for c, _, _ in visible_views(rig, T))
            for f in range(frames):
                name = f"{len(files):06d}.png"
                img = (render_markers(rig, cam.name, T, rng, blur_px=blur_px, noise_grey=noise_grey) if seen else
                       np.clip(rng.normal(90, noise_grey, (768, 1024)), 0, 255).astype(np.uint8))
                cv2.imwrite(str(folder / name), img, [cv2.IMWRITE_PNG_COMPRESSION, 1])
                stamps.append(t0 + 0.05 + 0.1 * f)
                files.append(name)
        write_frame_index(folder, np.array(stamps), files)
    with open(rec / "validation" / "poses.csv", "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["pose", "start_s", "end_s"])
        w.writerows([i + 1, a, b] for i, (a, b) in enumerate(intervals))


def bench_consistency(seeds: list[int], frames: int, noises: list[float], blurs: list[float],
                      floor_px: float = VisionOptions().corner_floor_px) -> None:
    """NEES/dof with its 95 % interval of the validation poses, 6-DoF and planar, the rig stated exactly
    (camera and marker sigmas 1e-6, as a lab that knows its rig would state it), rendered by the test
    renderer (not the simulator's) at each grey-level noise and blur; with the corner variance factors
    the recording's own residuals gave (gtrig.vision.noise); ``floor_px`` the corner floor
    (``VisionOptions.corner_floor_px``)."""
    from gtrig.evaluate.gt_aware import batch_interval
    from gtrig.vision.sequence import run_recording

    exact = RigUncertainty(1e-6, 1e-6, 1e-6, 1e-6)
    print(f"\n### Consistency: test renderer, the rig stated exactly, validation poses, corner floor {floor_px:g} px\n")
    print("| seed | noise (grey) | blur (px) | mode | localized | pos mean (mm) | NEES/dof [95 %] | corner factors "
          "| mean z^2: x, y, z, roll, pitch, yaw | single-view stops |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for seed in seeds:
        scene = make_scene(seed)
        rig = scene.rig_true
        Ts = [scene.T_world_robot(*p) for p in VALIDATION_POSES]
        for noise in noises:
            for blur in blurs:
                with tempfile.TemporaryDirectory() as d:
                    _render_validation(Path(d), rig, Ts, np.random.default_rng(seed), frames, blur, noise)
                    for planar in (False, True):
                        res = run_recording(Path(d), rig, "validation", planar=planar, workers=1,
                                            options=VisionOptions(planar=planar, rig_uncertainty=exact,
                                                                  corner_floor_px=floor_px))
                        dims = list(PLANAR_INDEX) if planar else list(range(6))
                        ne, pe, z2, single = [], [], [], 0
                        for e, T in zip(res.estimates, Ts, strict=True):
                            if e.ok:
                                xi = pose_error_xi(e.T_world_robot, T)
                                ne.append(nees(xi[dims], e.cov_6x6[np.ix_(dims, dims)]) / len(dims))
                                pe.append(float(np.linalg.norm(xi[:3])))
                                # per axis: which directions the corner model under- or overstates
                                z2.append(xi**2 / np.diag(e.cov_6x6))
                                single += len(e.views) == 1
                        iv = batch_interval(np.array(ne))
                        fac = ", ".join(f"{v:.3f}" for _, v in res.corner_scale)
                        zs = ", ".join(f"{v:.2f}" for v in np.mean(z2, axis=0))
                        print(f"| {seed} | {noise:g} | {blur:g} | {'planar' if planar else '6-DoF'} | "
                              f"{len(ne)}/{len(Ts)} | {1000 * np.mean(pe):.3f} | {iv.value:.2f} [{iv.low:.2f}, "
                              f"{iv.high:.2f}] | {fac} | {zs} | {single} |", flush=True)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    ap.add_argument("--level", nargs="+", default=["corners", "images"],
                    choices=["corners", "images", "recording", "tracking", "consistency"])
    ap.add_argument("--noise-grey", type=float, nargs="+", default=[0.5, 1.5, 4.0],
                    help="level consistency: the renders' grey-level noise")
    ap.add_argument("--blur-px", type=float, nargs="+", default=[0.5, 1.5],
                    help="level consistency: the renders' blur")
    ap.add_argument("--stop-images", type=int, default=2,
                    help="level consistency: images per camera and stop (averaged by GTvision)")
    ap.add_argument("--corner-floor-px", type=float, default=VisionOptions().corner_floor_px,
                    help="level consistency: GTvision's corner floor (VisionOptions.corner_floor_px)")
    ap.add_argument("--recording", type=Path, help="a simulated recording (level recording)")
    ap.add_argument("--rig", type=Path, help="its calibrated rig (level recording)")
    ap.add_argument("--noise-px", type=float, default=0.08)
    ap.add_argument("--workers", type=int, default=0)
    ap.add_argument("--frames", type=int, default=3)
    ap.add_argument("--sequence", default="run", choices=["run", "validation"], help="level tracking")
    ap.add_argument("--split", action="store_true",
                    help="level tracking: also the tracked detection pass in one process, its CPU split by part")
    a = ap.parse_args()
    if "corners" in a.level:
        bench_corners(a.seeds, a.noise_px)
    if "images" in a.level:
        bench_images(a.seeds[0], a.workers, a.frames)
    if "consistency" in a.level:
        bench_consistency(a.seeds, a.stop_images, a.noise_grey, a.blur_px, a.corner_floor_px)
    if "recording" in a.level:
        if a.recording is None or a.rig is None:
            ap.error("--level recording needs --recording and --rig")
        bench_recording(a.recording, a.rig, a.workers)
    if "tracking" in a.level:
        if a.recording is None or a.rig is None:
            ap.error("--level tracking needs --recording and --rig")
        bench_tracking(a.recording, a.rig, a.workers, a.sequence, a.split)


if __name__ == "__main__":
    main()
