"""A camera's intrinsics from a folder of images of a board with corner IDs (a ChArUco board or an
AprilGrid), with its views for the network's bundle adjustment.

The intrinsic sweeps of a recording (``calib/intrinsics/<cam>/``) may show such a board instead of the
chessboard (``sweep_board:`` in ``calib/boards.yaml``): every image's corners are found with
:func:`gtrig.calib.idboards.corner_detector`, views with at least :data:`MIN_SWEEP_CORNERS` corners
calibrate the lens (:func:`gtrig.calib.intrinsics.calibrate_point_sets`, Zhang's method with its outlier
rule), and each kept view becomes a :class:`gtrig.calib.network.SweepView` carrying its corners' board
points, so that the network refines the lens from the sweep as it does from a chessboard's.
"""

from __future__ import annotations

import logging
import os
from dataclasses import dataclass
from pathlib import Path

from gtrig.calib.charuco import CharucoView
from gtrig.calib.chessboard import list_images, read_grey
from gtrig.calib.idboards import IdBoard, corner_detector
from gtrig.calib.intrinsics import MIN_VIEWS, PointSetFit, calibrate_point_sets
from gtrig.calib.network import SweepView
from gtrig.errors import InputError
from gtrig.io.camfile import CameraIntrinsics, read_cam_yaml

log = logging.getLogger(__name__)

#: a view enters the lens's calibration with this many corners or more
MIN_SWEEP_CORNERS = 6


@dataclass(frozen=True)
class IdSweep:
    """One camera's sweep of a board with corner IDs, calibrated.

    Attributes
    ----------
    camera : the lens (``extra``: ``std``, ``per_view_rms_px``, ``rejected``, ``views_used``, ``warnings``).
    views : the kept views, in the board's frame (:mod:`gtrig.calib.charuco`), with their poses.
    fit : the point-set calibration it came from.
    missing : the images with fewer than :data:`MIN_SWEEP_CORNERS` corners.
    """

    camera: CameraIntrinsics
    views: tuple[SweepView, ...]
    fit: PointSetFit
    missing: tuple[str, ...]


def detect_id_folder(folder: str | os.PathLike[str], board: IdBoard
                          ) -> tuple[tuple[int, int], dict[str, CharucoView], list[str]]:
    """The board's corners in every image of ``folder``: the image size (w, h), the views with at least
    :data:`MIN_SWEEP_CORNERS` corners by file name, and the names of the others.

    Raises
    ------
    InputError
        Mixed resolutions.
    """
    detector = corner_detector(board)
    size: tuple[int, int] | None = None
    views: dict[str, CharucoView] = {}
    missing: list[str] = []
    for p in list_images(folder):
        grey = read_grey(p)
        s = (int(grey.shape[1]), int(grey.shape[0]))
        if size is not None and s != size:
            raise InputError(f"{p}: mixed resolutions: {s[0]} x {s[1]}, the folder's first image is "
                             f"{size[0]} x {size[1]}")
        size = s
        v = detector.detect(grey, MIN_SWEEP_CORNERS)
        if v is None:
            missing.append(p.name)
        else:
            views[p.name] = v
    assert size is not None  # list_images raises on an empty folder
    return size, views, missing


def calibrate_id_folder(folder: str | os.PathLike[str], board: IdBoard, *, camera: str,
                             estimate_k3: bool = False) -> IdSweep:
    """Calibrate ``camera``'s lens from its images of ``board`` in ``folder`` (module docstring).

    Raises
    ------
    InputError
        Fewer than :data:`gtrig.calib.intrinsics.MIN_VIEWS` images with the board.
    """
    d = Path(folder)
    size, views, missing = detect_id_folder(d, board)
    if len(views) < MIN_VIEWS:
        raise InputError(f"{d}: too few views: the {board.spec()} was found in {len(views)} of "
                         f"{len(views) + len(missing)} image(s), need {MIN_VIEWS}")
    P = board.object_points()
    names = sorted(views)
    fit = calibrate_point_sets([P[views[n].ids] for n in names], [views[n].corners_px for n in names], names,
                               size, estimate_k3=estimate_k3)
    warnings = []
    if missing:
        warnings.append(f"camera {camera}: no board in {len(missing)} image(s): {', '.join(missing[:5])}"
                        + (" ..." if len(missing) > 5 else ""))
        log.warning(warnings[-1])
    lens = fit.camera
    extra = dict(lens.extra) | {"warnings": warnings, "board": board.spec()}
    cam = CameraIntrinsics(lens.image_size, lens.camera_matrix, lens.dist_coeffs, lens.rms_px, extra)
    sweep = tuple(SweepView(camera, n, views[n].corners_px, T, P[views[n].ids])
                  for n, T in zip(fit.names, fit.T_cam_board, strict=True))
    log.info("camera %s: lens from %d views of the %s, RMS %.3f px", camera, len(sweep), board.spec(), lens.rms_px)
    return IdSweep(cam, sweep, fit, tuple(missing))


def load_id_intrinsics(source: str | os.PathLike[str], cameras: list[str], board: IdBoard, *,
                            estimate_k3: bool = False) -> tuple[dict[str, CameraIntrinsics], list[SweepView]]:
    """Intrinsics per camera from ``source``: ``<cam>.yaml`` files, or ``<cam>/`` folders of images of ``board``
    calibrated here; with the calibrated cameras' sweep views. Cameras with neither are left out.

    Raises
    ------
    InputError
        No camera has either; a folder with too few views.
    """
    root = Path(source)
    if not root.is_dir():
        raise InputError(f"{root}: no such folder")
    lenses: dict[str, CameraIntrinsics] = {}
    views: list[SweepView] = []
    for c in cameras:
        f = root / f"{c}.yaml"
        if f.is_file():
            lenses[c] = read_cam_yaml(f)
        elif (root / c).is_dir():
            sweep = calibrate_id_folder(root / c, board, camera=c, estimate_k3=estimate_k3)
            lenses[c] = sweep.camera
            views += sweep.views
    if not lenses:
        raise InputError(f"{root}: no <cam>.yaml and no <cam>/ image folder for any of {', '.join(cameras)}")
    return lenses, views
