"""GTlaser benchmark: localized share, errors and NEES against speed, with Open3D's ICP.

For each scenario and seed: the simulated GT room (people walking, uneven floor, mixed pixels,
reflectivity bias, scanner clock offsets of 2 ms), a background sequence, and the continuous run,
driven as the scenario says (``cruise``: 0.3 m/s; ``agile``: up to 1.5 m/s, 1 m/s^2, 2 rad/s;
``agile-blocked``: scanner 0 half blocked by clutter; ``agile-end-stamps``: scans stamped at the end of
the sweep; ``agile-two-fabrics``: a hull with dark and light sides; ``agile-2mps``: up to 2 m/s at
1.5 m/s^2; ``agile-one-clock``: the scanners' clock offsets zeroed; ``agile-common-clock``,
``agile-clock-differences``: only their mean, only their differences; ``agile-noise-only``: 1 cm range
noise and nothing else; ``agile-ideal``: exact scans (the yaw budget); ``agile-synced``,
``agile-blocked-synced``: each scanner's offset measured by the sync stage's fit against a stand-in for
GTvision and removed before tracking, as the pipeline's laser-clock stage does (gtrig.laser.clock);
``agile-middle-stamps``: stamped at the middle; ``agile-simultaneous``: every beam of a scan fired at
once, the rig saying so; ``agile-simultaneous-told-sweep``, ``agile-sweep-told-simultaneous``: the rig
declaring the other timing (the beam timing check of gtrig.laser.beam_timing should name every scanner);
``agile-glossy-fabrics``: dark and light sides 3 cm apart in range bias; ``like-issue-19``: those fabrics,
1 % dropouts, up to 0.9 m/s). The scanners are calibrated from the background sequence (nominal poses
3 cm / 2 deg off), then the run is tracked with the calibrated poses and with the true ones. The peer is Open3D's
point-to-point ``registration_icp`` (outline points of the hull to the same foreground points, started
from its own previous pose), else a SciPy KD-tree ICP; the table says which.

The room's surfaces range with the biases of their materials, the same in every run of a seed's room, so
a seed is one draw of the calibration's error: ``--surface-draws N`` runs each scenario and seed in N rooms
whose walls' and boxes' materials (``laser.surface_draw``) and noise are drawn anew, and summarises the
NEES / dof over them (the network's common shift and rotation, its scanners jointly, the track's calibration
share and the track) with 95 % intervals; ``--calibration-draws N`` only calibrates, in N such rooms per seed.

    python bench/laser.py [--seeds 0 1 2] [--scenarios cruise agile agile-blocked] [--duration S]
                          [--no-peer] [--by-turn-rate] [--surface-draws N] [--calibration-draws N]
"""

from __future__ import annotations

import argparse
import dataclasses
import time

import numpy as np

from gtrig.evaluate.gt_aware import batch_interval
from gtrig.geometry import T_to_se2, wrap_angle
from gtrig.io.scans import ScanLog
from gtrig.laser.background import build_background
from gtrig.laser.beam_timing import check_beam_timing, timing_check
from gtrig.laser.calibrate import calibrate_scanners
from gtrig.laser.clock import ScannerClock, scanners_on_clock
from gtrig.laser.foreground import foreground_mask, foreground_threshold
from gtrig.laser.fuse import frame_points
from gtrig.laser.hull_icp import HullModel
from gtrig.laser.synth import cast_rays, hull_segments_world
from gtrig.laser.track import OK, TrackSettings, track_frames
from gtrig.sim.config import LaserSimConfig, MotionSimConfig, SimConfig
from gtrig.sim.gtroom import VALIDATION_POSES, continuous_path, make_scene
from gtrig.sim.lasers import configure_scene, simulate_fixed_scans, with_scanner_stamp_sigma
from gtrig.sim.motion import RobotMotion, agile_path, static_motion


def visible_sides(rig, xytheta: np.ndarray, min_hits: int = 3) -> np.ndarray:
    """Hull sides (N,) hit by at least ``min_hits`` beams of some scanner at the true poses (hull only)."""
    out = np.zeros(len(xytheta), dtype=int)
    for k, pose in enumerate(xytheta):
        segs = hull_segments_world(rig.robot.hull, pose)
        hits = np.zeros(4, dtype=int)
        for s in rig.laser_scanners:
            T = s.T_world_scanner.matrix()
            a = s.angles_rad + np.arctan2(T[1, 0], T[0, 0])
            d = np.column_stack([np.cos(a), np.sin(a)])
            r = cast_rays(T[:2, 3], d, segs, s.range_max_m)
            hit = np.isfinite(r)
            if hit.any():
                p = T[:2, 3] + r[hit, None] * d[hit]
                # assign each hit to the side whose line it lies on
                e = segs[:, 1] - segs[:, 0]
                n = np.column_stack([e[:, 1], -e[:, 0]]) / np.linalg.norm(e, axis=1)[:, None]
                dist = np.abs(np.einsum("kj,pj->pk", n, p) - np.einsum("kj,kj->k", n, segs[:, 0]))
                side = np.argmin(dist, axis=1)
                hits = np.maximum(hits, np.bincount(side, minlength=4))
        out[k] = int(np.sum(hits >= min_hits))
    return out


