"""Extrinsic calibration of a camera network with narrow overlaps: double chessboard, chain, joint BA.

Method
------
1. **Pair edges** (the seeds' method, AD2.3 "Calibration of the camera network"). Each instant of a
   pair ``camA-camB`` sees board 1 in A and board 2 in B; with PnP poses ``T_A_b1``, ``T_B_b2`` and the
   double board's nominal ``T_b1_b2``: ``T_A_B = T_A_b1 @ T_b1_b2 @ inv(T_B_b2)``. The instants are
   averaged on SE(3) (:mod:`gtrig.calib.se3avg`), not element-wise as the seeds did.
2. **Chain.** From the world-anchored camera(s) (:func:`gtrig.calib.anchor.anchor_camera`), breadth-first
   over the pair graph: ``T_world_B = T_world_A @ T_A_B``. Errors add up along the chain, and the
   nominal double-board transform biases every edge.
3. **Joint bundle adjustment.** Unknowns: every ``T_world_cam``, every camera's lens (fx, fy, cx, cy,
   k1, k2, p1, p2, and k3 if asked), the double board's ``T_b1_b2``, the pose ``T_world_b1`` of the
   double board at every instant and the pose ``T_cam_board`` of the board in every view of the
   intrinsic sweeps; the world board's pose is fixed (it defines the world frame). Residuals: the
   reprojection error of every corner in pixels (sweeps, pairs, world board), plus a weak prior on
   ``T_b1_b2`` around its nominal value (``prior_T12_sigma_m``, ``prior_T12_sigma_deg``). The sweep views
   themselves, rather than the single-camera solution as a prior, tie each lens: that keeps every
   correlation between its parameters (the principal point and the tangential terms are strongly
   correlated, and ``calibrateCameraExtended`` reports only standard deviations). A camera without
   sweep views takes its lens's stated standard deviations (``extra["std"]`` of a ``cam.yaml``) as a
   prior, or holds it. The pairs and the world board then add what they know about the lenses: on the
   seeds' simulated rooms the focal lengths' standard deviation halves, the principal points' drops by
   a third.
   Solved by Levenberg-Marquardt on iteratively reweighted normal equations (Huber loss per corner,
   ``huber_px``) with an analytic sparse Jacobian (a corner depends on one camera, its lens, one board
   pose and perhaps ``T_b1_b2``); the board poses, 6-blocks that no corner shares, are eliminated by the
   Schur complement, so a step costs a solve in the cameras' and lenses' few parameters however many
   views there are. ``scipy.optimize.least_squares`` was tried first: with ``tr_solver="lsmr"`` it
   stalled on this problem's conditioning (RMS 0.13 px after 100 evaluations where the optimum is
   0.069 px), and ``"exact"`` needs a dense SVD per iteration; it reaches the same optimum as this
   solver.
   Poses are perturbed as ``R = Exp(w) R0, t = t0 + v``, so ``w`` and ``v`` are in the world frame (for a
   camera, ``v`` moves its optical centre in world metres; for a sweep board, the camera frame).
4. **Uncertainty.** ``Cov = s^2 (J^T J)^-1`` at the optimum, ``s^2`` the residual variance per degree of
   freedom (Triggs et al., "Bundle adjustment: a modern synthesis", 2000, section 9). For that to hold the
   prior rows (on ``T_b1_b2``, on a lens without sweep views) are in pixels too: the adjustment is solved
   once, then again with every prior row times the corners' standard deviation ``s``, so that a prior
   weighs as its stated sigma next to the corners (unscaled it weighed ``1 / s^2`` times more). The 6 x 6 block of
   a camera is ``[w (rad), v (m)]`` in world axes; it is marginal over the lenses, so it includes the
   intrinsics' uncertainty (a principal point off by 0.5 px turns a camera of f = 1500 px by 0.02 deg).
   The block with the lenses held (``sigma_*_fixed_intrinsics``) is kept for comparison.
"""

from __future__ import annotations

import logging
from collections import deque
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy.sparse import csr_matrix
from scipy.spatial.transform import Rotation

from gtrig import geometry as geo
from gtrig.calib.anchor import board_pose, oriented_board_pose, pose_distance
from gtrig.calib.chessboard import Board, flip_half_turn
from gtrig.calib.se3avg import PoseMean, mean_pose
from gtrig.errors import ConvergenceError, InputError
from gtrig.io.camfile import CameraIntrinsics

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class PairView:
    """One instant of the double board: board 1 in ``cam_a``, board 2 in ``cam_b`` (corners (N, 2), px)."""

    cam_a: str
    cam_b: str
    name: str
    corners_a: np.ndarray
    corners_b: np.ndarray

    @property
    def pair(self) -> str:
        return f"{self.cam_a}-{self.cam_b}"


@dataclass(frozen=True)
class WorldView:
    """One view of the world board by ``camera``: corners (N, 2) in pixels; the board at ``T_world_board``."""

    camera: str
    name: str
    corners: np.ndarray
    T_world_board: np.ndarray


@dataclass(frozen=True)
class SweepView:
    """One view of a camera's intrinsic sweep: corners (N, 2) in pixels and, if known, the board's pose
    ``T_cam_board`` (4, 4) from the single-camera calibration (initial value; PnP when None).

    ``object_points`` (N, 3): the corners in the sweep board's frame, metres, when the sweep shows
    another board than the network's (a ChArUco board's partial corner sets; ``T_cam_board`` is then
    required); None: the network's chessboard, all its corners in order.
    """

    camera: str
    name: str
    corners: np.ndarray
    T_cam_board: np.ndarray | None = None
    object_points: np.ndarray | None = None


@dataclass(frozen=True)
class NetworkProblem:
    """Everything the network calibration needs.

    Attributes
    ----------
    board : the chessboard geometry (both boards of the double board and the world board).
    T_board1_board2 : (4, 4) nominal double-board transform.
    cameras : {name: intrinsics}: the initial values of the lenses (and, through ``extra["std"]``, their
        prior when a camera has no sweep views).
    T_world_cam_nominal : {name: (4, 4)} the believed poses (tape measure): only to resolve the grid's
        half-turn ambiguity and to sanity-check the result, never as a constraint.
    pair_views, world_views : the observations.
    sweep_views : the intrinsic sweeps' views, so that the bundle adjustment refines each lens from all
        of its images (empty: lenses refined from their stated standard deviations, or held).
    """

    board: Board
    T_board1_board2: np.ndarray
    cameras: Mapping[str, CameraIntrinsics]
    T_world_cam_nominal: Mapping[str, np.ndarray]
    pair_views: Sequence[PairView]
    world_views: Sequence[WorldView]
    sweep_views: Sequence[SweepView] = ()


