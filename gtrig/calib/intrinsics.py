"""Single-camera intrinsic calibration from chessboard views.

Zhang's method ("A flexible new technique for camera calibration", PAMI 2000) as implemented by
``cv2.calibrateCameraExtended``, which also returns the parameters' standard deviations and the
per-view reprojection errors. Like the seeds' tool (Bouguet's Camera Calibration Toolbox, whose default
estimates k1, k2, p1, p2 only), the sixth-order radial term k3 is fixed at 0 unless asked for.

Outlier views (a mis-ordered grid, motion blur, a bent board) are rejected one at a time, worst first,
while a view's RMS exceeds both 3 x the median view RMS and the median + 5 robust sigmas (1.4826 MAD),
and is above ``min_reject_px``; each rejected image is named in a warning. Coverage is the fraction of the
image covered by the union of the boards' outlines; view variety is the spread of the boards' tilts
(angle between the board normal and the optical axis): parallel views leave the focal length unobservable.
"""

from __future__ import annotations

import logging
import os
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np

from gtrig import geometry as geo
from gtrig.calib.chessboard import Board, Detection, detect_folder
from gtrig.errors import ConvergenceError, InputError
from gtrig.io.camfile import CameraIntrinsics

log = logging.getLogger(__name__)

MIN_VIEWS = 3
COVERAGE_WARN = 0.5  # fraction of the image
TILT_WARN_DEG = 15.0  # at least two views tilted more than this, and this much spread
# A principal point this uncertain (1 sigma, px) turns the camera by about sigma / f rad and cannot
# promise the 0.5 px the network needs; with a narrow lens it is tied to the tangential distortion and
# only many views pin it (docs/calibration.md, "Measured on the simulator").
PP_SIGMA_WARN_PX = 0.25
STD_NAMES = ("fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2", "k3")


@dataclass(frozen=True)
class IntrinsicsResult:
    """The outcome of :func:`calibrate_intrinsics`.

    Attributes
    ----------
    camera : the calibration, with ``extra`` holding std, per-image RMS, rejections, coverage, tilts.
    views : detections used in the final solution.
    T_cam_board : (V, 4, 4) pose of the board in each used view (metres).
    per_image_rms_px : {file: RMS reprojection error in pixels} of the used views.
    rejected : {file: reason} (no board found, outlier).
    coverage : fraction of the image covered by board outlines (0..1).
    tilt_deg : (V,) angle between each board's normal and the optical axis.
    warnings : human-readable warnings (also logged).
    """

    camera: CameraIntrinsics
    views: tuple[Detection, ...]
    T_cam_board: np.ndarray
    per_image_rms_px: dict[str, float]
    rejected: dict[str, str]
    coverage: float
    tilt_deg: np.ndarray
    warnings: tuple[str, ...] = field(default=())

    @property
    def std(self) -> dict[str, float]:
        return dict(self.camera.extra.get("std", {}))


def coverage_fraction(views: Sequence[np.ndarray], image_size: tuple[int, int], board: Board) -> float:
    """Fraction of the image inside at least one board's outline of outer inner corners."""
    w, h = image_size
    s = 8.0
    mask = np.zeros((int(np.ceil(h / s)), int(np.ceil(w / s))), np.uint8)
    for c in views:
        g = np.asarray(c).reshape(board.rows, board.cols, 2)
        poly = np.array([g[0, 0], g[0, -1], g[-1, -1], g[-1, 0]]) / s
        cv2.fillConvexPoly(mask, np.round(poly * 16).astype(np.int32), 1, shift=4)
    return float(mask.mean())


