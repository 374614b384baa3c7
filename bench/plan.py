"""Planning benchmark: the speed of ``gtrig plan`` on a 10 m x 10 m room with 8 cameras and 4 scanners
(5 cm grid, 16 headings), beside its peer, GTvision's own fit of one pose on synthetic corners; and the
GT room's maps for docs/plan.md.

The speed is wall-clock and CPU time of :func:`gtrig.plan.predict.predict_plan` alone; the peer ratio is
the plan's CPU time per pose over the estimator's (``estimate_frame``) per pose, measured in the same run.

    python bench/plan.py [--grid-m 0.05] [--headings 16] [--workers 1] [--figures docs/figures]
    python bench/plan.py --suggest 25 --grid-m 0.1 --headings 16 [--suggest-kind scanners]
    python bench/plan.py --honesty RESULTS=RECORDING [RESULTS=RECORDING ...] [--calibrated] [--instant]
        [--corner-px SIGMA FLOOR] [--rig-sigma CAM_MM CAM_DEG MARKER_MM MARKER_DEG] [--stated]
        [--clock-sigma-ms MS] [--sunlit]

``--honesty``: the plan's predicted sigmas of GTlaser, fusion and GTvision at the true poses of simulated
runs (``gtrig run`` results folders beside the recordings ``gtrig sim`` wrote, with their truth) against
the runs' errors, per region of the floor (the camera that sees the robot best) and pooled over the runs;
and each camera's predicted coverage against the share of its images in which the run found a marker.
The plan is made from the recording's ``rig.yaml`` (the planned rig) with ``gtrig plan``'s defaults (a
calibrated run, :func:`gtrig.plan.vision.after_calibration`: the calibration's reach and the detector's
corner scatter; ``--rig-sigma`` to set other camera and marker sigmas; ``--stated``: the rig's stated
sigmas 0.5 mm / 0.01 deg and 0.3 mm / 0.05 deg with GTvision's corner model and floor, the model before
calibration), or with ``--calibrated`` from the results' ``rig.calibrated.yaml`` (its calibrated
covariances);
``--instant`` predicts fusion as the two sources' information at one instant (no smoother);
``--clock-sigma-ms`` sets fusion's clock offset sigma (:attr:`gtrig.plan.fused.FusionPlanSettings.clock_sigma_s`;
0: clocks known exactly);
``--corner-px`` sets the plan's corner noise (sigma at an 80 px marker, growing as the square root of
80 px over the side, and the floor added to it).
GTvision's poses are also split by exposure: those from images in which the robot's markers clip at
white (the robot in a sunlit patch) apart from the others. ``--sunlit`` tells the plan where the sun falls
(:attr:`gtrig.plan.vision.VisionPlanSettings.sunlit_xy`): the simulator's sun patch of each recording's seed
at the height of the robot's markers.
"""

from __future__ import annotations

import argparse
import os
import time
from pathlib import Path

import numpy as np

from gtrig import geometry as geo
from gtrig.rig.models import Pose, Rig
from gtrig.sim.gtroom import VALIDATION_POSES, make_scene, room_walls


def ten_metre_room() -> Rig:
    """The GT room's rig with 8 cameras on a ring 4.5 m out from the centre of a 10 m square, 3 m high,
    each aimed 2 m past the centre's near side, and its 4 scanners moved to the square's corners."""
    rig = make_scene(0).rig_nominal
    cams = []
    for i in range(8):
        a = 2 * np.pi * i / 8
        eye = np.array([5 + 4.5 * np.cos(a), 5 + 4.5 * np.sin(a), 3.0])
        T = geo.look_at(eye, np.array([5 + 1.0 * np.cos(a), 5 + 1.0 * np.sin(a), 0.0]))
        cams.append(rig.cameras[0].model_copy(update={"name": f"cam{i}", "T_world_cam": Pose.from_matrix(T)}))
    scans = []
    for i, (x, y) in enumerate(((0.2, 0.2), (9.8, 0.2), (9.8, 9.8), (0.2, 9.8))):
        yaw = np.degrees(np.arctan2(5 - y, 5 - x))
        scans.append(rig.laser_scanners[i].model_copy(update={
            "T_world_scanner": Pose(xyz=(x, y, 0.25), rpy_deg=(0.0, 0.0, float(yaw)))}))
    return rig.model_copy(update={"cameras": tuple(cams), "laser_scanners": tuple(scans)})


