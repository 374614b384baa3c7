"""Compiled kernels of the local matcher (numba): a uniform-grid nearest-neighbour search, scan-order
normals, the point-to-line Gauss-Newton loop and the residual evaluation at a pose.

Why compiled: the acceptance criterion is 2,000 matches per second for 181-beam scans, i.e. 0.5 ms
per match of 10-30 iterations; one NumPy/cKDTree iteration costs more than that in call overhead
alone. The grid is rebuilt per reference scan (O(M)); a query visits the (2k+1)^2 cells around the
point, k = ceil(radius / cell).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit


@njit(cache=True)
def grid_build(ref_xy: np.ndarray, cell: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Bucket (M, 2) points in square cells of side ``cell``.

    Returns ``origin`` (2,), ``shape`` (2,) int64 (nx, ny), ``start`` (nx*ny + 1,) and ``order`` (M,):
    the points of cell ``c = ix * ny + iy`` are ``order[start[c]:start[c + 1]]``.
    """
    M = ref_xy.shape[0]
    x0 = np.inf
    y0 = np.inf
    x1 = -np.inf
    y1 = -np.inf
    for j in range(M):
        x0 = min(x0, ref_xy[j, 0])
        y0 = min(y0, ref_xy[j, 1])
        x1 = max(x1, ref_xy[j, 0])
        y1 = max(y1, ref_xy[j, 1])
    if M == 0:
        x0 = y0 = x1 = y1 = 0.0
    nx = int((x1 - x0) / cell) + 1
    ny = int((y1 - y0) / cell) + 1
    counts = np.zeros(nx * ny + 1, np.int64)
    cid = np.empty(M, np.int64)
    for j in range(M):
        c = int((ref_xy[j, 0] - x0) / cell) * ny + int((ref_xy[j, 1] - y0) / cell)
        cid[j] = c
        counts[c + 1] += 1
    start = np.cumsum(counts)
    fill = start[:-1].copy()
    order = np.empty(M, np.int64)
    for j in range(M):
        order[fill[cid[j]]] = j
        fill[cid[j]] += 1
    origin = np.array([x0, y0])
    shape = np.array([nx, ny], np.int64)
    return origin, shape, start, order


@njit(cache=True)
def grid_nearest(px: float, py: float, ref_xy: np.ndarray, origin: np.ndarray, shape: np.ndarray,
                 start: np.ndarray, order: np.ndarray, cell: float, radius: float) -> tuple[int, float]:
    """Index and squared distance of the point nearest to (px, py) within ``radius``; (-1, inf) if none.

    Rings of cells around the point's cell are searched outwards; the search stops once the best
    distance is below the nearest possible distance of the next ring (``k * cell``).
    """
    nx, ny = shape[0], shape[1]
    kmax = int(math.ceil(radius / cell))
    fx = (px - origin[0]) / cell
    fy = (py - origin[1]) / cell
    if fx < -kmax or fy < -kmax or fx > nx + kmax or fy > ny + kmax:
        return -1, np.inf
    ix = int(math.floor(fx))
    iy = int(math.floor(fy))
    best = -1
    best_d2 = radius * radius
    for k in range(kmax + 1):
        for a in range(ix - k, ix + k + 1):
            if a < 0 or a >= nx:
                continue
            edge_a = a == ix - k or a == ix + k
            b = iy - k
            while b <= iy + k:
                if 0 <= b < ny:
                    c = a * ny + b
                    for q in range(start[c], start[c + 1]):
                        j = order[q]
                        dx = ref_xy[j, 0] - px
                        dy = ref_xy[j, 1] - py
                        d2 = dx * dx + dy * dy
                        if d2 < best_d2:
                            best_d2 = d2
                            best = j
                # inside the ring only its top and bottom cells are new
                b = b + 1 if edge_a or k == 0 else (iy + k if b == iy - k else b + 1)
        reach = k * cell
        if best >= 0 and best_d2 <= reach * reach:
            break
    if best < 0:
        return -1, np.inf
    return best, best_d2


