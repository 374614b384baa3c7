"""A lens's uncertainty from its views' scatter: the delete-one-view and the delete-one-time-block jackknife.

OpenCV's stated standard deviations (``calibrateCameraExtended``) treat every corner as an independent
measurement with the fit's mean residual variance. A hand-held board's corner errors are not independent
within a view: motion blur and a rolling shutter bend the whole view, the board is not quite flat, the
detector's bias depends on the view's tilt. Such errors are common to a view's corners and average out only
over views, so a lens from 13-29 views of a 12-corner board is less certain than the corner count says.
Refitting the lens without each view in turn measures that: with ``theta_i`` the fit without view ``i`` of
``n``, the jackknife variance is ``(n - 1) / n * sum (theta_i - mean theta)^2`` (Efron and Stein 1981), whose
expectation is at least the true variance for smooth estimators, whatever the errors' correlation within a
view.

Neither holds when neighbouring views share their errors. A video's frames a sixth of a second apart see
the board in nearly the same pose, blurred the same way, and a webcam's autofocus may move its lens between
them: on real webcams the focal length fitted to each single view (principal point and distortion held)
is correlated from frame to frame up to 0.5-1.5 s apart. Deleting one view then leaves its correlated
neighbours in, and the single-view jackknife is as optimistic as OpenCV's sigmas. Deleting contiguous time
blocks longer than that correlation (Kuensch 1989) keeps the blocks nearly independent: the same formula
with the ``g`` block-deleted fits in place of the ``n`` view-deleted ones.
"""

from __future__ import annotations

from collections.abc import Sequence

import cv2
import numpy as np

from gtrig.calib.intrinsics import STD_NAMES
from gtrig.errors import ConvergenceError
from gtrig.io.camfile import CameraIntrinsics

#: fewer groups than this give no jackknife deviation (NaN): three refits say little about a spread
MIN_GROUPS = 4


def time_blocks(stamps_s: np.ndarray, block_s: float) -> list[list[int]]:
    """The views grouped into consecutive time blocks of ``block_s`` seconds from the first view.

    Parameters
    ----------
    stamps_s : (V,) the views' frame times, seconds (any order).
    block_s : the blocks' duration, seconds (> 0).

    Returns
    -------
    The non-empty blocks in time order, each a list of indices into ``stamps_s``.
    """
    t = np.asarray(stamps_s, dtype=float)
    if t.size == 0:
        return []
    b = np.floor((t - t.min()) / block_s).astype(int)
    return [np.flatnonzero(b == u).tolist() for u in np.unique(b)]


def group_jackknife_std(object_points: Sequence[np.ndarray], image_points: Sequence[np.ndarray],
                        lens: CameraIntrinsics, groups: Sequence[Sequence[int]], *,
                        estimate_k3: bool = False) -> dict[str, float]:
    """Each lens parameter's delete-one-group jackknife standard deviation (module docstring).

    Parameters
    ----------
    object_points, image_points : the views the lens was fitted to, (N_i, 3) board metres and (N_i, 2) pixels.
    lens : the fit of all views (each refit starts from it).
    groups : disjoint lists of view indices covering the views; each refit leaves one group out.
    estimate_k3 : as in the fit (else k3 is held and its deviation is 0).

    Returns
    -------
    {name: sigma} for ``fx fy cx cy`` (pixels) and ``k1 k2 p1 p2 k3``; NaN for fewer than
    :data:`MIN_GROUPS` groups.
    """
    g = len(groups)
    if g < MIN_GROUPS:
        return {k: float("nan") for k in STD_NAMES}
    obj = [np.asarray(p, np.float32).reshape(-1, 3) for p in object_points]
    img = [np.asarray(p, np.float32).reshape(-1, 1, 2) for p in image_points]
    flags = cv2.CALIB_USE_INTRINSIC_GUESS | (0 if estimate_k3 else cv2.CALIB_FIX_K3)
    d0 = np.zeros(5)
    d0[: min(5, lens.dist_coeffs.size)] = lens.dist_coeffs.ravel()[:5]
    crit = (cv2.TERM_CRITERIA_COUNT + cv2.TERM_CRITERIA_EPS, 200, 1e-12)
    thetas = []
    threads = cv2.getNumThreads()
    cv2.setNumThreads(1)  # one summation order: the same digits on every run (as the lens's own fit)
    try:
        for out in groups:
            drop = set(out)
            keep = [k for k in range(len(obj)) if k not in drop]
            _rms, K, dist, _r, _t = cv2.calibrateCamera([obj[k] for k in keep], [img[k] for k in keep],
                                                        lens.image_size, lens.camera_matrix.copy(), d0.copy(),
                                                        flags=flags, criteria=crit)
            thetas.append(np.r_[K[0, 0], K[1, 1], K[0, 2], K[1, 2], np.ravel(dist)[:5]])
    except cv2.error as e:
        raise ConvergenceError(f"OpenCV calibration without some views failed: "
                               f"{str(e).splitlines()[-1].strip()}") from None
    finally:
        cv2.setNumThreads(threads)
    th = np.array(thetas)
    var = (g - 1) / g * np.sum((th - th.mean(axis=0)) ** 2, axis=0)
    return {k: float(np.sqrt(v)) for k, v in zip(STD_NAMES, var, strict=True)}


def view_jackknife_std(object_points: Sequence[np.ndarray], image_points: Sequence[np.ndarray],
                       lens: CameraIntrinsics, *, estimate_k3: bool = False) -> dict[str, float]:
    """Each lens parameter's delete-one-view jackknife standard deviation (:func:`group_jackknife_std` with
    one view per group); NaN for fewer than 4 views."""
    return group_jackknife_std(object_points, image_points, lens, [[k] for k in range(len(object_points))],
                               estimate_k3=estimate_k3)


def block_jackknife_std(object_points: Sequence[np.ndarray], image_points: Sequence[np.ndarray],
                        lens: CameraIntrinsics, stamps_s: np.ndarray, block_s: float, *,
                        estimate_k3: bool = False) -> dict[str, float]:
    """Each lens parameter's delete-one-time-block jackknife standard deviation: :func:`group_jackknife_std`
    over :func:`time_blocks` of ``block_s`` seconds (``stamps_s``: (V,) the views' frame times, seconds)."""
    return group_jackknife_std(object_points, image_points, lens, time_blocks(stamps_s, block_s),
                               estimate_k3=estimate_k3)