def cpu_seconds() -> float:
    """CPU time (user + system) of this process and of its finished worker processes, seconds."""
    t = os.times()
    return t.user + t.system + t.children_user + t.children_system


def peer_seconds_per_pose(n: int = 26) -> float:
    """CPU seconds of GTvision's fit of one pose (synthetic corners of the GT room's validation poses)."""
    from gtrig.vision.estimate import estimate_frame
    from gtrig.vision.observations import VisionModel
    from gtrig.vision.synthetic import synthetic_observations

    rig = make_scene(0).rig_true
    model = VisionModel.from_rig(rig)
    rng = np.random.default_rng(0)
    obs = [synthetic_observations(rig, geo.se2_to_T(*p), 0.0, rng) for p in VALIDATION_POSES[:n]]
    c = time.process_time()
    for o in obs:
        estimate_frame(model, o)
    return (time.process_time() - c) / len(obs)


def speed(grid_m: float, headings: int, workers: int) -> None:
    from gtrig.plan.grid import area_grid
    from gtrig.plan.predict import predict_plan

    rig = ten_metre_room()
    grid = area_grid(np.array([[0, 0], [10, 0], [10, 10], [0, 10.0]]), grid_m, headings)
    peer = peer_seconds_per_pose()
    t, c = time.perf_counter(), cpu_seconds()
    plan = predict_plan(rig, grid, workers=workers)
    wall, cpu = time.perf_counter() - t, cpu_seconds() - c
    n = grid.n_cells * grid.n_headings
    print(f"10 m x 10 m, {grid_m:g} m grid, {headings} headings: {n} poses, 8 cameras, 4 scanners")
    print(f"plan ({workers} worker(s)): wall {wall:.1f} s, CPU (all processes) {cpu:.1f} s "
          f"({1e6 * cpu / n:.1f} us CPU per pose); vision covers "
          f"{100 * np.isfinite(plan.sigma_xy_m('vision')).mean():.1f} %, laser "
          f"{100 * np.isfinite(plan.sigma_xy_m('laser')).mean():.1f} %")
    print(f"load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores")
    print(f"peer: GTvision's fit of one pose {1e3 * peer:.2f} ms CPU; plan per pose / fit per pose = "
          f"{cpu / n / peer:.4f}")


def suggestion(grid_m: float, headings: int, positions: int, kind: str, workers: int) -> None:
    """Time of ``--suggest cameras:1`` on the GT room with its second camera removed, or of
    ``--suggest scanners:1`` with its first scanner removed (2 aims per position)."""
    from gtrig.plan.grid import area_grid
    from gtrig.plan.predict import PlanSettings, predict_plan
    from gtrig.plan.suggest import suggest_sensors
    from gtrig.plan.vision import VisionPlanSettings
    from gtrig.vision.covariance import RigUncertainty

    full = make_scene(0).rig_nominal
    if kind == "cameras":
        rig = full.model_copy(update={"cameras": tuple(c for i, c in enumerate(full.cameras) if i != 1)})
        n_cam, n_scan, what = 1, 0, "cameras:1 on the GT room without cam1"
    else:
        rig = full.model_copy(update={"laser_scanners": full.laser_scanners[1:]})
        n_cam, n_scan, what = 0, 1, "scanners:1 on the GT room without laser0"
    grid = area_grid(room_walls()[:, 0], grid_m, headings)
    st = PlanSettings(vision=VisionPlanSettings(
        rig_uncertainty=RigUncertainty(0.0005, np.radians(0.01), 0.0003, np.radians(0.05))))
    c = cpu_seconds()
    plan = predict_plan(rig, grid, st)
    cpu_plan = cpu_seconds() - c
    t, c = time.perf_counter(), cpu_seconds()
    [s] = suggest_sensors(rig, plan, n_cam, n_scan, 0.003, np.radians(0.1), st, n_positions=positions, workers=workers)
    wall, cpu = time.perf_counter() - t, cpu_seconds() - c
    x, y, z = s.position_m
    print(f"suggest {what}, {grid.n_cells * grid.n_headings} poses, {s.n_candidates} candidates: wall {wall:.1f} s, "
          f"CPU {cpu:.1f} s ({workers} worker(s)); {s.kind} at ({x:.2f}, {y:.2f}, {z:.2f}) m, "
          f"share meeting 3 mm / 0.1 deg {100 * s.share_before:.1f} % -> {100 * s.share_after:.1f} % "
          f"(load average {os.getloadavg()[0]:.1f})")
    print(f"peer: the plan of the same rig and grid, {cpu_plan:.1f} s CPU in one process; suggestion / plan = "
          f"{cpu / cpu_plan:.2f}")


