"""Relative poses of fixed cameras from a hand-held board seen by two or more of them at once.

Method
------
1. **Board poses.** In every view with at least ``min_corners`` corners, the board's pose ``T_cam_board``
   by planar PnP (IPPE, then Levenberg-Marquardt) with the camera's intrinsics.
2. **Pair edges.** At each instant (``sync_index``) two cameras both see the board,
   ``T_a_b = T_a_board @ inv(T_b_board)``; a pair's instants are averaged on SE(3)
   (:func:`gtrig.geometry.se3avg.mean_pose`) after dropping those whose rotation or translation is more than
   ``3`` robust sigmas from a first mean.
3. **Chain.** From the reference camera, breadth-first over the pairs, most shared instants first.
4. **Bundle adjustment.** Unknowns: every camera's pose but the reference's (``T_cam_ref``) and the board's
   pose at every instant seen by two or more cameras; the intrinsics are held. Residuals: every corner's
   reprojection error in pixels, under a Huber loss (``huber_px``). Solved by Levenberg-Marquardt on
   iteratively reweighted normal equations, the Jacobian by central differences block by block (a corner
   depends on its camera's and its board's 12 unknowns).
5. **Uncertainty.** ``Cov = s^2 (J^T J)^-1`` at the optimum, ``s^2`` the residual variance per degree of
   freedom; the baselines' and relative angles' standard deviations are propagated from it to first order
   (cross terms between the cameras kept). The held intrinsics' uncertainty is added as for any two-step
   estimate: ``Cov += A Cov_lens A^T`` with ``A = -(J^T W J)^-1 J^T W J_lens`` the first-order sensitivity of
   the solution to the intrinsics (``J_lens`` by central differences of the same residuals), ``Cov_lens``
   diagonal from each lens's ``extra["std_honest"]`` (else ``extra["std"]``; a lens with neither adds
   nothing).

The reference camera's frame is the world: poses are ``T_ref_cam``.
"""

from __future__ import annotations

import logging
from collections import deque
from collections.abc import Mapping
from dataclasses import dataclass
from itertools import combinations

import cv2
import numpy as np
from scipy.sparse import csr_matrix, diags
from scipy.sparse.linalg import spsolve
from scipy.spatial.transform import Rotation

from gtrig import geometry as geo
from gtrig.calib.idboards import IdBoard
from gtrig.calib.video_detect import VideoDetections
from gtrig.errors import ConvergenceError, InputError
from gtrig.geometry.se3avg import mean_pose
from gtrig.io.camfile import CameraIntrinsics

log = logging.getLogger(__name__)

MIN_CORNERS = 6
MIN_PAIR_INSTANTS = 3


@dataclass(frozen=True)
class BoardObservation:
    """One camera's view of the board at one instant: corner IDs (N,), pixels (N, 2), PnP pose."""

    camera: str
    instant: int
    ids: np.ndarray
    corners_px: np.ndarray
    T_cam_board: np.ndarray


@dataclass(frozen=True)
class PairRelation:
    """A pair's relative pose from the instants both cameras saw the board.

    Attributes
    ----------
    T_a_b : (4, 4) camera b in camera a (metres).
    n_instants : instants averaged (after outliers are dropped).
    rms_rot_deg, rms_trans_m : the instants' spread about the mean.
    """

    cam_a: str
    cam_b: str
    T_a_b: np.ndarray
    n_instants: int
    rms_rot_deg: float
    rms_trans_m: float


@dataclass(frozen=True)
class VideoNetworkResult:
    """The cameras' poses in the reference camera's frame.

    Attributes
    ----------
    reference : the reference camera.
    T_ref_cam : {camera: (4, 4)} pose of each camera in the reference camera's frame (metres).
    cov : (6C, 6C) covariance of the non-reference cameras' ``T_cam_ref`` perturbations, in ``order``:
        ``[rx ry rz (rad), tx ty tz (m)]`` each, ``T_cam_ref = [Exp(r) R0, t0 + t]``.
    order : the non-reference cameras, in ``cov``'s order.
    pairs : the pair relations that seeded the adjustment.
    rms_px : {camera: reprojection RMS} of the adjustment; ``rms_px_all`` over every corner.
    n_instants : instants in the adjustment; ``n_corners`` corners.
    """

    reference: str
    T_ref_cam: dict[str, np.ndarray]
    cov: np.ndarray
    order: tuple[str, ...]
    pairs: tuple[PairRelation, ...]
    rms_px: dict[str, float]
    rms_px_all: float
    n_instants: int
    n_corners: int


