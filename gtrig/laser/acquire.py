"""Global search for the hull when the robot first appears or the track is lost.

1. Cluster the frame's foreground points (gaps over ``cluster_gap_m`` split clusters), and keep the
   clusters no larger than the hull's diagonal: people's legs, the robot.
2. For each cluster, the minimum-area rectangle (rotating calipers, OpenCV) gives the hull's orientation
   modulo 90 deg. An L of two sides or a full outline both give it; a single side gives it too, and the
   ICP will then flag the fit.
3. Hypotheses: the four orientations, each with the hull placed against each of the four corners of the
   cluster's bounding box in that orientation (16 per cluster), refined together by the point-to-line ICP
   (:func:`gtrig.laser.hull_icp.fit_hull_batch`) and ranked by inliers, then residual.
4. The rectangle's 180-degree symmetry cannot be resolved from one frame. The best hypothesis and its
   twin turned by pi explain the points equally; ``prior_theta`` (previous pose) picks one, else the
   result says ``ambiguous`` and the tracker resolves it from the direction of motion.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import cv2
import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from gtrig.geometry import wrap_angle
from gtrig.laser.hull_icp import BeamPoints, HullFit, HullFitBatch, HullModel, IcpSettings, fit_hull_batch


@dataclass(frozen=True)
class Acquisition:
    """The hull found by the global search.

    Attributes
    ----------
    fit : the refined fit (its ``xytheta`` is the chosen one of the two symmetric poses).
    ambiguous : True when nothing told the pose from its twin turned by pi.
    n_clusters : clusters examined.
    """

    fit: HullFit
    ambiguous: bool
    n_clusters: int


def cluster_points(xy: np.ndarray, gap_m: float) -> np.ndarray:
    """Connected components (M,) of points ``xy`` (M, 2) linked when closer than ``gap_m``."""
    m = xy.shape[0]
    if m == 0:
        return np.zeros(0, dtype=int)
    pairs = cKDTree(xy).query_pairs(gap_m, output_type="ndarray")
    g = coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(m, m))
    return connected_components(g, directed=False)[1]


def _crossings(
    model: HullModel, poses: np.ndarray, o: np.ndarray, d: np.ndarray, r_free: np.ndarray, margin_m: float
) -> np.ndarray:
    """For each pose (H, 3), the number of free rays that would hit its hull before their free range."""
    c, s = np.cos(poses[:, 2]), np.sin(poses[:, 2])
    R = np.stack([np.stack([c, -s], -1), np.stack([s, c], -1)], -2)  # (H, 2, 2)
    corners = np.einsum("hij,kj->hki", R, model.corners_xy) + poses[:, None, :2]  # (H, 4, 2)
    a = corners
    e = np.roll(corners, -1, axis=1) - corners  # (H, 4, 2)
    ao = a[:, None] - o[None, :, None]  # (H, R, 4, 2)
    den = d[None, :, None, 0] * -e[:, None, :, 1] + d[None, :, None, 1] * e[:, None, :, 0]
    with np.errstate(divide="ignore", invalid="ignore"):
        t = (ao[..., 0] * -e[:, None, :, 1] + ao[..., 1] * e[:, None, :, 0]) / den
        u = (d[None, :, None, 0] * ao[..., 1] - d[None, :, None, 1] * ao[..., 0]) / den
    hit = (np.abs(den) > 1e-12) & (t > 0) & (u >= 0) & (u <= 1)
    t_in = np.where(hit, t, np.inf).min(axis=2)  # (H, R)
    return np.sum(t_in < r_free[None] - margin_m, axis=1)


def acquire(
    model: HullModel,
    pts: BeamPoints,
    settings: IcpSettings | None = None,
    prior_xytheta: np.ndarray | None = None,
    search_radius_m: float | None = None,
    cluster_gap_m: float = 0.25,
    free_rays: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None,
    free_margin_m: float = 0.05,
) -> Acquisition | None:
    """Find the hull among one frame's foreground points without a start pose.

    Parameters
    ----------
    model, settings
        As in :func:`gtrig.laser.hull_icp.fit_hull_batch`.
    pts
        The frame's M points, world frame (their ``frame_index`` is not read).
    prior_xytheta
        (3,) a recent pose: resolves the 180-degree symmetry, and with ``search_radius_m`` limits the
        clusters to those near it.
    search_radius_m
        Only clusters whose centroid is this close to ``prior_xytheta`` are searched.
    cluster_gap_m
        Points closer than this belong to one cluster.
    free_rays
        Beams of the same frame that saw past the robot (background or no return): origins (R, 2), unit
        directions (R, 2), free range (R,). A hypothesis that such beams would cross is penalised: the
        negative information that tells a long side from a short one when only parts of two are seen.
    free_margin_m
        A beam must pass this far inside the hypothesised outline to count against it.

    Returns
    -------
    Acquisition or None
        None when no cluster gives a non-degenerate fit.
    """
    settings = IcpSettings() if settings is None else settings
    p = pts.xy_world
    if p.shape[0] < settings.min_points:
        return None
    near_prior = prior_xytheta if search_radius_m is not None else None
    inits, members, n_clusters = _hypotheses(model, p, settings, cluster_gap_m, near_prior, search_radius_m)
    if not inits:
        return None
    # refine all hypotheses at once: each hypothesis gets its own copy of its cluster's points
    fid = np.concatenate([np.full(m.size, i) for i, m in enumerate(members)])
    sel = np.concatenate(members)
    fits = fit_hull_batch(
        model,
        BeamPoints(p[sel], fid, pts.scanner_index[sel], pts.scanner_xy_world, pts.dir_world[sel], pts.sigma_range_m),
        np.array(inits),
        settings,
        wide_gate_m=max(0.2, 2 * settings.gate_m),
    )
    best = _best_hypothesis(model, fits, near_prior, free_rays, free_margin_m)
    if best is None:
        return None
    fit, ambiguous = _symmetric_choice(fits.item(best), model.corners_xy.mean(axis=0), prior_xytheta)
    return Acquisition(fit, ambiguous, n_clusters)


def _hypotheses(
    model: HullModel, p: np.ndarray, settings: IcpSettings, cluster_gap_m: float, near_prior: np.ndarray | None,
    search_radius_m: float | None,
) -> tuple[list[list[float]], list[np.ndarray], int]:
    """Start poses of the hull among the points ``p`` (M, 2, world): 16 per cluster of hull size (within
    ``search_radius_m`` of ``near_prior`` (3,) when given), and ``near_prior`` itself. Returns the start
    poses (x, y m; theta rad), each one's points (indices into ``p``) and the clusters examined."""
    labels = cluster_points(p, cluster_gap_m)
    corners = model.corners_xy
    ext = corners.max(axis=0) - corners.min(axis=0)  # (length, width) along robot x, y
    diag = float(np.hypot(*ext))
    inits: list[list[float]] = []
    members: list[np.ndarray] = []
    n_clusters = 0
    for lab in range(labels.max() + 1):
        idx = np.flatnonzero(labels == lab)
        if idx.size < settings.min_points:
            continue
        q = p[idx]
        if (near_prior is not None and search_radius_m is not None
                and np.linalg.norm(q.mean(axis=0) - near_prior[:2]) > search_radius_m):
            continue
        if np.max(np.linalg.norm(q - q.mean(axis=0), axis=1)) > diag:
            continue
        n_clusters += 1
        _corner_hypotheses(model, p, q, 0.5 * diag + 2 * settings.gate_m, inits, members)
    if near_prior is not None:
        # the recent pose itself is a hypothesis, on the points near it
        near = np.flatnonzero(np.linalg.norm(p - near_prior[:2], axis=1) < diag)
        if near.size >= settings.min_points:
            inits.append(list(near_prior))
            members.append(near)
    return inits, members, n_clusters


