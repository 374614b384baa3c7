"""Compiled accumulation of the hull ICP's normal equations from noise-free beam hits (numba).

One pass over the hits with no (M, 4) temporaries: each hit is assigned to a hull side and linearised
exactly as :func:`gtrig.laser.hull_icp.side_bias_normal_equations` does (nearest side facing its
scanner, gate and end margin, Huber weight, range noise along the beam plus the model error), and its
point-to-line row is added to its pose's blocks. ``tests/plan/test_plan_laser.py`` checks the result
equals that function's.
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

_jit = nb.njit(cache=True, fastmath=False, nogil=True)


@_jit
def icp_blocks(pose_idx: np.ndarray, scanner_idx: np.ndarray, xy_world: np.ndarray, dir_world: np.ndarray,
               poses_xytheta: np.ndarray, scanner_xy: np.ndarray, var_range: np.ndarray, normals: np.ndarray,
               offsets: np.ndarray, tangents: np.ndarray, t0: np.ndarray, lengths: np.ndarray, gate_m: float,
               end_margin_m: float, sigma_model_m: float, huber_k: float
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The ICP's blocks at K poses from M hits.

    Parameters
    ----------
    pose_idx, scanner_idx : (M,) pose and scanner of each hit.
    xy_world, dir_world : (M, 2) hit point (m) and unit beam direction, world frame.
    poses_xytheta : (K, 3) robot poses (m, m, rad).
    scanner_xy : (S, 2) scanner positions, world frame, m; ``var_range`` (S,) their range variance, m^2.
    normals, tangents : (4, 2) hull sides' outward normals and directions, robot frame; ``offsets`` (4,)
        ``n . corner``, ``t0`` (4,) ``t . corner``, ``lengths`` (4,) m.
    gate_m, end_margin_m, sigma_model_m, huber_k : the ICP's settings.

    Returns
    -------
    H_pp : (K, 3, 3) ``sum w J^T J`` (without the prior).
    H_pb : (K, 3, 4) ``sum w J c`` per side (``c = -n . u``, a side's range bias).
    inliers : (K, S, 4) hits each scanner puts on each side that the ICP keeps.
    """
    K = poses_xytheta.shape[0]
    S = scanner_xy.shape[0]
    H = np.zeros((K, 3, 3))
    Hpb = np.zeros((K, 3, 4))
    cnt = np.zeros((K, S, 4), dtype=np.int32)
    for i in range(pose_idx.shape[0]):
        k = pose_idx[i]
        s = scanner_idx[i]
        px, py, th = poses_xytheta[k, 0], poses_xytheta[k, 1], poses_xytheta[k, 2]
        c, sn = math.cos(th), math.sin(th)
        qx, qy = xy_world[i, 0] - px, xy_world[i, 1] - py
        prx, pry = c * qx + sn * qy, c * qy - sn * qx
        ox, oy = scanner_xy[s, 0] - px, scanner_xy[s, 1] - py
        orx, ory = c * ox + sn * oy, c * oy - sn * ox
        best, bd2, bover, bsd = -1, math.inf, 0.0, 0.0
        for j in range(4):
            if orx * normals[j, 0] + ory * normals[j, 1] - offsets[j] <= 0.0:
                continue
            sd = prx * normals[j, 0] + pry * normals[j, 1] - offsets[j]
            a = prx * tangents[j, 0] + pry * tangents[j, 1] - t0[j]
            over = max(0.0, max(-a, a - lengths[j]))
            d2 = sd * sd + over * over
            if d2 < bd2:
                best, bd2, bover, bsd = j, d2, over, sd
        if best < 0 or not (bd2 < gate_m * gate_m and bover <= end_margin_m):
            continue
        nx, ny = normals[best, 0], normals[best, 1]
        nwx, nwy = c * nx - sn * ny, sn * nx + c * ny
        cosi = dir_world[i, 0] * nwx + dir_world[i, 1] * nwy
        var = var_range[s] * cosi * cosi + sigma_model_m * sigma_model_m
        z2 = bsd * bsd / var
        hub = 1.0 if z2 <= huber_k * huber_k else huber_k / math.sqrt(max(z2, 1e-24))
        w = hub / var
        J0, J1, J2 = -nwx, -nwy, nwx * qy - nwy * qx
        cb = -cosi
        H[k, 0, 0] += w * J0 * J0
        H[k, 0, 1] += w * J0 * J1
        H[k, 0, 2] += w * J0 * J2
        H[k, 1, 1] += w * J1 * J1
        H[k, 1, 2] += w * J1 * J2
        H[k, 2, 2] += w * J2 * J2
        Hpb[k, 0, best] += w * J0 * cb
        Hpb[k, 1, best] += w * J1 * cb
        Hpb[k, 2, best] += w * J2 * cb
        cnt[k, s, best] += 1
    for k in range(K):
        H[k, 1, 0] = H[k, 0, 1]
        H[k, 2, 0] = H[k, 0, 2]
        H[k, 2, 1] = H[k, 1, 2]
    return H, Hpb, cnt


@_jit
def _wrap(a: float) -> float:
    return (a + math.pi) % (2.0 * math.pi) - math.pi