def _run(
    obj: list[np.ndarray], img: list[np.ndarray], size: tuple[int, int], flags: int, K0: np.ndarray | None
) -> tuple:
    crit = (cv2.TERM_CRITERIA_COUNT + cv2.TERM_CRITERIA_EPS, 200, 1e-12)
    # OpenCV's threads sum the views' normal equations in whatever order they finish: the lens then
    # differs in the ninth digit from run to run, which changes every later output and invalidates
    # GTvision's detection checkpoints; one thread costs nothing measurable here (7.5 s either way)
    threads = cv2.getNumThreads()
    cv2.setNumThreads(1)
    try:
        return cv2.calibrateCameraExtended(obj, img, size, K0, None, flags=flags, criteria=crit)  # type: ignore[call-overload]  # stubs: no None for K0
    except cv2.error as e:
        raise ConvergenceError(f"OpenCV calibration failed: {str(e).splitlines()[-1].strip()}") from None
    finally:
        cv2.setNumThreads(threads)


def calibrate_views(
    views: Sequence[Detection],
    board: Board,
    image_size: tuple[int, int],
    *,
    estimate_k3: bool = False,
    min_reject_px: float = 0.15,
    camera_matrix_guess: np.ndarray | None = None,
    rejected: dict[str, str] | None = None,
    subject: str = "",
) -> IntrinsicsResult:
    """Calibrate from detections already made (see :func:`calibrate_intrinsics`); every warning starts
    with ``subject`` (the camera or its folder) when given."""
    at = f"{subject}: " if subject else ""
    rejected = dict(rejected or {})
    views = list(views)
    if len(views) < MIN_VIEWS:
        raise InputError(
            f"too few views: {len(views)} image(s) with a board, need at least {MIN_VIEWS} "
            f"(tilted in different directions)"
        )
    flags = 0 if estimate_k3 else cv2.CALIB_FIX_K3
    K0 = None
    if camera_matrix_guess is not None:
        flags |= cv2.CALIB_USE_INTRINSIC_GUESS
        K0 = np.asarray(camera_matrix_guess, dtype=float).copy()
    P = board.object_points().astype(np.float32)
    warnings: list[str] = []
    while True:
        obj = [P] * len(views)
        img = [v.corners_px.astype(np.float32).reshape(-1, 1, 2) for v in views]
        rms, K, dist, rvecs, tvecs, std_int, _std_ext, per_view = _run(obj, img, image_size, flags, K0)
        e = np.asarray(per_view, dtype=float).ravel()
        med = float(np.median(e))
        mad = float(np.median(np.abs(e - med))) * 1.4826
        thr = max(3.0 * med, med + 5.0 * mad, min_reject_px)
        worst = int(np.argmax(e))
        if e[worst] <= thr or len(views) <= MIN_VIEWS:
            break
        name = views[worst].file
        rejected[name] = f"outlier: {e[worst]:.3f} px RMS (median {med:.3f} px)"
        msg = f"{at}rejected {name}: reprojection RMS {e[worst]:.3f} px, {e[worst] / med:.1f} x the median"
        log.warning(msg)
        warnings.append(msg)
        del views[worst]
    Ts = np.array([geo.make_T(cv2.Rodrigues(r)[0], t.ravel()) for r, t in zip(rvecs, tvecs, strict=True)])
    tilt = np.degrees(np.arccos(np.clip(np.abs(Ts[:, 2, 2]), 0, 1)))
    cover = coverage_fraction([v.corners_px for v in views], image_size, board)
    n_rej = len(warnings)
    if cover < COVERAGE_WARN:
        warnings.append(
            f"{at}poor coverage: the boards cover {100 * cover:.0f} % of the image; "
            "add views with the board near the image edges and corners"
        )
    normals = Ts[:, :3, 2]
    spread = float(np.degrees(np.max(np.arccos(np.clip(normals @ normals.T, -1, 1)))))
    if np.sum(tilt > TILT_WARN_DEG) < 2 or spread < TILT_WARN_DEG:
        warnings.append(
            f"{at}poor view variety: tilts {tilt.min():.0f}-{tilt.max():.0f} deg, normals spread "
            f"{spread:.0f} deg; tilt the board by 20-45 deg in different directions"
        )
    std = {n: float(s) for n, s in zip(STD_NAMES, np.asarray(std_int, dtype=float).ravel(), strict=False)}
    if max(std.get("cx", 0.0), std.get("cy", 0.0)) > PP_SIGMA_WARN_PX:
        warnings.append(
            f"{at}imprecise principal point: sigma cx {std['cx']:.2f} px, cy {std['cy']:.2f} px from "
            f"{len(views)} views; add views (a video sweep gives a hundred) with the board near the image "
            "corners"
        )
    for w_ in warnings[n_rej:]:
        log.warning(w_)
    dist = np.asarray(dist, dtype=float).ravel()[:5]
    if not estimate_k3:
        std["k3"] = 0.0
    per = {v.file: float(x) for v, x in zip(views, np.asarray(per_view).ravel(), strict=True)}
    extra = {
        "std": std,
        "per_image_rms_px": per,
        "rejected": rejected,
        "board": {"inner_corners": [board.cols, board.rows], "square_m": board.square_m},
        "views_used": len(views),
        "coverage": round(cover, 4),
        "tilt_deg": {"min": float(tilt.min()), "max": float(tilt.max()), "normals_spread": spread},
        "warnings": list(warnings),
    }
    cam = CameraIntrinsics(image_size, np.asarray(K, dtype=float), dist, float(rms), extra)
    return IntrinsicsResult(cam, tuple(views), Ts, per, rejected, cover, tilt, tuple(warnings))