def _corner_hypotheses(
    model: HullModel, p: np.ndarray, q: np.ndarray, reach_m: float, inits: list[list[float]],
    members: list[np.ndarray],
) -> None:
    """Append to ``inits`` and ``members`` the 16 start poses of the hull on cluster ``q`` (N, 2, world):
    its four orientations from the minimum-area rectangle, each against the four corners of the
    cluster's bounding box, and for each the points of ``p`` (M, 2) within ``reach_m`` of its centre."""
    corners = model.corners_xy
    centre_r = corners.mean(axis=0)
    ext = corners.max(axis=0) - corners.min(axis=0)
    (_, _), (_, _), ang_deg = cv2.minAreaRect(q.astype(np.float32))
    alpha = np.radians(ang_deg)
    for k in range(4):
        th = alpha + k * np.pi / 2
        c, s = np.cos(th), np.sin(th)
        R = np.array([[c, -s], [s, c]])
        qr = q @ R  # cluster in axes aligned with the candidate robot frame
        lo, hi = qr.min(axis=0), qr.max(axis=0)
        for cx in (lo[0] + ext[0] / 2, hi[0] - ext[0] / 2):
            for cy in (lo[1] + ext[1] / 2, hi[1] - ext[1] / 2):
                centre_w = R @ np.array([cx, cy])
                origin_w = centre_w - R @ centre_r
                inits.append([origin_w[0], origin_w[1], th])
                # all points near the hypothesised hull, not only the cluster's: a partly
                # occluded outline may fall apart into several clusters
                members.append(np.flatnonzero(np.linalg.norm(p - centre_w, axis=1) < reach_m))


