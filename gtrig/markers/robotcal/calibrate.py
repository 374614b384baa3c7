"""The marker-to-robot calibration, step by step (see :mod:`gtrig.markers.robotcal`)."""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np
from scipy.stats import chi2

from gtrig.errors import InputError
from gtrig.io.camfile import CameraIntrinsics
from gtrig.markers.robotcal.bundle import BundleOptions, BundleResult, bundle_adjust
from gtrig.markers.robotcal.graph import solve_graph
from gtrig.markers.robotcal.imageposes import image_pose
from gtrig.markers.robotcal.observe import Array, MarkerSpec, View
from gtrig.markers.robotcal.pairs import pair_edges
from gtrig.markers.robotcal.pnp import ViewPoses, ippe_both


@dataclass(frozen=True)
class RobotCalOptions:
    """Settings of the marker-to-robot calibration.

    Attributes
    ----------
    pair_tol_m, pair_tol_deg : candidate relative poses of a pair agree when closer than this.
    image_tol_m, image_tol_deg : a view agrees with its image's starting pose when closer than this.
    view_p : a view whose corners' chi-square (8 dof, in robust-scale units) has a p-value below this
        after the bundle adjustment is an outlier.
    image_bad_fraction : an image with more than this fraction of its views rejected is rejected whole
        (it moved during the exposure, was out of focus, or is not from this camera).
    corner_sigma_floor_px : added in quadrature to every corner's sigma from the detector, which models
        image noise only; the rest (lens model residuals, print and plate flatness, edge-model bias)
        is not in it.
    bundle : :class:`BundleOptions`.
    """

    pair_tol_m: float = 0.02
    pair_tol_deg: float = 2.0
    image_tol_m: float = 0.03
    image_tol_deg: float = 3.0
    view_p: float = 1e-6
    image_bad_fraction: float = 0.5
    corner_sigma_floor_px: float = 0.02
    bundle: BundleOptions = field(default_factory=BundleOptions)


@dataclass(frozen=True)
class RobotCalibration:
    """Marker poses on the robot, their uncertainty and what was left out.

    Attributes
    ----------
    anchor : the anchor marker's ID; ``T_robot_marker[anchor]`` is the given pose.
    T_robot_marker : {ID: (4, 4)} pose of each calibrated marker in the robot frame (metres).
    cov : {ID: (6, 6)} covariance over (dt, dphi): ``t_est - t_true`` and ``Log(R_est R_true^T)``, robot
        axes, m and rad (as :func:`gtrig.vision.covariance.pose_error_xi`); it includes the anchor's own
        uncertainty when one was given, fully correlated between markers (not represented here).
    cov_relative : {ID: (6, 6)} the same without the anchor's own uncertainty: what the images measured,
        the marker relative to the robot frame as the anchor realises it (zero for the anchor).
    n_views : {ID: images in which the marker's corners were used}.
    paths : {ID: chain of markers from the anchor used to start it}; length 2 means seen with the anchor,
        longer means bridged through other markers.
    pairs : {(a, b): images agreeing on the pair's relative pose} for co-visible pairs.
    bridged_pairs : calibrated pairs never seen together (related only through other markers).
    rejected_images : {image: reason}.
    rejected_views : {(image, ID): reason}.
    rejected_pairs : pairs whose averaged relative pose disagreed with the rest of the graph.
    uncalibrated : {ID: reason} markers asked for but not calibrated (never seen, or never with another).
    unknown_ids : {ID: detections} decoded markers not asked for (ignored).
    images_total, images_used : images read, images in the final adjustment.
    rms_px : RMS corner reprojection error of the final adjustment, pixels.
    variance_factor : weighted chi-square / dof with the detector's corner covariances (1 when they are
        right; the covariances are scaled by it when above 1).
    """

    anchor: int
    T_robot_marker: dict[int, Array]
    cov: dict[int, Array]
    n_views: dict[int, int]
    paths: dict[int, tuple[int, ...]]
    pairs: dict[tuple[int, int], int]
    bridged_pairs: tuple[tuple[int, int], ...]
    rejected_images: dict[str, str]
    rejected_views: dict[tuple[str, int], str]
    rejected_pairs: tuple[tuple[int, int], ...]
    uncalibrated: dict[int, str]
    unknown_ids: dict[int, int]
    images_total: int
    images_used: int
    rms_px: float
    variance_factor: float
    cov_relative: dict[int, Array] = field(default_factory=dict)

    def sigma(self, marker_id: int) -> tuple[float, float]:
        """One-sigma position (m, the RMS over axes times sqrt 3) and rotation (rad) uncertainty."""
        c = self.cov[marker_id]
        return float(math.sqrt(np.trace(c[:3, :3]))), float(math.sqrt(np.trace(c[3:, 3:])))