def figures(folder: Path) -> None:
    from gtrig.io.atomic import atomic_write_bytes
    from gtrig.plan import plots
    from gtrig.plan.grid import area_grid
    from gtrig.plan.maps import cell_maps, summarize_target
    from gtrig.plan.predict import PlanSettings, predict_plan
    from gtrig.plan.report import summary_lines

    rig = make_scene(0).rig_nominal
    grid = area_grid(room_walls()[:, 0], 0.1, 16)
    t = time.perf_counter()
    plan = predict_plan(rig, grid, PlanSettings())  # gtrig plan's defaults (docs/plan.md)
    el = time.perf_counter() - t
    maps = cell_maps(plan)
    s = summarize_target(plan, 0.001, np.radians(0.05))
    for line in summary_lines(plan, maps, s, el):
        print(line)
    folder.mkdir(parents=True, exist_ok=True)
    for src in ("fused", "vision", "laser"):
        png = plots.sigma_maps(plan, maps, src, 0.001, np.radians(0.05))
        atomic_write_bytes(folder / f"plan_gtroom_{src}.png", png)
    atomic_write_bytes(folder / "plan_gtroom_coverage.png", plots.coverage_maps(plan, maps))
    atomic_write_bytes(folder / "plan_gtroom_target.png", plots.target_map(plan, s))


def _truth_xytheta(truth, stamps_s: np.ndarray) -> np.ndarray:  # noqa: ANN001
    th = np.unwrap(geo.yaw_of_quats(truth.quat_xyzw))
    return np.column_stack([np.interp(stamps_s, truth.stamps_s, truth.xyz[:, 0]),
                            np.interp(stamps_s, truth.stamps_s, truth.xyz[:, 1]),
                            np.interp(stamps_s, truth.stamps_s, th)])


def _camera_stamps(recording: Path, camera: str) -> np.ndarray:
    import csv

    with open(recording / "run" / "cameras" / camera / "timestamps.csv", encoding="utf-8") as f:
        return np.array([float(r["stamp_s"]) for r in csv.DictReader(f)])


def _rms_sigma(cov_xytheta: np.ndarray) -> tuple[float, float]:
    """RMS position sigma per axis (m) and RMS yaw sigma (rad) of covariances (K, 3, 3)."""
    v = np.diagonal(cov_xytheta, axis1=1, axis2=2)
    return float(np.sqrt(np.mean(v[:, :2]))), float(np.sqrt(np.mean(v[:, 2])))


VISION_PARTS = ("corner", "corner+camera", "corner+marker", "all, one instant")


def instant_cameras(rig: Rig, rec: Path, res: Path, stamps_s: np.ndarray, sync_tol_s: float = 0.005) -> np.ndarray:
    """(K, n_cameras) bool: the cameras with an image within ``sync_tol_s`` of each GTvision pose's stamp
    (``stamps_s`` (K,)) in which the run found a marker (its checkpoint)."""
    from gtrig.report.coverage import read_checkpoint

    per, _ = read_checkpoint(res / "gt_vision_run.checkpoint")
    out = np.zeros((stamps_s.size, len(rig.cameras)), dtype=bool)
    for j, cam in enumerate(rig.cameras):
        st = _camera_stamps(rec, cam.name)
        marked = np.zeros(st.size, dtype=bool)
        c = per.get(cam.name)
        if c is not None:
            marked[np.asarray(c.rows, dtype=int)] = np.asarray(c.marked, dtype=bool)
        i = np.clip(np.searchsorted(st, stamps_s), 1, st.size - 1)
        for n in (i - 1, i):
            out[:, j] |= (np.abs(st[n] - stamps_s) <= sync_tol_s) & marked[n]
    return out


#: share of a marker region's pixels at the 8-bit clip above which its image counts as over-exposed
CLIPPED_SHARE = 0.02