def board_observations(
    dets: Mapping[str, VideoDetections], cams: Mapping[str, CameraIntrinsics], board: IdBoard,
    min_corners: int = MIN_CORNERS,
) -> list[BoardObservation]:
    """Every view with ``min_corners`` or more, with its PnP pose (method, step 1)."""
    P = board.object_points()
    out = []
    for name, det in dets.items():
        K, dist = cams[name].camera_matrix, cams[name].dist_coeffs
        for inst, v in zip(det.sync_index, det.views, strict=True):
            if len(v.ids) < min_corners:
                continue
            obj, img = P[v.ids], v.corners_px
            ok, rv, tv = cv2.solvePnP(obj, img, K, dist, flags=cv2.SOLVEPNP_IPPE)
            if not ok:
                continue
            rv, tv = cv2.solvePnPRefineLM(obj, img, K, dist, rv, tv)
            out.append(BoardObservation(name, int(inst), v.ids, v.corners_px,
                                        geo.make_T(cv2.Rodrigues(rv)[0], tv.ravel())))
    return out


def _robust_mean(T: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    first = mean_pose(T).T
    dr = np.linalg.norm(Rotation.from_matrix(np.einsum("ji,njk->nik", first[:3, :3], T[:, :3, :3])).as_rotvec(), axis=1)
    dt = np.linalg.norm(T[:, :3, 3] - first[:3, 3], axis=1)
    keep = np.ones(len(T), bool)
    for d in (dr, dt):
        med = np.median(d)
        keep &= d <= med + 3.0 * 1.4826 * np.median(np.abs(d - med)) + 1e-12
    return T[keep], keep


def pair_relations(obs: list[BoardObservation]) -> list[PairRelation]:
    """Each pair's averaged relative pose (method, step 2); pairs with fewer than 3 instants are left out."""
    by_inst: dict[int, dict[str, BoardObservation]] = {}
    for o in obs:
        by_inst.setdefault(o.instant, {})[o.camera] = o
    cams = sorted({o.camera for o in obs})
    out = []
    for a, b in combinations(cams, 2):
        Ts = np.array([s[a].T_cam_board @ geo.inv_T(s[b].T_cam_board) for s in by_inst.values() if a in s and b in s])
        if len(Ts) < MIN_PAIR_INSTANTS:
            continue
        kept, _ = _robust_mean(Ts)
        m = mean_pose(kept)
        out.append(PairRelation(a, b, m.T, m.n, float(np.degrees(m.rot_rms_rad)), m.trans_rms_m))
    return out


def chain_poses(reference: str, cameras: list[str], pairs: list[PairRelation]) -> dict[str, np.ndarray]:
    """``T_ref_cam`` of every camera reachable from ``reference`` (method, step 3)."""
    T = {reference: np.eye(4)}
    queue = deque([reference])
    ranked = sorted(pairs, key=lambda p: -p.n_instants)
    while queue:
        a = queue.popleft()
        for p in ranked:
            for x, y, T_xy in ((p.cam_a, p.cam_b, p.T_a_b), (p.cam_b, p.cam_a, geo.inv_T(p.T_a_b))):
                if x == a and y not in T:
                    T[y] = T[a] @ T_xy
                    queue.append(y)
    missing = [c for c in cameras if c not in T]
    if missing:
        raise InputError(f"cameras {', '.join(missing)} share no instant with the board with the others "
                         f"(need {MIN_PAIR_INSTANTS} instants seen by two cameras)")
    return T


def project(X_cam: np.ndarray, K: np.ndarray, dist: np.ndarray) -> np.ndarray:
    """OpenCV's pinhole projection with (k1, k2, p1, p2, k3) distortion: points (N, 3) to pixels (N, 2)."""
    d = np.zeros(5)
    d[: min(5, dist.size)] = dist[:5]
    k1, k2, p1, p2, k3 = d
    x, y = X_cam[:, 0] / X_cam[:, 2], X_cam[:, 1] / X_cam[:, 2]
    r2 = x * x + y * y
    radial = 1 + k1 * r2 + k2 * r2**2 + k3 * r2**3
    xd = x * radial + 2 * p1 * x * y + p2 * (r2 + 2 * x * x)
    yd = y * radial + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y
    return np.column_stack([K[0, 0] * xd + K[0, 1] * yd + K[0, 2], K[1, 1] * yd + K[1, 2]])


def _exp_so3(w: np.ndarray) -> np.ndarray:
    """Rodrigues' formula: a rotation vector (3,), rad, to a rotation matrix (3, 3)."""
    th = float(np.sqrt(w[0] * w[0] + w[1] * w[1] + w[2] * w[2]))
    W = np.array([[0.0, -w[2], w[1]], [w[2], 0.0, -w[0]], [-w[1], w[0], 0.0]])
    if th < 1e-12:
        return np.eye(3) + W
    return np.eye(3) + (np.sin(th) / th) * W + ((1.0 - np.cos(th)) / th**2) * (W @ W)


def _perturb(T0: np.ndarray, p: np.ndarray) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3] = _exp_so3(p[:3]) @ T0[:3, :3]
    T[:3, 3] = T0[:3, 3] + p[3:]
    return T


