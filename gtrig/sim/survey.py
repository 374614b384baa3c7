"""Simulated hand-laser survey (AD2.3, "Determination of the coordinates of the world-points" and
"Collection of the validation data").

Truth: the scene's true world points ``scene.world_points_xy`` and true reference points
``scene.reference_true_xy``; ``reference_points.csv`` gets the NOMINAL reference points (what the operator
believes, ``scene.rig_nominal.survey``) with their sigma, so the reference-point error is part of the
simulated survey. Distances are horizontal (the seeds aligned the spot only horizontally), with Gaussian
hand-laser noise of ``scene.rig_true.survey.hand_laser_sigma_m``.

Robot points: the origin and the ends of the x and y axes of the robot frame at ``axis_length_m``
(default 0.5 m: the seeds' accuracy experiment says 1 deg moves the x-axis end by 8.7 mm, i.e. 0.5 m;
the "dima" text says about 0.6 m and 0.4 m). A robot point is drawn on the floor straight below its
place on the robot: its world xy is ``T_world_robot @ (x, y, 0)`` projected on the floor.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from gtrig.io.survey_csv import Distances, NamedPoints, write_distances, write_named_xy
from gtrig.sim.config import SimConfig, noise_stream
from gtrig.sim.gtroom import WORLD_POINT_NAMES, Scene


@dataclass(frozen=True)
class SurveySimConfig:
    """Settings of the simulated survey.

    Attributes
    ----------
    axis_length_m : distance of the x and y axis ends from the robot origin.
    world_points_per_pose : readings per robot point (nearest world points first); None: all.
    network_max_m : also read the distance between every two world points closer than this whose line
        of sight misses the clutter (a surveyor's network, :mod:`gtrig.survey.network`); None: only the
        readings to the reference points, as the seeds did.
    """

    axis_length_m: float = 0.5
    world_points_per_pose: int | None = None
    network_max_m: float | None = 6.0


@dataclass(frozen=True)
class SimulatedSurvey:
    """A survey in memory (the content of the four CSVs), arrays in the world frame, metres.

    ``world_d`` (W, R) distances from every world point to every reference point; ``network_pairs``
    (K, 2) indices of world points read from each other, ``network_d`` (K,) those distances;
    ``pose_d`` (P, A, W) from every robot point of every pose to every world point (nan where not
    measured).
    """

    reference_names: tuple[str, ...]
    reference_nominal_xy: np.ndarray
    reference_sigma_m: np.ndarray
    world_names: tuple[str, ...]
    world_d: np.ndarray
    network_pairs: np.ndarray
    network_d: np.ndarray
    robot_names: tuple[str, ...]
    robot_xy: np.ndarray
    pose_names: tuple[str, ...]
    pose_d: np.ndarray
    sigma_m: float


def robot_points(axis_length_m: float = 0.5) -> tuple[tuple[str, ...], np.ndarray]:
    """Names and robot-frame coordinates (3, 2) of the origin and the ends of the x and y axes."""
    return ("O", "X", "Y"), np.array([[0.0, 0.0], [axis_length_m, 0.0], [0.0, axis_length_m]])


def _segments_cross(p: np.ndarray, q: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(K, E) whether segments p-q (K, 2) cross segments a-b (E, 2)."""

    def orient(u: np.ndarray, v: np.ndarray, w: np.ndarray) -> np.ndarray:
        d1, d2 = v - u, w - u
        return np.sign(d1[..., 0] * d2[..., 1] - d1[..., 1] * d2[..., 0])

    P, Q, A, B = p[:, None], q[:, None], a[None], b[None]
    return (orient(P, Q, A) != orient(P, Q, B)) & (orient(A, B, P) != orient(A, B, Q))


def network_pairs(scene: Scene, max_m: float) -> np.ndarray:
    """Pairs (K, 2) of world points closer than ``max_m`` whose line of sight misses every clutter box."""
    W = np.asarray(scene.world_points_xy, dtype=float)
    i, j = np.triu_indices(len(W), 1)
    keep = np.linalg.norm(W[i] - W[j], axis=1) < max_m
    for box in scene.boxes:
        c = box.corners_xy()
        keep &= ~_segments_cross(W[i], W[j], c, np.roll(c, -1, axis=0)).any(axis=1)
    return np.column_stack([i[keep], j[keep]])


def simulate_survey(
    scene: Scene,
    T_world_robot: np.ndarray,
    rng: np.random.Generator,
    cfg: SurveySimConfig = SurveySimConfig(),
    reference_true_xy: dict[str, tuple[float, float]] | None = None,
) -> SimulatedSurvey:
    """Draw one survey: readings with hand-laser noise from the true geometry.

    Parameters
    ----------
    T_world_robot : (P, 4, 4) robot poses at the validation stops.
    reference_true_xy : true reference points; default ``scene.reference_true_xy`` (Monte-Carlo runs
        redraw them to make the reference error random too).
    """
    sigma = float(scene.rig_true.survey.hand_laser_sigma_m)
    refs = scene.rig_nominal.survey.reference_points
    rnames = tuple(r.name for r in refs)
    ref_true = scene.reference_true_xy if reference_true_xy is None else reference_true_xy
    R_true = np.array([ref_true[n] for n in rnames])
    W = np.asarray(scene.world_points_xy, dtype=float)
    world_d = np.linalg.norm(W[:, None, :] - R_true[None], axis=2)
    world_d = world_d + rng.normal(0.0, sigma, world_d.shape)
    pairs = network_pairs(scene, cfg.network_max_m) if cfg.network_max_m else np.empty((0, 2), dtype=int)
    net_d = np.linalg.norm(W[pairs[:, 0]] - W[pairs[:, 1]], axis=1) + rng.normal(0.0, sigma, len(pairs))
    qnames, Q = robot_points(cfg.axis_length_m)
    T = np.asarray(T_world_robot, dtype=float).reshape(-1, 4, 4)
    q3 = np.column_stack([Q, np.zeros(len(Q)), np.ones(len(Q))])
    S = np.einsum("pij,aj->pai", T, q3)[..., :2]  # (P, A, 2) robot points on the floor
    pose_d = np.linalg.norm(W[None, None] - S[:, :, None, :], axis=3)
    if cfg.world_points_per_pose is not None:
        far = np.argsort(pose_d, axis=2)[..., cfg.world_points_per_pose :]
        np.put_along_axis(pose_d, far, np.nan, axis=2)
    pose_d = pose_d + rng.normal(0.0, sigma, pose_d.shape)
    names = WORLD_POINT_NAMES if len(W) == len(WORLD_POINT_NAMES) else tuple(str(i + 1) for i in range(len(W)))
    return SimulatedSurvey(
        reference_names=rnames,
        reference_nominal_xy=np.array([r.xy for r in refs], dtype=float),
        reference_sigma_m=np.array([r.sigma_m for r in refs], dtype=float),
        world_names=names,
        world_d=world_d,
        network_pairs=pairs,
        network_d=net_d,
        robot_names=qnames,
        robot_xy=Q,
        pose_names=tuple(str(i + 1) for i in range(T.shape[0])),
        pose_d=pose_d,
        sigma_m=sigma,
    )


def as_inputs(sv: SimulatedSurvey) -> tuple[NamedPoints, Distances, NamedPoints, Distances]:
    """The four survey tables in memory, as the CSV readers return them: reference points, world
    distances (to the reference points, then between world points), robot points, pose distances."""
    a = [w for w in sv.world_names for _ in sv.reference_names]
    b = [r for _ in sv.world_names for r in sv.reference_names]
    d = list(sv.world_d.ravel())
    for (i, j), dist in zip(sv.network_pairs, sv.network_d, strict=True):
        a.append(sv.world_names[i])
        b.append(sv.world_names[j])
        d.append(dist)
    n = len(d)
    wd = Distances(
        ("",) * n, tuple(a), tuple(b), np.array(d), np.full(n, sv.sigma_m), tuple(f"w:{k}" for k in range(n))
    )
    p, q, w = np.nonzero(np.isfinite(sv.pose_d))
    m = p.size
    pd = Distances(
        tuple(sv.pose_names[i] for i in p),
        tuple(sv.robot_names[i] for i in q),
        tuple(sv.world_names[i] for i in w),
        sv.pose_d[p, q, w],
        np.full(m, sv.sigma_m),
        tuple(f"p:{k}" for k in range(m)),
    )
    ref = NamedPoints(sv.reference_names, sv.reference_nominal_xy, sv.reference_sigma_m)
    robot = NamedPoints(sv.robot_names, sv.robot_xy, np.zeros(len(sv.robot_names)))
    return ref, wd, robot, pd


def write_simulated_survey(sv: SimulatedSurvey, rec_dir: str | os.PathLike[str]) -> None:
    """Write the four survey CSVs of ``docs/formats.md`` under ``rec_dir/survey/``."""
    out = Path(rec_dir) / "survey"
    write_named_xy(
        out / "reference_points.csv",
        sv.reference_names,
        sv.reference_nominal_xy,
        sigma_m=sv.reference_sigma_m,
    )
    write_distances(
        out / "world_distances.csv",
        ("point", "reference", "distance", "sigma"),
        [
            (w, r, float(sv.world_d[i, j]), float(sv.sigma_m))
            for i, w in enumerate(sv.world_names)
            for j, r in enumerate(sv.reference_names)
        ]
        + [
            (sv.world_names[i], sv.world_names[j], float(d), float(sv.sigma_m))
            for (i, j), d in zip(sv.network_pairs, sv.network_d, strict=True)
        ],
    )
    write_named_xy(out / "robot_points.csv", sv.robot_names, sv.robot_xy)
    rows = []
    for p, pn in enumerate(sv.pose_names):
        for a, an in enumerate(sv.robot_names):
            for w, wn in enumerate(sv.world_names):
                if np.isfinite(sv.pose_d[p, a, w]):
                    rows.append((pn, an, wn, float(sv.pose_d[p, a, w]), float(sv.sigma_m)))
    write_distances(out / "pose_distances.csv", ("pose", "robot_point", "world_point", "distance", "sigma"), rows)


def write_survey(
    scene: Scene,
    T_world_robot_validation: np.ndarray,
    rec_dir: str | os.PathLike[str],
    cfg: SimConfig | None = None,
    seed: int = 0,
    survey_cfg: SurveySimConfig = SurveySimConfig(),
) -> SimulatedSurvey:
    """Simulate the survey of a recording and write ``rec_dir/survey/*.csv``.

    Parameters
    ----------
    scene : the installation (truth and nominal).
    T_world_robot_validation : (P, 4, 4) true robot poses at the validation stops (P = 26 in the GT room).
    rec_dir : the recording folder.
    cfg : the simulator settings (its noise draw redraws the readings' noise); None: the seed's own noise.
    seed : random seed of the hand-laser noise.
    survey_cfg : robot-point layout and readings per pose.
    """
    draw = 0 if cfg is None else cfg.noise_draw_of("survey")
    key = [seed, 0x5E7]
    sv = simulate_survey(scene, T_world_robot_validation, noise_stream(np.random.default_rng(key), key, draw),
                         survey_cfg)
    write_simulated_survey(sv, rec_dir)
    return sv
