"""Where one more camera or fixed laser scanner helps most: a greedy search over candidate mounting poses.

Candidates stand on the area's outline (pulled ``inset_m`` inside it), spaced evenly along it, each
aimed at the area's centre or at the centre of the cells that miss the target: cameras at
``height_m``, looking at that point on the floor; scanners at their own height (the rig's first
scanner's by default), the middle of their fan towards it. Each round adds, among the kinds still to
add, the candidate that most increases the share of cells meeting the target at every heading (ties
broken by the mean of the worst fused position sigma over the target, capped at 10).

Information form: a sensor adds its own information to every pose's normal matrices (GTvision's over
the robot pose and the markers' corrections, its own correction eliminated; the hull ICP's over the
pose and the hull sides' range biases), so a candidate is scored from the rig's matrices, computed once
per round, plus the candidate's own at the poses it sees; nothing else is predicted again. The poses
are visited a few whole cells (all their headings) at a time, every candidate per visit, so memory
stays bounded.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Literal

import numpy as np

from gtrig import geometry as geo
from gtrig.errors import InputError
from gtrig.plan.laser import LaserInformation, laser_covariance, laser_information, predict_laser, scanner_rate_hz
from gtrig.plan.maps import summarize_target
from gtrig.plan.predict import PlanResult, PlanSettings, fuse_sources
from gtrig.plan.visibility import camera_sight
from gtrig.plan.vision import (
    marker_part,
    planar_covariance,
    pose_covariance,
    predict_vision,
    prior_information,
    vision_information,
)
from gtrig.rig.models import Camera, LaserScanner, Pose, Rig
from gtrig.vision.observations import VisionModel

SensorKind = Literal["camera", "scanner"]


@dataclass(frozen=True)
class Suggestion:
    """One sensor added: its kind and model (with its pose), the shares meeting the target before and
    after, the candidates tried, and the rig and plan with it."""

    kind: SensorKind
    sensor: Camera | LaserScanner
    share_before: float
    share_after: float
    n_candidates: int
    rig: Rig
    plan: PlanResult

    @property
    def position_m(self) -> tuple[float, float, float]:
        """The sensor's position (x, y, z), world frame, metres."""
        T = self.sensor.T_world_cam if isinstance(self.sensor, Camera) else self.sensor.T_world_scanner
        x, y, z = T.xyz
        return float(x), float(y), float(z)


def outline_points(polygon_xy: np.ndarray, n: int, inset_m: float) -> np.ndarray:
    """``n`` points (n, 2) evenly spaced along the polygon's perimeter, moved ``inset_m`` towards its centroid."""
    P = np.asarray(polygon_xy, dtype=float)
    seg = np.roll(P, -1, axis=0) - P
    L = np.linalg.norm(seg, axis=1)
    s = (np.arange(n) + 0.5) * L.sum() / n
    k = np.searchsorted(np.cumsum(L), s, side="right")
    k = np.minimum(k, len(P) - 1)
    f = (s - (np.cumsum(L) - L)[k]) / L[k]
    pts = P[k] + f[:, None] * seg[k]
    c = P.mean(axis=0)
    d = c - pts
    return pts + inset_m * d / np.maximum(np.linalg.norm(d, axis=1, keepdims=True), 1e-9)


def candidate_cameras(template: Camera, polygon_xy: np.ndarray, aims_xy: list[np.ndarray], height_m: float,
                      n_positions: int, inset_m: float = 0.1, name: str = "suggested") -> list[Camera]:
    """Cameras like ``template`` (its lens and image) on the outline at ``height_m``, aimed at each of
    ``aims_xy`` (points on the floor)."""
    out = []
    for p in outline_points(polygon_xy, n_positions, inset_m):
        for aim in aims_xy:
            T = geo.look_at(np.r_[p, height_m], np.r_[aim, 0.0])
            out.append(template.model_copy(update={"name": name, "T_world_cam": Pose.from_matrix(T)}))
    return out


