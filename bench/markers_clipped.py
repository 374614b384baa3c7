"""Corner accuracy and stated covariance of sunlit (clipped) markers on the simulated GT room.

The simulator renders the robot (its four AprilTag markers) in frames of every camera of the GT room
of ``--seed``: half of the robot poses in the sun patch of the floor, where the markers' white paper
clips at 255, half away from it; each pose still and moving (``--speed`` m/s forward and ``--yaw-rate``
rad/s during the 8 ms exposure: the simulator's motion blur). The true corners are the true rig's
projections at mid-exposure. Each marker gtrig detects is classed as well exposed, clipped still or
clipped moving (clipped: more than 2 % of the pixels in the box of its true corners at 255; moving:
the image motion of the robot's top over the exposure at least ``--min-motion-px``), and per class
printed: markers, corner RMS error (px), the RMS of the stated sigma (sqrt of half the covariance's
trace, px), the mean NEES per corner over its 2 dof and the share of corners beyond chi-square(2) at
95 %. A covariance that states the errors right has NEES/dof about 1 and 5 % beyond.

With ``--synth`` the same figures come from :mod:`gtrig.markers.synth` renders instead, over a grid of
clipping degrees (the paper's level over the clip level, ``W/C``), optical blurs and a 3 px motion smear,
in the order a sensor sees them: the light is blurred and smeared, the noise (2 grey levels) added, and
only then clipped at 255 (the light is rendered below the clip and scaled, so its levels are
quantised in steps of at most ``W/C`` grey levels).

With ``--run RESULTS=RECORDING ...`` the figures come from a simulated recording's own run instead: the
detections GTvision kept (``gt_vision_run.checkpoint``) against the true rig's projection at each frame's
true mid-exposure stamp (the written stamp less the simulator's jitter draw); per class (clipped or not),
the corner error, stated sigma and NEES, and the four edges' offsets along their outward normals: their
RMS, each marker's mean (the offset its edges share), each edge's own, and their correlation within a
marker (second moments, and about the mean offset).

Usage::

    python bench/markers.py --clipped                      # 60 robot poses, seed 0
    python bench/markers_clipped.py --poses 40 --seed 1
    python bench/markers.py --clipped --synth              # synth renders, W/C x blur x smear
    python bench/markers_clipped.py --run s0/results=s0/recording s1/results=s1/recording
"""

from __future__ import annotations

import argparse
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from gtrig import geometry as geo
from gtrig.markers.detect import MarkerDetector
from gtrig.sim import gtroom
from gtrig.sim.cameras import _cached_view, render_robot_frame
from gtrig.sim.config import SimConfig
from gtrig.sim.gtroom import Scene, make_scene
from gtrig.sim.motion import RobotMotion
from gtrig.sim.textures import SUN_SOFT_M, _signed_dist_convex, sun_geometry
from gtrig.vision.detect import GtrigDetector
from gtrig.vision.observations import MarkerView, VisionModel

#: share of a marker's box at 255 above which it counts as clipped (as ``bench/plan.py``)
CLIPPED_SHARE = 0.02
#: chi-square(2) at 95 %
CHI2_2_95 = -2.0 * math.log(0.05)
CLASSES = ("well exposed", "clipped still", "clipped moving", "well exposed moving")


@dataclass
class ClassStats:
    """Corner errors and stated covariances of one class of markers."""

    err: list[np.ndarray] = field(default_factory=list)
    cov: list[np.ndarray] = field(default_factory=list)

    def add(self, err: np.ndarray, cov: np.ndarray) -> None:
        self.err.append(err)
        self.cov.append(cov)

    def row(self, name: str) -> str:
        if not self.err:
            return f"{name:22s} {0:7d}"
        e = np.concatenate(self.err)
        c = np.concatenate(self.cov)
        nees = np.einsum("ni,nij,nj->n", e, np.linalg.inv(c), e)
        rms = math.sqrt(float(np.mean(np.sum(e**2, axis=1))))
        stated = math.sqrt(float(np.mean(np.trace(c, axis1=1, axis2=2))))
        return (f"{name:22s} {len(self.err):7d} {rms:9.3f} {stated:9.3f} {np.mean(nees) / 2:9.2f} "
                f"{np.mean(nees > CHI2_2_95) * 100:8.1f}")