def hull_model_points(model: HullModel, step_m: float = 0.01) -> np.ndarray:
    pts = []
    for k in range(4):
        n = max(2, int(model.lengths[k] / step_m))
        u = np.linspace(0, 1, n, endpoint=False)[:, None]
        pts.append(model.corners_xy[k] + u * (np.roll(model.corners_xy, -1, axis=0)[k] - model.corners_xy[k]))
    return np.concatenate(pts)


def baseline_icp(fp, model: HullModel, init: np.ndarray, first: int, gate_m: float = 0.6):
    """Point-to-point ICP per frame (model outline points -> foreground points near the previous pose)."""
    try:
        import open3d as o3d

        name = f"Open3D {o3d.__version__} registration_icp (point-to-point)"
    except Exception:  # noqa: BLE001
        o3d = None
        name = "SciPy cKDTree point-to-point ICP"
    from scipy.spatial import cKDTree

    mp = hull_model_points(model)
    out = np.full((fp.n_frames, 3), np.nan)
    pose = init.copy()
    if o3d is not None:
        src = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(np.column_stack([mp, np.zeros(len(mp))])))
        crit = o3d.pipelines.registration.ICPConvergenceCriteria(max_iteration=30)
        est = o3d.pipelines.registration.TransformationEstimationPointToPoint()
    t0 = time.perf_counter()
    for k in range(first, fp.n_frames):
        q = fp.xy_world[fp.frame(k)]
        q = q[np.hypot(*(q - pose[:2]).T) < gate_m]
        if len(q) < 6:
            continue
        c, s = np.cos(pose[2]), np.sin(pose[2])
        T0 = np.eye(4)
        T0[:2, :2] = [[c, -s], [s, c]]
        T0[:2, 3] = pose[:2]
        if o3d is not None:
            tgt = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(np.column_stack([q, np.zeros(len(q))])))
            # the model's points that face the data are matched to the data (target = data)
            reg = o3d.pipelines.registration.registration_icp(src, tgt, 0.1, T0, est, crit)
            T = np.asarray(reg.transformation)
        else:
            tree = cKDTree(q)
            T = T0
            for _ in range(30):
                m = mp @ T[:2, :2].T + T[:2, 3]
                d, i = tree.query(m, distance_upper_bound=0.1)
                ok = np.isfinite(d)
                if ok.sum() < 3:
                    break
                a, b = m[ok], q[i[ok]]
                ca, cb = a.mean(0), b.mean(0)
                U, _, Vt = np.linalg.svd((a - ca).T @ (b - cb))
                R = Vt.T @ U.T
                if np.linalg.det(R) < 0:
                    Vt[1] *= -1
                    R = Vt.T @ U.T
                dT = np.eye(4)
                dT[:2, :2] = R
                dT[:2, 3] = cb - R @ ca
                T = dT @ T
        pose = np.array([T[0, 3], T[1, 3], pose[2] + wrap_angle(np.arctan2(T[1, 0], T[0, 0]) - pose[2])])
        out[k] = pose
    return out, time.perf_counter() - t0, name


def validation(vals, motion, intervals, scs, bgm, model: HullModel) -> dict:
    """Track the static validation sequence; errors per pose (median over its frames). Poses entered after
    a long carry are ``AMBIGUOUS`` (pi symmetry): their error is taken modulo the symmetry, i.e. against
    the twin pose nearest the truth."""
    masks = [foreground_mask(vals[s.name].ranges_m, foreground_threshold(b)) for s, b in zip(scs, bgm, strict=True)]
    fp = frame_points(scs, [vals[s.name].stamps_s for s in scs], [vals[s.name].ranges_m for s in scs], masks)
    res = track_frames(fp, model, TrackSettings())
    tru = motion.planar(res.stamps_s)
    centre = model.corners_xy.mean(axis=0)
    have = np.isfinite(res.xytheta[:, 0])
    pos, yaw, status = [], [], []
    for a, b in intervals:
        m = have & (res.stamps_s >= a) & (res.stamps_s <= b)
        if not m.any():
            pos.append(np.nan)
            yaw.append(np.nan)
            status.append(-1)
            continue
        est, t = res.xytheta[m], tru[m]
        errs = []
        for turn in (0.0, np.pi):
            th = est[:, 2]
            R = np.stack([[np.cos(th), -np.sin(th)], [np.sin(th), np.cos(th)]]).transpose(2, 0, 1)
            xy = est[:, :2] + (2 * R @ centre if turn else 0.0)
            errs.append((np.hypot(*(xy - t[:, :2]).T), np.abs(wrap_angle(th + turn - t[:, 2]))))
        e = min(errs, key=lambda z: np.median(z[1]))  # the twin nearest in heading
        pos.append(float(np.median(e[0])))
        yaw.append(float(np.median(e[1])))
        status.append(int(np.bincount(res.status[m]).argmax()))
    pos_a, yaw_a, st_a = np.array(pos), np.array(yaw), np.array(status)
    return {
        "n": len(intervals),
        "found": int(np.sum(np.isfinite(pos_a))),
        "ok": int(np.sum(st_a == OK)),
        "ambiguous": int(np.sum(st_a == 3)),
        "degenerate": int(np.sum(st_a == 1)),
        "pos_mm": 1000 * float(np.nanmean(pos_a)),
        "pos_max_mm": 1000 * float(np.nanmax(pos_a)),
        "yaw_deg": float(np.degrees(np.nanmean(yaw_a))),
        "wrong_5cm": int(np.sum(pos_a > 0.05)),
    }