def candidate_scanners(template: LaserScanner, polygon_xy: np.ndarray, aims_xy: list[np.ndarray], height_m: float,
                       n_positions: int, inset_m: float = 0.1, name: str = "suggested_laser") -> list[LaserScanner]:
    """Scanners like ``template`` (its beams, range and noise) on the outline at ``height_m``, level, the
    middle of their fan towards each of ``aims_xy``."""
    fan_mid = template.angle_min_rad + 0.5 * template.angle_increment_rad * (template.beams - 1)
    out = []
    for p in outline_points(polygon_xy, n_positions, inset_m):
        for aim in aims_xy:
            yaw = float(np.arctan2(aim[1] - p[1], aim[0] - p[0])) - fan_mid
            pose = Pose(xyz=(float(p[0]), float(p[1]), float(height_m)), rpy_deg=(0.0, 0.0, float(np.degrees(yaw))))
            out.append(template.model_copy(update={"name": name, "T_world_scanner": pose}))
    return out


def _with_camera(rig: Rig, plan: PlanResult, cam: Camera, settings: PlanSettings) -> tuple[Rig, PlanResult]:
    """The rig and plan with ``cam`` added (vision predicted again where it sees a marker)."""
    rig2 = rig.model_copy(update={"cameras": (*rig.cameras, cam)})
    model = VisionModel.from_rig(rig2)
    poses = plan.poses_xytheta
    corners = np.stack([model.corners_robot[m.id] for m in rig.robot.markers])
    sight = camera_sight(model.cameras[cam.name], corners, poses, rig.robot.hull, settings.vision.margin_px,
                         settings.vision.min_side_px)
    hit = np.flatnonzero(sight.visible.any(axis=1))
    cov_v, pose_v = plan.vision_for_fusion.copy(), plan.cov["vision"].copy()
    per_v = np.full(cov_v.shape, np.nan) if plan.vision_persistent is None else plan.vision_persistent.copy()
    views = np.column_stack([plan.views, np.zeros(poses.shape[0], dtype=plan.views.dtype)])
    side = np.column_stack([plan.side_px, np.zeros(poses.shape[0], dtype=plan.side_px.dtype)])
    step = max(1, int(settings.chunk_poses))
    for a in range(0, hit.size, step):
        h = hit[a:a + step]
        pv = predict_vision(rig2, poses[h], settings.vision, model)
        cov_v[h], views[h], side[h], per_v[h] = pv.cov_xytheta, pv.views, pv.side_px, pv.cov_persistent_xytheta
        pose_v[h] = pv.cov_of_a_pose
    fused = fuse_sources(rig2, poses, plan.grid.path_velocity, cov_v, plan.cov["laser"], per_v, settings.fusion)
    cov = {"vision": pose_v, "laser": plan.cov["laser"], "fused": fused}
    return rig2, replace(plan, camera_names=(*plan.camera_names, cam.name), cov=cov, views=views, side_px=side,
                         vision_persistent=per_v, vision_instant=None if plan.vision_instant is None else cov_v)


def _with_scanner(rig: Rig, plan: PlanResult, scanner: LaserScanner, settings: PlanSettings) -> tuple[Rig, PlanResult]:
    """The rig and plan with ``scanner`` added (GTlaser predicted again everywhere)."""
    rig2 = rig.model_copy(update={"laser_scanners": (*rig.laser_scanners, scanner)})
    poses = plan.poses_xytheta
    K = poses.shape[0]
    cov_l = np.full((K, 3, 3), np.nan)
    beams = np.zeros((K, len(rig2.laser_scanners)), dtype=plan.beams.dtype)
    sides = np.zeros((K, len(rig2.laser_scanners)), dtype=plan.sides.dtype)
    step = max(1, int(settings.chunk_poses))
    for a in range(0, K, step):
        pl = predict_laser(rig2, poses[a:a + step], settings.laser)
        cov_l[a:a + step], beams[a:a + step], sides[a:a + step] = pl.cov_xytheta, pl.beams, pl.sides
    fused = fuse_sources(rig2, poses, plan.grid.path_velocity, plan.vision_for_fusion, cov_l, plan.vision_persistent,
                         settings.fusion)
    cov = {"vision": plan.cov["vision"], "laser": cov_l, "fused": fused}
    return rig2, replace(plan, scanner_names=(*plan.scanner_names, scanner.name), cov=cov, beams=beams, sides=sides)