@njit(cache=True)
def ordered_normals(xy: np.ndarray, valid: np.ndarray, gap_m: np.ndarray, half: int,
                    max_flatness: float, noise_var: np.ndarray, chi2_95: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Unit normals of an ordered scan's points (N, 2) by a line fit over the neighbours ``i - half ..
    i + half`` closer than ``gap_m[i]``; ``ok[i]`` when at least 3 points fit a line: its smaller
    spread / larger spread ratio (eigenvalues) is below ``max_flatness``, or (4 points or more) the
    points' scatter across the line is what their noise explains: the smaller eigenvalue of the scatter
    matrix is within ``chi2_95[cnt - 2] * noise_var[i]`` (the chi-square 95 % quantile of a line's
    ``cnt - 2`` degrees of freedom times the point's variance). The second test keeps the normals of
    densely sampled walls (0.5-degree scans at a metre or two: a 5-point window spans a few
    centimetres, comparable to the noise) that the ratio alone refuses."""
    N = xy.shape[0]
    nrm = np.zeros((N, 2))
    ok = np.zeros(N, np.bool_)
    for i in range(N):
        if not valid[i]:
            continue
        sx = 0.0
        sy = 0.0
        cnt = 0
        for j in range(max(0, i - half), min(N, i + half + 1)):
            if valid[j]:
                dx = xy[j, 0] - xy[i, 0]
                dy = xy[j, 1] - xy[i, 1]
                if dx * dx + dy * dy <= gap_m[i] * gap_m[i]:
                    sx += xy[j, 0]
                    sy += xy[j, 1]
                    cnt += 1
        if cnt < 3:
            continue
        mx = sx / cnt
        my = sy / cnt
        cxx = 0.0
        cxy = 0.0
        cyy = 0.0
        for j in range(max(0, i - half), min(N, i + half + 1)):
            if valid[j]:
                dx = xy[j, 0] - xy[i, 0]
                dy = xy[j, 1] - xy[i, 1]
                if dx * dx + dy * dy <= gap_m[i] * gap_m[i]:
                    ux = xy[j, 0] - mx
                    uy = xy[j, 1] - my
                    cxx += ux * ux
                    cxy += ux * uy
                    cyy += uy * uy
        tr = cxx + cyy
        det = cxx * cyy - cxy * cxy
        disc = math.sqrt(max(0.0, 0.25 * tr * tr - det))
        lmax = 0.5 * tr + disc
        lmin = 0.5 * tr - disc
        if lmax <= 0.0:
            continue
        # eigenvector of the smaller eigenvalue
        if abs(cxy) > 1e-300:
            vx = lmin - cyy
            vy = cxy
        elif cxx < cyy:
            vx = 1.0
            vy = 0.0
        else:
            vx = 0.0
            vy = 1.0
        n = math.hypot(vx, vy)
        nrm[i, 0] = vx / n
        nrm[i, 1] = vy / n
        ok[i] = lmin <= max_flatness * lmax or (cnt >= 4 and lmin <= chi2_95[cnt - 2] * noise_var[i])
    return nrm, ok


@njit(cache=True)
def icp_point_to_line(ref_xy: np.ndarray, ref_n: np.ndarray, ref_ok: np.ndarray, cur_xy: np.ndarray,
                      pose0: np.ndarray, cell: float, r_start: float, r_min: float, shrink: float,
                      trim: float, max_iter: int, tol_m: float, tol_rad: float) -> tuple[np.ndarray, int, int, float]:
    """Point-to-line ICP (Censi 2008's error metric; Gauss-Newton on the exact rotation).

    The current points ``cur_xy`` (N, 2) are moved by ``pose`` = (x, y, theta) onto the reference
    (M, 2) with normals ``ref_n``; each is associated with its nearest reference point within the
    association radius, which starts at ``r_start`` and shrinks by ``shrink`` per iteration down to
    ``r_min``; the ``trim`` fraction of the largest residuals is dropped. Stops when an update is
    below ``tol_m`` / ``tol_rad`` at the final radius.

    Returns the pose (3,), the iterations run, the number of correspondences of the last one (0: too
    few, the pose is ``pose0``) and the last update's size (metres, rotation taken at 1 m).
    """
    origin, shape, start, order = grid_build(ref_xy, cell)
    N = cur_xy.shape[0]
    pose = pose0.copy()
    r = r_start
    e = np.empty(N)
    ae = np.empty(N)
    J = np.empty((N, 3))
    m = 0
    it = 0
    step = np.inf
    small = 0
    for it in range(1, max_iter + 1):
        c = math.cos(pose[2])
        s = math.sin(pose[2])
        m = 0
        for i in range(N):
            qx = c * cur_xy[i, 0] - s * cur_xy[i, 1]
            qy = s * cur_xy[i, 0] + c * cur_xy[i, 1]
            px = qx + pose[0]
            py = qy + pose[1]
            j, d2 = grid_nearest(px, py, ref_xy, origin, shape, start, order, cell, r)
            if j < 0 or not ref_ok[j]:
                continue
            nx_ = ref_n[j, 0]
            ny_ = ref_n[j, 1]
            e[m] = nx_ * (px - ref_xy[j, 0]) + ny_ * (py - ref_xy[j, 1])
            ae[m] = abs(e[m])
            J[m, 0] = nx_
            J[m, 1] = ny_
            J[m, 2] = -nx_ * qy + ny_ * qx
            m += 1
        if m < 6:
            return pose0.copy(), it, 0, np.inf
        thr = np.inf
        if trim > 0.0:
            srt = np.sort(ae[:m])
            thr = srt[min(m - 1, int((1.0 - trim) * m))]
        H = np.zeros((3, 3))
        g = np.zeros(3)
        for k in range(m):
            if ae[k] <= thr:
                for a in range(3):
                    g[a] += J[k, a] * e[k]
                    for b in range(3):
                        H[a, b] += J[k, a] * J[k, b]
        # a small damping keeps a degenerate direction (a corridor's axis) from exploding
        for a in range(3):
            H[a, a] += 1e-9
        d = np.linalg.solve(H, -g)
        pose[0] += d[0]
        pose[1] += d[1]
        pose[2] += d[2]
        step = math.hypot(d[0], d[1]) + abs(d[2])
        at_min = r <= r_min * 1.0000001
        if at_min and math.hypot(d[0], d[1]) < tol_m and abs(d[2]) < tol_rad:
            break
        # an association flipping between two neighbours oscillates below 0.1 mm: stop after three
        small = small + 1 if at_min and step < 1e-4 else 0
        if small >= 3:
            break
        r = max(r_min, r * shrink)
    pose[2] = math.atan2(math.sin(pose[2]), math.cos(pose[2]))
    return pose, it, m, step


@njit(cache=True)
def residuals_at(ref_xy: np.ndarray, ref_n: np.ndarray, ref_ok: np.ndarray, cur_xy: np.ndarray,
                 pose: np.ndarray, cell: float, radius: float) -> tuple[np.ndarray, np.ndarray, np.ndarray,
                                                                        np.ndarray]:
    """At ``pose``: per current point the distance to the nearest reference point within ``radius``
    (inf if none), its point-to-line residual (nan if none or no normal), the Jacobian row (N, 3) of
    the residual with respect to (x, y, theta), and the index of the reference point (-1 if none)."""
    origin, shape, start, order = grid_build(ref_xy, cell)
    N = cur_xy.shape[0]
    c = math.cos(pose[2])
    s = math.sin(pose[2])
    d = np.full(N, np.inf)
    e = np.full(N, np.nan)
    J = np.zeros((N, 3))
    idx = np.full(N, -1, np.int64)
    for i in range(N):
        qx = c * cur_xy[i, 0] - s * cur_xy[i, 1]
        qy = s * cur_xy[i, 0] + c * cur_xy[i, 1]
        px = qx + pose[0]
        py = qy + pose[1]
        j, d2 = grid_nearest(px, py, ref_xy, origin, shape, start, order, cell, radius)
        if j < 0:
            continue
        d[i] = math.sqrt(d2)
        idx[i] = j
        if ref_ok[j]:
            nx_ = ref_n[j, 0]
            ny_ = ref_n[j, 1]
            e[i] = nx_ * (px - ref_xy[j, 0]) + ny_ * (py - ref_xy[j, 1])
            J[i, 0] = nx_
            J[i, 1] = ny_
            J[i, 2] = -nx_ * qy + ny_ * qx
    return d, e, J, idx


@njit(cache=True)
def evaluate_fit(ref_xy: np.ndarray, ref_n: np.ndarray, ref_ok: np.ndarray, ref_sigma: np.ndarray,
                 cur_xy: np.ndarray, cur_sigma: np.ndarray, pose: np.ndarray, cell: float, radius: float,
                 inlier_sigma: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, int, float,
                                               np.ndarray]:
    """:func:`residuals_at` plus the inlier test, the inliers' normal matrix and the covariance in one pass.

    Returns residuals (N,), expected sigmas (N,) (nan: no association), inlier mask (N,), Jacobian
    rows (N, 3), ``H = J^T J`` over the inliers (3, 3), the number of associated points, the
    inliers' sum of squared residuals and ``s^2 H^-1`` (3, 3; inf when H is not positive definite or
    there are 3 inliers or fewer).
    """
    d, e, J, idx = residuals_at(ref_xy, ref_n, ref_ok, cur_xy, pose, cell, radius)
    N = cur_xy.shape[0]
    sig = np.full(N, np.nan)
    inl = np.zeros(N, np.bool_)
    H = np.zeros((3, 3))
    n_matched = 0
    sse = 0.0
    for i in range(N):
        j = idx[i]
        if j < 0:
            continue
        n_matched += 1
        s = math.sqrt(cur_sigma[i] * cur_sigma[i] + ref_sigma[j] * ref_sigma[j])
        sig[i] = s
        if np.isfinite(e[i]) and abs(e[i]) <= inlier_sigma * s:
            inl[i] = True
            sse += e[i] * e[i]
            for a in range(3):
                for b in range(3):
                    H[a, b] += J[i, a] * J[i, b]
    m = 0
    for i in range(N):
        if inl[i]:
            m += 1
    cov = np.full((3, 3), np.inf)
    if m > 3:
        # Cholesky by hand: it both inverts and proves H positive definite
        L = np.zeros((3, 3))
        ok = True
        for a in range(3):
            for b in range(a + 1):
                acc = H[a, b]
                for k in range(b):
                    acc -= L[a, k] * L[b, k]
                if a == b:
                    if acc <= 0.0:
                        ok = False
                        break
                    L[a, a] = math.sqrt(acc)
                else:
                    L[a, b] = acc / L[b, b]
            if not ok:
                break
        if ok:
            Li = np.zeros((3, 3))
            for a in range(3):
                Li[a, a] = 1.0 / L[a, a]
                for b in range(a):
                    acc = 0.0
                    for k in range(b, a):
                        acc -= L[a, k] * Li[k, b]
                    Li[a, b] = acc / L[a, a]
            s2 = sse / (m - 3)
            for a in range(3):
                for b in range(3):
                    acc = 0.0
                    for k in range(3):
                        acc += Li[k, a] * Li[k, b]
                    cov[a, b] = s2 * acc
    return e, sig, inl, J, H, n_matched, sse, cov