@dataclass(frozen=True)
class CameraPose:
    """One camera's estimated pose, and its lens when refined in the bundle adjustment.

    Attributes
    ----------
    T_world_cam : (4, 4).
    cov : (6, 6) covariance of ``[w (rad), v (m)]`` in world axes (see module docstring), marginal over
        every other unknown, the camera's intrinsics included when they were refined.
    sigma_pos_m : (3,) standard deviation of the optical centre in world x, y, z (metres).
    sigma_rot_rad : (3,) standard deviation of the rotation about world x, y, z (radians).
    rms_px : reprojection RMS of the network's corners (pairs, world board) this camera saw (pixels).
    n_points : number of those corners.
    intrinsics : the lens used for the final pose: refined in the bundle adjustment (``extra["std"]``
        then holds its standard deviations from the joint covariance), or as given.
    cov_pose_intrinsics : (6 + k, 6 + k) joint covariance of ``[w, v]`` and the k refined intrinsics
        (``INTRINSICS_NAMES`` order: px for fx, fy, cx, cy; unitless for the distortion); (6, 6) when the
        intrinsics were held.
    sigma_pos_m_fixed_intrinsics, sigma_rot_rad_fixed_intrinsics : (3,) the same standard deviations with
        the intrinsics held at their estimates (what the report showed before intrinsics were refined).
    rms_px_sweep : reprojection RMS of this camera's intrinsic sweep in the bundle adjustment (NaN when
        its sweep views were not part of it).
    n_sweep_views : sweep views in the bundle adjustment.
    """

    T_world_cam: np.ndarray
    cov: np.ndarray
    sigma_pos_m: np.ndarray
    sigma_rot_rad: np.ndarray
    rms_px: float
    n_points: int
    intrinsics: CameraIntrinsics | None = None
    cov_pose_intrinsics: np.ndarray | None = None
    sigma_pos_m_fixed_intrinsics: np.ndarray | None = None
    sigma_rot_rad_fixed_intrinsics: np.ndarray | None = None
    rms_px_sweep: float = float("nan")
    n_sweep_views: int = 0


@dataclass(frozen=True)
class NetworkResult:
    """The outcome of :func:`calibrate_network`.

    Attributes
    ----------
    joint : {camera: CameraPose} from the bundle adjustment.
    chain : {camera: (4, 4) T_world_cam} from chaining the averaged pair edges (the seeds' method).
    chain_path : {camera: [anchor, ..., camera]} the chain each camera was reached by.
    edges : {pair: PoseMean of T_camA_camB} the per-pair averages (with their spread).
    T_board1_board2 : (4, 4) the double board's transform estimated jointly.
    T_board1_board2_sigma : (6,) its standard deviations ([w rad, v m]).
    rms_px_pair : {pair: RMS over both cameras' corners}.
    rms_px_world : {camera: RMS of its world-board corners}.
    rms_px : RMS over the network's corners (pairs and world board; sweeps excluded);
    sigma_px : the residual standard deviation per degree of freedom (all corners).
    n_iterations : function evaluations of the solver.
    warnings : human-readable warnings.
    """

    joint: dict[str, CameraPose]
    chain: dict[str, np.ndarray]
    chain_path: dict[str, list[str]]
    edges: dict[str, PoseMean]
    T_board1_board2: np.ndarray
    T_board1_board2_sigma: np.ndarray
    rms_px_pair: dict[str, float]
    rms_px_world: dict[str, float]
    rms_px: float
    sigma_px: float
    n_iterations: int
    warnings: tuple[str, ...] = field(default=())

    def to_dict(self) -> dict[str, Any]:
        """A plain document for the report (metres, degrees, pixels)."""
        cams: dict[str, Any] = {}
        for n, c in self.joint.items():
            t, q = geo.xyz_quat_from_T(c.T_world_cam)
            dch, rch = geo.pose_error(self.chain[n], c.T_world_cam) if n in self.chain else (np.nan, np.nan)
            cams[n] = {
                "xyz": [float(v) for v in t],
                "quat_xyzw": [float(v) for v in q],
                "sigma_pos_mm": [float(v * 1000) for v in c.sigma_pos_m],
                "sigma_rot_deg": [float(np.degrees(v)) for v in c.sigma_rot_rad],
                "rms_px": float(c.rms_px),
                "n_points": int(c.n_points),
                **(
                    {}
                    if c.sigma_rot_rad_fixed_intrinsics is None or c.sigma_pos_m_fixed_intrinsics is None
                    else {
                        "sigma_pos_mm_intrinsics_held": [float(v * 1000) for v in c.sigma_pos_m_fixed_intrinsics],
                        "sigma_rot_deg_intrinsics_held": [
                            float(np.degrees(v)) for v in c.sigma_rot_rad_fixed_intrinsics
                        ],
                    }
                ),
                **(
                    {}
                    if c.intrinsics is None or not c.intrinsics.extra.get("refined_in_network")
                    else {
                        "intrinsics": {
                            "camera_matrix": np.asarray(c.intrinsics.camera_matrix).tolist(),
                            "dist_coeffs": np.asarray(c.intrinsics.dist_coeffs).tolist(),
                            "std": dict(c.intrinsics.extra.get("std", {})),
                            "sweep_rms_px": float(c.rms_px_sweep),
                            "sweep_views": int(c.n_sweep_views),
                        }
                    }
                ),
                "chain_path": self.chain_path.get(n, []),
                "chain_minus_joint_mm": float(dch * 1000),
                "chain_minus_joint_deg": float(np.degrees(rch)),
            }
        t12, q12 = geo.xyz_quat_from_T(self.T_board1_board2)
        return {
            "cameras": cams,
            "pairs": {
                p: {
                    "rms_px": float(self.rms_px_pair[p]),
                    "views": int(e.n),
                    "edge_spread_mm": float(e.trans_rms_m * 1000),
                    "edge_spread_deg": float(np.degrees(e.rot_rms_rad)),
                }
                for p, e in self.edges.items()
            },
            "world_board_rms_px": {k: float(v) for k, v in self.rms_px_world.items()},
            "T_board1_board2": {
                "xyz": [float(v) for v in t12],
                "quat_xyzw": [float(v) for v in q12],
                "sigma_mm": [float(v * 1000) for v in self.T_board1_board2_sigma[3:]],
                "sigma_deg": [float(np.degrees(v)) for v in self.T_board1_board2_sigma[:3]],
            },
            "rms_px": float(self.rms_px),
            "sigma_px": float(self.sigma_px),
            "warnings": list(self.warnings),
        }


