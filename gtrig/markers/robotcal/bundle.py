"""Step 5: bundle adjustment of every image pose and marker pose on the corners, with covariance.

Unknowns: ``T_cam_robot`` of every image and ``T_robot_marker`` of every marker but the anchor, whose
pose is given (it fixes the gauge). Each pose is perturbed as ``t <- t + dt``, ``R <- Exp(dphi) R``
(``dt``, ``dphi`` in the parent frame's axes), the same parametrisation as the covariance written out
(:func:`gtrig.vision.covariance.pose_error_xi`). Residuals are the corners' reprojection errors in
normalised coordinates, whitened by the detector's corner covariances; the loss is Huber's on each
corner's whitened error norm (``huber_k`` times a robust scale: the median error norm over that of a
2-D standard normal, re-estimated every iteration, and at least 1), solved by Levenberg-Marquardt on the normal
equations with the image poses eliminated (Schur complement: each corner touches one image and one
marker, so the image blocks are 6 x 6 and independent; Triggs et al., "Bundle adjustment - a modern
synthesis", 2000, section 6.1).

The markers' covariance is the inverse of that Schur complement (the image poses marginalised out),
times the a-posteriori variance factor when it exceeds one (the detector's covariances are then too
optimistic for these images; never scaled below what the detector claims).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from gtrig.markers.robotcal.observe import Array, View, marker_object_points

_CHI2_2D_MEDIAN = math.sqrt(2.0 * math.log(2.0))  # median norm of a 2-D standard normal


@dataclass(frozen=True)
class BundleOptions:
    """Settings of the bundle adjustment.

    Attributes
    ----------
    huber_k : Huber threshold on a corner's whitened error norm, in robust-scale units.
    max_iter : Levenberg-Marquardt iterations.
    step_tol : stop when the largest update is below this (metres, radians).
    """

    huber_k: float = 3.0
    max_iter: int = 50
    step_tol: float = 1e-10


@dataclass(frozen=True)
class BundleResult:
    """The adjusted poses.

    Attributes
    ----------
    T_cam_robot : (N, 4, 4) image poses, in the order of ``images``.
    T_robot_marker : {ID: (4, 4)} marker poses (the anchor's as given).
    cov : {ID: (6, 6)} covariance of each free marker over (dt, dphi), robot axes, m and rad.
    view_chi2 : {(image, ID): whitened chi-square of the view's 8 corner coordinates, in scale units}.
    view_rms_px : {(image, ID): RMS corner reprojection error, pixels}.
    scale : robust scale of the whitened errors, at least 1 (1 when the corner covariances are right or
        pessimistic).
    variance_factor : weighted chi-square over degrees of freedom.
    iterations : LM iterations run.
    """

    images: tuple[str, ...]
    T_cam_robot: Array
    T_robot_marker: dict[int, Array]
    cov: dict[int, Array]
    view_chi2: dict[tuple[str, int], float]
    view_rms_px: dict[tuple[str, int], float]
    scale: float
    variance_factor: float
    iterations: int


def _skew(v: Array) -> Array:
    """Skew matrices (N, 3, 3) of vectors (N, 3)."""
    z = np.zeros(len(v))
    return np.stack([np.stack([z, -v[:, 2], v[:, 1]], 1), np.stack([v[:, 2], z, -v[:, 0]], 1),
                     np.stack([-v[:, 1], v[:, 0], z], 1)], 1)


@dataclass(frozen=True)
class _Problem:
    ci: np.ndarray  # (K,) image index of each corner
    mi: np.ndarray  # (K,) free-marker index, -1 for the anchor
    P: Array  # (K, 3) corner in its marker frame
    x: Array  # (K, 2) observed, normalised
    L: Array  # (K, 2, 2) whitening: r = L (pred - obs)
    view: np.ndarray  # (K,) view index
    f_px: float


def _build(views: Sequence[View], images: Sequence[str], free: Sequence[int], side_m: Mapping[int, float],
           f_px: float) -> _Problem:
    im = {n: i for i, n in enumerate(images)}
    mk = {m: i for i, m in enumerate(free)}
    ci, mi, P, x, L, vi = [], [], [], [], [], []
    for k, v in enumerate(views):
        obj = marker_object_points(side_m[v.marker_id])
        Winv = np.linalg.inv(v.cov_n)
        C = np.linalg.cholesky(0.5 * (Winv + np.swapaxes(Winv, -1, -2)))  # Winv = C C^T
        ci += [im[v.image]] * 4
        mi += [mk.get(v.marker_id, -1)] * 4
        P.append(obj)
        x.append(v.corners_n)
        L.append(np.swapaxes(C, -1, -2))
        vi += [k] * 4
    return _Problem(np.array(ci), np.array(mi), np.vstack(P), np.vstack(x), np.concatenate(L), np.array(vi),
                    f_px)


def _residuals(pb: _Problem, Tc: Array, Tm: Array, jac: bool
               ) -> tuple[Array, Array | None, Array | None]:
    """Whitened errors (K, 2) and their Jacobians (K, 2, 6) w.r.t. the image and the marker perturbation.

    ``Tm`` is (M + 1, 4, 4): the free markers, then the anchor last (index -1)."""
    Rm, tm = Tm[pb.mi, :3, :3], Tm[pb.mi, :3, 3]
    Rc, tc = Tc[pb.ci, :3, :3], Tc[pb.ci, :3, 3]
    q = np.einsum("kij,kj->ki", Rm, pb.P)  # R_m P, robot axes
    pr = q + tm
    Rpr = np.einsum("kij,kj->ki", Rc, pr)
    pc = Rpr + tc
    z = pc[:, 2]
    pred = pc[:, :2] / z[:, None]
    e = np.einsum("kij,kj->ki", pb.L, pred - pb.x)
    if not jac:
        return e, None, None
    Jp = np.zeros((len(z), 2, 3))
    Jp[:, 0, 0] = Jp[:, 1, 1] = 1.0 / z
    Jp[:, :, 2] = -pred / z[:, None]
    LJ = pb.L @ Jp  # (K, 2, 3)
    Jc = np.concatenate([LJ, -LJ @ _skew(Rpr)], axis=2)
    LJR = LJ @ Rc
    Jm = np.concatenate([LJR, -LJR @ _skew(q)], axis=2)
    return e, Jc, Jm


def _apply(T: Array, d: Array) -> Array:
    out = T.copy()
    out[..., :3, 3] += d[..., :3]
    out[..., :3, :3] = Rotation.from_rotvec(d[..., 3:].reshape(-1, 3)).as_matrix().reshape(d.shape[:-1] + (3, 3)) \
        @ T[..., :3, :3]
    return out


def _weights(e: Array, k: float) -> tuple[Array, float]:
    r = np.linalg.norm(e, axis=1)
    # never below 1: errors smaller than the corners' covariances claim are not a reason to distrust them
    s = max(float(np.median(r)) / _CHI2_2D_MEDIAN, 1.0)
    th = k * s
    return np.where(r <= th, 1.0, th / np.maximum(r, 1e-300)), s


def _huber_cost(e: Array, w_th: float) -> float:
    r = np.linalg.norm(e, axis=1)
    return float(np.sum(np.where(r <= w_th, 0.5 * r * r, w_th * (r - 0.5 * w_th))))


def _normal(pb: _Problem, w: Array, e: Array, Jc: Array, Jm: Array, n_img: int, n_free: int
            ) -> tuple[Array, Array, Array, Array, Array]:
    """Blocks of the weighted normal equations: H_cc (N,6,6), H_cm (N,M,6,6), H_mm (M,6,6), g_c, g_m."""
    wJc = Jc * w[:, None, None]
    wJm = Jm * w[:, None, None]
    Hcc = np.zeros((n_img, 6, 6))
    np.add.at(Hcc, pb.ci, np.einsum("kai,kaj->kij", wJc, Jc))
    gc = np.zeros((n_img, 6))
    np.add.at(gc, pb.ci, np.einsum("kai,ka->ki", wJc, e))
    Hcm = np.zeros((n_img, n_free, 6, 6))
    Hmm = np.zeros((n_free, 6, 6))
    gm = np.zeros((n_free, 6))
    f = pb.mi >= 0
    if np.any(f):
        np.add.at(Hcm, (pb.ci[f], pb.mi[f]), np.einsum("kai,kaj->kij", wJc[f], Jm[f]))
        np.add.at(Hmm, pb.mi[f], np.einsum("kai,kaj->kij", wJm[f], Jm[f]))
        np.add.at(gm, pb.mi[f], np.einsum("kai,ka->ki", wJm[f], e[f]))
    return Hcc, Hcm, Hmm, gc, gm


def _schur(Hcc: Array, Hcm: Array, Hmm: Array, gc: Array, gm: Array, lam: float
           ) -> tuple[Array, Array, Array]:
    """Reduced system (6M, 6M), its right-hand side, and the damped inverses of the image blocks."""
    n_img, n_free = Hcm.shape[:2]
    D = Hcc + lam * np.einsum("nii->ni", Hcc)[:, :, None] * np.eye(6)
    Dinv = np.linalg.inv(D)
    Hcm_f = Hcm.transpose(0, 2, 1, 3).reshape(n_img, 6, 6 * n_free)
    S = np.zeros((6 * n_free, 6 * n_free))
    for m in range(n_free):
        blk = Hmm[m] + lam * np.diag(np.diag(Hmm[m]))
        S[6 * m:6 * m + 6, 6 * m:6 * m + 6] = blk
    S -= np.einsum("nia,nij,njb->ab", Hcm_f, Dinv, Hcm_f)
    rhs = gm.ravel() - np.einsum("nia,nij,nj->a", Hcm_f, Dinv, gc)
    return S, rhs, Dinv


def bundle_adjust(views: Sequence[View], side_m: Mapping[int, float], T_cam_robot: Mapping[str, Array],
                  T_robot_marker: Mapping[int, Array], anchor: int, f_px: float,
                  options: BundleOptions = BundleOptions()) -> BundleResult:
    """Adjust image and marker poses to the corners of ``views``.

    Parameters
    ----------
    views : the views used (every image among them must appear in ``T_cam_robot``).
    side_m : {ID: black-square side, metres}.
    T_cam_robot : {image: (4, 4) initial pose of the robot frame in the camera}.
    T_robot_marker : {ID: (4, 4) initial marker pose}; the anchor's is held fixed.
    anchor : the anchor marker's ID.
    f_px : the camera's focal length (pixels), to report errors in pixels.
    """
    images = tuple(sorted({v.image for v in views}))
    free = tuple(sorted({v.marker_id for v in views} - {anchor}))
    pb = _build(views, images, free, side_m, f_px)
    Tc = np.stack([T_cam_robot[n] for n in images])
    Tm = np.stack([T_robot_marker[m] for m in free] + [T_robot_marker[anchor]])
    n_img, n_free = len(images), len(free)
    lam = 1e-6
    iterations = 0
    e, Jc, Jm = _residuals(pb, Tc, Tm, True)
    w, s = _weights(e, options.huber_k)
    for _ in range(options.max_iter):
        iterations += 1
        assert Jc is not None and Jm is not None
        cost = _huber_cost(e, options.huber_k * s)
        Hcc, Hcm, Hmm, gc, gm = _normal(pb, w, e, Jc, Jm, n_img, n_free)
        while True:
            S, rhs, Dinv = _schur(Hcc, Hcm, Hmm, gc, gm, lam)
            dm = np.asarray(np.linalg.solve(S, -rhs) if n_free else np.zeros(0), dtype=np.float64)
            dc = -np.einsum("nij,nj->ni", Dinv, gc + np.einsum("nmij,mj->ni", Hcm, dm.reshape(n_free, 6)))
            Tc_new = _apply(Tc, dc)
            Tm_new = Tm.copy()
            if n_free:
                Tm_new[:n_free] = _apply(Tm[:n_free], dm.reshape(n_free, 6))
            e_new, _, _ = _residuals(pb, Tc_new, Tm_new, False)
            if _huber_cost(e_new, options.huber_k * s) <= cost or lam > 1e6:
                break
            lam *= 10.0
        Tc, Tm = Tc_new, Tm_new
        lam = max(lam / 10.0, 1e-9)
        e, Jc, Jm = _residuals(pb, Tc, Tm, True)
        w, s = _weights(e, options.huber_k)
        step = max(float(np.abs(dc).max()), float(np.abs(dm).max()) if n_free else 0.0)
        if step < options.step_tol:
            break
    assert Jc is not None and Jm is not None
    # covariance at the solution, without damping: (image poses marginalised) inverse Schur complement
    Hcc, Hcm, Hmm, gc, gm = _normal(pb, w, e, Jc, Jm, n_img, n_free)
    n_par = 6 * (n_img + n_free)
    chi2_w = float(np.sum(w * np.sum(e * e, axis=1)))
    dof = max(1, 2 * len(e) - n_par)
    vf = chi2_w / dof
    cov: dict[int, Array] = {}
    if n_free:
        S, _, _ = _schur(Hcc, Hcm, Hmm, gc, gm, 0.0)
        C = np.linalg.inv(S) * max(1.0, vf)
        for m, mid in enumerate(free):
            blk = C[6 * m:6 * m + 6, 6 * m:6 * m + 6]
            cov[mid] = 0.5 * (blk + blk.T)
    # per-view diagnostics
    chi2_c = np.sum(e * e, axis=1) / (s * s)
    e_n, _, _ = _residuals(pb, Tc, Tm, False)
    err_n = np.linalg.solve(pb.L, e_n[:, :, None])[:, :, 0]  # back to normalised units
    view_chi2: dict[tuple[str, int], float] = {}
    view_rms: dict[tuple[str, int], float] = {}
    for k, v in enumerate(views):
        sel = pb.view == k
        view_chi2[(v.image, v.marker_id)] = float(chi2_c[sel].sum())
        view_rms[(v.image, v.marker_id)] = float(np.sqrt(np.mean(np.sum(err_n[sel] ** 2, axis=1)))) * f_px
    T_rm = {mid: Tm[m] for m, mid in enumerate(free)}
    T_rm[anchor] = Tm[-1]
    return BundleResult(images, Tc, T_rm, cov, view_chi2, view_rms, s, vf, iterations)