def overexposed_poses(rig: Rig, rec: Path, stamps_s: np.ndarray, true_xyt: np.ndarray, sync_tol_s: float = 0.005
                      ) -> np.ndarray:
    """(K,) bool: the GTvision poses (``stamps_s`` (K,), true planar poses ``true_xyt`` (K, 3)) one of whose
    instant's images (within ``sync_tol_s``) clips the white of the robot's markers: more than
    :data:`CLIPPED_SHARE` of the pixels in the box of the markers' projected corners at 255 (the robot in a
    sunlit patch of the floor)."""
    from gtrig.io.frames import read_frame_index
    from gtrig.vision.observations import VisionModel

    model = VisionModel.from_rig(rig)
    corners = np.concatenate([model.corners_robot[m.id] for m in rig.robot.markers])
    out = np.zeros(stamps_s.size, dtype=bool)
    for cam in rig.cameras:
        g = model.cameras[cam.name]
        index = read_frame_index(rec / "run" / "cameras" / cam.name)
        st = index.stamps_s
        i = np.clip(np.searchsorted(st, stamps_s), 1, st.size - 1)
        for n in (i - 1, i):
            for k in np.flatnonzero((np.abs(st[n] - stamps_s) <= sync_tol_s) & ~out):
                p_cam = geo.transform_points(g.T_cam_world @ geo.se2_to_T(*true_xyt[k]), corners)
                if np.any(p_cam[:, 2] <= 0.05):
                    continue
                uv = geo.project_points(p_cam, g.K, g.dist)
                (x0, y0), (x1, y1) = np.floor(uv.min(axis=0)).astype(int), np.ceil(uv.max(axis=0)).astype(int) + 1
                w, h = g.size
                x0, y0, x1, y1 = max(x0, 0), max(y0, 0), min(x1, w), min(y1, h)
                if x1 - x0 < 2 or y1 - y0 < 2:
                    continue
                img = index.read(int(n[k]))
                out[k] = np.mean(img[y0:y1, x0:x1] >= 255) > CLIPPED_SHARE
    return out