def calibrate_intrinsics(
    images: str | os.PathLike[str] | Sequence[Path],
    board: Board,
    *,
    estimate_k3: bool = False,
    min_reject_px: float = 0.15,
    camera: str | None = None,
) -> IntrinsicsResult:
    """Calibrate one camera from a folder (or a list) of chessboard images.

    Parameters
    ----------
    images
        A folder of JPEG/PNG/... images of one camera (any size, colour or grey), or a list of files.
    board
        The chessboard (inner corners, square size in metres).
    estimate_k3
        Also estimate the sixth-order radial coefficient (wide-angle lenses, many views).
    min_reject_px
        Views below this RMS are never rejected as outliers.
    camera
        The camera's name: its warnings start with ``camera NAME``, else with the images' folder.

    Raises
    ------
    InputError
        No board in any image, mixed resolutions, fewer than 3 usable views.
    """
    if isinstance(images, str | os.PathLike):
        det = detect_folder(images, board)
    else:
        files = list(images)
        det = detect_folder(files[0].parent if files else Path("."), board, files)
    rejected = {m: "no board found" for m in det.missing}
    subject = f"camera {camera}" if camera else str(det.folder)
    for m in det.missing:
        log.warning("%s: no %dx%d board found, image skipped", m, board.cols, board.rows)
    if len(det.found) < MIN_VIEWS:
        raise InputError(
            f"{det.folder}: too few views: a {board.cols}x{board.rows} board was found in "
            f"{len(det.found)} of {len(det.found) + len(det.missing)} image(s), need {MIN_VIEWS}"
        )
    res = calibrate_views(
        det.found,
        board,
        det.image_size,
        estimate_k3=estimate_k3,
        min_reject_px=min_reject_px,
        rejected=rejected,
        subject=subject,
    )
    if det.missing:
        msg = f"{subject}: no board in {len(det.missing)} image(s): {', '.join(det.missing[:5])}" + (
            " ..." if len(det.missing) > 5 else ""
        )
        cam = res.camera
        extra = dict(cam.extra)
        extra["warnings"] = [msg, *extra["warnings"]]
        res = IntrinsicsResult(
            CameraIntrinsics(cam.image_size, cam.camera_matrix, cam.dist_coeffs, cam.rms_px, extra),
            res.views,
            res.T_cam_board,
            res.per_image_rms_px,
            res.rejected,
            res.coverage,
            res.tilt_deg,
            (msg, *res.warnings),
        )
    return res