TURN_RATE_EDGES = (0.0, 0.25, 0.75, 1.25, 1.75, np.inf)  # rad/s


def yaw_by_turn_rate(err_rad: np.ndarray, rate_radps: np.ndarray) -> dict:
    """Where the yaw error piles up: mean |yaw error| (deg) and share of frames per bin of |true yaw rate|
    (:data:`TURN_RATE_EDGES`), and the least-squares slope of the signed error on the yaw rate, in ms: a
    track whose clock runs ``tau`` late shows ``err = -tau * rate`` (the lag it would take)."""
    a = np.abs(rate_radps)
    bins = []
    for lo, hi in zip(TURN_RATE_EDGES[:-1], TURN_RATE_EDGES[1:], strict=True):
        m = (a >= lo) & (a < hi)
        bins.append((float(np.mean(m)), float(np.degrees(np.mean(np.abs(err_rad[m])))) if m.any() else float("nan")))
    slope = -float(np.sum(err_rad * rate_radps) / max(float(np.sum(rate_radps**2)), 1e-12))
    return {"bins": bins, "lag_ms": 1000 * slope}


def vision_stand_in(mot: RobotMotion, t_end: float, jitter_s: float, seed: int, rate_hz: float = 30.0,
                    share: float = 0.4, sigma_xy_m: float = 1.5e-3, sigma_th_rad: float = np.radians(0.035),
                    corr_s: float = 0.5):
    """A stand-in for GTvision's run track, the sync stage's reference for the scanners (no images are
    rendered in this bench): the true pose at ``share`` of ``rate_hz`` instants (the full recordings
    localize 38-39 % of 31 Hz), each taken at its stamp plus a camera jitter, with an error of
    ``sigma_xy_m`` / ``sigma_th_rad`` per axis, half of it white and half slow (correlation time
    ``corr_s``, a marker's calibration error while it stays in view), and that covariance with it;
    on the GT clock, as the simulated cameras are."""
    from gtrig.trajectory import PoseTrack

    rng = np.random.default_rng(seed)
    t = np.arange(0.05, t_end - 0.05, 1.0 / rate_hz)
    t = t[rng.random(t.size) < share]
    true = mot.planar(t + rng.normal(0.0, jitter_s, t.size) / np.sqrt(2.0))
    sig = np.array([sigma_xy_m, sigma_xy_m, sigma_th_rad])
    a = np.exp(-np.diff(t, prepend=t[0]) / corr_s)
    slow = np.zeros((t.size, 3))
    w = rng.normal(size=(t.size, 3))
    for k in range(1, t.size):
        slow[k] = a[k] * slow[k - 1] + np.sqrt(1 - a[k] ** 2) * w[k]
    err = sig * (rng.normal(size=(t.size, 3)) + slow) / np.sqrt(2.0)
    cov = np.broadcast_to(np.diag(sig**2), (t.size, 3, 3)).copy()
    return PoseTrack.from_xytheta(t, true + err, cov=cov, cov_kind="xyyaw", source="GTvision")


def measured_clocks(fp, vision, corners_xy: np.ndarray) -> dict[str, ScannerClock]:  # noqa: ANN001
    """Each scanner's offset to ``vision``'s clock as the pipeline's sync stage measures it
    (:func:`gtrig.sync.sensors.scanner_offsets` on GTlaser's framed returns against ``vision``
    smoothed), as :func:`gtrig.laser.clock.clocks_from_sync` reads it from ``sync.yaml``."""
    from gtrig.fusion.measurements import fixes_from_track
    from gtrig.laser.clock import clocks_from_sync
    from gtrig.sync.reference import reference_track
    from gtrig.sync.returns import ScannerReturns
    from gtrig.sync.scanners import scanner_offsets

    est = scanner_offsets(ScannerReturns.from_framed(fp), reference_track([fixes_from_track(vision, "vision")]),
                          corners_xy)
    doc = {e.source: {"verdict": e.verdict, "offset_to_vision_s": e.offset_s, "ci95_to_vision_s": list(e.ci95_s)}
           for e in est}
    return clocks_from_sync(doc, "vision")