def _sigmas(cov_xytheta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(K,) position sigma (sqrt of the largest x-y eigenvalue, m) and yaw sigma (rad); inf: uncovered."""
    ok = np.all(np.isfinite(cov_xytheta), axis=(1, 2))
    sxy, syaw = np.full(ok.shape[0], np.inf), np.full(ok.shape[0], np.inf)
    if ok.any():
        sxy[ok] = np.sqrt(np.maximum(np.linalg.eigvalsh(cov_xytheta[ok, :2, :2])[:, -1], 0.0))
        syaw[ok] = np.sqrt(cov_xytheta[ok, 2, 2])
    return sxy, syaw


@dataclass(frozen=True)
class _Candidate:
    """A candidate with what scoring it needs: the rig with it and its vision model (camera), or a rig
    holding it alone (scanner)."""

    kind: SensorKind
    sensor: Camera | LaserScanner
    rig: Rig
    model: VisionModel | None


def _candidate_fused(c: _Candidate, poses: np.ndarray, chunk: dict[str, np.ndarray], H_vision: np.ndarray | None,
                     laser: LaserInformation | None, settings: PlanSettings) -> tuple[np.ndarray, np.ndarray]:
    """The poses (n,) of a chunk the candidate changes and the fused covariance (n, 3, 3) there, from the
    rig's covariances at the chunk's poses (``chunk``: :func:`_fusion_inputs`), its vision normal matrices
    ``H_vision`` (Kc, D, D, priors included) or laser pieces, plus the candidate's own."""
    cov_v, cov_l, per_v, vel = chunk["vision"], chunk["laser"], chunk["vision_persistent"], chunk.get("velocity")
    if c.kind == "camera":
        assert H_vision is not None and isinstance(c.sensor, Camera)
        own = vision_information(c.rig, poses, settings.vision, c.model, (c.sensor.name,), priors=False)
        hit = np.flatnonzero(own.seen)
        if hit.size == 0:
            return hit, np.zeros((0, 3, 3))
        H = own.H
        H += H_vision[hit]
        cov6 = pose_covariance(H)
        new_v = planar_covariance(cov6)
        return hit, fuse_sources(c.rig, poses[hit], None if vel is None else vel[hit], new_v, cov_l[hit],
                                 marker_part(H, cov6), settings.fusion)
    assert laser is not None
    own_l = laser_information(c.rig, poses, settings.laser)
    hit = np.flatnonzero(own_l.beams[:, 0] > 0)
    if hit.size == 0:
        return hit, np.zeros((0, 3, 3))
    new_l = laser_covariance(laser.take(hit).plus(own_l.take(hit)), scanner_rate_hz(c.rig), settings.laser).cov_xytheta
    return hit, fuse_sources(c.rig, poses[hit], None if vel is None else vel[hit], cov_v[hit], new_l, per_v[hit],
                             settings.fusion)


def _fusion_inputs(plan: PlanResult) -> dict[str, np.ndarray]:
    """Per pose of the plan, what a candidate's fused covariance is made from: the sources' covariances
    (``"vision"``, ``"laser"``, ``"fused"``), GTvision's persistent part (``"vision_persistent"``) and, on
    a path with stamps, the robot's velocity (``"velocity"``)."""
    out = dict(plan.cov)
    out["vision"] = plan.vision_for_fusion
    out["vision_persistent"] = (np.full(plan.cov["vision"].shape, np.nan) if plan.vision_persistent is None
                                else plan.vision_persistent)
    if plan.grid.path_velocity is not None:
        out["velocity"] = plan.grid.path_velocity
    return out


def _cell_results(rig: Rig, cands: list[_Candidate], poses: np.ndarray, cov: dict[str, np.ndarray], n_headings: int,
                  target_xy_m: float, target_yaw_rad: float, settings: PlanSettings) -> tuple[np.ndarray, np.ndarray]:
    """For whole cells (their poses (C' H, 3), cell-major, and the plan's covariances there): whether each
    candidate makes each cell meet the target at every heading, and the cell's worst fused position
    sigma (m; inf: a heading uncovered), both (n_candidates, C'), a few cells at a time."""
    Hn = n_headings
    C = poses.shape[0] // Hn
    meets = np.zeros((len(cands), C), dtype=bool)
    worst = np.zeros((len(cands), C))
    any_cam = any(c.kind == "camera" for c in cands)
    any_scan = any(c.kind == "scanner" for c in cands)
    P_vision = prior_information(rig, settings.vision) if any_cam else None
    cells_per_chunk = max(1, int(settings.chunk_poses) // Hn)
    for c0 in range(0, C, cells_per_chunk):
        c1 = min(C, c0 + cells_per_chunk)
        a, b = c0 * Hn, c1 * Hn
        chunk = {k: v[a:b] for k, v in cov.items()}
        base_sxy, base_syaw = _sigmas(cov["fused"][a:b])
        H_vision = None
        if P_vision is not None:
            vi = vision_information(rig, poses[a:b], settings.vision)
            H_vision = np.broadcast_to(P_vision, (b - a,) + P_vision.shape).copy()
            H_vision[vi.seen] = vi.H
        laser = laser_information(rig, poses[a:b], settings.laser) if any_scan else None
        for j, c in enumerate(cands):
            sxy, syaw = base_sxy.copy(), base_syaw.copy()
            hit, fused = _candidate_fused(c, poses[a:b], chunk, H_vision, laser, settings)
            sxy[hit], syaw[hit] = _sigmas(fused)
            ok = (sxy <= target_xy_m) & (syaw <= target_yaw_rad)
            meets[j, c0:c1] = ok.reshape(-1, Hn).all(axis=1)
            worst[j, c0:c1] = sxy.reshape(-1, Hn).max(axis=1)
    return meets, worst


def _score_candidates(rig: Rig, plan: PlanResult, cands: list[_Candidate], target_xy_m: float, target_yaw_rad: float,
                      settings: PlanSettings, workers: int = 1) -> list[tuple[float, float]]:
    """Each candidate's (share of cells meeting the target, minus the mean capped worst sigma over the
    target) (module docstring), the cells split over ``workers`` processes."""
    g = plan.grid
    C, Hn = g.n_cells, g.n_headings
    poses = plan.poses_xytheta
    args = (Hn, target_xy_m, target_yaw_rad, settings)
    inputs = _fusion_inputs(plan)
    if workers <= 1 or C * Hn < 4 * settings.chunk_poses:
        meets, worst = _cell_results(rig, cands, poses, inputs, *args)
    else:
        from gtrig.parallel import process_pool

        edges = np.linspace(0, C, 4 * workers + 1).astype(int) * Hn
        with process_pool(workers) as ex:
            futures = [ex.submit(_cell_results, rig, cands, poses[a:b], {k: v[a:b] for k, v in inputs.items()},
                                 *args) for a, b in zip(edges[:-1], edges[1:], strict=True)]
            parts = [f.result() for f in futures]
        meets, worst = (np.concatenate(x, axis=1) for x in zip(*parts, strict=True))
    return [(float(meets[j].mean()), -float(np.mean(np.minimum(worst[j] / target_xy_m, 10.0))))
            for j in range(len(cands))]


def _candidates(rig: Rig, plan: PlanResult, kinds: list[SensorKind], aims: list[np.ndarray], height_m: float,
                scanner_height_m: float, n_positions: int, index: dict[SensorKind, int]) -> list[_Candidate]:
    """The candidates of every kind in ``kinds`` for the next round."""
    g = plan.grid
    out: list[_Candidate] = []
    if "camera" in kinds:
        for cam in candidate_cameras(rig.cameras[0], g.polygon_xy, aims, height_m, n_positions,
                                     name=f"suggested{index['camera']}"):
            rig2 = rig.model_copy(update={"cameras": (*rig.cameras, cam)})
            out.append(_Candidate("camera", cam, rig2, VisionModel.from_rig(rig2)))
    if "scanner" in kinds:
        for sc in candidate_scanners(rig.laser_scanners[0], g.polygon_xy, aims, scanner_height_m, n_positions,
                                     name=f"suggested_laser{index['scanner']}"):
            out.append(_Candidate("scanner", sc, rig.model_copy(update={"laser_scanners": (sc,)}), None))
    return out


def check_suggestion(rig: Rig, n_cameras: int, n_scanners: int, scanner_height_m: float | None = None) -> float:
    """The suggested scanners' height (m; ``scanner_height_m`` or the rig's first scanner's), or a one-line
    :class:`InputError` when the rig cannot support the search (no sensor to copy, no markers, no hull, a
    scanning plane that misses the hull)."""
    if n_cameras and not rig.cameras:
        raise InputError("--suggest cameras: the rig has no camera whose lens a suggested one could copy")
    if n_cameras and not rig.robot.markers:
        raise InputError("--suggest cameras: the robot has no markers")
    if not n_scanners:
        return 0.0
    if not rig.laser_scanners:
        raise InputError("--suggest scanners: the rig has no fixed laser scanner whose model a suggested one "
                         "could copy")
    hull = rig.robot.hull
    if hull is None:
        raise InputError("--suggest scanners: the robot has no hull for the scanners to see")
    z = float(rig.laser_scanners[0].T_world_scanner.xyz[2]) if scanner_height_m is None else float(scanner_height_m)
    if not hull.z_min_m < z < hull.z_max_m:
        raise InputError(f"--suggest scanners: a scanner at {z:g} m does not cut the hull "
                         f"(between {hull.z_min_m:g} and {hull.z_max_m:g} m)")
    return z


def suggest_sensors(rig: Rig, plan: PlanResult, n_cameras: int, n_scanners: int, target_xy_m: float,
                    target_yaw_rad: float, settings: PlanSettings | None = None, height_m: float = 2.8,
                    n_positions: int = 24, scanner_height_m: float | None = None, workers: int = 1
                    ) -> list[Suggestion]:
    """Add ``n_cameras`` cameras and ``n_scanners`` fixed scanners one at a time, each round the best
    candidate of the kinds still to add (module docstring).

    Parameters
    ----------
    rig, plan : the planned rig and its plan (:func:`gtrig.plan.predict.predict_plan`).
    n_cameras, n_scanners : how many of each to add.
    target_xy_m, target_yaw_rad : the target (one sigma) a cell meets at every heading.
    settings : the plan's settings.
    height_m : the cameras' height, m.
    n_positions : candidate positions along the outline (each with 1 or 2 aims).
    scanner_height_m : the scanners' height, m (default: the rig's first scanner's).
    workers : processes that score the candidates (each a share of the cells).

    Returns
    -------
    One :class:`Suggestion` per sensor added, in the order they were chosen.
    """
    settings = PlanSettings() if settings is None else settings
    z_scan = check_suggestion(rig, n_cameras, n_scanners, scanner_height_m)
    left: dict[SensorKind, int] = {"camera": n_cameras, "scanner": n_scanners}
    out: list[Suggestion] = []
    while left["camera"] + left["scanner"] > 0:
        before = summarize_target(plan, target_xy_m, target_yaw_rad, n_regions=0)
        g = plan.grid
        aims = [g.cells_xy.mean(axis=0)]
        if not before.meets.all():
            aims.append(g.cells_xy[~before.meets].mean(axis=0))
        kinds: list[SensorKind] = [k for k in ("camera", "scanner") if left[k] > 0]
        index: dict[SensorKind, int] = {"camera": n_cameras - left["camera"] + 1,
                                        "scanner": n_scanners - left["scanner"] + 1}
        cands = _candidates(rig, plan, kinds, aims, height_m, z_scan, n_positions, index)
        scores = _score_candidates(rig, plan, cands, target_xy_m, target_yaw_rad, settings, workers)
        best = max(range(len(cands)), key=lambda j: scores[j])
        c = cands[best]
        if c.kind == "camera":
            assert isinstance(c.sensor, Camera)
            rig, plan = _with_camera(rig, plan, c.sensor, settings)
        else:
            assert isinstance(c.sensor, LaserScanner)
            rig, plan = _with_scanner(rig, plan, c.sensor, settings)
        left[c.kind] -= 1
        out.append(Suggestion(c.kind, c.sensor, before.share_worst, scores[best][0], len(cands), rig, plan))
    return out


def suggest_cameras(rig: Rig, plan: PlanResult, n_add: int, target_xy_m: float, target_yaw_rad: float,
                    settings: PlanSettings | None = None, height_m: float = 2.8, n_positions: int = 24,
                    workers: int = 1) -> list[Suggestion]:
    """Add ``n_add`` cameras one at a time, each the best of the candidates (:func:`suggest_sensors`)."""
    return suggest_sensors(rig, plan, n_add, 0, target_xy_m, target_yaw_rad, settings, height_m, n_positions,
                           workers=workers)
