"""Compiled test of which markers a camera sees whole at many robot poses (numba).

The rules are those of :mod:`gtrig.plan.visibility` (GTvision's synthetic views plus the hull's
shadow), evaluated marker by marker in one pass without (K, 4, 3) temporaries.
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

_jit = nb.njit(cache=True, fastmath=False, nogil=True)


@_jit
def _hidden_by_hull(a: np.ndarray, b: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> bool:
    """Whether the segment from ``a`` to ``b`` (3,) crosses the box ``[lo, hi]`` (slab test, robot frame)."""
    tmin, tmax = -math.inf, math.inf
    for ax in range(3):
        d = b[ax] - a[ax]
        t0 = (lo[ax] - a[ax]) / d if d != 0.0 else math.nan
        t1 = (hi[ax] - a[ax]) / d if d != 0.0 else math.nan
        if math.isfinite(t0) and math.isfinite(t1):
            tmin = max(tmin, min(t0, t1))
            tmax = min(tmax, max(t0, t1))
        elif a[ax] < lo[ax] or a[ax] > hi[ax]:
            return False
    return tmin <= tmax and tmax > 0.0 and tmin < 1.0


@_jit
def sight(poses_xytheta: np.ndarray, cand: np.ndarray, corners_robot: np.ndarray, R_cw: np.ndarray,
          t_cw: np.ndarray, K: np.ndarray, dist: np.ndarray, width: float, height: float, eye_world: np.ndarray,
          hull_lo: np.ndarray, hull_hi: np.ndarray, has_hull: bool, margin_px: float, min_side_px: float,
          min_depth_m: float, vis: np.ndarray, uv: np.ndarray, side: np.ndarray) -> None:
    """Fill ``vis`` (K, M), ``uv`` (K, M, 4, 2) and ``side`` (K, M) at the poses ``cand`` (n,).

    Parameters
    ----------
    poses_xytheta : (K, 3) robot poses on the floor (m, m, rad).
    cand : (n,) the poses to test (the others are left as they are).
    corners_robot : (M, 4, 3) the markers' corners, robot frame, m (TL TR BR BL).
    R_cw, t_cw : the camera's ``T_cam_world`` rotation (3, 3) and translation (3,).
    K, dist : the camera matrix (3, 3) and the OpenCV distortion (8,); ``width``, ``height`` the image, px.
    eye_world : (3,) the camera centre, world frame.
    hull_lo, hull_hi : (3,) the hull's box, robot frame (shrunk by 1e-6); ``has_hull`` whether there is one.
    margin_px, min_side_px, min_depth_m : the test's thresholds.
    vis, uv, side : outputs; ``uv`` is set where the marker is in front and faces the camera.
    """
    M = corners_robot.shape[0]
    k1, k2, p1, p2, k3, k4, k5, k6 = dist[0], dist[1], dist[2], dist[3], dist[4], dist[5], dist[6], dist[7]
    pw = np.empty((4, 3))
    pc = np.empty((4, 3))
    a = np.empty(3)
    b = np.empty(3)
    for ci in range(cand.shape[0]):
        k = cand[ci]
        X, Y, th = poses_xytheta[k, 0], poses_xytheta[k, 1], poses_xytheta[k, 2]
        c, s = math.cos(th), math.sin(th)
        for m in range(M):
            ok = True
            for q in range(4):
                px, py, pz = corners_robot[m, q, 0], corners_robot[m, q, 1], corners_robot[m, q, 2]
                pw[q, 0] = c * px - s * py + X
                pw[q, 1] = s * px + c * py + Y
                pw[q, 2] = pz
                for r in range(3):
                    pc[q, r] = R_cw[r, 0] * pw[q, 0] + R_cw[r, 1] * pw[q, 1] + R_cw[r, 2] * pw[q, 2] + t_cw[r]
                if not pc[q, 2] > min_depth_m:
                    ok = False
            if not ok:
                continue
            # the face's normal (TR - TL) x (TL - BL) must point away from the camera
            e1x, e1y, e1z = pc[1, 0] - pc[0, 0], pc[1, 1] - pc[0, 1], pc[1, 2] - pc[0, 2]
            e2x, e2y, e2z = pc[0, 0] - pc[3, 0], pc[0, 1] - pc[3, 1], pc[0, 2] - pc[3, 2]
            nx, ny, nz = e1y * e2z - e1z * e2y, e1z * e2x - e1x * e2z, e1x * e2y - e1y * e2x
            cx = 0.25 * (pc[0, 0] + pc[1, 0] + pc[2, 0] + pc[3, 0])
            cy = 0.25 * (pc[0, 1] + pc[1, 1] + pc[2, 1] + pc[3, 1])
            cz = 0.25 * (pc[0, 2] + pc[1, 2] + pc[2, 2] + pc[3, 2])
            if not nx * cx + ny * cy + nz * cz < 0.0:
                continue
            inside = True
            for q in range(4):
                x, y = pc[q, 0] / pc[q, 2], pc[q, 1] / pc[q, 2]
                r2 = x * x + y * y
                rad = (1 + r2 * (k1 + r2 * (k2 + r2 * k3))) / (1 + r2 * (k4 + r2 * (k5 + r2 * k6)))
                xd = x * rad + 2 * p1 * x * y + p2 * (r2 + 2 * x * x)
                yd = y * rad + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y
                u = K[0, 0] * xd + K[0, 1] * yd + K[0, 2]
                v = K[1, 1] * yd + K[1, 2]
                uv[k, m, q, 0], uv[k, m, q, 1] = u, v
                if not (u >= -0.5 + margin_px and v >= -0.5 + margin_px and u <= width - 0.5 - margin_px
                        and v <= height - 0.5 - margin_px):
                    inside = False
            sd = 0.0
            for q in range(4):
                du = uv[k, m, q, 0] - uv[k, m, q - 1, 0]
                dv = uv[k, m, q, 1] - uv[k, m, q - 1, 1]
                sd += math.sqrt(du * du + dv * dv)
            sd *= 0.25
            if not (inside and sd >= min_side_px):
                continue
            if has_hull:
                hidden = False
                for q in range(4):
                    dx, dy = pw[q, 0] - X, pw[q, 1] - Y
                    a[0], a[1], a[2] = c * dx + s * dy, -s * dx + c * dy, pw[q, 2]
                    dx, dy = eye_world[0] - X, eye_world[1] - Y
                    b[0], b[1], b[2] = c * dx + s * dy, -s * dx + c * dy, eye_world[2]
                    if _hidden_by_hull(a, b, hull_lo, hull_hi):
                        hidden = True
                        break
                if hidden:
                    continue
            vis[k, m] = True
            side[k, m] = sd