def network_errors(cal, cov_xytheta: np.ndarray, true_scanners) -> dict:  # noqa: ANN001
    """The calibrated scanners' planar pose errors (world x, y m, theta rad) against the true ones and what
    the calibration states of them: the joint NEES / dof (3 S dof), and the network's common shift and
    rotation (the mean of the scanners' errors: a rigid motion of the whole network about its scanners'
    centroid, which every robot pose inherits) with its stated sd and NEES / dof (3 dof)."""
    e = []
    for s, t in zip(cal, true_scanners, strict=True):
        d = T_to_se2(s.T_world_scanner.matrix()) - T_to_se2(t.T_world_scanner.matrix())
        d[2] = wrap_angle(d[2])
        e.append(d)
    z = np.concatenate(e)
    P = np.tile(np.eye(3), len(e)) / len(e)
    g, Cg = P @ z, P @ cov_xytheta @ P.T
    return {"joint_nees_dof": float(z @ np.linalg.solve(cov_xytheta, z)) / z.size, "common": g,
            "common_sd": np.sqrt(np.diag(Cg)), "common_nees_dof": float(g @ np.linalg.solve(Cg, g)) / 3}


def _scene_and_config(seed: int, laser: dict, motion: dict | None, draw: int) -> tuple:
    """The configured scene (its rigs stating the scanners' clock sigma, as a recording's rig.yaml does) and
    the settings; ``draw`` > 0: the surfaces' materials and the measurement noise both redrawn."""
    if draw:
        laser = {**laser, "surface_draw": draw}
    cfg = SimConfig(seed=seed, noise_draw=draw, laser=LaserSimConfig(**laser),
                    motion=MotionSimConfig(**(motion or {})))
    sc = configure_scene(make_scene(seed), cfg)
    sc = dataclasses.replace(sc, rig_true=with_scanner_stamp_sigma(sc.rig_true),
                             rig_nominal=with_scanner_stamp_sigma(sc.rig_nominal))
    return sc, cfg


def _calibrated_network(sc, cfg: SimConfig, seed: int) -> tuple:  # noqa: ANN001
    """The background sequence, the scanners calibrated from it and the report, the CPU seconds the
    calibration took, and :func:`network_errors`."""
    bgs, _ = simulate_fixed_scans(sc, None, np.array([[-10.0, -10.0 + cfg.background_s]]), cfg, seed * 10 + 1)
    obj = [b.corners_xy() for b in sc.boxes if b.name.startswith("calib_object")]
    nom = sc.rig_nominal.laser_scanners
    t0 = time.process_time()
    cal, rep = calibrate_scanners(nom, [build_background(bgs[s.name].ranges_m, s) for s in nom], obj)
    t_cal = time.process_time() - t0
    return bgs, cal, rep, t_cal, network_errors(cal, rep.cov_xytheta, sc.rig_true.laser_scanners)


def calibration_draw(seed: int, draw: int) -> dict:
    """``{"seed", "network"}``: :func:`network_errors` of the scanners calibrated from one background
    sequence of the room of ``seed`` with its surfaces' materials and noise of ``draw`` (0: the seed's own)."""
    sc, cfg = _scene_and_config(seed, {}, None, draw)
    return {"seed": seed, "network": _calibrated_network(sc, cfg, seed)[-1]}


