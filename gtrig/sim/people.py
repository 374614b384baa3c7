"""People walking through the room, seen by the laser scanners as two moving legs.

Physical source: in the seeds' recordings people cross the room while the scanners run (operators, the
robot's minder); a 2D scanner 25 cm above the floor cuts their shins. Each person walks between random
way points in the free part of the room at 0.6-1.1 m/s (comfortable walking in a lab, slower than the
1.3 m/s of free walking outdoors), sometimes pausing, steered by a simple social-force model that keeps
them away from walls, clutter, the scanners, each other and the robot (people walk around a moving
robot rather than through it). Legs are circles of ``LEG_RADIUS_M`` (a shin is about 12 cm across)
on either side of the walking line, swinging forwards and backwards with the gait: the legs' distance
along the walking direction oscillates with one period per stride (two steps, about 1.3 m).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from gtrig.sim.gtroom import Scene
from gtrig.sim.motion import RobotMotion

LEG_RADIUS_M = 0.06
HIP_HALF_WIDTH_M = 0.09  # legs' lateral offset from the walking line, at shin height
LEG_SWING_M = 0.22  # half the fore-aft distance between the shins at full walking speed
STRIDE_M = 1.3  # two steps
SIM_DT_S = 0.04
# Keep-out radii of the social-force model (metres).
ROBOT_CLEARANCE_M = 0.9  # from the robot's centre (its half diagonal is 0.48 m)
SCANNER_CLEARANCE_M = 0.7
WALL_CLEARANCE_M = 0.45


@dataclass(frozen=True)
class People:
    """Sampled walks of ``P`` people.

    Attributes
    ----------
    stamps_s : (T,) seconds, uniform steps of ``SIM_DT_S``.
    centres_xy : (T, P, 2) walking-line position in the world, metres.
    heading_rad : (T, P) walking direction (continuous, unwrapped).
    gait_phase_rad : (T, P) gait phase (advances 2 pi per stride).
    swing_m : (T, P) current fore-aft swing amplitude (0 when standing).
    """

    stamps_s: np.ndarray
    centres_xy: np.ndarray
    heading_rad: np.ndarray
    gait_phase_rad: np.ndarray
    swing_m: np.ndarray

    @property
    def count(self) -> int:
        return int(self.centres_xy.shape[1])

    def legs_xy(self, t: ArrayLike) -> np.ndarray:
        """Leg centres in the world at times ``t`` (...,): shape (..., 2 P, 2), metres.

        Legs ``2 p`` and ``2 p + 1`` belong to person ``p`` (left, right).
        """
        t = np.asarray(t, dtype=float)
        shape = t.shape
        tf = t.ravel()
        P = self.count
        if P == 0:
            return np.zeros((*shape, 0, 2))
        # uniform sampling: interpolate by index arithmetic, much faster than np.interp per column
        f = np.clip((tf - self.stamps_s[0]) / SIM_DT_S, 0, len(self.stamps_s) - 1)
        i0 = np.minimum(f.astype(np.intp), len(self.stamps_s) - 2) if len(self.stamps_s) > 1 else np.zeros(
            f.shape, dtype=np.intp)
        a = (f - i0)[:, None]
        i1 = np.minimum(i0 + 1, len(self.stamps_s) - 1)

        def lerp(x: np.ndarray) -> np.ndarray:
            return x[i0] * (1 - a[..., None] if x.ndim == 3 else 1 - a) + x[i1] * (
                a[..., None] if x.ndim == 3 else a)

        c = lerp(self.centres_xy)  # (M, P, 2)
        h = lerp(self.heading_rad)
        ph = lerp(self.gait_phase_rad)
        sw = lerp(self.swing_m)
        fwd = np.stack([np.cos(h), np.sin(h)], axis=-1)
        left = np.stack([-np.sin(h), np.cos(h)], axis=-1)
        along = (sw * np.sin(ph))[..., None]
        leg_l = c + HIP_HALF_WIDTH_M * left + along * fwd
        leg_r = c - HIP_HALF_WIDTH_M * left - along * fwd
        legs = np.stack([leg_l, leg_r], axis=2).reshape(len(tf), 2 * P, 2)
        return legs.reshape(*shape, 2 * P, 2)


def _cross2(a: np.ndarray, b: np.ndarray) -> float:
    return float(a[0] * b[1] - a[1] * b[0])


def _inside(corners: np.ndarray, p: np.ndarray, margin: float) -> bool:
    # convex room, counter-clockwise or clockwise: p must be on the inner side of every wall by `margin`
    n = len(corners)
    sign = np.sign(_cross2(corners[1] - corners[0], corners[2] - corners[1]))
    for i in range(n):
        a, b = corners[i], corners[(i + 1) % n]
        e = b - a
        if sign * _cross2(e, p - a) / np.linalg.norm(e) < margin:
            return False
    return True


def _obstacles(scene: Scene) -> tuple[np.ndarray, np.ndarray]:
    """Clutter and scanners as keep-out circles: centres (K, 2), radii (K,)."""
    cs: list[tuple[float, float]] = []
    rs: list[float] = []
    for b in scene.boxes:
        cs.append(b.centre_xy)
        rs.append(0.5 * math.hypot(b.size[0], b.size[1]) + 0.25)
    for s in scene.rig_true.laser_scanners:
        cs.append((s.T_world_scanner.xyz[0], s.T_world_scanner.xyz[1]))
        rs.append(SCANNER_CLEARANCE_M)
    return np.array(cs, dtype=float).reshape(-1, 2), np.array(rs, dtype=float)


def _free_point(rng: np.random.Generator, corners: np.ndarray, obs_c: np.ndarray, obs_r: np.ndarray
                ) -> np.ndarray:
    lo, hi = corners.min(axis=0), corners.max(axis=0)
    for _ in range(1000):
        p = rng.uniform(lo, hi)
        if _inside(corners, p, WALL_CLEARANCE_M + 0.3) and np.all(
                np.linalg.norm(obs_c - p, axis=1) > obs_r + 0.2):
            return p
    return corners.mean(axis=0)


def simulate_people(
    scene: Scene, motion: RobotMotion | None, t0: float, t1: float, n_people: int, seed: int
) -> People:
    """Walks of ``n_people`` people from ``t0`` to ``t1`` (seconds) in ``scene``'s room.

    ``motion`` is the robot they walk around (``None``: the empty room). The same arguments give the
    same walks.
    """
    rng = np.random.default_rng(seed)
    n_t = max(2, int(math.ceil((t1 - t0) / SIM_DT_S)) + 1)
    stamps = t0 + SIM_DT_S * np.arange(n_t)
    P = n_people
    corners = scene.walls[:, 0, :]
    obs_c, obs_r = _obstacles(scene)
    robot_xy = motion.planar(stamps)[:, :2] if motion is not None else None

    # nobody starts where the robot stands
    start_c, start_r = obs_c, obs_r
    if robot_xy is not None:
        start_c, start_r = np.vstack([obs_c, robot_xy[:1]]), np.r_[obs_r, ROBOT_CLEARANCE_M + 0.3]
    pos = np.array([_free_point(rng, corners, start_c, start_r) for _ in range(P)]).reshape(P, 2)
    goal = np.array([_free_point(rng, corners, obs_c, obs_r) for _ in range(P)]).reshape(P, 2)
    v_pref = rng.uniform(0.6, 1.1, P)
    heading = rng.uniform(-np.pi, np.pi, P)
    phase = rng.uniform(0, 2 * np.pi, P)
    pause = np.zeros(P)
    since_goal = np.zeros(P)

    C = np.zeros((n_t, P, 2))
    H = np.zeros((n_t, P))
    PH = np.zeros((n_t, P))
    SW = np.zeros((n_t, P))
    tau = 0.5
    # plain floats in the loop: a few thousand steps of tiny vectors are faster without NumPy
    wall_list = _inward_walls(scene.walls)
    obs_list = [(float(c[0]), float(c[1]), float(r)) for c, r in zip(obs_c, obs_r, strict=True)]
    robot_list = robot_xy.tolist() if robot_xy is not None else None
    px, py = [float(v) for v in pos[:, 0]], [float(v) for v in pos[:, 1]]
    vx, vy = [0.0] * P, [0.0] * P
    for k in range(n_t):
        for p in range(P):
            sp = math.hypot(vx[p], vy[p])
            C[k, p] = (px[p], py[p])
            H[k, p], PH[k, p] = heading[p], phase[p]
            SW[k, p] = LEG_SWING_M * min(1.0, sp / 0.9)
        for p in range(P):
            dvx, dvy = _desired_velocity(rng, p, px[p], py[p], goal, pause, since_goal, v_pref[p], corners,
                                         obs_c, obs_r)
            fx, fy = (dvx - vx[p]) / tau, (dvy - vy[p]) / tau
            others = [(cx, cy, r, 3.0) for cx, cy, r in obs_list]
            if robot_list is not None:
                # stronger: a person steps aside for a robot driving at them
                others.append((robot_list[k][0], robot_list[k][1], ROBOT_CLEARANCE_M, 8.0))
            others += [(px[q], py[q], 0.6, 3.0) for q in range(P) if q != p]
            fx, fy = _repelled(fx, fy, px[p], py[p], wall_list, others)
            vx[p], vy[p], sp = _accelerated(vx[p], vy[p], fx, fy, 1.3 * v_pref[p])
            if sp > 0.05:
                # people face where they walk; turn the short way, keep the angle continuous
                target = math.atan2(vy[p], vx[p])
                heading[p] += (target - heading[p] + math.pi) % (2 * math.pi) - math.pi
            phase[p] += 2 * math.pi * sp * SIM_DT_S / STRIDE_M
        for p in range(P):
            px[p] += vx[p] * SIM_DT_S
            py[p] += vy[p] * SIM_DT_S
    return People(stamps, C, H, PH, SW)


def _inward_walls(walls: np.ndarray) -> list[tuple[float, float, float, float]]:
    """Each wall (W, 2, 2: end points, world, metres) as a point on it and its unit normal into the
    room: ``(ax, ay, nx, ny)``."""
    corners = walls[:, 0, :]
    orient = np.sign(_cross2(corners[1] - corners[0], corners[2] - corners[1]))
    wall_n = []
    for a, b in walls:
        e = (b - a) / np.linalg.norm(b - a)
        wall_n.append(orient * np.array([-e[1], e[0]]))
    return [(float(a[0]), float(a[1]), float(n[0]), float(n[1]))
            for a, n in zip(walls[:, 0, :], np.array(wall_n), strict=True)]


def _desired_velocity(rng: np.random.Generator, p: int, x: float, y: float, goal: np.ndarray, pause: np.ndarray,
                      since_goal: np.ndarray, v_pref: float, corners: np.ndarray, obs_c: np.ndarray,
                      obs_r: np.ndarray) -> tuple[float, float]:
    """Velocity (m/s, world) person ``p`` at ``(x, y)`` wants: towards its goal at its preferred speed, or
    nil while it pauses. A goal reached (or not reached in 20 s) is replaced, sometimes after a pause;
    ``goal`` (P, 2), ``pause`` and ``since_goal`` (P,) are updated in place."""
    since_goal[p] += SIM_DT_S
    gx, gy = goal[p, 0] - x, goal[p, 1] - y
    dist = math.hypot(gx, gy)
    if dist < 0.3 or since_goal[p] > 20.0:
        if dist < 0.3 and rng.random() < 0.3:
            pause[p] = rng.uniform(1.0, 3.0)
        goal[p] = _free_point(rng, corners, obs_c, obs_r)
        since_goal[p] = 0.0
        gx, gy = goal[p, 0] - x, goal[p, 1] - y
        dist = math.hypot(gx, gy)
    if pause[p] > 0:
        pause[p] -= SIM_DT_S
        return 0.0, 0.0
    return v_pref * gx / max(dist, 1e-9), v_pref * gy / max(dist, 1e-9)


def _repelled(fx: float, fy: float, x: float, y: float, walls: list[tuple[float, float, float, float]],
              others: list[tuple[float, float, float, float]]) -> tuple[float, float]:
    """The force ``(fx, fy)`` (m/s^2) on a person at ``(x, y)`` with the repulsion of the walls
    (:func:`_inward_walls`) and of ``others`` (centre x, y, keep-out radius m, strength m/s^2) added:
    exponential social forces (the strength at the keep-out distance, range 0.25 m), clipped to 6 m/s^2
    per axis."""
    for ax, ay, nx, ny in walls:
        f = 3.0 * math.exp(-((x - ax) * nx + (y - ay) * ny - WALL_CLEARANCE_M) / 0.25)
        fx, fy = fx + f * nx, fy + f * ny
    for cx, cy, r, strength in others:
        rx, ry = x - cx, y - cy
        d = max(math.hypot(rx, ry), 1e-6)
        f = strength * math.exp(-(d - r) / 0.25) / d
        fx, fy = fx + f * rx, fy + f * ry
    return min(6.0, max(-6.0, fx)), min(6.0, max(-6.0, fy))


def _accelerated(vx: float, vy: float, fx: float, fy: float, vmax: float) -> tuple[float, float, float]:
    """Velocity (m/s) after one step of force ``(fx, fy)``, its speed capped at ``vmax``, and that speed."""
    vx += fx * SIM_DT_S
    vy += fy * SIM_DT_S
    sp = math.hypot(vx, vy)
    if sp > vmax:
        vx, vy = vx * vmax / sp, vy * vmax / sp
        sp = vmax
    return vx, vy, sp