def vision_detail(rig: Rig, rec: Path, res: Path, stamps_s: np.ndarray, true_xyt: np.ndarray, err: np.ndarray,
                  plan_cov: np.ndarray, region: np.ndarray, base, pooled: dict) -> None:  # noqa: ANN001
    """GTvision per region: the plan's ratio with and without the poses whose error the run's own
    covariance (``gt_vision_run_cov.csv``) does not explain (NEES beyond chi-square 3 dof at 0.1 %), the
    run's covariance's own ratio, and what the plan's sigma is made of (corner noise alone, with the
    cameras' pose errors, with the markers', all at one instant: without the time-stamp jitter); and the
    plan's ratio when each pose is predicted from the cameras whose images made it (``own``, at one
    instant: without the jitter), and with the plan's instants per camera (``per camera``, likewise); every
    prediction with the corner noise of ``base`` (the plan's :class:`VisionPlanSettings`)."""
    from dataclasses import replace

    from gtrig.io.posetrack import read_covariance_csv
    from gtrig.plan.honesty import extreme_poses, region_ratios
    from gtrig.plan.vision import predict_vision
    from gtrig.vision.covariance import RigUncertainty

    ru = base.rig_uncertainty
    st, cov, _, _, _, _ = read_covariance_csv(res / "gt_vision_run_cov.csv")
    assert cov is not None, "gt_vision_run_cov.csv holds no covariance"
    i = np.clip(np.searchsorted(st, stamps_s), 0, st.size - 1)
    run_cov = np.where((np.abs(st[i] - stamps_s) < 1e-6)[:, None, None], cov[i], np.nan)
    flagged = extreme_poses(err, run_cov)
    variants = (RigUncertainty.none(), RigUncertainty(ru.camera_xyz_m, ru.camera_rot_rad, 0.0, 0.0),
                RigUncertainty(0.0, 0.0, ru.marker_xyz_m, ru.marker_rot_rad), ru)
    parts = [predict_vision(rig, true_xyt, replace(base, rig_uncertainty=u)).cov_xytheta for u in variants]
    free = predict_vision(rig, true_xyt, replace(base, instants="per_camera")).cov_of_a_pose
    # the cameras whose images made each pose: GTvision's instant holds the images within its sync
    # tolerance (5 ms), one camera's in most instants of free-running cameras
    own = instant_cameras(rig, rec, res, stamps_s)
    cov_own = np.full_like(parts[-1], np.nan)
    for combo in {tuple(r) for r in own if r.any()}:
        m = np.all(own == np.array(combo), axis=1)
        sub = rig.model_copy(update={"cameras": tuple(c for c, k in zip(rig.cameras, combo, strict=True) if k)})
        cov_own[m] = predict_vision(sub, true_xyt[m], base).cov_xytheta
    print(f"  vision: poses made of one camera's images {100 * np.mean(own.sum(axis=1) == 1):.0f} %, of two "
          f"{100 * np.mean(own.sum(axis=1) == 2):.0f} %")
    print(f"  vision: {int(flagged.sum())} of {err.shape[0]} poses flagged (NEES under the run's covariance "
          f"beyond chi2(3) at 0.1 %)")
    by = {r.region: r for r in region_ratios(err, plan_cov, region)}
    kept = {r.region: r for r in region_ratios(err, plan_cov, region, keep=~flagged)}
    run = {r.region: r for r in region_ratios(err, run_cov, region)}
    run_kept = {r.region: r for r in region_ratios(err, run_cov, region, keep=~flagged)}
    inst = {r.region: r for r in region_ratios(err, cov_own, region)}
    per_cam = {r.region: r for r in region_ratios(err, free, region)}
    per_cam_kept = {r.region: r for r in region_ratios(err, free, region, keep=~flagged)}
    inst_kept = {r.region: r for r in region_ratios(err, cov_own, region, keep=~flagged)}
    for reg, r in by.items():
        m = region == reg
        sig = [_rms_sigma(c[m & np.isfinite(c[:, 0, 0])]) for c in parts]
        k, o, ok_ = kept.get(reg), run.get(reg), run_kept.get(reg)
        print(f"  vision region cam{reg}: {int((m & flagged).sum())} flagged; plan pos/yaw all "
              f"{r.position:.2f}/{r.yaw:.2f}, without flagged "
              + (f"{k.position:.2f}/{k.yaw:.2f} (error {1e3 * k.rms_error_m:.2f} mm)" if k else "-")
              + (f"; run's covariance all {o.position:.2f}/{o.yaw:.2f} ({1e3 * o.rms_sigma_m:.2f} mm)" if o else "")
              + (f", without flagged {ok_.position:.2f}/{ok_.yaw:.2f}" if ok_ else ""))
        if reg in inst:
            i_, ik = inst[reg], inst_kept.get(reg)
            print(f"      plan from the pose's own cameras (one instant, no jitter): "
                  f"all {i_.position:.2f}/{i_.yaw:.2f} "
                  f"({1e3 * i_.rms_sigma_m:.2f} mm)"
                  + (f", without flagged {ik.position:.2f}/{ik.yaw:.2f}" if ik else ""))
        if reg in per_cam:
            f_, fk = per_cam[reg], per_cam_kept.get(reg)
            print(f"      plan with instants per camera (one instant, no jitter): all {f_.position:.2f}/{f_.yaw:.2f} "
                  f"({1e3 * f_.rms_sigma_m:.2f} mm)"
                  + (f", without flagged {fk.position:.2f}/{fk.yaw:.2f}" if fk else ""))
        print("      plan sigma parts (mm / deg): " + ", ".join(
            f"{n} {1e3 * a:.2f}/{np.degrees(b):.4f}" for n, (a, b) in zip(VISION_PARTS, sig, strict=True))
            + f", with the jitter {1e3 * r.rms_sigma_m:.2f}/{np.degrees(r.rms_sigma_rad):.4f}")
        for key, rr in (("all", r), ("kept", k), ("run", o), ("run kept", ok_), ("own", inst.get(reg)),
                        ("own kept", inst_kept.get(reg)), ("per camera", per_cam.get(reg)),
                        ("per camera kept", per_cam_kept.get(reg))):
            if rr is not None:
                pooled.setdefault((key, reg), []).append(np.array(
                    [rr.poses, rr.rms_error_m**2, rr.rms_sigma_m**2, rr.rms_error_rad**2, rr.rms_sigma_rad**2]))
        for n, (a, b) in zip(VISION_PARTS, sig, strict=True):
            pooled.setdefault(("part " + n, reg), []).append(np.array([m.sum(), a**2, b**2]))
    exposure_split(rig, rec, stamps_s, true_xyt, err, {"plan": plan_cov, "run": run_cov}, region, pooled)