@dataclass(frozen=True)
class _Problem:
    order: tuple[str, ...]
    instants: tuple[int, ...]
    obs: tuple[BoardObservation, ...]
    T_cam_ref0: dict[str, np.ndarray]
    T_ref_board0: dict[int, np.ndarray]


def _build(reference: str, obs: list[BoardObservation], T_ref_cam: dict[str, np.ndarray]) -> _Problem:
    count: dict[int, int] = {}
    for o in obs:
        count[o.instant] = count.get(o.instant, 0) + 1
    shared = tuple(sorted(i for i, n in count.items() if n >= 2))
    kept = tuple(o for o in obs if count[o.instant] >= 2 and o.camera in T_ref_cam)
    T_ref_board: dict[int, list[np.ndarray]] = {}
    for o in kept:
        T_ref_board.setdefault(o.instant, []).append(T_ref_cam[o.camera] @ o.T_cam_board)
    order = tuple(sorted(c for c in T_ref_cam if c != reference))
    return _Problem(order, shared, kept, {c: geo.inv_T(T_ref_cam[c]) for c in order},
                    {i: mean_pose(np.array(v)).T for i, v in T_ref_board.items()})


def _obs_residual(o: BoardObservation, cam: CameraIntrinsics, P: np.ndarray, T_cam_ref: np.ndarray,
                  T_ref_board: np.ndarray) -> np.ndarray:
    T = T_cam_ref @ T_ref_board
    Xc = P[o.ids] @ T[:3, :3].T + T[:3, 3]
    return (project(Xc, cam.camera_matrix, cam.dist_coeffs) - o.corners_px).ravel()


def _blocks(prob: _Problem) -> list[tuple[int | None, int]]:
    """Per observation: the column of its camera's block (None for the reference) and of its board's."""
    cam_index = {c: 6 * k for k, c in enumerate(prob.order)}
    inst_index = {i: 6 * len(prob.order) + 6 * k for k, i in enumerate(prob.instants)}
    return [(cam_index.get(o.camera), inst_index[o.instant]) for o in prob.obs]


def _poses(x: np.ndarray, prob: _Problem, blocks: list[tuple[int | None, int]],
           k: int) -> tuple[np.ndarray, np.ndarray]:
    jc, jb = blocks[k]
    o = prob.obs[k]
    T_cam_ref = np.eye(4) if jc is None else _perturb(prob.T_cam_ref0[o.camera], x[jc: jc + 6])
    return T_cam_ref, _perturb(prob.T_ref_board0[o.instant], x[jb: jb + 6])