# --------------------------------------------------------------------------------------------------
# initial values


def _orient_pair(prob: NetworkProblem, v: PairView) -> tuple[PairView, np.ndarray, np.ndarray]:
    """Choose the half-turn orderings of both grids that agree best with the nominal rig."""
    ca, cb = prob.cameras[v.cam_a], prob.cameras[v.cam_b]
    T_AB_nom = geo.inv_T(prob.T_world_cam_nominal[v.cam_a]) @ prob.T_world_cam_nominal[v.cam_b]
    best: tuple[float, PairView, np.ndarray, np.ndarray] | None = None
    for fa in (False, True):
        A = flip_half_turn(v.corners_a) if fa else v.corners_a
        TA, _ = board_pose(ca.camera_matrix, ca.dist_coeffs, A, prob.board)
        for fb in (False, True):
            B = flip_half_turn(v.corners_b) if fb else v.corners_b
            TB, _ = board_pose(cb.camera_matrix, cb.dist_coeffs, B, prob.board)
            T_AB = TA @ prob.T_board1_board2 @ geo.inv_T(TB)
            d = pose_distance(T_AB, T_AB_nom)
            if best is None or d < best[0]:
                best = (d, PairView(v.cam_a, v.cam_b, v.name, A, B), TA, TB)
    assert best is not None
    return best[1], best[2], best[3]


def _graph_order(anchors: Sequence[str], edges: Mapping[str, tuple[str, str]]) -> dict[str, list[str]]:
    paths = {a: [a] for a in anchors}
    q = deque(anchors)
    while q:
        a = q.popleft()
        for _, (x, y) in sorted(edges.items()):
            for u, w in ((x, y), (y, x)):
                if u == a and w not in paths:
                    paths[w] = paths[a] + [w]
                    q.append(w)
    return paths


# --------------------------------------------------------------------------------------------------
# bundle adjustment