def exposure_split(rig: Rig, rec: Path, stamps_s: np.ndarray, true_xyt: np.ndarray, err: np.ndarray,
                   covs: dict[str, np.ndarray], region: np.ndarray, pooled: dict) -> None:  # noqa: ANN001
    """GTvision per region, the poses from images whose markers' white is clipped (:func:`overexposed_poses`)
    apart from the others: each covariance of ``covs`` (name: (K, 3, 3)) against the errors ``err`` (K, 3)."""
    from gtrig.plan.honesty import region_ratios

    over = overexposed_poses(rig, rec, stamps_s, true_xyt)
    print(f"  vision: {int(over.sum())} of {over.size} poses from images with the markers' white clipped")
    for name, cov in covs.items():
        for label, keep in (("well exposed", ~over), ("clipped", over)):
            rr = region_ratios(err, cov, region, min_poses=3, keep=keep)
            print(f"      {name}, {label}: " + "; ".join(
                f"cam{r.region} {r.poses} poses {r.position:.2f}/{r.yaw:.2f} ({1e3 * r.rms_error_m:.2f} mm)"
                for r in rr))
            for r in rr:
                pooled.setdefault((f"{name} {label}", r.region), []).append(np.array(
                    [r.poses, r.rms_error_m**2, r.rms_sigma_m**2, r.rms_error_rad**2, r.rms_sigma_rad**2]))


def sun_patch_xy(rec: Path, rig: Rig) -> tuple[tuple[float, float], ...]:
    """The simulated room's sun patch (the window cast along the sunlight, :func:`gtrig.sim.textures.sun_geometry`
    of the recording's seed) at the height of the robot's markers: the floor polygon over which their white
    clips, world frame, m."""
    from gtrig.io.yamlfile import safe_load
    from gtrig.sim.textures import sun_geometry

    seed = int((safe_load((rec / "sim_config.yaml").read_text(encoding="utf-8")) or {}).get("seed", 0))
    win, d = sun_geometry(make_scene(seed))
    h = float(np.mean([m.T_robot_marker.matrix()[2, 3] for m in rig.robot.markers]))
    poly = win[:, :2] + ((h - win[:, 2:3]) / d[2]) * d[:2]
    return tuple((float(x), float(y)) for x, y in poly)


def _pooled_ratio(rows: list[np.ndarray]) -> tuple[float, float, float]:
    """Poses-weighted pooled (position ratio, yaw ratio, RMS error m) of region rows (poses, e2, s2, y2, ys2)."""
    e2, s2, y2, ys2 = np.sum([r[0] * r[1:] for r in rows], axis=0) / np.sum([r[0] for r in rows])
    return float(np.sqrt(e2 / s2)), float(np.sqrt(y2 / ys2)), float(np.sqrt(e2))