def _anchor_propagation(T_robot_anchor: Array, T_robot_m: Array) -> Array:
    """Jacobian (6, 6) of marker ``m``'s (dt, dphi) w.r.t. the anchor's, the relative pose held fixed:
    ``R_m = R_a R_am`` gives ``dphi_m = dphi_a``; ``t_m = t_a + R_a t_am`` gives
    ``dt_m = dt_a - [t_m - t_a]x dphi_a``."""
    d = T_robot_m[:3, 3] - T_robot_anchor[:3, 3]
    A = np.eye(6)
    A[:3, 3:] = -np.array([[0, -d[2], d[1]], [d[2], 0, -d[0]], [-d[1], d[0], 0]])
    return A


def calibrate_from_views(views: Sequence[View], markers: Sequence[MarkerSpec], anchor: int,
                         T_robot_anchor: Array, camera: CameraIntrinsics, images_total: int,
                         anchor_cov: Array | None = None, unknown_ids: Mapping[int, int] | None = None,
                         options: RobotCalOptions = RobotCalOptions()) -> RobotCalibration:
    """Calibrate marker poses on the robot from detected views (see :func:`calibrate_robot_markers`)."""
    side = {m.id: m.side_m for m in markers}
    views = [v.with_sigma_floor(options.corner_sigma_floor_px) for v in views]
    if anchor not in side:
        raise InputError(f"anchor marker {anchor} is not among the markers to calibrate ({sorted(side)})")
    seen = {v.marker_id for v in views}
    uncal: dict[int, str] = {m: "never detected" for m in side if m not in seen}
    if anchor not in seen:
        raise InputError(f"anchor marker {anchor} is not detected in any image")

    sols: dict[str, dict[int, ViewPoses]] = {}
    for v in views:
        sols.setdefault(v.image, {})[v.marker_id] = ippe_both(v, side[v.marker_id])
    multi = {im: s for im, s in sols.items() if len(s) >= 2}
    edges = pair_edges(multi, options.pair_tol_m, math.radians(options.pair_tol_deg))
    graph = solve_graph(sorted(seen), edges, anchor)
    for m in graph.unreached:
        uncal[m] = "never seen together with a marker linked to the anchor"
    if len(graph.T_anchor_marker) < 2:
        raise InputError(f"no marker is seen together with the anchor {anchor} (or linked to it) in two "
                         f"images: nothing to calibrate")
    T_rm = {m: T_robot_anchor @ T for m, T in graph.T_anchor_marker.items()}
    T_rm[anchor] = np.asarray(T_robot_anchor, float).copy()

    rejected_images: dict[str, str] = {}
    rejected_views: dict[tuple[str, int], str] = {}
    T_cr = _start_image_poses(sols, T_rm, options, rejected_images, rejected_views)
    live = [v for v in views if v.image in T_cr and v.marker_id in T_rm and (v.image, v.marker_id)
            not in rejected_views]
    f_px = float(math.sqrt(camera.camera_matrix[0, 0] * camera.camera_matrix[1, 1]))
    result, live = _adjust_rejecting(live, side, T_cr, T_rm, anchor, f_px, options, rejected_images, rejected_views)

    cov = dict(result.cov)
    calibrated = set(cov)
    for m in sorted(set(T_rm) - calibrated - {anchor}):
        uncal[m] = "all its views were rejected"
    out_T = {m: T_rm[m] for m in sorted(calibrated | {anchor})}
    cov, cov_rel = _with_anchor_uncertainty(cov, out_T, anchor, anchor_cov)
    n_views = {m: sum(1 for v in live if v.marker_id == m) for m in out_T}
    pairs = {(e.a, e.b): e.n for e in edges if e.a in out_T and e.b in out_T}
    ids = sorted(out_T)
    bridged = tuple((a, b) for i, a in enumerate(ids) for b in ids[i + 1:] if (a, b) not in pairs)
    rms = math.sqrt(float(np.mean([r * r for r in result.view_rms_px.values()])))
    return RobotCalibration(
        anchor=anchor, T_robot_marker=out_T, cov={m: cov[m] for m in out_T}, n_views=n_views,
        paths={m: p for m, p in graph.paths.items() if m in out_T}, pairs=pairs, bridged_pairs=bridged,
        rejected_images=dict(sorted(rejected_images.items())), rejected_views=dict(sorted(rejected_views.items())),
        rejected_pairs=graph.rejected_edges, uncalibrated=dict(sorted(uncal.items())),
        unknown_ids=dict(unknown_ids or {}), images_total=images_total, images_used=len(result.images),
        rms_px=rms, variance_factor=result.variance_factor,
        cov_relative={m: cov_rel[m] for m in out_T})