def _residuals(x: np.ndarray, prob: _Problem, cams: Mapping[str, CameraIntrinsics], P: np.ndarray) -> np.ndarray:
    blocks = _blocks(prob)
    return np.concatenate([
        _obs_residual(o, cams[o.camera], P, *_poses(x, prob, blocks, k)) for k, o in enumerate(prob.obs)
    ])


def _jacobian(x: np.ndarray, prob: _Problem, cams: Mapping[str, CameraIntrinsics], P: np.ndarray) -> np.ndarray:
    """Dense (M, N) Jacobian by central differences, block by block (a corner depends on 12 unknowns)."""
    blocks = _blocks(prob)
    rows = sum(2 * len(o.ids) for o in prob.obs)
    J = np.zeros((rows, x.size))
    eps = 1e-6
    r = 0
    for k, o in enumerate(prob.obs):
        m = 2 * len(o.ids)
        cam = cams[o.camera]
        T_cam_ref, T_ref_board = _poses(x, prob, blocks, k)
        jc, jb = blocks[k]
        for d in range(6):
            e = np.zeros(6)
            e[d] = eps
            if jc is not None:
                J[r: r + m, jc + d] = (_obs_residual(o, cam, P, _perturb(T_cam_ref, e), T_ref_board)
                                       - _obs_residual(o, cam, P, _perturb(T_cam_ref, -e), T_ref_board)) / (2 * eps)
            J[r: r + m, jb + d] = (_obs_residual(o, cam, P, T_cam_ref, _perturb(T_ref_board, e))
                                   - _obs_residual(o, cam, P, T_cam_ref, _perturb(T_ref_board, -e))) / (2 * eps)
        r += m
    return J


#: the intrinsics whose sigmas are propagated: ``fx fy cx cy`` (pixels), ``k1 k2 p1 p2 k3``
LENS_PARAMS = ("fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2", "k3")


def lens_sigmas(cam: CameraIntrinsics) -> np.ndarray:
    """The lens's standard deviations (9,) in :data:`LENS_PARAMS` order; zero where none is stated.

    ``extra["std_honest"]`` (the largest of OpenCV's and the jackknives over views and over 1 s blocks) if present,
    else ``extra["std"]``.
    """
    std = cam.extra.get("std_honest") or cam.extra.get("std") or {}
    sig = np.array([float(std.get(k, 0.0)) for k in LENS_PARAMS])
    return np.where(np.isfinite(sig), sig, 0.0)


def _shift_lens(cam: CameraIntrinsics, k: int, h: float) -> CameraIntrinsics:
    """The lens with parameter ``LENS_PARAMS[k]`` moved by ``h``."""
    K = cam.camera_matrix.astype(float).copy()
    dist = np.zeros(5)
    dist[: min(5, cam.dist_coeffs.size)] = np.ravel(cam.dist_coeffs)[:5]
    if k < 4:
        K[(0, 1, 0, 1)[k], (0, 1, 2, 2)[k]] += h
    else:
        dist[k - 4] += h
    return CameraIntrinsics(cam.image_size, K, dist)


def _lens_jacobian(x: np.ndarray, prob: _Problem, cams: Mapping[str, CameraIntrinsics], P: np.ndarray,
                   lens_order: tuple[str, ...]) -> np.ndarray:
    """Dense (M, 9L) derivative of the residuals w.r.t. each lens's :data:`LENS_PARAMS`, central differences."""
    blocks = _blocks(prob)
    col = {c: 9 * k for k, c in enumerate(lens_order)}
    J = np.zeros((sum(2 * len(o.ids) for o in prob.obs), 9 * len(lens_order)))
    r = 0
    for k, o in enumerate(prob.obs):
        m = 2 * len(o.ids)
        if o.camera in col:
            T_cam_ref, T_ref_board = _poses(x, prob, blocks, k)
            for d in range(9):
                h = 1e-4 if d < 4 else 1e-6
                up, down = _shift_lens(cams[o.camera], d, h), _shift_lens(cams[o.camera], d, -h)
                J[r: r + m, col[o.camera] + d] = (_obs_residual(o, up, P, T_cam_ref, T_ref_board)
                                                  - _obs_residual(o, down, P, T_cam_ref, T_ref_board)) / (2 * h)
        r += m
    return J