@dataclass(frozen=True)
class PointSetFit:
    """The outcome of :func:`calibrate_point_sets`.

    Attributes
    ----------
    camera : the calibration; ``extra`` holds ``std`` (each parameter's standard deviation, pixels for
        fx fy cx cy), ``per_view_rms_px``, ``rejected`` and ``views_used``.
    names : (V,) the names of the views used.
    T_cam_board : (V, 4, 4) the board's pose in each used view (metres).
    per_view_rms_px : (V,) reprojection RMS of each used view, pixels.
    rejected : {name: reason} of the outlier views.
    """

    camera: CameraIntrinsics
    names: tuple[str, ...]
    T_cam_board: np.ndarray
    per_view_rms_px: np.ndarray
    rejected: dict[str, str]

    @property
    def std(self) -> dict[str, float]:
        return dict(self.camera.extra.get("std", {}))


def calibrate_point_sets(
    object_points: Sequence[np.ndarray],
    image_points: Sequence[np.ndarray],
    names: Sequence[str],
    image_size: tuple[int, int],
    *,
    estimate_k3: bool = False,
    min_reject_px: float = 0.15,
) -> PointSetFit:
    """Calibrate one camera from views of any planar target with partial corner sets (a ChArUco board).

    Zhang's method with the outlier rule of :func:`calibrate_views` (module docstring).

    Parameters
    ----------
    object_points : (V,) arrays (N_i, 3), the corners seen in view i in the board frame, metres (z = 0).
    image_points : (V,) arrays (N_i, 2), their pixels.
    names : (V,) a name per view, for the messages.
    image_size : (w, h) pixels.

    Raises
    ------
    InputError
        Fewer than 3 views. ConvergenceError: OpenCV's calibration fails.
    """
    obj = [np.asarray(p, dtype=np.float32).reshape(-1, 3) for p in object_points]
    img = [np.asarray(p, dtype=np.float32).reshape(-1, 1, 2) for p in image_points]
    keep = list(range(len(obj)))
    if len(keep) < MIN_VIEWS:
        raise InputError(f"too few views: {len(keep)} with the board, need at least {MIN_VIEWS}")
    flags = 0 if estimate_k3 else cv2.CALIB_FIX_K3
    rejected: dict[str, str] = {}
    while True:
        rms, K, dist, rvecs, tvecs, std_int, _std_ext, per_view = _run(
            [obj[i] for i in keep], [img[i] for i in keep], image_size, flags, None
        )
        e = np.asarray(per_view, dtype=float).ravel()
        med = float(np.median(e))
        thr = max(3.0 * med, med + 5.0 * 1.4826 * float(np.median(np.abs(e - med))), min_reject_px)
        worst = int(np.argmax(e))
        if e[worst] <= thr or len(keep) <= MIN_VIEWS:
            break
        rejected[names[keep[worst]]] = f"outlier: {e[worst]:.3f} px RMS (median {med:.3f} px)"
        log.warning("rejected %s: reprojection RMS %.3f px, %.1f x the median", names[keep[worst]], e[worst],
                    e[worst] / med)
        del keep[worst]
    Ts = np.array([geo.make_T(cv2.Rodrigues(r)[0], t.ravel()) for r, t in zip(rvecs, tvecs, strict=True)])
    std = {n: float(s) for n, s in zip(STD_NAMES, np.asarray(std_int, dtype=float).ravel(), strict=False)}
    if not estimate_k3:
        std["k3"] = 0.0
    used = tuple(names[i] for i in keep)
    extra = {"std": std, "per_view_rms_px": dict(zip(used, e.tolist(), strict=True)), "rejected": rejected,
             "views_used": len(keep)}
    cam = CameraIntrinsics(image_size, np.asarray(K, dtype=float), np.asarray(dist, dtype=float).ravel()[:5],
                           float(rms), extra)
    return PointSetFit(cam, used, Ts, e, rejected)