def _start_image_poses(sols: Mapping[str, Mapping[int, ViewPoses]], T_rm: Mapping[int, Array],
                       options: RobotCalOptions, rejected_images: dict[str, str],
                       rejected_views: dict[tuple[str, int], str]) -> dict[str, Array]:
    """Starting pose ``T_cam_robot`` (4, 4) of each image with two usable views, from its markers' poses
    ``T_rm`` on the robot; an image whose markers disagree goes into ``rejected_images``, a view that
    disagrees with its image into ``rejected_views``."""
    T_cr: dict[str, Array] = {}
    for im, s in sols.items():
        usable = [x for x in s.values() if x.view.marker_id in T_rm]
        if len(usable) < 2:
            continue
        ip = image_pose(usable, T_rm, options.image_tol_m, math.radians(options.image_tol_deg))
        if ip is None:
            rejected_images[im] = "its markers disagree with each other (no two give the same camera pose)"
            continue
        T_cr[im] = ip.T_cam_robot
        for m in ip.disagree:
            rejected_views[(im, m)] = "pose disagrees with the image's other markers (flip or misread)"
    return T_cr


def _adjust_rejecting(live: list[View], side: Mapping[int, float], T_cr: dict[str, Array], T_rm: dict[int, Array],
                      anchor: int, f_px: float, options: RobotCalOptions, rejected_images: dict[str, str],
                      rejected_views: dict[tuple[str, int], str]) -> tuple[BundleResult, list[View]]:
    """Bundle-adjust the ``live`` views, set aside the views (or whole images) whose corners do not fit,
    and adjust again, up to ten rounds; ``T_cr`` and ``T_rm`` are updated in place. Returns the last
    adjustment and the views in it."""
    lim = float(chi2.isf(options.view_p, 8))
    result: BundleResult | None = None
    for _round in range(10):
        live = _drop_single(live)
        if not live or not ({v.marker_id for v in live} - {anchor}):
            raise InputError("no image keeps two consistent markers: nothing to calibrate")
        result = bundle_adjust(live, side, T_cr, T_rm, anchor, f_px, options.bundle)
        T_rm.update(result.T_robot_marker)
        T_cr.update(dict(zip(result.images, result.T_cam_robot, strict=True)))
        bad = {k for k, c in result.view_chi2.items() if c > lim}
        if not bad:
            break
        _reject_misfits(live, result, bad, lim, options, rejected_images, rejected_views)
        live = [v for v in live if v.image not in rejected_images and (v.image, v.marker_id) not in bad]
    assert result is not None
    return result, live


def _reject_misfits(live: Sequence[View], result: BundleResult, bad: set[tuple[str, int]], lim: float,
                    options: RobotCalOptions, rejected_images: dict[str, str],
                    rejected_views: dict[tuple[str, int], str]) -> None:
    """Record the views ``bad`` (image, ID) whose corners' chi-square exceeds ``lim``: an image with more
    than ``image_bad_fraction`` of its views bad is rejected whole (its views leave ``bad``), the others
    view by view."""
    per_image: dict[str, list[tuple[str, int]]] = {}
    for v in live:
        per_image.setdefault(v.image, []).append((v.image, v.marker_id))
    for im, keys in per_image.items():
        nb = sum(k in bad for k in keys)
        if nb and nb > options.image_bad_fraction * len(keys):
            rejected_images[im] = (f"{nb} of {len(keys)} markers do not fit the adjustment "
                                   f"(chi-square above {lim:.0f})")
            for k in keys:
                bad.discard(k)
        else:
            for k in keys:
                if k in bad:
                    rejected_views[k] = (f"corners do not fit the adjustment (chi-square "
                                         f"{result.view_chi2[k]:.0f} > {lim:.0f}, "
                                         f"RMS {result.view_rms_px[k]:.2f} px)")


def _with_anchor_uncertainty(cov: dict[int, Array], T_robot_marker: Mapping[int, Array], anchor: int,
                             anchor_cov: Array | None) -> tuple[dict[int, Array], dict[int, Array]]:
    """The markers' covariances (6, 6) with the anchor's own uncertainty ``anchor_cov`` propagated into
    them, and without it (relative to the anchor; zero for the anchor)."""
    Ta = T_robot_marker[anchor]
    Ca = np.zeros((6, 6)) if anchor_cov is None else np.asarray(anchor_cov, float)
    calibrated = set(cov)
    cov = dict(cov)
    cov[anchor] = Ca.copy()
    cov_rel = {m: c.copy() for m, c in cov.items()}
    cov_rel[anchor] = np.zeros((6, 6))
    if anchor_cov is not None:
        for m in calibrated:
            A = _anchor_propagation(Ta, T_robot_marker[m])
            cov[m] = cov[m] + A @ Ca @ A.T
    return cov, cov_rel


def _drop_single(views: list[View]) -> list[View]:
    """Keep images with at least two views: one marker alone fixes its image's pose and says nothing about
    where it sits relative to the others."""
    count: dict[str, int] = {}
    for v in views:
        count[v.image] = count.get(v.image, 0) + 1
    return [v for v in views if count[v.image] >= 2]