def run_seed(seed: int, duration: float | None, laser: dict | None = None, motion: dict | None = None,
             calibrate: bool = True, validate: bool = True, peer: bool = True, draw: int = 0) -> dict:
    laser = dict(laser or {})
    ideal = bool(laser.pop("ideal", False))  # exact geometry: no noise, bias, mixed pixels, clock offsets
    declared = laser.pop("declared", None)  # the rig's beam timing when it differs from the scanners'
    clocks = laser.pop("clocks", None)  # "common": the offsets' mean only; "differences": mean removed;
    # "synced": each scanner's offset measured by the sync stage's fit against a GTvision stand-in and removed
    sc, cfg = _scene_and_config(seed, laser, motion, draw)
    if cfg.motion.profile == "agile":
        m = cfg.motion
        ts, xyth = agile_path(VALIDATION_POSES, m.speed_mps, m.accel_mps2, m.lat_accel_mps2,
                              m.yaw_rate_max_radps, duration_s=duration)
    else:
        ts, xyth = continuous_path(speed_mps=cfg.motion.speed_mps, duration_s=duration)
    mot = RobotMotion(ts, xyth, sc.floor)
    bgs, cal, rep, t_cal, network = _calibrated_network(sc, cfg, seed)
    runs, info = simulate_fixed_scans(sc, mot, np.array([[0.0, ts[-1]]]), cfg, seed * 10 + 3, ideal=ideal)
    if clocks in ("common", "differences"):  # the same scans re-stamped: an offset only shifts a scanner's stamps
        off = info.clock_offsets_s
        mean = float(np.mean(list(off.values())))
        runs = {k: ScanLog(v.stamps_s - off[k] + (mean if clocks == "common" else off[k] - mean), v.ranges_m)
                for k, v in runs.items()}
    if validate:
        val, val_iv = static_motion(VALIDATION_POSES, sc.floor, cfg.static_pose_s)
        vals, _ = simulate_fixed_scans(sc, val, val_iv, cfg, seed * 10 + 2)
    cal_err = []
    for s, t in zip(cal, sc.rig_true.laser_scanners, strict=True):
        a, b = s.T_world_scanner.matrix(), t.T_world_scanner.matrix()
        cal_err.append(
            (
                np.hypot(*(a[:2, 3] - b[:2, 3])),
                abs(wrap_angle(np.arctan2(a[1, 0], a[0, 0]) - np.arctan2(b[1, 0], b[0, 0]))),
            )
        )
    out = {
        "seed": seed,
        "cal_pos_mm": 1000 * np.mean([e[0] for e in cal_err]),
        "cal_yaw_deg": np.degrees(np.mean([e[1] for e in cal_err])),
        "cal_s": t_cal,
        "network": network,
    }
    model = HullModel.from_hull(sc.rig_true.robot.hull)
    if clocks == "synced":
        out["true_offsets_ms"] = {k: 1000 * v for k, v in info.clock_offsets_s.items()}
        vision_ref = vision_stand_in(mot, ts[-1], cfg.camera.stamp_jitter_s, seed * 10 + 4)
    tracked: dict = {}
    for label, scs in (("calibrated", cal), ("true", sc.rig_true.laser_scanners)):
        if declared:
            scs = tuple(s.model_copy(update=declared) for s in scs)
        t0 = time.perf_counter()
        bgm = [build_background(bgs[s.name].ranges_m, s) for s in scs]
        masks = [
            foreground_mask(runs[s.name].ranges_m, foreground_threshold(b))
            for s, b in zip(scs, bgm, strict=True)
        ]
        fp = frame_points(
            scs, [runs[s.name].stamps_s for s in scs], [runs[s.name].ranges_m for s in scs], masks
        )
        if clocks == "synced":  # as the pipeline does after its sync stage (gtrig.laser.clock)
            cl = measured_clocks(fp, vision_ref, sc.rig_true.robot.hull.corners_xy())
            out.setdefault("measured_offsets_ms", {})[label] = {k: (1000 * c.offset_s, 1000 * c.sigma_s)
                                                                 for k, c in cl.items()}
            scs, logs = scanners_on_clock(scs, runs, cl)
            fp = frame_points(scs, [logs[s.name].stamps_s for s in scs], [logs[s.name].ranges_m for s in scs],
                              masks)
        res = track_frames(fp, model, TrackSettings(), rep.cov_xytheta if label == "calibrated" else None)
        dt = time.perf_counter() - t0
        tracked[label] = res
        n_scans = sum(len(runs[s.name].stamps_s) for s in scs)
        tru = mot.planar(res.stamps_s)
        tru[:, 2] = np.unwrap(tru[:, 2])
        ok = res.status == OK
        e = np.hypot(*(res.xytheta[ok, :2] - tru[ok, :2]).T)
        ey = np.abs(wrap_angle(res.xytheta[ok, 2] - tru[ok, 2]))
        er = np.hypot(*(res.raw_xytheta[ok, :2] - tru[ok, :2]).T)
        eyr = np.abs(wrap_angle(res.raw_xytheta[ok, 2] - tru[ok, 2]))
        z = res.xytheta[ok] - tru[ok]
        z[:, 2] = wrap_angle(z[:, 2])
        nees = np.einsum("ni,nij,nj->n", z, np.linalg.inv(res.cov_xytheta[ok]), z)
        rate = np.gradient(tru[:, 2], res.stamps_s)  # the true yaw rate at each frame, rad/s
        ey_signed = wrap_angle(res.xytheta[ok, 2] - tru[ok, 2])
        vis = visible_sides(sc.rig_true, tru)
        two = vis >= 2
        deg = res.status == 1
        e_all = np.hypot(*(res.xytheta[:, :2] - tru[:, :2]).T)
        out[label] = {
            "scans_per_s": n_scans / dt,
            "frames": len(res),
            "ok": int(ok.sum()),
            "deg": int(deg.sum()),
            "pos_mm": 1000 * e.mean(),
            "yaw_deg": np.degrees(ey.mean()),
            "raw_pos_mm": 1000 * er.mean(),
            "raw_yaw_deg": np.degrees(eyr.mean()),
            "nees": nees.mean(),
            "nees_dof": batch_interval(nees / 3),
            "timing": timing_check(check_beam_timing(fp, res.xytheta, ok, res.track_id, scs, model)),
            "nees_xy": float(np.mean(np.einsum(
                "ni,nij,nj->n", z[:, :2], np.linalg.inv(res.cov_xytheta[ok][:, :2, :2]), z[:, :2]))),
            "nees_th": float(np.mean(z[:, 2] ** 2 / res.cov_xytheta[ok][:, 2, 2])),
            "ok_max_mm": 1000 * float(e.max()) if e.size else float("nan"),
            "speed_max": float(np.max(np.hypot(*np.gradient(xyth[:, :2], ts, axis=0).T))),
            "loc_2sides": float(np.mean(ok[two])) if two.any() else float("nan"),
            "ok_wrong_5cm": int(np.sum(e > 0.05)),
            "deg_wrong_5cm": int(np.sum(e_all[deg] > 0.05)),
            "by_rate": yaw_by_turn_rate(ey_signed, rate[ok]),
        }
        if label == "calibrated" and validate:
            out["validation"] = validation(vals, val, val_iv, scs, bgm, model)
        if label == "true" and peer:
            first = int(np.flatnonzero(ok)[0])
            bl, t_bl, name = baseline_icp(fp, model, res.raw_xytheta[first], first)
            m = np.isfinite(bl[:, 0]) & ok
            eb = np.hypot(*(bl[m, :2] - tru[m, :2]).T)
            eyb = np.abs(wrap_angle(bl[m, 2] - tru[m, 2]))
            ebb = np.abs(wrap_angle(2 * (bl[m, 2] - tru[m, 2]))) / 2  # modulo pi
            out["baseline"] = {
                "name": name,
                "frames_per_s": np.sum(np.isfinite(bl[:, 0])) / t_bl,
                "pos_mm": 1000 * eb.mean(),
                "yaw_deg": np.degrees(eyb.mean()),
                "yaw_mod_pi_deg": np.degrees(ebb.mean()),
                "n": int(m.sum()),
                "share_5cm": float(np.mean(np.where(
                    np.isfinite(bl[ok, 0]), np.hypot(*(bl[ok, :2] - tru[ok, :2]).T), np.inf) < 0.05)),
                "frames_track_per_s": len(res) / dt,
            }
    out["calibration_share"] = calibration_share(tracked["calibrated"], tracked["true"])
    return out


