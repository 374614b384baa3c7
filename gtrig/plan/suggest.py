"""Where one more camera helps most: a greedy search over candidate mounting poses.

Candidates stand on the area's outline (pulled ``inset_m`` inside it) at ``height_m``, spaced evenly
along it, each aimed at the area's centre or at the centre of the cells that miss the target. Each
round adds the candidate that most increases the share of cells meeting the target at every heading
(ties broken by the mean of the worst fused position sigma over the target, capped at 10); only the
poses where the candidate sees a marker are predicted again, since a camera changes nothing elsewhere.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from gtrig import geometry as geo
from gtrig.errors import InputError
from gtrig.plan.maps import cell_maps, summarize_target
from gtrig.plan.predict import PlanResult, PlanSettings, fuse_information
from gtrig.plan.visibility import camera_sight
from gtrig.plan.vision import predict_vision
from gtrig.rig.models import Camera, Pose, Rig
from gtrig.vision.observations import VisionModel


@dataclass(frozen=True)
class Suggestion:
    """One camera added: the camera (its pose), the shares meeting the target before and after, the
    candidates tried, and the rig and plan with it."""

    camera: Camera
    share_before: float
    share_after: float
    n_candidates: int
    rig: Rig
    plan: PlanResult


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


def _with_camera(rig: Rig, plan: PlanResult, cam: Camera, settings: PlanSettings) -> tuple[Rig, PlanResult]:
    """The rig and plan with ``cam`` added (vision predicted again where it sees a marker)."""
    rig2 = rig.model_copy(update={"cameras": (*rig.cameras, cam)})
    model = VisionModel.from_rig(rig2)
    poses = plan.poses_xytheta
    corners = np.stack([model.corners_robot[m.id] for m in rig.robot.markers])
    sight = camera_sight(model.cameras[cam.name], corners, poses, rig.robot.hull, settings.vision.margin_px,
                         settings.vision.min_side_px)
    hit = np.flatnonzero(sight.visible.any(axis=1))
    cov_v = plan.cov["vision"].copy()
    views = np.column_stack([plan.views, np.zeros(poses.shape[0], dtype=plan.views.dtype)])
    side = np.column_stack([plan.side_px, np.zeros(poses.shape[0], dtype=plan.side_px.dtype)])
    if hit.size:
        pv = predict_vision(rig2, poses[hit], settings.vision, model)
        cov_v[hit], views[hit], side[hit] = pv.cov_xytheta, pv.views, pv.side_px
    cov = {"vision": cov_v, "laser": plan.cov["laser"], "fused": fuse_information([cov_v, plan.cov["laser"]])}
    return rig2, replace(plan, camera_names=(*plan.camera_names, cam.name), cov=cov, views=views, side_px=side)


def _score(plan: PlanResult, target_xy_m: float, target_yaw_rad: float) -> tuple[float, float]:
    s = summarize_target(plan, target_xy_m, target_yaw_rad, n_regions=0)
    worst = cell_maps(plan).sigma_xy_m["fused"][0]
    return s.share_worst, -float(np.mean(np.minimum(worst / target_xy_m, 10.0)))


def suggest_cameras(rig: Rig, plan: PlanResult, n_add: int, target_xy_m: float, target_yaw_rad: float,
                    settings: PlanSettings | None = None, height_m: float = 2.8, n_positions: int = 24
                    ) -> list[Suggestion]:
    """Add ``n_add`` cameras one at a time, each the best of the candidates (module docstring)."""
    settings = PlanSettings() if settings is None else settings
    if not rig.cameras:
        raise InputError("--suggest cameras: the rig has no camera whose lens a suggested one could copy")
    if not rig.robot.markers:
        raise InputError("--suggest cameras: the robot has no markers")
    out: list[Suggestion] = []
    for i in range(n_add):
        before = summarize_target(plan, target_xy_m, target_yaw_rad, n_regions=0)
        g = plan.grid
        aims = [g.cells_xy.mean(axis=0)]
        if not before.meets.all():
            aims.append(g.cells_xy[~before.meets].mean(axis=0))
        cands = candidate_cameras(rig.cameras[0], g.polygon_xy, aims, height_m, n_positions,
                                  name=f"suggested{i + 1}")
        best: tuple[tuple[float, float], Rig, PlanResult, Camera] | None = None
        for cam in cands:
            rig2, plan2 = _with_camera(rig, plan, cam, settings)
            sc = _score(plan2, target_xy_m, target_yaw_rad)
            if best is None or sc > best[0]:
                best = (sc, rig2, plan2, cam)
        assert best is not None
        rig, plan = best[1], best[2]
        out.append(Suggestion(best[3], before.share_worst, best[0][0], len(cands), rig, plan))
    return out