def _lens_covariance(x: np.ndarray, prob: _Problem, cams: Mapping[str, CameraIntrinsics], P: np.ndarray,
                    J: np.ndarray, w: np.ndarray, H_inv: np.ndarray) -> np.ndarray:
    """The (N, N) covariance the held lenses' sigmas add to the unknowns: ``A Cov_lens A^T`` (method, step 5).

    ``J`` (M, N) and ``w`` (M,) are the unknowns' Jacobian and IRLS weights at the solution, ``H_inv`` (N, N)
    the inverse of ``J^T W J``.
    """
    lens_order = tuple(sorted({o.camera for o in prob.obs}))
    sig = np.concatenate([lens_sigmas(cams[c]) for c in lens_order])
    if not np.any(sig > 0):
        return np.zeros_like(H_inv)
    J_lens = _lens_jacobian(x, prob, cams, P, lens_order)
    A = -H_inv @ (J.T @ (J_lens * w[:, None]))
    As = A * sig[None, :]
    return As @ As.T


def _huber_weights(r: np.ndarray, huber_px: float) -> np.ndarray:
    """Per residual, the IRLS weight of its corner's pixel error under a Huber loss."""
    e = np.linalg.norm(r.reshape(-1, 2), axis=1)
    w = np.where(e <= huber_px, 1.0, huber_px / np.maximum(e, 1e-12))
    return np.repeat(w, 2)


