"""Each camera's clock offset from its own marker corners, by reprojection against a reference trajectory.

The pose fit of :func:`gtrig.sync.sensors.camera_offsets` compares whole GTvision poses with the
reference: a pose of several cameras' views mixes their clocks (GTvision moves it to the instant's mean
stamp), its planar part carries what the 6-DoF fit coupled in from height and tilt, and a one-marker view
rests on a resolved planar ambiguity. Here each camera is timed by what it alone saw:

* every image of camera ``c`` with markers, at its frame stamp ``t`` on the camera's clock, sees the robot
  at the reference pose of ``t - tau_c`` (the reference: GTlaser restamped by the scanners' offsets and
  smoothed, :func:`gtrig.sync.sensors.reference_track`, on GTvision's clock), moved by a constant
  world-frame bias ``b_c`` (x, y, yaw: that camera's calibration error, as the pose fit's per-camera bias);
  height, roll and pitch are GTvision's at the nearest instant (the floor's tilt; no clock in them);
* the image's corners are projected through the calibrated camera with the calibrated markers on the
  robot (:class:`gtrig.vision.observations.VisionModel`), and the whitened reprojection residuals are
  reduced to the image's planar correction ``y`` (3,) with its covariance ``C_y`` (the Gauss-Newton step
  of that image alone: exact for the linearised problem);
* ``y = -V tau_c + b_c`` (``V`` the reference's velocity) is fitted by weighted least squares with the
  weight ``(C_y + Sigma_ref)^-1`` (the reference's own marginal covariance: at 0.5-1 mm it dominates the
  corners' information, so the images count alike rather than by their number of corners), Huber on
  each image's whitened residual, relinearised (Gauss-Newton on the 1-D ``tau_c`` with its 3 nuisances);
* interval: a jackknife over blocks of ``block_s`` (the reference's errors are correlated over about half
  a second, so the images are not independent), Student's t with B - 1 dof, as the pose fit;
* ``relative``: the offsets to GTvision's clock, i.e. minus their mean weighted by each camera's share of
  GTvision's poses, so that an along-track shift of the reference frame (a time offset common to every
  camera) drops out, as in the pose fit.

Verdicts and the cost curve as :func:`gtrig.sync.sensors.offset_verdict`.
"""

from __future__ import annotations

import logging
import os
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from gtrig.evaluate.associate import nearest_indices
from gtrig.io.checkpoint import checkpoint_records
from gtrig.sync.offset import OffsetEstimate
from gtrig.sync.reference import Reference, cost_score, jackknife, near_reference, offset_verdict, ridge
from gtrig.trajectory import PoseTrack
from gtrig.vision.observations import MarkerView, StackedCorners, VisionModel, stack_corners
from gtrig.vision.projection import project_cam, whiten

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class CameraCorners:
    """One camera's marker corners over a sequence.

    Attributes
    ----------
    name : the camera. stamps_s : (I,) each image's frame stamp, the camera's clock, seconds.
    corners : the images' corners stacked (N rows; :class:`StackedCorners`, robot-frame corners of the
        calibrated markers, pixels, covariances px^2 with the floor added). image : (N,) index into
        ``stamps_s`` of each corner's image.
    """

    name: str
    stamps_s: np.ndarray
    corners: StackedCorners
    image: np.ndarray


def read_camera_corners(checkpoint: str | os.PathLike[str], model: VisionModel,
                        camera_stamps_s: Mapping[str, np.ndarray], floor_px: float = 0.1,
                        ) -> dict[str, CameraCorners]:
    """Every camera's marker corners from GTvision's checkpoint of detections (version 5: one line per
    camera and time window, ``{"camera", "frames": [[row, [[marker_id, corners (4, 2), cov (4, 2, 2)(,
    blur)], ...]], ...]}``).

    Markers not on the robot and IDs seen twice in one image are dropped (as GTvision does); each corner's
    covariance gets GTvision's isotropic floor ``floor_px^2 I`` (the detector's covariance alone ignores
    the print's and the lens model's errors). A checkpoint of whole instants (before version 5) holds no
    per-camera rows: an empty dict is returned and a warning logged.
    """
    views: dict[str, list[MarkerView]] = {}
    floor = floor_px**2 * np.eye(2)
    for d in checkpoint_records(checkpoint):
        cam = d.get("camera")
        if cam is None:
            log.warning("%s: a checkpoint of whole instants (before version 5): no per-camera corners", checkpoint)
            return {}
        if cam not in model.cameras or cam not in camera_stamps_s:
            continue
        for row, dets in d["frames"]:
            ids = [int(e[0]) for e in dets]
            for m, uv, cov, *_ in dets:  # (a fourth entry, the detector's blur, where it gave one)
                if int(m) in model.corners_robot and ids.count(int(m)) == 1:
                    views.setdefault(cam, []).append(
                        MarkerView(cam, int(m), np.asarray(uv, float), np.asarray(cov, float) + floor, int(row)))
    out = {}
    for cam, vs in views.items():
        rows = np.array([v.frame for v in vs])
        uniq, img = np.unique(rows, return_inverse=True)
        st = np.asarray(camera_stamps_s[cam], float)
        out[cam] = CameraCorners(cam, st[uniq], stack_corners(model, vs), np.repeat(img, 4))
    return out