def calibration_share(cal, true) -> dict:  # noqa: ANN001 (TrackResult)
    """What the scanners' calibration error did to the track, against what GTlaser states of it: the
    difference (F, 3) between the track on the calibrated scanners and the one on the true scanners (the
    same scans, so the calibration error's effect alone), per frame against ``cov_calibration`` and its
    mean over the frames both localize against ``cov_calibration_shared`` (world x, y m, yaw rad)."""
    both = (cal.status == OK) & (true.status == OK)
    d = cal.xytheta[both] - true.xytheta[both]
    d[:, 2] = wrap_angle(d[:, 2])
    m = d.mean(axis=0)
    S = cal.cov_calibration_shared
    q = np.einsum("ni,nij,nj->n", d, np.linalg.inv(cal.cov_calibration[both]), d) / 3
    return {"mean": m, "stated_sd": np.sqrt(np.diag(S)), "mean_nees_dof": float(m @ np.linalg.solve(S, m) / 3),
            "frame_nees_dof": float(q.mean()), "frame_rms": np.sqrt(np.mean(d**2, axis=0)),
            "frame_sd": np.sqrt(np.mean(np.diagonal(cal.cov_calibration[both], axis1=1, axis2=2), axis=0))}


SCENARIOS = {
    # name: (laser settings, motion settings)
    "cruise": ({}, {}),
    "agile": ({}, {"profile": "agile", "speed_mps": 1.5}),
    "agile-blocked": ({"blocked_scanner": 0, "blocked_fraction": 0.5}, {"profile": "agile", "speed_mps": 1.5}),
    "agile-end-stamps": ({"stamp_at": "end"}, {"profile": "agile", "speed_mps": 1.5}),
    "agile-middle-stamps": ({"stamp_at": "middle"}, {"profile": "agile", "speed_mps": 1.5}),
    # beams fired all at once (a flash device, another simulator), the rig saying so, or the default sweep
    "agile-simultaneous": ({"beam_timing": "simultaneous"}, {"profile": "agile", "speed_mps": 1.5}),
    "agile-simultaneous-told-sweep": ({"beam_timing": "simultaneous", "declared": {"beam_timing": "sweep"}},
                                      {"profile": "agile", "speed_mps": 1.5}),
    "agile-sweep-told-simultaneous": ({"declared": {"beam_timing": "simultaneous"}},
                                      {"profile": "agile", "speed_mps": 1.5}),
    "agile-two-fabrics": ({"gown_reflectivity": (0.15, 0.9, 0.15, 0.9)}, {"profile": "agile", "speed_mps": 1.5}),
    "agile-2mps": ({}, {"profile": "agile", "speed_mps": 2.0, "accel_mps2": 1.5}),
    # the yaw budget: the scanners on one clock (no offsets; the same noise otherwise)
    "agile-one-clock": ({"clock_offset_sigma_s": 0.0}, {"profile": "agile", "speed_mps": 1.5}),
    "agile-common-clock": ({"clocks": "common"}, {"profile": "agile", "speed_mps": 1.5}),
    "agile-clock-differences": ({"clocks": "differences"}, {"profile": "agile", "speed_mps": 1.5}),
    # the scanners' offsets measured against a GTvision stand-in and removed, as the pipeline does after sync
    "agile-synced": ({"clocks": "synced"}, {"profile": "agile", "speed_mps": 1.5}),
    "agile-blocked-synced": ({"blocked_scanner": 0, "blocked_fraction": 0.5, "clocks": "synced"},
                             {"profile": "agile", "speed_mps": 1.5}),
    "agile-noise-only": ({"clock_offset_sigma_s": 0.0, "people": 0, "dropout_prob": 0.0, "mixed_pixels": False,
                          "reflectivity_bias_m": 0.0}, {"profile": "agile", "speed_mps": 1.5}),
    "agile-ideal": ({"ideal": True}, {"profile": "agile", "speed_mps": 1.5}),
    # glossy dark and light fabrics, 3 cm between black and white: the sides' range bias estimated
    "agile-glossy-fabrics": ({"gown_reflectivity": (0.1, 0.9, 0.1, 0.9), "reflectivity_bias_m": 0.03},
                             {"profile": "agile", "speed_mps": 1.5}),
    # the other simulator: up to 0.9 m/s, 1 % dropouts, fabrics of different bias
    "like-issue-19": ({"gown_reflectivity": (0.1, 0.9, 0.1, 0.9), "reflectivity_bias_m": 0.03, "dropout_prob": 0.01},
                      {"profile": "agile", "speed_mps": 0.9}),
}


