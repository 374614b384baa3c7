"""``gtrig sim``: write a whole simulated recording, plus its truth, in the real on-disk layout.

The steps read like the recording's table of contents (docs/formats.md). Each step writes its files
atomically and is recorded in ``.gtrig_sim_state.json`` once complete, so an interrupted run resumes
where it stopped when called again with the same settings.
"""

from __future__ import annotations

import csv
import hashlib
import json
import logging
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from gtrig.errors import InputError
from gtrig.io.atomic import atomic_open, atomic_write_text
from gtrig.io.tum import Trajectory, write_tum
from gtrig.rig.load import dump_rig
from gtrig.rig.models import Camera, Rig
from gtrig.sim.config import SimConfig
from gtrig.sim.gtroom import VALIDATION_POSES, WORLD_POINT_NAMES, Scene, continuous_path, make_scene
from gtrig.sim.lasers import configure_scene, with_scanner_stamp_sigma
from gtrig.sim.motion import RobotMotion, agile_path, static_motion

log = logging.getLogger(__name__)

# One clock for the whole recording (an arbitrary epoch, as real loggers use).
EPOCH_S = 1_700_000_000.0
BACKGROUND_T0_S = EPOCH_S
VALIDATION_T0_S = EPOCH_S + 100.0
RUN_T0_S = EPOCH_S + 300.0
STATE_FILE = ".gtrig_sim_state.json"


@dataclass(frozen=True)
class Timeline:
    """When each sequence happens and how the robot moves in it (true motion, recording clock)."""

    run: RobotMotion
    run_interval_s: np.ndarray  # (1, 2)
    validation: RobotMotion
    validation_intervals_s: np.ndarray  # (26, 2)
    background_interval_s: np.ndarray  # (1, 2)


@dataclass(frozen=True)
class PlannedPath:
    """The continuous run's path given by the user instead of the built-in one: stamps (N,) seconds from
    its start, increasing, and planar poses (N, 3) x, y (m), heading (rad, continuous), world frame."""

    stamps_s: np.ndarray
    xytheta: np.ndarray


def make_timeline(scene: Scene, cfg: SimConfig, path: PlannedPath | None = None) -> Timeline:
    """When each sequence happens: the background, the validation stops, the continuous run (along
    ``path`` when given, else the built-in path through the validation positions, cut to
    ``cfg.run_duration_s``)."""
    duration = cfg.run_duration_s
    m = cfg.motion
    if path is not None:
        keep = path.stamps_s <= (duration if duration is not None else np.inf)
        stamps, xyth = path.stamps_s[keep], path.xytheta[keep]
    elif m.profile == "agile":
        stamps, xyth = agile_path(VALIDATION_POSES, m.speed_mps, m.accel_mps2, m.lat_accel_mps2,
                                  m.yaw_rate_max_radps, duration_s=duration)
    else:
        stamps, xyth = continuous_path(speed_mps=m.speed_mps, duration_s=duration)
    run = RobotMotion(stamps + RUN_T0_S, xyth, scene.floor)
    val, intervals = static_motion(VALIDATION_POSES, scene.floor, cfg.static_pose_s)
    val = RobotMotion(val.stamps_s + VALIDATION_T0_S, val.xytheta, scene.floor)
    return Timeline(
        run=run,
        run_interval_s=np.array([[run.stamps_s[0], run.stamps_s[-1]]]),
        validation=val,
        validation_intervals_s=intervals + VALIDATION_T0_S,
        background_interval_s=np.array([[BACKGROUND_T0_S, BACKGROUND_T0_S + cfg.background_s]]),
    )


def camera_stamps(interval_s: np.ndarray, rate_hz: float, offset_s: float) -> np.ndarray:
    """Exposure mid-times of a free-running camera inside the given intervals (K, 2)."""
    out = []
    for t0, t1 in interval_s:
        first = np.ceil((t0 - offset_s) * rate_hz) / rate_hz + offset_s
        out.append(np.arange(first, t1 + 1e-9, 1.0 / rate_hz))
    return np.concatenate(out)