def out_of_plane(vision: PoseTrack, t: np.ndarray, window_s: float = 1.0, tol_s: float = 0.05,
                 ) -> tuple[np.ndarray, np.ndarray]:
    """Height (I,) m and the tilt rotation (I, 3, 3) (``R = Rz(yaw) R_tilt``) of the robot at each of ``t``
    (I,): the mean of GTvision's usable poses within ``window_s / 2`` (the floor's height and tilt change
    over decimetres, while one instant's tilt is GTvision's least certain term: 0.1-0.3 deg, i.e. 1-2 mm
    at the markers' height, which would enter the planar fit as noise on every image); 0 and the identity
    where no pose is within ``max(tol_s, window_s / 2)``."""
    u = vision.usable()
    z, R_tilt = np.zeros(t.size), np.tile(np.eye(3), (t.size, 1, 1))
    if len(u) == 0:
        return z, R_tilt
    T = u.matrices()
    yaw = np.arctan2(T[:, 1, 0], T[:, 0, 0])
    tilt = _rz(-yaw) @ T[:, :3, :3]
    # small tilts: the rotation's (x, y) components, averaged, rebuilt (the z component is 0 by the yaw)
    rx, ry = 0.5 * (tilt[:, 2, 1] - tilt[:, 1, 2]), 0.5 * (tilt[:, 0, 2] - tilt[:, 2, 0])
    half = max(tol_s, window_s / 2)
    lo, hi = np.searchsorted(u.stamps_s, t - half), np.searchsorted(u.stamps_s, t + half, side="right")
    n = hi - lo
    near = n > 0
    cs = [np.r_[0.0, np.cumsum(a)] for a in (T[:, 2, 3], rx, ry)]
    zm, ax, ay = ((c[hi] - c[lo]) / np.maximum(n, 1) for c in cs)
    z[near] = zm[near]
    R_tilt[near] = Rotation.from_rotvec(np.column_stack([ax[near], ay[near], np.zeros(int(near.sum()))])).as_matrix()
    return z, R_tilt


def _rz(yaw: np.ndarray) -> np.ndarray:
    c, s = np.cos(yaw), np.sin(yaw)
    R = np.zeros((yaw.size, 3, 3))
    R[:, 0, 0], R[:, 0, 1], R[:, 1, 0], R[:, 1, 1], R[:, 2, 2] = c, -s, s, c, 1.0
    return R