def honesty(pairs: list[str], calibrated: bool, instant: bool = False, every: int = 3,
            corner_px: tuple[float, float] | None = None,
            rig_sigma: tuple[float, float, float, float] | None = None, stated: bool = False,
            clock_sigma_s: float | None = None, sunlit: bool = False) -> None:
    """Predicted against measured, per region and source (module docstring); ``corner_px``: the plan's
    corner sigma at an 80 px marker and its floor, pixels, ``rig_sigma``: its camera and marker sigmas
    (mm, deg, mm, deg; None: the model's), ``stated``: the rig's stated sigmas with GTvision's corner
    model and floor instead of a calibrated run (:func:`gtrig.plan.vision.after_calibration`),
    ``clock_sigma_s``: fusion's clock offset sigma (None: the plan's default), ``sunlit``: the plan told
    where each recording's sun falls (:func:`sun_patch_xy`)."""
    from dataclasses import replace

    from gtrig.io.tum import read_tum
    from gtrig.plan.fused import FusionPlanSettings
    from gtrig.plan.grid import path_grid
    from gtrig.plan.honesty import best_camera_region, coverage_check, pose_errors, region_ratios
    from gtrig.plan.predict import PlanSettings, predict_plan
    from gtrig.plan.vision import CALIBRATED_RIG, VisionPlanSettings, after_calibration, predict_vision
    from gtrig.report.coverage import read_checkpoint
    from gtrig.rig.load import load_rig
    from gtrig.vision.covariance import RigUncertainty
    from gtrig.vision.synthetic import CornerNoise

    if rig_sigma is None:
        ru = RigUncertainty(0.0005, np.radians(0.01), 0.0003, np.radians(0.05)) if stated else CALIBRATED_RIG
    else:
        ru = RigUncertainty(rig_sigma[0] / 1000, np.radians(rig_sigma[1]), rig_sigma[2] / 1000,
                            np.radians(rig_sigma[3]))
    vision = VisionPlanSettings(rig_uncertainty=ru) if stated else after_calibration(ru)
    if corner_px is not None:
        vision = VisionPlanSettings(rig_uncertainty=ru, corner_noise=CornerNoise(corner_px[0], 80.0),
                                    corner_floor_px=corner_px[1])
    fusion = FusionPlanSettings(smooth=not instant)
    if clock_sigma_s is not None:
        fusion = replace(fusion, clock_sigma_s=clock_sigma_s)
    settings = PlanSettings(vision=vision, fusion=fusion)
    sources = (("laser", "gt_laser.tum"), ("fused", "gt_fused.tum"), ("vision", "gt_vision_run.tum"))
    pooled: dict[tuple[str, int], list[np.ndarray]] = {}
    vision_pooled: dict[tuple[str, int], list[np.ndarray]] = {}
    for pair in pairs:
        res_s, _, rec_s = pair.partition("=")
        res, rec = Path(res_s), Path(rec_s)
        rig = load_rig(res / "rig.calibrated.yaml" if calibrated else rec / "rig.yaml")
        truth = read_tum(rec / "truth" / "run.tum")
        if sunlit:
            settings = replace(settings, vision=replace(settings.vision, sunlit_xy=sun_patch_xy(rec, rig)))
        print(f"{res} against {rec / 'truth'} ({'calibrated rig' if calibrated else 'planned rig'}):")
        for src, fname in sources:
            est = read_tum(res / fname)
            t = est.stamps_s
            keep = np.flatnonzero((t >= truth.stamps_s[0]) & (t <= truth.stamps_s[-1]))[::every]
            true_xyt = _truth_xytheta(truth, t[keep])
            est_xyt = np.column_stack([est.xyz[keep, :2], geo.yaw_of_quats(est.quat_xyzw[keep])])
            err = pose_errors(est_xyt, true_xyt)
            plan = predict_plan(rig, path_grid(true_xyt[:, :2], true_xyt[:, 2], t[keep]), settings)
            region = best_camera_region(plan.views)
            for r in region_ratios(err, plan.cov[src], region):
                pooled.setdefault((src, r.region), []).append(
                    np.array([r.poses, r.rms_error_m**2, r.rms_sigma_m**2, r.rms_error_rad**2, r.rms_sigma_rad**2]))
                print(f"  {src:<6} region cam{r.region}: {r.poses:4d} poses, RMS error / sigma: position "
                      f"{r.position:.2f} ({1e3 * r.rms_error_m:.3f} / {1e3 * r.rms_sigma_m:.3f} mm), yaw {r.yaw:.2f} "
                      f"({np.degrees(r.rms_error_rad):.4f} / {np.degrees(r.rms_sigma_rad):.4f} deg)")
            if src == "vision":
                vision_detail(rig, rec, res, t[keep], true_xyt, err, plan.cov[src], region, settings.vision,
                              vision_pooled)
        per, _ = read_checkpoint(res / "gt_vision_run.checkpoint")
        for cam in rig.cameras:
            stamps = _camera_stamps(rec, cam.name)
            seen = predict_vision(rig.model_copy(update={"cameras": (cam,)}), _truth_xytheta(truth, stamps),
                                  settings.vision).views[:, 0] > 0
            localized = np.zeros(stamps.size, dtype=bool)
            c = per.get(cam.name)
            if c is not None:
                localized[np.asarray(c.rows, dtype=int)] = np.asarray(c.marked, dtype=bool)
            cc = coverage_check(cam.name, seen, localized)
            print(f"  coverage {cam.name}: {cc.images} images, predicted {cc.predicted_pct:.1f} %, marker found "
                  f"{cc.localized_pct:.1f} %, difference {cc.difference_points:+.1f} points, agree on "
                  f"{cc.agree_pct:.1f} % of the images")
    print("pooled over the runs (RMS error / RMS sigma per region):")
    for (src, reg), rows in sorted(pooled.items()):
        # poses-weighted mean squares over the runs
        pos, yaw, _ = _pooled_ratio(rows)
        print(f"  {src:<6} region cam{reg}: position {pos:.2f}, yaw {yaw:.2f}")
    print("GTvision pooled: plan's ratio position/yaw, all poses and without the flagged ones; the run's "
          "covariance's; the plan's from each pose's own cameras and with instants per camera; the plan's sigma "
          "parts (mm / deg):")
    for reg in sorted({k[1] for k in vision_pooled}):
        line = f"  region cam{reg}:"
        for key in ("all", "kept", "run", "run kept", "own", "own kept", "per camera", "per camera kept",
                    "plan well exposed", "plan clipped", "run well exposed", "run clipped"):
            found = vision_pooled.get((key, reg))
            if found:
                pos, yaw, e = _pooled_ratio(found)
                line += f" {key} {pos:.2f}/{yaw:.2f} ({1e3 * e:.2f} mm);"
        parts = []
        for n in VISION_PARTS:
            rows = vision_pooled.get(("part " + n, reg), [])
            a2, b2 = np.sum([r[0] * r[1:] for r in rows], axis=0) / np.sum([r[0] for r in rows])
            parts.append(f"{n} {1e3 * np.sqrt(a2):.2f}/{np.degrees(np.sqrt(b2)):.4f}")
        print(line + " parts " + ", ".join(parts))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--grid-m", type=float, default=0.05)
    ap.add_argument("--headings", type=int, default=16)
    ap.add_argument("--workers", type=int, default=1)
    ap.add_argument("--suggest", type=int, default=0, help="time a camera suggestion over this many positions "
                    "along the GT room's outline (2 candidates each) instead")
    ap.add_argument("--suggest-kind", choices=("cameras", "scanners"), default="cameras",
                    help="what --suggest times: a camera (GT room without cam1) or a scanner (without laser0)")
    ap.add_argument("--figures", type=Path, default=None, help="write the GT room's maps here (and skip the speed)")
    ap.add_argument("--honesty", nargs="+", metavar="RESULTS=RECORDING", default=None,
                    help="check the plan against these simulated runs instead (module docstring)")
    ap.add_argument("--calibrated", action="store_true", help="with --honesty: plan with the calibrated rig")
    ap.add_argument("--instant", action="store_true", help="with --honesty: fusion without its smoother")
    ap.add_argument("--rig-sigma", nargs=4, type=float, metavar=("CAM_MM", "CAM_DEG", "MARKER_MM", "MARKER_DEG"),
                    default=None, help="with --honesty: the plan's camera and marker pose sigmas (default: gtrig "
                    "plan's)")
    ap.add_argument("--stated", action="store_true", help="with --honesty: GTvision predicted with the rig's "
                    "stated sigmas, GTvision's corner model and floor (before calibration) instead of gtrig plan's "
                    "calibrated run")
    ap.add_argument("--clock-sigma-ms", type=float, default=None, help="with --honesty: fusion's clock offset "
                    "sigma in the plan, ms (default: the plan's)")
    ap.add_argument("--sunlit", action="store_true", help="with --honesty: tell the plan where the simulated sun "
                    "falls (the markers' white clips there)")
    ap.add_argument("--corner-px", nargs=2, type=float, metavar=("SIGMA", "FLOOR"), default=None,
                    help="with --honesty: the plan's corner sigma at an 80 px marker and its floor, px "
                         "(default: the plan's)")
    a = ap.parse_args()
    if a.honesty:
        honesty(a.honesty, a.calibrated, a.instant, corner_px=None if a.corner_px is None else tuple(a.corner_px),
                rig_sigma=None if a.rig_sigma is None else tuple(a.rig_sigma), stated=a.stated,
                clock_sigma_s=None if a.clock_sigma_ms is None else a.clock_sigma_ms / 1000, sunlit=a.sunlit)
    elif a.suggest:
        suggestion(a.grid_m, a.headings, a.suggest, a.suggest_kind, a.workers)
    elif a.figures is not None:
        figures(a.figures)
    else:
        speed(a.grid_m, a.headings, a.workers)


if __name__ == "__main__":
    main()