def _csv(path: Path, header: list[str], rows: list[list[object]]) -> None:
    with atomic_open(path, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(header)
        w.writerows(rows)


# ---------------------------------------------------------------------------------------------- steps
def _with_stamp_sigma(rig: Rig, cfg: SimConfig) -> Rig:
    cams = tuple(c.model_copy(update={"stamp_sigma_s": cfg.camera.stamp_jitter_s}) for c in rig.cameras)
    return with_scanner_stamp_sigma(rig.model_copy(update={"cameras": cams}))


def _write_rigs_and_truth(scene: Scene, tl: Timeline, out: Path, cfg: SimConfig) -> None:
    # the lab knows its cameras' time-stamp jitter (datasheet, or a sync test): the rig says it
    dump_rig(_with_stamp_sigma(scene.rig_nominal, cfg), out / "rig.yaml")
    dump_rig(_with_stamp_sigma(scene.rig_true, cfg), out / "truth" / "rig.yaml")
    settings = cfg.model_dump(mode="json", exclude=_default_draw_settings(cfg))
    atomic_write_text(out / "sim_config.yaml", yaml.safe_dump(settings, sort_keys=False))
    run_T = tl.run.T_world_robot_many(tl.run.stamps_s)
    write_tum(out / "truth" / "run.tum", Trajectory.from_matrices(tl.run.stamps_s, run_T))
    mid = tl.validation_intervals_s.mean(axis=1)
    write_tum(out / "truth" / "validation.tum",
              Trajectory.from_matrices(mid, tl.validation.T_world_robot_many(mid)))
    _csv(out / "truth" / "validation_poses.csv", ["pose", "x", "y", "theta"],
         [[i + 1, f"{x:.6f}", f"{y:.6f}", f"{th:.8f}"] for i, (x, y, th) in enumerate(VALIDATION_POSES)])
    _csv(out / "truth" / "world_points.csv", ["name", "x", "y"],
         [[n, f"{x:.6f}", f"{y:.6f}"] for n, (x, y) in zip(WORLD_POINT_NAMES, scene.world_points_xy, strict=True)])
    _csv(out / "truth" / "reference_points.csv", ["name", "x", "y"],
         [[n, f"{x:.6f}", f"{y:.6f}"] for n, (x, y) in scene.reference_true_xy.items()])
    _csv(out / "validation" / "poses.csv", ["pose", "start_s", "end_s"],
         [[i + 1, f"{a:.6f}", f"{b:.6f}"] for i, (a, b) in enumerate(tl.validation_intervals_s)])
    write_laser_object(out)


def write_laser_object(out: Path) -> None:
    """``calib/laser_object.yaml``: the outlines of the objects that define the world frame for the
    scanners' calibration (the GT room's ``calib_object*`` boxes, fixed and seed-independent), world
    frame, metres; what a lab writes from its own survey of those objects (docs/formats.md)."""
    from gtrig.sim.gtroom import clutter

    objs = [{"name": b.name, "corners_xy": [[float(x), float(y)] for x, y in b.corners_xy()]}
            for b in clutter() if b.name.startswith("calib_object")]
    doc = {"units": "world frame, metres; corners in order around each object", "objects": objs}
    atomic_write_text(out / "calib" / "laser_object.yaml", yaml.safe_dump(doc, sort_keys=False))


def _camera_offsets(scene: Scene) -> list[float]:
    # free-running cameras: each starts at its own phase of the 10 Hz period
    rng = np.random.default_rng([scene.seed, 7])
    return [float(rng.uniform(0, 1.0 / _rate_hz(c))) for c in scene.rig_true.cameras]


def _rate_hz(cam: Camera) -> float:
    # the simulated cameras are video cameras: a still (rate_hz None) is a bug in the scene
    if cam.rate_hz is None:
        raise ValueError(f"simulated camera {cam.name} has no rate_hz")
    return cam.rate_hz


def _write_camera_sequence(scene: Scene, motion: RobotMotion, intervals: np.ndarray, folder: Path,
                           cfg: SimConfig, salt: int) -> None:
    from gtrig.sim.cameras import render_sequence

    for i, (cam, off) in enumerate(zip(scene.rig_true.cameras, _camera_offsets(scene), strict=True)):
        stamps = camera_stamps(intervals, _rate_hz(cam), off)
        render_sequence(scene, cam, motion, stamps, folder / "cameras" / cam.name, cfg,
                        seed=cfg.seed * 1000 + salt * 10 + i)


def _step_run_cameras(scene: Scene, tl: Timeline, out: Path, cfg: SimConfig) -> None:
    _write_camera_sequence(scene, tl.run, tl.run_interval_s, out / "run", cfg, 1)


def _step_validation_cameras(scene: Scene, tl: Timeline, out: Path, cfg: SimConfig) -> None:
    _write_camera_sequence(scene, tl.validation, tl.validation_intervals_s, out / "validation", cfg, 2)


def _step_calibration_images(scene: Scene, tl: Timeline, out: Path, cfg: SimConfig) -> None:
    from gtrig.sim.cameras import write_calibration_sets, write_handheld_set

    write_calibration_sets(scene, out, cfg)
    write_handheld_set(scene, out, cfg)


def _step_lasers(scene: Scene, tl: Timeline, out: Path, cfg: SimConfig) -> None:
    from gtrig.sim.lasers import write_fixed_scans, write_onboard_scans

    infos = {
        "background": write_fixed_scans(scene, None, tl.background_interval_s, out / "background" / "lasers",
                                        cfg, seed=cfg.seed * 10 + 1),
        "validation": write_fixed_scans(scene, tl.validation, tl.validation_intervals_s,
                                        out / "validation" / "lasers", cfg, seed=cfg.seed * 10 + 2),
        "run": write_fixed_scans(scene, tl.run, tl.run_interval_s, out / "run" / "lasers", cfg,
                                 seed=cfg.seed * 10 + 3),
        "validation_onboard": write_onboard_scans(scene, tl.validation, tl.validation_intervals_s,
                                                  out / "validation" / "onboard", cfg, seed=cfg.seed * 10 + 4),
        "run_onboard": write_onboard_scans(scene, tl.run, tl.run_interval_s, out / "run" / "onboard", cfg,
                                           seed=cfg.seed * 10 + 5),
    }
    # what a real recording would not tell: the scanners' clock offsets, for checking time-sync tools
    doc = {k: {"clock_offsets_s": dict(v.clock_offsets_s)} for k, v in infos.items()}
    atomic_write_text(out / "truth" / "laser_clocks.yaml", yaml.safe_dump(doc, sort_keys=True))


def _step_odometry(scene: Scene, tl: Timeline, out: Path, cfg: SimConfig) -> None:
    import dataclasses

    from gtrig.sim.odometry import write_odometry

    t0, t1 = tl.run_interval_s[0]
    errors = write_odometry(scene, tl.run, t0, t1, out / "run" / "odometry.csv", cfg, seed=cfg.seed * 10 + 6)
    atomic_write_text(out / "truth" / "odometry_errors.yaml", yaml.safe_dump(dataclasses.asdict(errors)))
    atomic_write_text(out / "truth" / "robot_clock.yaml", yaml.safe_dump(
        {"offset_s": float(cfg.odometry_clock_offset_s),
         "convention": "robot stamp (odometry, onboard scans) - GT clock stamp of the same instant"}))


def _step_survey(scene: Scene, tl: Timeline, out: Path, cfg: SimConfig) -> None:
    from gtrig.sim.survey import write_survey

    mid = tl.validation_intervals_s.mean(axis=1)
    write_survey(scene, tl.validation.T_world_robot_many(mid), out, cfg, seed=cfg.seed * 10 + 7)


def _step_map(scene: Scene, tl: Timeline, out: Path, cfg: SimConfig) -> None:
    from gtrig.sim.map import write_maps

    write_maps(scene, out)


def _scene(cfg: SimConfig, plan: Rig | None) -> Scene:
    """The GT room with its own rig, or with ``plan`` installed in it, as ``cfg.laser`` sets it up."""
    if plan is None:
        return configure_scene(make_scene(cfg.seed), cfg)
    from gtrig.sim.install import install

    return configure_scene(install(plan, cfg.seed), cfg)


def check_path(path: PlannedPath, outline_xy: np.ndarray | None = None) -> None:
    """Refuse, with one line, a path the simulator cannot drive: fewer than 2 poses, stamps not
    increasing, a pose outside the room's walls (``outline_xy`` (V, 2), world xy; None: the GT room's)."""
    from gtrig.sim.gtroom import room_walls
    from gtrig.sim.install import inside_polygon

    t, p = path.stamps_s, path.xytheta
    if t.ndim != 1 or p.shape != (t.size, 3) or t.size < 2:
        raise InputError("--path: the path needs at least 2 poses")
    if not (np.all(np.isfinite(t)) and np.all(np.isfinite(p))):
        raise InputError("--path: a stamp or pose is not a finite number")
    if np.any(np.diff(t) <= 0):
        i = int(np.flatnonzero(np.diff(t) <= 0)[0]) + 2
        raise InputError(f"--path: pose {i}: the stamps must increase")
    walls = room_walls()[:, 0] if outline_xy is None else np.asarray(outline_xy, dtype=float)
    for i, xy in enumerate(p[:, :2]):
        if not inside_polygon(xy, walls):
            raise InputError(f"--path: pose {i + 1} at ({xy[0]:.2f}, {xy[1]:.2f}) m is outside the simulated "
                             "room's walls")


Step = Callable[[Scene, Timeline, Path, SimConfig], None]
STEPS: tuple[tuple[str, Step], ...] = (
    ("rig and truth", _write_rigs_and_truth),
    ("survey", _step_survey),
    ("odometry", _step_odometry),
    ("laser scans", _step_lasers),
    ("calibration images", _step_calibration_images),
    ("validation images", _step_validation_cameras),
    ("run images", _step_run_cameras),
    ("map", _step_map),
)


def _default_draw_settings(cfg: SimConfig) -> dict[str, Any]:
    """The draw settings at their defaults (the measurement noise's and the surfaces' materials'), as
    ``model_dump``'s ``exclude``: named neither in ``sim_config.yaml`` nor in the key, so that a recording
    of the seed's own noise and room has one key and one ``sim_config.yaml`` whichever version of the
    simulator wrote it."""
    unset: dict[str, Any] = {"noise_draw": True} if cfg.noise_draw == 0 else {}
    if cfg.noise_redrawn == "all":
        unset["noise_redrawn"] = True
    if cfg.laser.surface_draw == 0:
        unset["laser"] = {"surface_draw"}
    return unset


def _config_key(cfg: SimConfig, plan: Rig | None = None, path: PlannedPath | None = None) -> str:
    # workers change speed, never output
    # the robot clock's offset joined the settings later: at its default it leaves the key unchanged
    # so did the sweeps' board (chessboard by default)
    skip: dict[str, Any] = {"workers": True, **_default_draw_settings(cfg)}
    if cfg.odometry_clock_offset_s == 0:
        skip["odometry_clock_offset_s"] = True
    if cfg.calib_board == "chessboard":
        skip["calib_board"] = True
    doc: dict[str, Any] = cfg.model_dump(mode="json", exclude=skip)
    # a planned rig and path are part of what is simulated (absent: the key is the built-in scene's)
    if plan is not None:
        doc["plan"] = plan.model_dump(mode="json")
    if path is not None:
        doc["path"] = hashlib.sha256(np.ascontiguousarray(np.column_stack([path.stamps_s, path.xytheta]))
                                     .tobytes()).hexdigest()
    return hashlib.sha256(json.dumps(doc, sort_keys=True).encode()).hexdigest()[:16]


def _read_state(path: Path) -> dict[str, Any]:
    """The resume state, validated: never trusted when it is not what :func:`simulate` writes."""
    try:
        state = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError):
        state = None
    names = {name for name, _ in STEPS}
    if not (isinstance(state, dict) and isinstance(state.get("config"), str) and isinstance(state.get("done"), list)
            and all(isinstance(d, str) and d in names for d in state["done"])):
        raise InputError(f"{path}: a corrupt resume state (not what gtrig sim writes); delete the folder "
                         "(or this file) to simulate afresh")
    return state