def _solve(prob: _Problem, cams: Mapping[str, CameraIntrinsics], P: np.ndarray, huber_px: float,
           max_iter: int = 30) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Levenberg-Marquardt on iteratively reweighted normal equations; returns x, r, J, weights."""
    n = 6 * len(prob.order) + 6 * len(prob.instants)
    x = np.zeros(n)
    lam = 1e-3
    r = _residuals(x, prob, cams, P)
    for _ in range(max_iter):
        w = _huber_weights(r, huber_px)
        J = csr_matrix(_jacobian(x, prob, cams, P))
        H = (J.T @ J.multiply(w[:, None])).tocsc()
        g = J.T @ (w * r)
        cost = float(np.sum(w * r * r))
        d = H.diagonal() + 1e-12
        while True:
            dx = -spsolve(H + diags(lam * d), g)
            if not np.all(np.isfinite(dx)):
                raise ConvergenceError("camera network adjustment: singular normal equations")
            r_new = _residuals(x + dx, prob, cams, P)
            if float(np.sum(w * r_new * r_new)) < cost or lam > 1e8:
                break
            lam *= 10.0
        if lam > 1e8:
            break
        new_cost = float(np.sum(w * r_new * r_new))
        x, r = x + dx, r_new
        lam = max(lam / 10.0, 1e-9)
        if cost - new_cost < 1e-6 * cost or float(np.max(np.abs(dx))) < 1e-8:
            break
    w = _huber_weights(r, huber_px)
    return x, r, _jacobian(x, prob, cams, P), w


def calibrate_video_network(
    dets: Mapping[str, VideoDetections],
    cams: Mapping[str, CameraIntrinsics],
    board: IdBoard,
    reference: str | None = None,
    *,
    huber_px: float = 1.0,
    min_corners: int = MIN_CORNERS,
    lens_uncertainty: bool = True,
) -> VideoNetworkResult:
    """The cameras' relative poses (module docstring).

    Parameters
    ----------
    dets : each camera's board detections (with ``sync_index`` giving the instants).
    cams : each camera's intrinsics (held).
    board : the board.
    reference : the camera whose frame is the world (default: the first by name).
    lens_uncertainty : add the held lenses' sigmas (:func:`lens_sigmas`) to ``cov`` (method, step 5).

    Raises
    ------
    InputError
        A camera shares no instant with the others. ConvergenceError: the adjustment fails.
    """
    names = sorted(dets)
    ref = reference or names[0]
    if ref not in dets:
        raise InputError(f"reference camera {ref!r}: not one of {', '.join(names)}")
    obs = board_observations(dets, cams, board, min_corners)
    pairs = pair_relations(obs)
    T0 = chain_poses(ref, names, pairs)
    prob = _build(ref, obs, T0)
    P = board.object_points()
    n = 6 * len(prob.order) + 6 * len(prob.instants)
    x, r, J, w = _solve(prob, cams, P, huber_px)
    dof = max(r.size - n, 1)
    s2 = float(np.sum(w * r * r) / dof)
    H_inv = np.linalg.pinv(J.T @ (J * w[:, None]))
    cov_all = s2 * H_inv
    if lens_uncertainty:
        cov_all = cov_all + _lens_covariance(x, prob, cams, P, J, w, H_inv)
    T_ref_cam = {ref: np.eye(4)}
    for k, c in enumerate(prob.order):
        T_ref_cam[c] = geo.inv_T(_perturb(prob.T_cam_ref0[c], x[6 * k: 6 * k + 6]))
    rms: dict[str, float] = {}
    start = 0
    per_cam: dict[str, list[np.ndarray]] = {}
    for o in prob.obs:
        m = 2 * len(o.ids)
        per_cam.setdefault(o.camera, []).append(r[start: start + m])
        start += m
    for c, parts in per_cam.items():
        e = np.concatenate(parts).reshape(-1, 2)
        rms[c] = float(np.sqrt(np.mean(np.sum(e**2, axis=1))))
    rms_all = float(np.sqrt(np.mean(np.sum(r.reshape(-1, 2) ** 2, axis=1))))
    nc6 = 6 * len(prob.order)
    log.info("camera network: %d instants, %d corners, RMS %.3f px", len(prob.instants), r.size // 2, rms_all)
    return VideoNetworkResult(ref, T_ref_cam, cov_all[:nc6, :nc6], prob.order, tuple(pairs), rms, rms_all,
                              len(prob.instants), r.size // 2)


@dataclass(frozen=True)
class RelativePose:
    """Camera b seen from camera a: baseline (m) and rotation angle (deg), each with a standard deviation."""

    cam_a: str
    cam_b: str
    baseline_m: float
    sigma_baseline_m: float
    angle_deg: float
    sigma_angle_deg: float


def _pair_quantities(T_a_ref: np.ndarray, T_b_ref: np.ndarray) -> np.ndarray:
    T_a_b = T_a_ref @ geo.inv_T(T_b_ref)
    ang = float(np.linalg.norm(Rotation.from_matrix(T_a_b[:3, :3]).as_rotvec()))
    return np.array([np.linalg.norm(T_a_b[:3, 3]), np.degrees(ang)])


def relative_poses(res: VideoNetworkResult) -> list[RelativePose]:
    """Every pair's baseline and relative angle with first-order standard deviations from ``res.cov``."""
    idx = {c: k for k, c in enumerate(res.order)}
    T_cam_ref = {c: geo.inv_T(T) for c, T in res.T_ref_cam.items()}
    out = []
    eps = 1e-7
    for a, b in combinations(sorted(res.T_ref_cam), 2):
        f0 = _pair_quantities(T_cam_ref[a], T_cam_ref[b])
        J = np.zeros((2, res.cov.shape[0]))
        for cam in (a, b):
            if cam not in idx:
                continue
            for d in range(6):
                p = np.zeros(6)
                p[d] = eps
                Ta = _perturb(T_cam_ref[a], p) if cam == a else T_cam_ref[a]
                Tb = _perturb(T_cam_ref[b], p) if cam == b else T_cam_ref[b]
                J[:, 6 * idx[cam] + d] = (_pair_quantities(Ta, Tb) - f0) / eps
        C = J @ res.cov @ J.T
        out.append(RelativePose(a, b, float(f0[0]), float(np.sqrt(C[0, 0])), float(f0[1]), float(np.sqrt(C[1, 1]))))
    return out