def image_corrections(cc: CameraCorners, pose: np.ndarray, z: np.ndarray, R_tilt: np.ndarray,
                      sigma_z_m: float = 0.003, sigma_tilt_rad: float = np.radians(0.3),
                      ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Each image's planar correction to ``pose`` from its corners alone (one Gauss-Newton step).

    The step is over the whole 6-DoF pose (world-frame perturbation ``t += (dx, dy, dz)``,
    ``R <- Exp(dphi) R``), height and tilt held to ``z``, ``R_tilt`` by a prior of ``sigma_z_m`` and
    ``sigma_tilt_rad`` (GTvision's floor prior: a tilt error at the markers' height moves them as a
    translation would, so holding the tilt fixed would turn its error into a planar one), and the planar
    part (x, y, yaw) is taken with its marginal covariance.

    Parameters
    ----------
    cc : the camera's corners. pose : (I, 3) world x, y (m), yaw (rad) of the robot per image.
    z, R_tilt : (I,), (I, 3, 3) height and tilt per image (:func:`out_of_plane`).
    sigma_z_m, sigma_tilt_rad : the prior on height and tilt (inf: free).

    Returns
    -------
    y : (I, 3) the correction (x, y m, yaw rad, world frame; ``R <- Rz(dyaw) R``); C_y : (I, 3, 3) its
        marginal covariance (the whitened corners' with the prior); rms : (I,) each image's whitened
        reprojection RMS at ``pose`` (inf: a corner behind the camera, or no information).
    """
    sc, img = cc.corners, cc.image
    R = _rz(pose[:, 2]) @ R_tilt
    q = np.einsum("nij,nj->ni", R[img], sc.p_robot)
    p_w = q + np.column_stack([pose[img, :2], z[img]])
    p_c = np.einsum("nij,nj->ni", sc.R_cw, p_w) + sc.t_cw
    uv, Jp = project_cam(sc, p_c, True)
    assert Jp is not None
    JR = Jp @ sc.R_cw
    J = np.concatenate([JR, np.cross(q[:, None, :], JR)], axis=2)  # (N, 2, 6) as project_pose's
    rw, Jw = whiten(sc, sc.uv - uv), whiten(sc, J)
    I = cc.stamps_s.size
    A = np.zeros((I, 6, 6))
    b = np.zeros((I, 6))
    np.add.at(A, img, np.einsum("nki,nkj->nij", Jw, Jw))
    np.add.at(b, img, np.einsum("nki,nk->ni", Jw, rw))
    prior = np.array([0.0, 0.0, sigma_z_m, sigma_tilt_rad, sigma_tilt_rad, 0.0])
    with np.errstate(divide="ignore"):
        A[:, [2, 3, 4], [2, 3, 4]] += np.where(np.isfinite(prior[2:5]), 1.0 / prior[2:5] ** 2, 0.0)
    ss = np.bincount(img, np.einsum("nk,nk->n", rw, rw), minlength=I)
    cnt = np.bincount(img, minlength=I) * 2.0
    behind = np.bincount(img, p_c[:, 2] <= 0, minlength=I) > 0
    good = ~behind & (np.linalg.cond(A) < 1e14)
    C6 = np.full((I, 6, 6), np.nan)
    C6[good] = np.linalg.inv(A[good])
    x = np.einsum("mij,mj->mi", np.nan_to_num(C6), b)
    pl = np.array([0, 1, 5])
    rms = np.where(good, np.sqrt(ss / np.maximum(cnt, 1)), np.inf)
    return x[:, pl], C6[:, pl][:, :, pl], rms


def _cov_at(ref: Reference, t: np.ndarray) -> np.ndarray:
    """The reference's marginal covariance (M, 3, 3) at its nearest grid stamp to each of ``t``."""
    _, k = nearest_indices(t, ref.stamps_s, np.inf)
    return ref.cov[k]


@dataclass(frozen=True)
class _CameraFit:
    """One camera's converged fit: offset ``tau`` (s), world bias (3,), per-block normal equations
    (B, 4, 4), (B, 4) over (tau, bias), and what the cost curve needs."""

    tau: float
    bias: np.ndarray
    H_b: np.ndarray
    g_b: np.ndarray
    n_images: int
    n_blocks: int
    taus: np.ndarray
    curve: np.ndarray


def _fit_camera(cc: CameraCorners, ref: Reference, z: np.ndarray, R_tilt: np.ndarray, keep: np.ndarray,
                blocks: np.ndarray, B: int, huber_k: float, gate_rms: float, search_s: float,
                iterations: int = 5) -> _CameraFit:
    """Gauss-Newton on (tau, bias) of one camera (module docstring); ``keep`` (I,) the images near the
    reference, ``blocks`` (I,) their block of time."""
    t = cc.stamps_s
    tau, bias = 0.0, np.zeros(3)
    S_ref = _cov_at(ref, t)
    w_img = keep.astype(float)
    H_b, g_b = np.zeros((B, 4, 4)), np.zeros((B, 4))

    def terms(tau_: float, bias_: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        P, V = ref.at(t - tau_)
        y, Cy, rms = image_corrections(cc, P + bias_, z, R_tilt)
        ok = keep & np.isfinite(rms) & (rms <= gate_rms)
        S = np.where(ok[:, None, None], np.nan_to_num(Cy) + S_ref, np.eye(3))
        return y, np.linalg.inv(S), V, ok

    for _ in range(iterations):
        y, W, V, ok = terms(tau, bias)
        z2 = np.einsum("mi,mij,mj->m", y, W, y)
        hub = np.where(z2 <= huber_k**2, 1.0, huber_k / np.sqrt(np.maximum(z2, 1e-24)))
        w_img = np.where(ok, hub, 0.0)
        A = np.zeros((t.size, 3, 4))
        A[:, :, 0] = -V  # d (predicted correction) / d tau: the pose moves by -V dtau
        A[:, :, 1:] = np.eye(3)
        Hn = np.einsum("m,mia,mij,mjb->mab", w_img, A, W, A)
        gn = -np.einsum("m,mia,mij,mj->ma", w_img, A, W, y)  # residual y - A x, gradient at x = 0
        H_b, g_b = np.zeros((B, 4, 4)), np.zeros((B, 4))
        np.add.at(H_b, blocks[ok], Hn[ok])
        np.add.at(g_b, blocks[ok], gn[ok])
        H = H_b.sum(axis=0)
        dx = -np.linalg.solve(H + ridge(H), g_b.sum(axis=0))
        tau, bias = tau + float(dx[0]), bias + dx[1:]
        if abs(dx[0]) < 1e-7:
            break
    taus = tau + np.linspace(-search_s, search_s, 81)
    cost = np.empty(taus.size)
    for j, ts in enumerate(taus):  # the fit's cost over trial offsets, the bias and weights held
        y, W, _, _ = terms(float(ts), bias)
        cost[j] = float(np.einsum("m,mi,mij,mj->", w_img, y, W, y))
    used = w_img > 0
    return _CameraFit(tau, bias, H_b, g_b, int(used.sum()), int(np.unique(blocks[used]).size), taus, cost_score(cost))


def camera_offsets_reprojection(corners: Mapping[str, CameraCorners], ref: Reference, vision: PoseTrack,
                                mean_share: Mapping[str, float] | None = None, block_s: float = 5.0,
                                max_ci_s: float = 0.01, search_s: float = 0.02, min_images: int = 20,
                                huber_k: float = 3.0, gate_rms: float = 30.0) -> list[OffsetEstimate]:
    """Every camera's clock offset by reprojection of its own corners (module docstring).

    Parameters
    ----------
    corners : per camera, its corners (:func:`read_camera_corners`), in the order the estimates come out.
    ref : the reference (GTlaser restamped by the scanners' offsets, smoothed), on GTvision's clock.
    vision : GTvision's track: the height and tilt of the robot (:func:`out_of_plane`).
    mean_share : each camera's mean share of GTvision's poses (GTvision's clock is that mean of the
        cameras'); the offsets come out relative to it. None: to the reference's clock.
    block_s, max_ci_s, search_s, huber_k : as :func:`gtrig.sync.sensors.camera_offsets`.
    min_images : fewer images with markers near the reference: ``unobservable``.
    gate_rms : an image whose whitened reprojection RMS at the reference pose exceeds this is not fitted
        (a false detection or a marker misread), sigmas.

    Returns
    -------
    One :class:`OffsetEstimate` per camera, named ``vision/<camera>``.
    """
    names = list(corners)
    C = len(names)
    t0 = min((float(cc.stamps_s.min()) for cc in corners.values() if cc.stamps_s.size), default=0.0)
    t1 = max((float(cc.stamps_s.max()) for cc in corners.values() if cc.stamps_s.size), default=0.0)
    B = int(np.floor((t1 - t0) / block_s)) + 1
    fits: list[_CameraFit | None] = []
    for name in names:
        cc = corners[name]
        keep = near_reference(ref, cc.stamps_s, 0.05)
        if keep.sum() < min_images:
            fits.append(None)
            continue
        z, R_tilt = out_of_plane(vision, cc.stamps_s)
        blocks = np.floor((cc.stamps_s - t0) / block_s).astype(int)
        fits.append(_fit_camera(cc, ref, z, R_tilt, keep, blocks, B, huber_k, gate_rms, search_s))
    # one block-diagonal system over the cameras, so the jackknife of the relative offsets is joint
    n = 4 * C
    H_b, g_b = np.zeros((B, n, n)), np.zeros((B, n))
    for c, f in enumerate(fits):
        if f is not None:
            H_b[:, 4 * c:4 * c + 4, 4 * c:4 * c + 4] = f.H_b
            g_b[:, 4 * c:4 * c + 4] = f.g_b
    tau = np.array([f.tau if f is not None else 0.0 for f in fits])
    share = np.array([float((mean_share or {}).get(nm, 0.0)) if fits[c] is not None else 0.0
                      for c, nm in enumerate(names)])
    share = share / share.sum() if mean_share is not None and share.sum() > 0 else np.zeros(C)
    L = np.eye(C) - np.ones((C, 1)) @ share[None, :]
    # the converged fits have zero gradients: the jackknife's solve gives the leave-one-block-out steps
    _, se, _ = jackknife(H_b, g_b, np.arange(0, n, 4), L)
    H = H_b.sum(axis=0)
    Hinv = np.linalg.inv(H + ridge(H))[np.ix_(np.arange(0, n, 4), np.arange(0, n, 4))]
    white = np.sqrt(np.maximum(np.diag(L @ Hinv @ L.T), 0.0))
    common = float(share @ tau)
    out = []
    for c, (name, f) in enumerate(zip(names, fits, strict=True)):
        if f is None:
            out.append(offset_verdict(f"vision/{name}", float("nan"), float("inf"), float("inf"), 0, np.zeros(0),
                                np.zeros(0), max_ci_s, int(corners[name].stamps_s.size), min_images))
            continue
        e = offset_verdict(f"vision/{name}", f.tau - common, float(se[c]), float(white[c]), f.n_blocks,
                     f.taus - common, f.curve, max_ci_s, f.n_images, min_images)
        out.append(e)
    return out