def _exp_apply(R0: np.ndarray, t0: np.ndarray, p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Poses ``R = Exp(w) R0, t = t0 + v`` for parameter rows ``p = [w, v]`` (n, 6)."""
    R = Rotation.from_rotvec(p[:, :3]).as_matrix() @ R0
    return R, t0 + p[:, 3:]


INTRINSICS_NAMES = ("fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2", "k3")


def _skew(v: np.ndarray) -> np.ndarray:
    """Cross-product matrices (..., 3, 3) of vectors (..., 3)."""
    S_ = np.zeros(v.shape[:-1] + (3, 3))
    S_[..., 0, 1], S_[..., 0, 2], S_[..., 1, 2] = -v[..., 2], v[..., 1], -v[..., 0]
    S_[..., 1, 0], S_[..., 2, 0], S_[..., 2, 1] = v[..., 2], -v[..., 1], v[..., 0]
    return S_


def _intrinsics_vector(ci: CameraIntrinsics, n_i: int) -> np.ndarray:
    """``[fx, fy, cx, cy, k1, k2, p1, p2(, k3)]`` (n_i,) of a lens (px; distortion unitless)."""
    K = np.asarray(ci.camera_matrix, dtype=float)
    d = np.zeros(5)
    dc = np.asarray(ci.dist_coeffs, dtype=float).ravel()
    d[: min(5, dc.size)] = dc[:5]
    return np.r_[K[0, 0], K[1, 1], K[0, 2], K[1, 2], d[: n_i - 4]]


def _apply_intrinsics(ci: CameraIntrinsics, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The lens ``ci`` with its first ``len(q)`` parameters replaced: (K (3, 3), dist (>= 5,)). The skew and
    any higher-order distortion terms stay as given."""
    K = np.asarray(ci.camera_matrix, dtype=float).copy()
    K[0, 0], K[1, 1], K[0, 2], K[1, 2] = q[:4]
    dc = np.asarray(ci.dist_coeffs, dtype=float).ravel()
    d = np.zeros(max(dc.size, 5))
    d[: dc.size] = dc
    d[: len(q) - 4] = q[4:]
    return K, d


def _prior_std(ci: CameraIntrinsics, n_i: int) -> np.ndarray | None:
    """The stated standard deviations (n_i,) of a lens (``extra["std"]`` of a ``cam.yaml``), or None when
    some are missing or not positive (the lens is then held)."""
    std = ci.extra.get("std") if isinstance(ci.extra, dict) else None
    if not isinstance(std, dict):
        return None
    try:
        sd = np.array([float(std[k]) for k in INTRINSICS_NAMES[:n_i]])
    except (KeyError, TypeError, ValueError):
        return None
    return sd if np.all(np.isfinite(sd)) and np.all(sd > 0) else None


def _intrinsics_jacobian(Xc: np.ndarray, K: np.ndarray, dist: np.ndarray, n_i: int) -> np.ndarray:
    """d(u, v) / d[fx, fy, cx, cy, k1, k2, p1, p2(, k3)] (n, 2, n_i) of camera-frame points Xc (n, 3)
    under OpenCV's model (as :func:`gtrig.geometry.project_points`; the skew held)."""
    d = np.zeros(8)
    dc = np.asarray(dist, dtype=float).ravel()
    d[: min(8, dc.size)] = dc[:8]
    k1, k2, p1, p2, k3, k4, k5, k6 = d
    x, y = Xc[:, 0] / Xc[:, 2], Xc[:, 1] / Xc[:, 2]
    r2 = x * x + y * y
    den = 1 + r2 * (k4 + r2 * (k5 + r2 * k6))
    radial = (1 + r2 * (k1 + r2 * (k2 + r2 * k3))) / den
    xd = x * radial + 2 * p1 * x * y + p2 * (r2 + 2 * x * x)
    yd = y * radial + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y
    fx, s, fy = K[0, 0], K[0, 1], K[1, 1]
    J = np.zeros((len(Xc), 2, n_i))
    J[:, 0, 0] = xd
    J[:, 1, 1] = yd
    J[:, 0, 2] = 1.0
    J[:, 1, 3] = 1.0
    # d(xd, yd) / d(k1, k2, p1, p2, k3)
    dxy = [
        (x * r2 / den, y * r2 / den),
        (x * r2**2 / den, y * r2**2 / den),
        (2 * x * y, r2 + 2 * y * y),
        (r2 + 2 * x * x, 2 * x * y),
        (x * r2**3 / den, y * r2**3 / den),
    ]
    for k, (dx, dy) in enumerate(dxy[: n_i - 4]):
        J[:, 0, 4 + k] = fx * dx + s * dy
        J[:, 1, 4 + k] = fy * dy
    return J


def _levenberg_marquardt(
    fun: Any,
    jac: Any,
    n_par: int,
    n_obs: int,
    huber_px: float,
    warnings: list[str],
    local: tuple[int, int] = (0, 0),
    max_iter: int = 50,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, int]:
    """Minimise the Huber cost of ``fun`` (2 pixel residuals per corner, then prior rows) by
    Levenberg-Marquardt on the iteratively reweighted normal equations (Huber weights per corner).

    The parameters ``local[0]:local[1]`` are 6-blocks that no residual row shares (one board pose each):
    they are eliminated by the Schur complement, so that a step costs a solve in the few global
    parameters (cameras, lenses, the double board) whatever the number of views.

    Returns the parameters (n_par,), the Schur complement ``S`` of ``J^T W J`` on the global parameters
    at the optimum (whose inverse is their block of ``(J^T W J)^-1``), the global parameters' indices
    (rows of ``S``) and the iterations.
    """
    l0, l1 = local
    nL = (l1 - l0) // 6
    glob = np.r_[0:l0, l1:n_par].astype(int)
    loc = np.arange(l0, l1)

    def weights(r: np.ndarray) -> tuple[np.ndarray, float]:
        e = np.sqrt(r[: 2 * n_obs : 2] ** 2 + r[1 : 2 * n_obs : 2] ** 2)
        w = np.where(e <= huber_px, 1.0, huber_px / np.maximum(e, 1e-300))
        rho = np.where(e <= huber_px, e**2, 2 * huber_px * e - huber_px**2)
        wr = np.ones(len(r))
        wr[: 2 * n_obs] = np.repeat(w, 2)
        return wr, float(np.sum(rho) + np.sum(r[2 * n_obs :] ** 2))

    def normal(x: np.ndarray, r: np.ndarray, wr: np.ndarray) -> tuple:
        J = csr_matrix(jac(x))
        JW = csr_matrix(J.multiply(wr[:, None]))
        A = csr_matrix(J.T @ JW)
        g = JW.T @ r
        Agg = A[glob][:, glob].toarray()
        Agl = A[glob][:, loc].toarray().reshape(len(glob), nL, 6)
        Bll = np.zeros((nL, 6, 6))
        coo = A[loc][:, loc].tocoo()
        Bll[coo.row // 6, coo.row % 6, coo.col % 6] = coo.data
        return Agg, Agl, Bll, g[glob], g[loc].reshape(nL, 6)

    def schur(Agg: np.ndarray, Agl: np.ndarray, Bll: np.ndarray, lam: float) -> tuple:
        dg = np.sqrt(np.maximum(np.diag(Agg), 1e-30))
        dl = np.sqrt(np.maximum(np.einsum("bii->bi", Bll), 1e-30))
        Binv = np.linalg.inv(Bll + lam * np.einsum("bi,ij->bij", dl**2, np.eye(6)))
        AB = np.einsum("gbi,bij->gbj", Agl, Binv)
        S = Agg + lam * np.diag(dg**2) - np.einsum("gbj,hbj->gh", AB, Agl)
        return S, AB, Binv

    x = np.zeros(n_par)
    r = fun(x)
    wr, cost = weights(r)
    lam = 1e-4
    it = 0
    for it in range(1, max_iter + 1):  # noqa: B007 (it is returned)
        Agg, Agl, Bll, gg, gl = normal(x, r, wr)
        improved = False
        for _ in range(20):
            try:
                S, AB, Binv = schur(Agg, Agl, Bll, lam)
                sg = -np.linalg.solve(S, gg - np.einsum("gbj,bj->g", AB, gl))
            except np.linalg.LinAlgError:
                lam *= 10
                continue
            sl = -np.einsum("bij,bj->bi", Binv, gl + np.einsum("gbi,g->bi", Agl, sg))
            step = np.zeros(n_par)
            step[glob], step[loc] = sg, sl.ravel()
            r_new = fun(x + step)
            wr_new, cost_new = weights(r_new)
            if cost_new <= cost:
                improved = True
                rel = (cost - cost_new) / max(cost, 1e-300)
                x, r, wr, cost = x + step, r_new, wr_new, cost_new
                lam = max(lam / 10, 1e-12)
                break
            lam *= 10
        if not improved or rel < 1e-12 or np.max(np.abs(step)) < 1e-12:
            break
    else:
        warnings.append(f"network bundle adjustment stopped after {max_iter} iterations")
        log.warning(warnings[-1])
    Agg, Agl, Bll, _, _ = normal(x, r, wr)
    try:
        S = schur(Agg, Agl, Bll, 0.0)[0]
    except np.linalg.LinAlgError:
        raise ConvergenceError(
            "network bundle adjustment: the problem is singular (a board pose not constrained)"
        ) from None
    return x, S, glob, it


def calibrate_network(
    prob: NetworkProblem,
    *,
    prior_T12_sigma_m: float = 0.01,
    prior_T12_sigma_deg: float = 1.0,
    huber_px: float = 0.5,
    estimate_T12: bool = True,
    refine_intrinsics: bool = True,
    estimate_k3: bool = False,
) -> NetworkResult:
    """Calibrate the extrinsics of a camera network (see the module docstring for the method).

    Parameters
    ----------
    prob : the observations and initial values.
    prior_T12_sigma_m, prior_T12_sigma_deg : the prior on the double board's transform around its nominal
        value (metres, degrees).
    huber_px : the Huber loss's threshold on a corner's reprojection error (pixels).
    estimate_T12 : estimate the double board's transform (else held at its nominal value).
    refine_intrinsics : refine each camera's lens in the bundle adjustment: from its sweep views when
        ``prob.sweep_views`` has some, else from its stated standard deviations as a prior; a lens with
        neither is held.
    estimate_k3 : also refine k3 (else held at its given value, 0 for the seeds' model).

    Raises
    ------
    InputError
        No world-board view; a camera connected to the anchored camera(s) by no pair; a camera in the
        observations without intrinsics or nominal pose.
    """
    warnings: list[str] = []
    _check_cameras(prob)
    anchors, world_views, by_cam = _world_anchors(prob)
    pair_views, T_A_b1, edges, pair_cams = _pair_edges(prob)
    chain, paths, cams = _chain(prob, anchors, edges, pair_cams, warnings)
    for w in warnings:
        log.warning(w)
    ba = _Bundle(prob, cams, chain, world_views, pair_views, T_A_b1, prior_T12_sigma_m, prior_T12_sigma_deg,
                 estimate_T12, refine_intrinsics, estimate_k3)
    x, S, glob, n_iter, e2, sigma2 = ba.solve(huber_px, warnings)
    cov, cov_fixed = ba.covariances(S, sigma2)
    pos = np.full(ba.n_par, -1)
    pos[glob] = np.arange(len(glob))
    joint = ba.camera_poses(x, cov, cov_fixed, pos, e2)
    _, _, _, _, _, _, R12, t12, _ = ba.unpack(x)
    keys = np.array(ba.obs_key)
    rms_pair = {p: float(np.sqrt(np.mean(e2[keys == f"pair:{p}"]))) for p in edges}
    rms_world = {c: float(np.sqrt(np.mean(e2[keys == f"world:{c}"]))) for c in by_cam}
    s12 = np.sqrt(np.clip(np.diag(cov)[pos[ba.off_12:ba.off_i]], 0, None)) if ba.n_T12 else np.zeros(6)
    T12 = geo.make_T(R12, t12)
    d12, r12 = geo.pose_error(T12, prob.T_board1_board2)
    log.info(
        "network BA: %d corners (%d of sweeps), %d parameters (intrinsics of %d cameras), RMS %.3f px; "
        "T_board1_board2 moved %.1f mm / %.3f deg from nominal",
        ba.nObs,
        int(ba.m_sw.sum()),
        ba.n_par,
        ba.nR,
        float(np.sqrt(np.mean(e2))),
        d12 * 1000,
        np.degrees(r12),
    )
    return NetworkResult(
        joint,
        {n: chain[n] for n in cams},
        {n: paths[n] for n in cams},
        edges,
        T12,
        s12,
        rms_pair,
        rms_world,
        float(np.sqrt(np.mean(e2[~ba.m_sw]))),
        float(np.sqrt(sigma2)),
        n_iter,
        tuple(warnings),
    )


def _check_cameras(prob: NetworkProblem) -> None:
    """Every camera a pair or the world board names has intrinsics and a nominal pose; a world board is seen."""
    for v in prob.pair_views:
        for c in (v.cam_a, v.cam_b):
            if c not in prob.cameras or c not in prob.T_world_cam_nominal:
                raise InputError(f"pair {v.pair}: camera {c!r} has no intrinsics or is not in the rig")
    if not prob.world_views:
        raise InputError("no view of the world board: nothing anchors the network to the world frame")
    for wv in prob.world_views:
        if wv.camera not in prob.cameras or wv.camera not in prob.T_world_cam_nominal:
            raise InputError(
                f"world board view {wv.name}: camera {wv.camera!r} has no intrinsics or is not in the rig"
            )


def _world_anchors(prob: NetworkProblem) -> tuple[dict[str, PoseMean], list[WorldView], dict[str, list[WorldView]]]:
    """Step 1: each camera that sees the world board, anchored by the mean of its views' poses; the views
    with their corners ordered as the board's (a half-turned board flipped back)."""
    anchors: dict[str, PoseMean] = {}
    world_views: list[WorldView] = []
    by_cam: dict[str, list[WorldView]] = {}
    for wv in prob.world_views:
        by_cam.setdefault(wv.camera, []).append(wv)
    for cam, vs in by_cam.items():
        ci = prob.cameras[cam]
        Ts = []
        for wv in vs:
            expected = geo.inv_T(prob.T_world_cam_nominal[cam]) @ wv.T_world_board
            corners, T_cam_board, _ = oriented_board_pose(
                ci.camera_matrix, ci.dist_coeffs, wv.corners, prob.board, expected
            )
            world_views.append(WorldView(cam, wv.name, corners, wv.T_world_board))
            Ts.append(wv.T_world_board @ geo.inv_T(T_cam_board))
        anchors[cam] = mean_pose(np.array(Ts))
    return anchors, world_views, by_cam


def _pair_edges(prob: NetworkProblem) -> tuple[list[PairView], list[np.ndarray], dict[str, PoseMean],
                                               dict[str, tuple[str, str]]]:
    """Step 2: each pair's relative pose ``T_A_B``, the mean over its double-board instants; the oriented
    views and each instant's ``T_A_b1``."""
    pair_views: list[PairView] = []
    T_A_b1: list[np.ndarray] = []
    per_pair: dict[str, list[np.ndarray]] = {}
    pair_cams: dict[str, tuple[str, str]] = {}
    for v in prob.pair_views:
        vo, TA, TB = _orient_pair(prob, v)
        pair_views.append(vo)
        T_A_b1.append(TA)
        per_pair.setdefault(v.pair, []).append(TA @ prob.T_board1_board2 @ geo.inv_T(TB))
        pair_cams[v.pair] = (v.cam_a, v.cam_b)
    edges = {p: mean_pose(np.array(Ts)) for p, Ts in per_pair.items()}
    return pair_views, T_A_b1, edges, pair_cams


def _chain(prob: NetworkProblem, anchors: dict[str, PoseMean], edges: dict[str, PoseMean],
           pair_cams: dict[str, tuple[str, str]], warnings: list[str]
           ) -> tuple[dict[str, np.ndarray], dict[str, list[str]], list[str]]:
    """Step 3: every camera's pose chained from the anchored ones over the pair graph, breadth first; the
    cameras reached, warnings for the others and for a pose far from its nominal one."""
    names = sorted(prob.cameras)
    paths = _graph_order(sorted(anchors), pair_cams)
    unreached = [n for n in names if n not in paths and any(n in pc for pc in pair_cams.values())]
    if unreached:
        raise InputError(
            f"camera {unreached[0]}: no chain of pairs links it to a camera that sees the world board"
        )
    chain: dict[str, np.ndarray] = {}
    for cam, path in sorted(paths.items(), key=lambda kv: len(kv[1])):
        if len(path) == 1:
            chain[cam] = anchors[cam].T
            continue
        prev = path[-2]
        p_fwd, p_bwd = f"{prev}-{cam}", f"{cam}-{prev}"
        T_prev_cam = edges[p_fwd].T if p_fwd in edges else geo.inv_T(edges[p_bwd].T)
        chain[cam] = chain[prev] @ T_prev_cam
    cams = [n for n in names if n in chain]
    for n in names:
        if n not in chain:
            warnings.append(f"camera {n}: no pair and no world-board view; not calibrated")
    for n in cams:
        dt, dr = geo.pose_error(chain[n], prob.T_world_cam_nominal[n])
        if dt > 0.5 or dr > np.radians(20):
            warnings.append(
                f"camera {n}: calibrated pose is {dt:.2f} m / {np.degrees(dr):.1f} deg from the "
                "nominal one; check the rig file and the pair folder names"
            )
    return chain, paths, cams


class _Bundle:
    """Step 4, the joint bundle adjustment: its parameters (cameras, double-board instants, sweep views,
    ``T_b1_b2``, lenses, in that order), one observation row per corner, the residuals and their analytic
    sparse Jacobian, the solve, the covariances and each camera's result."""

    def __init__(self, prob: NetworkProblem, cams: list[str], chain: dict[str, np.ndarray],
                 world_views: list[WorldView], pair_views: list[PairView], T_A_b1: list[np.ndarray],
                 prior_T12_sigma_m: float, prior_T12_sigma_deg: float, estimate_T12: bool,
                 refine_intrinsics: bool, estimate_k3: bool) -> None:
        self.prob, self.cams = prob, cams
        board = prob.board
        self.ci_of = ci_of = {n: i for i, n in enumerate(cams)}
        self.n_i = n_i = 9 if estimate_k3 else 8
        self.sweeps = sweeps = [sv for sv in prob.sweep_views if sv.camera in ci_of] if refine_intrinsics else []
        with_sweep = {sv.camera for sv in sweeps}
        self.prior_sd: dict[str, np.ndarray] = {}
        prior_sd = self.prior_sd
        if refine_intrinsics:
            for n in cams:
                sd = None if n in with_sweep else _prior_std(prob.cameras[n], n_i)
                if sd is not None:
                    prior_sd[n] = sd
        self.refined = refined = [n for n in cams if n in with_sweep or n in prior_sd]
        self.ri_of = {n: k for k, n in enumerate(refined)}
        self.nC, self.nB, self.nS, self.nR = len(cams), len(pair_views), len(sweeps), len(refined)
        self.R0c = np.array([chain[n][:3, :3] for n in cams])
        self.t0c = np.array([chain[n][:3, 3] for n in cams])
        Tb0 = np.array([chain[v.cam_a] @ T for v, T in zip(pair_views, T_A_b1, strict=True)]).reshape(-1, 4, 4)
        self.R0b, self.t0b = Tb0[:, :3, :3], Tb0[:, :3, 3]
        self.Ts0 = np.array(
            [
                sv.T_cam_board
                if sv.T_cam_board is not None
                else board_pose(prob.cameras[sv.camera].camera_matrix, prob.cameras[sv.camera].dist_coeffs,
                                sv.corners, board)[0]
                for sv in sweeps
            ]
        ).reshape(-1, 4, 4)
        self.T12_0 = prob.T_board1_board2
        self.q0 = np.array([_intrinsics_vector(prob.cameras[n], n_i) for n in refined]).reshape(self.nR, n_i)
        self.n_T12 = 6 if estimate_T12 else 0
        self.off_b = 6 * self.nC
        self.off_s = self.off_b + 6 * self.nB
        self.off_12 = self.off_s + 6 * self.nS
        self.off_i = self.off_12 + self.n_T12
        self.n_par = self.off_i + n_i * self.nR
        self._observations(board.object_points(), world_views, pair_views)
        self.sig_r = np.radians(prior_T12_sigma_deg)
        self.sig_t = prior_T12_sigma_m
        self.prior_rows = np.concatenate([prior_sd[n] for n in refined if n in prior_sd]) if prior_sd else np.zeros(0)
        self.prior_cols = (
            np.concatenate([self.off_i + n_i * self.ri_of[n] + np.arange(n_i) for n in refined if n in prior_sd])
            if prior_sd
            else np.zeros(0, int)
        )
        # the corners' residuals are in pixels, the priors' in their standard deviations: a prior row
        # times the corners' standard deviation (px) weighs the prior as stated next to the corners.
        # Unscaled, with corners at 0.03 px, a 1 cm prior on T_b1_b2 acted as one of 0.3 mm and held the
        # double board near its nominal transform (simulator, 8 views: 0.95 mm off the truth where the
        # data alone say 0.2 mm), and every pair link with it.
        self.prior_px = 1.0

    def _observations(self, P: np.ndarray, world_views: list[WorldView], pair_views: list[PairView]) -> None:
        """One row per corner; kind 0: world board (fixed), 1: double board, 2: sweep board."""
        cam_i, kind_i, brd_i, use12, uv = [], [], [], [], []
        self.obs_key: list[str] = []

        X: list[np.ndarray] = []

        def add(cam: str, kind: int, b: int, u12: bool, corners: np.ndarray, key: str,
                P_view: np.ndarray = P) -> None:
            n = len(P_view)
            cam_i.append(np.full(n, self.ci_of[cam]))
            kind_i.append(np.full(n, kind))
            brd_i.append(np.full(n, b))
            use12.append(np.full(n, u12))
            uv.append(np.asarray(corners, dtype=float).reshape(-1, 2))
            X.append(np.asarray(P_view, dtype=float).reshape(-1, 3))
            self.obs_key.extend([key] * n)

        for k, wv in enumerate(world_views):
            add(wv.camera, 0, k, False, wv.corners, f"world:{wv.camera}")
        for b, v in enumerate(pair_views):
            add(v.cam_a, 1, b, False, v.corners_a, f"pair:{v.pair}")
            add(v.cam_b, 1, b, True, v.corners_b, f"pair:{v.pair}")
        for s, sv in enumerate(self.sweeps):
            add(sv.camera, 2, s, False, sv.corners, f"sweep:{sv.camera}",
                P if sv.object_points is None else sv.object_points)
        self.cam_a = np.concatenate(cam_i)
        kind_a = np.concatenate(kind_i)
        self.brd_a = np.concatenate(brd_i)
        self.u12_a = np.concatenate(use12)
        self.uv_a = np.concatenate(uv)
        self.X_a = np.concatenate(X)
        self.m_world, self.m_pair, self.m_sw = kind_a == 0, kind_a == 1, kind_a == 2
        self.Rf = np.array([wv.T_world_board[:3, :3] for wv in world_views]).reshape(-1, 3, 3)
        self.tf = np.array([wv.T_world_board[:3, 3] for wv in world_views]).reshape(-1, 3)
        self.nObs = len(self.cam_a)
        self.sel_cam = [self.cam_a == i for i in range(self.nC)]
        # the board parameter block of each row: a double-board instant or a sweep view (none for the world)
        self.col_board = np.where(self.m_pair, self.off_b + 6 * self.brd_a, self.off_s + 6 * self.brd_a)
        self.eye_rows = np.broadcast_to(np.eye(3), (int(self.m_sw.sum()), 3, 3))

    def unpack(self, x: np.ndarray) -> tuple:
        """Rotations and translations of the cameras, double-board instants and sweep views, ``T_b1_b2``
        and the lenses' parameters at ``x``."""
        nC, nB, nS = self.nC, self.nB, self.nS
        Rc, tc = _exp_apply(self.R0c, self.t0c, x[: self.off_b].reshape(nC, 6))
        Rb, tb = (_exp_apply(self.R0b, self.t0b, x[self.off_b : self.off_s].reshape(nB, 6)) if nB
                  else (self.R0b, self.t0b))
        Ts0 = self.Ts0
        Rs, ts = _exp_apply(Ts0[:, :3, :3], Ts0[:, :3, 3], x[self.off_s : self.off_12].reshape(nS, 6)) if nS else (
            Ts0[:, :3, :3], Ts0[:, :3, 3])
        T12_0 = self.T12_0
        if self.n_T12:
            R12, t12 = _exp_apply(T12_0[None, :3, :3], T12_0[None, :3, 3], x[self.off_12 : self.off_i].reshape(1, 6))
            R12, t12 = R12[0], t12[0]
        else:
            R12, t12 = T12_0[:3, :3], T12_0[:3, 3]
        q = self.q0 + x[self.off_i :].reshape(self.nR, self.n_i)
        return Rc, tc, Rb, tb, Rs, ts, R12, t12, q

    def lens(self, q: np.ndarray) -> list[tuple[np.ndarray, np.ndarray]]:
        out = []
        for n in self.cams:
            ci = self.prob.cameras[n]
            out.append(_apply_intrinsics(ci, q[self.ri_of[n]]) if n in self.ri_of else (ci.camera_matrix,
                                                                                        ci.dist_coeffs))
        return out

    def geometry(self, x: np.ndarray) -> tuple:
        """Per row: the board's pose (in the world, or in the camera for a sweep view), the camera's pose
        (identity for a sweep view), the board point in the world and in the camera, and the lenses."""
        Rc, tc, Rb, tb, Rs, ts, R12, t12, q = self.unpack(x)
        m_world, m_pair, m_sw, brd_a = self.m_world, self.m_pair, self.m_sw, self.brd_a
        X1 = np.where(self.u12_a[:, None], self.X_a @ R12.T + t12, self.X_a)
        Rbo = np.empty((self.nObs, 3, 3))
        tbo = np.empty((self.nObs, 3))
        Rbo[m_world], tbo[m_world] = self.Rf[brd_a[m_world]], self.tf[brd_a[m_world]]
        Rbo[m_pair], tbo[m_pair] = Rb[brd_a[m_pair]], tb[brd_a[m_pair]]
        Rbo[m_sw], tbo[m_sw] = Rs[brd_a[m_sw]], ts[brd_a[m_sw]]
        Rcr, tcr = Rc[self.cam_a], tc[self.cam_a]
        Rcr[m_sw], tcr[m_sw] = self.eye_rows, 0.0
        Xw = np.einsum("nij,nj->ni", Rbo, X1) + tbo
        Xc = np.einsum("nji,nj->ni", Rcr, Xw - tcr)
        return Rcr, tcr, Rbo, R12, X1, Xw, Xc, self.lens(q)

    def project(self, Xc: np.ndarray, lz: list) -> np.ndarray:
        out = np.empty((len(Xc), 2))
        for c, (K, d) in enumerate(lz):
            out[self.sel_cam[c]] = geo.project_points(Xc[self.sel_cam[c]], K, d)
        return out

    def project_all(self, x: np.ndarray) -> np.ndarray:
        g = self.geometry(x)
        return self.project(g[6], g[7])

    def fun(self, x: np.ndarray) -> np.ndarray:
        """The residuals: every corner's reprojection error (px), then the priors' rows."""
        r = [(self.project_all(x) - self.uv_a).ravel()]
        if self.n_T12:
            p12 = x[self.off_12 : self.off_i]
            r += [self.prior_px * p12[:3] / self.sig_r, self.prior_px * p12[3:] / self.sig_t]
        if self.prior_sd:
            r.append(self.prior_px * x[self.prior_cols] / self.prior_rows)
        return np.concatenate(r)

    def jac(self, x: np.ndarray) -> csr_matrix:
        """Analytic chain rule through the poses (first order in the perturbations, Exp(w) ~ I + [w]x) and
        the lens; central differences for the projection's derivative with respect to the camera-frame
        point."""
        Rcr, tcr, Rbo, R12, X1, Xw, Xc, lz = self.geometry(x)
        nObs, n_i = self.nObs, self.n_i
        h = 1e-6 * np.maximum(np.abs(Xc[:, 2:3]), 1e-3)
        dP = np.empty((nObs, 2, 3))
        for k in range(3):
            e = np.zeros(3)
            e[k] = 1.0
            dP[:, :, k] = (self.project(Xc + h * e, lz) - self.project(Xc - h * e, lz)) / (2 * h)
        A = dP @ np.transpose(Rcr, (0, 2, 1))  # d uv / d Xw  (n, 2, 3)
        blocks = []
        # camera: Xc = Rc^T (Xw - tc), Rc = Exp(w) Rc0 -> dXc/dw = Rc^T [Xw - tc]x ; dXc/dv = -Rc^T
        blocks.append((6 * self.cam_a, np.concatenate([A @ _skew(Xw - tcr), -A], axis=2), ~self.m_sw))
        # board: Xw = Rb X1 + tb -> dXw/dw = -[Rb X1]x ; dXw/dv = I (a sweep board: Xw is Xc)
        RbX = np.einsum("nij,nj->ni", Rbo, X1)
        blocks.append((self.col_board, np.concatenate([-A @ _skew(RbX), A], axis=2), ~self.m_world))
        if self.n_T12:
            B = A @ Rbo
            blocks.append((np.full(nObs, self.off_12), np.concatenate([-B @ _skew(self.X_a @ R12.T), B], axis=2),
                           self.u12_a))
        if self.nR:
            D = np.zeros((nObs, 2, n_i))
            col_i = np.zeros(nObs, int)
            has = np.zeros(nObs, bool)
            for n in self.refined:
                c = self.ci_of[n]
                K, d = lz[c]
                D[self.sel_cam[c]] = _intrinsics_jacobian(Xc[self.sel_cam[c]], K, d, n_i)
                col_i[self.sel_cam[c]] = self.off_i + n_i * self.ri_of[n]
                has |= self.sel_cam[c]
            blocks.append((col_i, D, has))
        rows_, cols_, vals_ = [], [], []
        r0 = np.arange(nObs) * 2
        for col0, Db, sel in blocks:
            idx = np.nonzero(sel)[0]
            for k in range(Db.shape[2]):
                for ax in (0, 1):
                    rows_.append(r0[idx] + ax)
                    cols_.append(col0[idx] + k)
                    vals_.append(Db[idx, ax, k])
        n_rows = 2 * nObs
        if self.n_T12:
            rows_.append(n_rows + np.arange(6))
            cols_.append(self.off_12 + np.arange(6))
            vals_.append(self.prior_px * np.r_[np.full(3, 1.0 / self.sig_r), np.full(3, 1.0 / self.sig_t)])
            n_rows += 6
        if self.prior_sd:
            rows_.append(n_rows + np.arange(len(self.prior_rows)))
            cols_.append(self.prior_cols)
            vals_.append(self.prior_px / self.prior_rows)
            n_rows += len(self.prior_rows)
        return csr_matrix(
            (np.concatenate(vals_), (np.concatenate(rows_), np.concatenate(cols_))), shape=(n_rows, self.n_par)
        )

    def solve(self, huber_px: float, warnings: list[str]) -> tuple:
        """Levenberg-Marquardt, twice when priors exist: the second pass with the priors scaled by the first
        pass's corner noise. Returns the solution, the normal matrix, its parameters' global indices, the
        iterations, each corner's squared error and the residual variance per degree of freedom."""
        dof = max(2 * self.nObs - self.n_par, 1)
        for _ in range(2):
            x, S, glob, n_iter = _levenberg_marquardt(
                self.fun, self.jac, self.n_par, self.nObs, huber_px, warnings, local=(self.off_b, self.off_12)
            )
            res = self.project_all(x) - self.uv_a
            e2 = np.sum(res**2, axis=1)
            sigma2 = float(np.sum(e2) / dof)
            if not (self.n_T12 or self.prior_sd):
                break
            self.prior_px = float(np.sqrt(sigma2))
        return x, S, glob, n_iter, e2, sigma2

    def covariances(self, S: np.ndarray, sigma2: float) -> tuple[np.ndarray, np.ndarray]:
        """The parameters' covariance, and the cameras' and ``T_b1_b2``'s with the lenses held at their
        estimates (what the poses' uncertainty would be if the intrinsics were exact)."""
        # rows of S: the cameras' 6 * nC parameters, then T_b1_b2's n_T12, then the lenses' n_i * nR
        n_held = 6 * self.nC + self.n_T12
        try:
            cov = np.linalg.inv(S) * sigma2
            cov_fixed = np.linalg.inv(S[:n_held, :n_held]) * sigma2 if self.nR else cov
        except np.linalg.LinAlgError:
            raise ConvergenceError(
                "network bundle adjustment: the problem is singular (a camera or board pose not constrained)"
            ) from None
        return cov, cov_fixed

    def camera_poses(self, x: np.ndarray, cov: np.ndarray, cov_fixed: np.ndarray, pos: np.ndarray,
                     e2: np.ndarray) -> dict[str, CameraPose]:
        """Each camera's pose, its covariance (marginal over the lens, and with the lens held), its corners'
        RMS and, for a refined lens, the lens with its standard deviations."""
        Rc, tc, _, _, _, _, _, _, q = self.unpack(x)
        n_i = self.n_i
        joint: dict[str, CameraPose] = {}
        for n in self.cams:
            i = self.ci_of[n]
            idx = pos[np.r_[6 * i : 6 * i + 6]]
            if n in self.ri_of:
                idx = np.r_[idx, pos[self.off_i + n_i * self.ri_of[n] + np.arange(n_i)]]
            C_full = cov[np.ix_(idx, idx)]
            C = C_full[:6, :6]
            sd = np.sqrt(np.clip(np.diag(C), 0, None))
            sd_fix = np.sqrt(np.clip(np.diag(cov_fixed[6 * i : 6 * i + 6, 6 * i : 6 * i + 6]), 0, None))
            net_rows = self.sel_cam[i] & ~self.m_sw
            sw_rows = self.sel_cam[i] & self.m_sw
            ci = self.prob.cameras[n]
            if n in self.ri_of:
                K, d = _apply_intrinsics(ci, q[self.ri_of[n]])
                sd_q = np.sqrt(np.clip(np.diag(C_full[6:, 6:]), 0, None))
                std = {k: float(v) for k, v in zip(INTRINSICS_NAMES, sd_q, strict=False)}
                rms_sw = float(np.sqrt(np.mean(e2[sw_rows]))) if sw_rows.any() else float("nan")
                extra = dict(ci.extra) | {"std": std, "refined_in_network": True}
                intr = CameraIntrinsics(ci.image_size, K, d, rms_sw if sw_rows.any() else ci.rms_px, extra)
            else:
                intr, rms_sw = ci, float("nan")
            joint[n] = CameraPose(
                geo.make_T(Rc[i], tc[i]),
                C,
                sd[3:],
                sd[:3],
                float(np.sqrt(np.mean(e2[net_rows]))),
                int(net_rows.sum()),
                intrinsics=intr,
                cov_pose_intrinsics=C_full,
                sigma_pos_m_fixed_intrinsics=sd_fix[3:],
                sigma_rot_rad_fixed_intrinsics=sd_fix[:3],
                rms_px_sweep=rms_sw,
                n_sweep_views=int(sum(sv.camera == n for sv in self.sweeps)),
            )
        return joint