def sun_poses(scene: Scene, n: int, rng: np.random.Generator, lit: bool) -> np.ndarray:
    """(n, 3) robot poses (x, y, heading) whose centre is well inside (``lit``) or well away from the sun
    patch, on the floor inside the room's walls."""
    win, d = sun_geometry(scene)
    poly = win[:, :2] + (-win[:, 2:3] / d[2]) * d[:2]
    lo, hi = scene.walls[:, 0].min(axis=0) + 0.6, scene.walls[:, 0].max(axis=0) - 0.6
    out: list[list[float]] = []
    while len(out) < n:
        xy = rng.uniform(lo, hi)
        sd = float(_signed_dist_convex(xy[None], poly)[0])
        if (lit and sd > 0.25 + SUN_SOFT_M) or (not lit and sd < -0.5):
            out.append([*xy, rng.uniform(-math.pi, math.pi)])
    return np.array(out)


def _motion(scene: Scene, xyt: np.ndarray, speed: float, yaw_rate: float) -> RobotMotion:
    """A motion through pose ``xyt`` at time 0, at ``speed`` m/s along the heading and ``yaw_rate`` rad/s."""
    t = np.array([-0.05, 0.05])
    x, y, th = xyt
    path = np.array([[x + speed * tt * math.cos(th), y + speed * tt * math.sin(th), th + yaw_rate * tt] for tt in t])
    return RobotMotion(t, path, scene.floor)


def _image_motion(scene: Scene, model: VisionModel, cam: str, motion: RobotMotion, exposure_s: float) -> float:
    """Image motion (px) of the robot's top centre over the exposure."""
    g = model.cameras[cam]
    top = np.array([[0.0, 0.0, gtroom.ROBOT_TOP_M]])
    ends = [geo.transform_points(motion.T_world_robot(s), top)[0] for s in (-exposure_s / 2, exposure_s / 2)]
    uv = geo.project_points(geo.transform_points(g.T_cam_world, np.array(ends)), g.K, g.dist)
    return float(np.linalg.norm(uv[1] - uv[0]))


def _clipped(img: np.ndarray, corners: np.ndarray) -> bool:
    """More than :data:`CLIPPED_SHARE` of the box of ``corners`` (4, 2) at 255."""
    (x0, y0), (x1, y1) = np.floor(corners.min(axis=0)).astype(int), np.ceil(corners.max(axis=0)).astype(int) + 1
    h, w = img.shape
    x0, y0, x1, y1 = max(x0, 0), max(y0, 0), min(x1, w), min(y1, h)
    return x1 - x0 >= 2 and y1 - y0 >= 2 and float(np.mean(img[y0:y1, x0:x1] >= 255)) > CLIPPED_SHARE


def _true_corners(model: VisionModel, cam: str, T_world_robot: np.ndarray, marker_id: int) -> np.ndarray | None:
    g = model.cameras[cam]
    p = geo.transform_points(g.T_cam_world @ T_world_robot, model.corners_robot[marker_id])
    return None if np.any(p[:, 2] <= 0.05) else geo.project_points(p, g.K, g.dist)