def _best_hypothesis(
    model: HullModel, fits: HullFitBatch, near_prior: np.ndarray | None,
    free_rays: tuple[np.ndarray, np.ndarray, np.ndarray] | None, free_margin_m: float,
) -> int | None:
    """The refined hypothesis to keep: among the non-degenerate fits scoring within 10 % of the best
    (inliers, less two per free ray crossed, no turn of about 90 degrees from ``near_prior``), the one
    of least residual; None when none scores above zero."""
    good = ~fits.degenerate
    if not np.any(good):
        return None
    score = fits.n_points.astype(float)
    if free_rays is not None and free_rays[0].shape[0]:
        score = score - 2.0 * _crossings(model, fits.xytheta, *free_rays, free_margin_m)
    if near_prior is not None:
        # near a recent pose, a turn of the hull by about 90 degrees is implausible
        dth = np.abs(wrap_angle(2.0 * (fits.xytheta[:, 2] - near_prior[2]))) / 2.0
        score = np.where(dth < np.radians(30.0), score, score - 1e6)
    n_in = np.where(good, score, -np.inf)
    best_n = n_in.max()
    if not best_n > 0:
        return None
    cand = np.flatnonzero(n_in >= 0.9 * best_n)
    cand = cand[np.argsort(fits.rms_m[cand])]
    return int(cand[0])


def _symmetric_choice(fit: HullFit, centre_r: np.ndarray, prior_xytheta: np.ndarray | None) -> tuple[HullFit, bool]:
    """``fit`` or its symmetric twin (same outline, heading turned by pi, origin mirrored through the
    hull centre ``centre_r`` (2,), robot frame), whichever heads nearer ``prior_xytheta`` (3,), with its
    covariance carried over; and whether nothing told them apart (no prior)."""
    R = np.array(
        [[np.cos(fit.xytheta[2]), -np.sin(fit.xytheta[2])], [np.sin(fit.xytheta[2]), np.cos(fit.xytheta[2])]]
    )
    centre_w = fit.xytheta[:2] + R @ centre_r
    twin = np.r_[centre_w + R @ centre_r, fit.xytheta[2] + np.pi]  # R(th + pi) = -R
    ambiguous = prior_xytheta is None
    chosen, Jt = fit.xytheta.copy(), np.eye(3)
    if prior_xytheta is not None and (
        abs(wrap_angle(twin[2] - prior_xytheta[2])) < abs(wrap_angle(fit.xytheta[2] - prior_xytheta[2]))
    ):
        chosen = twin
        Jt[:2, 2] = 2.0 * (np.array([[0.0, -1.0], [1.0, 0.0]]) @ R @ centre_r)  # d twin_xy / d theta
    chosen[2] = float(wrap_angle(chosen[2]))
    return replace(fit, xytheta=chosen, cov_xytheta=Jt @ fit.cov_xytheta @ Jt.T), ambiguous