def simulate(
    cfg: SimConfig, out_dir: str | Path, on_step: Callable[[str, int, int], None] | None = None,
    plan: Rig | None = None, path: PlannedPath | None = None,
) -> dict[str, float]:
    """Write a full recording of ``cfg.scenario`` into ``out_dir``; returns seconds per step.

    Parameters
    ----------
    cfg : the simulator settings (written to ``sim_config.yaml``).
    out_dir : the recording folder; created if needed. A folder holding a recording made with other
        settings is refused rather than mixed.
    on_step : called as ``on_step(name, index, count)`` before each step (progress display).
    plan : a planned rig installed in the GT room instead of the GT room's own
        (:func:`gtrig.sim.install.install`; refused with one line when the simulator cannot simulate it).
    path : the continuous run's path instead of the built-in one (inside the GT room's walls).
    """
    if cfg.scenario == "outdoor":  # RTK-GPS and odometry on a campus (gtrig.sim.outdoor, docs/gps.md)
        from gtrig.sim.outdoor import simulate_outdoor

        t = time.perf_counter()
        simulate_outdoor(out_dir, seed=cfg.seed, quick=cfg.quick)
        return {"outdoor": time.perf_counter() - t}
    if cfg.scenario != "gtroom":
        raise InputError(f"unknown scenario {cfg.scenario!r}; available: gtroom, outdoor")
    scene = _scene(cfg, plan)
    if path is not None:
        check_path(path, scene.walls[:, 0])
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    state_path = out / STATE_FILE
    key = _config_key(cfg, plan, path)
    done: list[str] = []
    if state_path.exists():
        state = _read_state(state_path)
        if state.get("config") != key:
            raise InputError(f"{out}: holds a recording simulated with other settings; choose another --out")
        done = list(state.get("done", []))
    elif any(out.iterdir()):
        raise InputError(f"{out}: folder is not empty and holds no simulated recording; choose another --out")

    tl = make_timeline(scene, cfg, path)
    timings: dict[str, float] = {}
    for i, (name, step) in enumerate(STEPS):
        if on_step:
            on_step(name, i, len(STEPS))
        if name in done:
            log.info("%s: already written, skipped (resumed run)", name)
            continue
        t = time.perf_counter()
        step(scene, tl, out, cfg)
        timings[name] = time.perf_counter() - t
        done.append(name)
        atomic_write_text(state_path, json.dumps({"config": key, "done": done}))
    return timings