def measure(seed: int, n_poses: int, speed: float, yaw_rate: float, min_motion_px: float
            ) -> dict[str, ClassStats]:
    """Per class (:data:`CLASSES`) the corner errors and covariances of ``n_poses`` robot poses (half in the
    sun) seen still and moving by every camera of seed ``seed``'s GT room."""
    from gtrig.sim.lasers import configure_scene

    cfg = SimConfig(seed=seed)
    scene = configure_scene(make_scene(seed), cfg)
    rig = scene.rig_true
    model = VisionModel.from_rig(rig)
    det = GtrigDetector(rig, MarkerDetector)
    rng = np.random.default_rng([seed, 53])
    poses = np.vstack([sun_poses(scene, n_poses - n_poses // 2, rng, True), sun_poses(scene, n_poses // 2, rng, False)])
    stats = {c: ClassStats() for c in CLASSES}
    for k, xyt in enumerate(poses):
        for moving in (False, True):
            motion = _motion(scene, xyt, speed if moving else 0.0, yaw_rate if moving else 0.0)
            T = motion.T_world_robot(0.0)
            for ci, cam in enumerate(rig.cameras):
                view = _cached_view(scene, cam, cfg.camera)
                img = render_robot_frame(scene, view, motion, 0.0, cfg.camera,
                                         np.random.default_rng([seed, 53, k, ci, int(moving)]))
                fast = moving and _image_motion(scene, model, cam.name, motion, cfg.camera.exposure_s) >= min_motion_px
                if moving and not fast:
                    continue
                for v in det(img, model.cameras[cam.name]):
                    _add(stats, v, img, model, cam.name, T, fast)
    return stats


def _add(stats: dict[str, ClassStats], v: MarkerView, img: np.ndarray, model: VisionModel, cam: str,
         T_world_robot: np.ndarray, moving: bool) -> None:
    truth = _true_corners(model, cam, T_world_robot, v.marker_id)
    if truth is None or np.abs(v.corners_px - truth).max() > 3.0:
        return
    clipped = _clipped(img, truth)
    name = ("clipped moving" if moving else "clipped still") if clipped else (
        "well exposed moving" if moving else "well exposed")
    stats[name].add(v.corners_px - truth, v.corner_cov)


#: the synth grid: the paper's level over the clip level, optical blur sigma (px), motion smear (px)
SYNTH_RATIOS = (1.1, 1.3, 1.57, 2.0, 3.0)
SYNTH_BLURS = (0.5, 1.0, 2.0)
SYNTH_SMEARS = (None, (3.0, 1.0))


def synth_clipped(ratio: float, blur: float, smear: tuple[float, float] | None, seeds: int = 4,
                  noise: float = 2.0) -> tuple[ClassStats, int]:
    """Corner errors and covariances of ``3 * seeds`` AprilTag markers (70 px, tilted) whose paper lies at
    ``ratio`` times the clip level, blurred by ``blur`` px and optionally smeared by the motion ``smear``
    (px) before the noise and the clip; and the number of markers rendered."""
    import cv2

    from gtrig.markers.synth import WHITE, homography_from_pose, render
    from gtrig.rig.models import MarkerFamily
    from gtrig.sim.cameras import motion_kernel

    fam = MarkerFamily.APRILTAG_36H11
    base_gain = 250.0 / WHITE  # the paper just below the clip: rendered without clipping
    stats = ClassStats()
    for seed in range(seeds):
        rng = np.random.default_rng([seed, 54])
        markers = [(fam, 3 + 11 * i,
                     homography_from_pose(70, (150 + 250 * i, 200), 20, 30 + 60 * i, 15 * i + 10 * seed))
                   for i in range(3)]
        img, truths = render((480, 800), markers, blur_px=blur, noise=0.0, gain=base_gain, rng=rng)
        light = img.astype(np.float32) * np.float32(ratio * 255.0 / 250.0)
        if smear is not None:
            k = motion_kernel(*smear)
            if k is not None:
                light = np.asarray(cv2.filter2D(light, -1, k, borderType=cv2.BORDER_REPLICATE))
        shot = np.clip(np.rint(light + rng.normal(0.0, noise, light.shape)), 0, 255).astype(np.uint8)
        for d in MarkerDetector(fam).detect(shot):
            t = next((t for t in truths if t.marker_id == d.id), None)
            if t is not None and np.abs(d.corners_px - t.corners_px).max() < 3.0:
                stats.add(d.corners_px - t.corners_px, d.corner_cov)
    return stats, 3 * seeds


def run_synth(seeds: int = 4) -> None:
    """Print the synth grid's table (see the module docstring)."""
    print(f"synth renders, {3 * seeds} markers per row (70 px, noise 2), clip after blur, smear and noise")
    print(f"{'W/C blur smear':22s} {'markers':>7s} {'rms px':>9s} {'sigma px':>9s} {'NEES/dof':>9s} {'>95% %':>8s}")
    for ratio in SYNTH_RATIOS:
        for blur in SYNTH_BLURS:
            for smear in SYNTH_SMEARS:
                st, n = synth_clipped(ratio, blur, smear, seeds)
                name = f"{ratio:4.2f} {blur:3.1f} {'3 px' if smear else 'still'}"
                print(st.row(name), flush=True)


def _run_detections(res: Path, rec: Path) -> list[tuple[np.ndarray, np.ndarray, np.ndarray, float]]:
    """(corners, true corners, covariances, share of the markers' box at 255) of every detection GTvision kept
    in the run of recording ``rec`` (results ``res``) whose corners are within 3 px of the truth."""
    from scipy.spatial.transform import Rotation, Slerp

    from gtrig.io.checkpoint import checkpoint_records
    from gtrig.io.frames import read_frame_index
    from gtrig.io.tum import read_tum
    from gtrig.io.yamlfile import safe_load
    from gtrig.rig.load import load_rig
    from gtrig.sim.cameras import _frame_rng

    cfg = safe_load((rec / "sim_config.yaml").read_text(encoding="utf-8")) or {}
    seed, jitter = int(cfg.get("seed", 0)), float((cfg.get("camera") or {}).get("stamp_jitter_s", 0.0))
    rig = load_rig(rec / "truth" / "rig.yaml")
    model = VisionModel.from_rig(rig)
    truth = read_tum(rec / "truth" / "run.tum")
    Tm = truth.matrices()
    slerp = Slerp(truth.stamps_s, Rotation.from_matrix(Tm[:, :3, :3]))
    names = [c.name for c in rig.cameras]
    out = []
    for d in checkpoint_records(res / "gt_vision_run.checkpoint"):
        if not isinstance(d, dict) or "camera" not in d:
            continue
        cam = d["camera"]
        ci = names.index(cam)
        index = read_frame_index(rec / "run" / "cameras" / cam)
        for row, dets in d.get("frames") or []:
            # the run's images are rendered with seed * 1000 + 10 + camera (gtrig.sim.recording)
            j = _frame_rng(seed * 1000 + 10 + ci, ci, int(row), 1, 0).normal(0.0, jitter) if jitter > 0 else 0.0
            t = index.stamps_s[int(row)] - j
            if not dets or not truth.stamps_s[0] <= t <= truth.stamps_s[-1]:
                continue
            T = np.eye(4)
            T[:3, :3] = slerp([t]).as_matrix()[0]
            T[:3, 3] = [np.interp(t, truth.stamps_s, Tm[:, i, 3]) for i in range(3)]
            img = index.read(int(row))
            for m in dets:
                corners, cov = np.array(m[1]), np.array(m[2])
                tr = _true_corners(model, cam, T, int(m[0]))
                if tr is None or np.abs(corners - tr).max() > 3.0 or np.any(cov[:, 0, 0] > 1.0):
                    continue  # a corner released outside the image: not measured
                (x0, y0), (x1, y1) = np.floor(tr.min(0)).astype(int), np.ceil(tr.max(0)).astype(int) + 1
                box = img[max(y0, 0):max(y1, 0), max(x0, 0):max(x1, 0)]
                out.append((corners, tr, cov, float(np.mean(box >= 255)) if box.size else 0.0))
    return out


def _edge_offsets(corners: np.ndarray, truth: np.ndarray) -> np.ndarray:
    """(4,) each edge's offset along its outward normal (px): the mean of its two corners' errors on it."""
    e = np.roll(truth, -1, axis=0) - truth
    n = np.column_stack([e[:, 1], -e[:, 0]]) / np.linalg.norm(e, axis=1, keepdims=True)
    n *= np.sign(np.sum(n * (truth - truth.mean(axis=0)), axis=1))[:, None]
    err = corners - truth
    return 0.5 * (np.einsum("ki,ki->k", n, err) + np.einsum("ki,ki->k", n, np.roll(err, -1, axis=0)))


def run_edges(pairs: list[str]) -> None:
    """Print the runs' table (module docstring)."""
    dets = [d for pair in pairs for d in _run_detections(*(Path(p) for p in pair.split("=", 1)))]
    print(f"{'class':14s} {'markers':>7s} {'rms px':>7s} {'sigma px':>8s} {'NEES/dof':>8s} | edge offsets px: "
          "mean, RMS, marker's mean RMS, own RMS; correlation within a marker, about its mean")
    for name, keep in (("clipped", lambda s: s > CLIPPED_SHARE), ("well exposed", lambda s: s <= CLIPPED_SHARE)):
        g = [d for d in dets if keep(d[3])]
        if not g:
            continue
        e = np.concatenate([c - t for c, t, _, _ in g])
        cov = np.concatenate([v for _, _, v, _ in g])
        nees = np.einsum("ni,nij,nj->n", e, np.linalg.inv(cov), e)
        off = np.array([_edge_offsets(c, t) for c, t, _, _ in g])
        m = off.mean(axis=1)
        M = off.T @ off / len(off)
        C = np.corrcoef(off.T)
        pair = ~np.eye(4, dtype=bool)
        print(f"{name:14s} {len(g):7d} {math.sqrt(np.mean(np.sum(e**2, axis=1))):7.3f} "
              f"{math.sqrt(np.mean(np.trace(cov, axis1=1, axis2=2))):8.3f} {np.mean(nees) / 2:8.2f} | "
              f"{off.mean():+.3f} {math.sqrt(np.mean(off**2)):.3f} {math.sqrt(np.mean(m**2)):.3f} "
              f"{math.sqrt(np.mean((off - m[:, None]) ** 2) * 4 / 3):.3f}; {M[pair].mean() / np.diag(M).mean():.2f} "
              f"{C[pair].mean():.2f}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--poses", type=int, default=60, help="robot poses (half in the sun)")
    ap.add_argument("--speed", type=float, default=0.3, help="forward speed of the moving frames, m/s")
    ap.add_argument("--yaw-rate", type=float, default=0.3, help="yaw rate of the moving frames, rad/s")
    ap.add_argument("--min-motion-px", type=float, default=1.0,
                    help="moving frames whose robot moved less in the image are left out")
    ap.add_argument("--synth", action="store_true", help="synth renders over W/C, blur and smear instead")
    ap.add_argument("--run", nargs="+", metavar="RESULTS=RECORDING", default=None,
                    help="a simulated recording's run instead: its detections against the truth")
    a = ap.parse_args()
    if a.run:
        run_edges(a.run)
        return
    if a.synth:
        run_synth()
        return
    run(a.seed, a.poses, a.speed, a.yaw_rate, a.min_motion_px)


def run(seed: int, poses: int, speed: float = 0.3, yaw_rate: float = 0.3, min_motion_px: float = 1.0) -> None:
    """Print the table (see the module docstring)."""
    stats = measure(seed, poses, speed, yaw_rate, min_motion_px)
    print(f"seed {seed}, {poses} robot poses, moving at {speed} m/s and {yaw_rate} rad/s")
    print(f"{'class':22s} {'markers':>7s} {'rms px':>9s} {'sigma px':>9s} {'NEES/dof':>9s} {'>95% %':>8s}")
    for c in CLASSES:
        print(stats[c].row(c))


if __name__ == "__main__":
    main()