def _nees(iv) -> str:  # noqa: ANN001
    return f"{iv.value:.2f} [{iv.low:.2f}, {iv.high:.2f}]"


def _print_run(name: str, seed: int, r: dict) -> None:
    """One scenario's row of the table and its calibration share's line."""
    c, t = r["calibrated"], r["true"]
    b = r.get("baseline")
    peer = f"{b['pos_mm']:.1f} | {b['yaw_mod_pi_deg']:.2f} | {100 * b['share_5cm']:.1f} %" if b else "- | - | -"
    print(
        f"| {name} | {seed} | {c['speed_max']:.2f} | {c['frames']} | {100 * c['loc_2sides']:.2f} % | "
        f"{c['pos_mm']:.2f} / {c['ok_max_mm']:.1f} | {c['yaw_deg']:.3f} | "
        f"{_nees(c['nees_dof'])} ({_nees(t['nees_dof'])}) | {c['ok_wrong_5cm']} | {peer} | "
        f"{c['timing'][0]} (max {c['timing'][1]:.1f} sd) |",
        flush=True,
    )
    cs, nw = r["calibration_share"], r["network"]
    print(f"  calibration's share, calibrated minus true scanners' track: mean over the run x / y "
          f"{1e3 * cs['mean'][0]:+.3f} / {1e3 * cs['mean'][1]:+.3f} mm, yaw {1e3 * cs['mean'][2]:+.4f} mrad "
          f"(stated sd {1e3 * cs['stated_sd'][0]:.3f} / {1e3 * cs['stated_sd'][1]:.3f} mm, "
          f"{1e3 * cs['stated_sd'][2]:.4f} mrad; NEES/dof {cs['mean_nees_dof']:.2f}); per frame rms "
          f"{1e3 * cs['frame_rms'][0]:.3f} / {1e3 * cs['frame_rms'][1]:.3f} mm, "
          f"{1e3 * cs['frame_rms'][2]:.4f} mrad (stated {1e3 * cs['frame_sd'][0]:.3f} / "
          f"{1e3 * cs['frame_sd'][1]:.3f} mm, {1e3 * cs['frame_sd'][2]:.4f} mrad; NEES/dof "
          f"{cs['frame_nees_dof']:.2f})", flush=True)
    print(f"  scanners' network: joint NEES/dof {nw['joint_nees_dof']:.2f}; common shift x / y "
          f"{_network_common(nw)}", flush=True)
    if "measured_offsets_ms" in r:
        m = r["measured_offsets_ms"]["calibrated"]
        print("  offsets true / measured (sigma), ms: " + ", ".join(
            f"{k} {r['true_offsets_ms'][k]:+.2f} / {m[k][0]:+.2f} ({m[k][1]:.2f})" if k in m
            else f"{k} {r['true_offsets_ms'][k]:+.2f} / -" for k in r["true_offsets_ms"]), flush=True)


def _network_common(nw: dict) -> str:
    g, sd = 1e3 * nw["common"], 1e3 * nw["common_sd"]
    return (f"{g[0]:+.3f} / {g[1]:+.3f} mm, rotation {g[2]:+.4f} mrad (stated sd {sd[0]:.3f} / {sd[1]:.3f} mm, "
            f"{sd[2]:.4f} mrad; NEES/dof {nw['common_nees_dof']:.2f})")


def _print_by_turn_rate(rates: list) -> None:
    heads = [f"{lo:g}-{hi:g}" if np.isfinite(hi) else f">= {lo:g}"
             for lo, hi in zip(TURN_RATE_EDGES[:-1], TURN_RATE_EDGES[1:], strict=True)]
    print()
    print("Mean |yaw| error (deg) of the OK frames by |true yaw rate| (rad/s), calibrated scanners; in brackets")
    print("the share of frames; lag: the slope of the signed yaw error on the yaw rate (err = -lag * rate).")
    print()
    print("| scenario | seed | " + " | ".join(heads) + " | lag (ms) |")
    print("|---|---|" + "---|" * len(heads) + "---|")
    for name, seed, r in rates:
        br = r["calibrated"]["by_rate"]
        cells = " | ".join(f"{y:.3f} ({100 * f:.0f} %)" for f, y in br["bins"])
        print(f"| {name} | {seed} | {cells} | {br['lag_ms']:+.2f} |", flush=True)