@_jit
def _beam_span(X: float, Y: float, c: float, s: float, corners_xy: np.ndarray, ox: float, oy: float, yaw: float,
               a_lo: float, inc: float, n_beams: int, cw: np.ndarray) -> tuple[int, int]:
    """The hull's corners in the world ``cw`` (4, 2, filled) at pose (X, Y, cos, sin), and the first and
    past-the-last beam (of the scanner at (ox, oy), heading ``yaw``, fan from ``a_lo`` by ``inc``) within
    the angle they subtend."""
    mx, my = 0.0, 0.0
    for j in range(4):
        cw[j, 0] = c * corners_xy[j, 0] - s * corners_xy[j, 1] + X
        cw[j, 1] = s * corners_xy[j, 0] + c * corners_xy[j, 1] + Y
        mx += 0.25 * cw[j, 0]
        my += 0.25 * cw[j, 1]
    ref = math.atan2(my - oy, mx - ox)
    rmin, rmax = math.inf, -math.inf
    for j in range(4):
        rel = _wrap(math.atan2(cw[j, 1] - oy, cw[j, 0] - ox) - ref)
        rmin, rmax = min(rmin, rel), max(rmax, rel)
    # the hull's bearings (scanner frame), moved by whole turns next to the middle of the beams' fan
    fan_mid = a_lo + 0.5 * inc * (n_beams - 1)
    mid = ref - yaw
    shift = fan_mid + _wrap(mid - fan_mid) - mid
    f0 = math.ceil((ref + rmin - yaw + shift - a_lo) / inc)
    f1 = math.floor((ref + rmax - yaw + shift - a_lo) / inc)
    if f0 > n_beams - 1 or f1 < 0:
        return 0, 0
    i0, i1 = int(max(f0, 0.0)), int(min(f1, n_beams - 1.0))
    return (i0, i1 + 1) if i1 >= i0 else (0, 0)


@_jit
def cast_scanner(poses_xytheta: np.ndarray, corners_xy: np.ndarray, origin_xy: np.ndarray, yaw: float, a_lo: float,
                 inc: float, n_beams: int, range_max_m: float
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """One scanner's beams that hit the hull at K poses.

    Parameters
    ----------
    poses_xytheta : (K, 3) robot poses (m, m, rad).
    corners_xy : (4, 2) the hull's corners, robot frame, m (side j: corner j to j + 1).
    origin_xy : (2,) the scanner's position, world frame, m; ``yaw`` its heading, rad.
    a_lo, inc, n_beams : the fan's lowest beam angle (scanner frame, rad), its step (> 0) and beam count.
    range_max_m : the scanner's range, m.

    Returns
    -------
    pose : (M,) pose of each hit; xy : (M, 2) hit point, world frame, m; dir : (M, 2) unit beam direction;
    side : (M,) hull side hit (the first one the beam crosses).
    """
    K = poses_xytheta.shape[0]
    ox, oy = origin_xy[0], origin_xy[1]
    cw = np.empty((4, 2))
    n_max = 0
    for k in range(K):
        c, s = math.cos(poses_xytheta[k, 2]), math.sin(poses_xytheta[k, 2])
        b0, b1 = _beam_span(poses_xytheta[k, 0], poses_xytheta[k, 1], c, s, corners_xy, ox, oy, yaw, a_lo, inc,
                            n_beams, cw)
        n_max += b1 - b0
    pose = np.empty(n_max, dtype=np.int64)
    xy = np.empty((n_max, 2))
    dirs = np.empty((n_max, 2))
    side = np.empty(n_max, dtype=np.int64)
    m = 0
    for k in range(K):
        c, s = math.cos(poses_xytheta[k, 2]), math.sin(poses_xytheta[k, 2])
        b0, b1 = _beam_span(poses_xytheta[k, 0], poses_xytheta[k, 1], c, s, corners_xy, ox, oy, yaw, a_lo, inc,
                            n_beams, cw)
        for beam in range(b0, b1):
            ang = yaw + a_lo + inc * beam
            ux, uy = math.cos(ang), math.sin(ang)
            best, r_best = 0, math.inf
            # first side crossed: ray o + r u against each side c_j + t e_j, t in [0, 1]
            for j in range(4):
                j1 = (j + 1) % 4
                ex, ey = cw[j1, 0] - cw[j, 0], cw[j1, 1] - cw[j, 1]
                wx, wy = cw[j, 0] - ox, cw[j, 1] - oy
                den = ux * ey - uy * ex
                if den == 0.0:
                    continue
                r = (wx * ey - wy * ex) / den
                t = (wx * uy - wy * ux) / den
                if r > 0.0 and t >= 0.0 and t <= 1.0 and r < r_best:
                    best, r_best = j, r
            if r_best <= range_max_m:
                pose[m] = k
                xy[m, 0], xy[m, 1] = ox + r_best * ux, oy + r_best * uy
                dirs[m, 0], dirs[m, 1] = ux, uy
                side[m] = best
                m += 1
    return pose[:m], xy[:m], dirs[:m], side[:m]