def _draws_summary(label: str, runs: list[dict]) -> None:
    """NEES / dof over independent draws (surfaces' materials and noise), the mean and its 95 % interval
    (Student t over the draws), for the network's common shift and rotation, its scanners jointly and,
    where the run was tracked, the track's calibration share (its mean over the run and per frame) and the
    track itself; and the common shift's rms error against its stated sd."""
    nw = [r["network"] for r in runs]
    g = np.array([n["common"] for n in nw])
    sd = np.array([n["common_sd"] for n in nw])
    rms, st = 1e3 * np.sqrt(np.mean(g**2, axis=0)), 1e3 * np.sqrt(np.mean(sd**2, axis=0))
    rows = {"network's common shift and rotation": [n["common_nees_dof"] for n in nw],
            "scanners jointly": [n["joint_nees_dof"] for n in nw]}
    if "calibration_share" in runs[0]:
        rows["track's calibration share, mean over the run"] = [r["calibration_share"]["mean_nees_dof"]
                                                                for r in runs]
        rows["track's calibration share, per frame"] = [r["calibration_share"]["frame_nees_dof"] for r in runs]
        rows["track, calibrated scanners"] = [r["calibrated"]["nees_dof"].value for r in runs]
    print(f"\n{label}, {len(runs)} draws: NEES / dof, mean over the draws [95 %]")
    for k, v in rows.items():
        print(f"  {k}: {_nees(batch_interval(np.array(v)))}")
    print(f"  common shift rms x / y {rms[0]:.3f} / {rms[1]:.3f} mm, rotation {rms[2]:.4f} mrad "
          f"(stated sd {st[0]:.3f} / {st[1]:.3f} mm, {st[2]:.4f} mrad)", flush=True)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    ap.add_argument("--duration", type=float, default=None, help="seconds of run (default: the whole path)")
    ap.add_argument("--scenarios", nargs="+", default=["cruise", "agile", "agile-blocked"], choices=SCENARIOS)
    ap.add_argument("--blocked-seeds", type=int, nargs="+", default=[0])
    ap.add_argument("--no-peer", action="store_true", help="skip Open3D's ICP (its columns left empty)")
    ap.add_argument("--synced", action="store_true",
                    help="every scenario with its scanners' offsets measured and removed (as agile-synced)")
    ap.add_argument("--by-turn-rate", action="store_true",
                    help="also print, per run, the mean |yaw| error by |true yaw rate| and the apparent lag")
    ap.add_argument("--surface-draws", type=int, default=0, metavar="N",
                    help="run every scenario and seed in N rooms whose surfaces' materials (range biases) and "
                         "noise are drawn anew (draws 1..N) instead of the seed's own, and summarise over them")
    ap.add_argument("--calibration-draws", type=int, default=0, metavar="N",
                    help="only calibrate the scanners, in N drawn rooms per seed, and summarise over them")
    a = ap.parse_args()
    if a.calibration_draws:
        runs = [calibration_draw(seed, k) for seed in a.seeds for k in range(1, a.calibration_draws + 1)]
        _draws_summary(f"the scanners' calibration, seeds {a.seeds}", runs)
        print(f"\nCPU time of this process: {time.process_time():.0f} s")
        return
    print("GTlaser benchmark: 4 scanners x 75 Hz, people walking, uneven floor; the whole run unless --duration")
    print("Same foreground points for both methods; Open3D is started from GTlaser's first pose and then")
    print("from its own previous one (no prediction); its yaw is taken modulo 180 deg.")
    print()
    print("| scenario | seed | max speed (m/s) | frames | localized, >=2 sides | pos mean / max OK (mm) "
          "| yaw mean (deg) "
          "| NEES/dof calibrated [95 %] (true [95 %]) | OK > 5 cm | peer pos (mm) | peer yaw mod 180 (deg) "
          "| peer share < 5 cm | beam timing check (calibrated) |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    rates, drawn = [], {}
    draws = range(1, a.surface_draws + 1) if a.surface_draws else (0,)
    for name in a.scenarios:
        laser, motion = SCENARIOS[name]
        if a.synced:
            laser = {**laser, "clocks": "synced"}
        seeds = a.blocked_seeds if "blocked" in name else a.seeds
        for seed in seeds:
            for k in draws:
                r = run_seed(seed, a.duration, laser, motion, validate=False, peer=not a.no_peer, draw=k)
                _print_run(f"{name}, surfaces {k}" if k else name, seed, r)
                rates.append((name, seed, r))
                drawn.setdefault(name, []).append(r)
    if a.surface_draws:
        for name, runs in drawn.items():
            _draws_summary(f"{name}, seeds {sorted({r['seed'] for r in runs})}", runs)
    if a.by_turn_rate:
        _print_by_turn_rate(rates)
    print(f"\nCPU time of this process: {time.process_time():.0f} s")


if __name__ == "__main__":
    main()
