"""ChArUco corners refined on their saddles (gtrig.calib.saddle) in a warped, blurred, noisy print."""

from __future__ import annotations

import cv2
import numpy as np

from gtrig.calib.charuco import CharucoBoard, CharucoCornerDetector
from gtrig.calib.saddle import image_noise_grey, local_homographies, refine_saddles

BOARD = CharucoBoard(7, 5, 0.04, 0.03, "DICT_4X4_50")
PX_PER_SQUARE_PRINT = 64


def _warped_view(scale: float, noise: float, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """The board printed at 64 px a square, seen through a homography (``scale`` px per print px near the
    centre), blurred by 0.7 px and with Gaussian noise: the image and its inner corners' true pixels."""
    s = PX_PER_SQUARE_PRINT
    printed = BOARD.opencv_board().generateImage((BOARD.squares_x * s, BOARD.squares_y * s), marginSize=0,
                                                 borderBits=1).astype(np.float64)
    printed = printed * (175 / 255) + 40  # black 40, white 215: the noise never clips
    H = np.array([[scale * 0.95, scale * 0.12, 60.0], [-scale * 0.05, scale * 0.9, 50.0], [2e-5, 1e-4, 1.0]])
    size = (640, 480)
    img = cv2.warpPerspective(printed, H, size, flags=cv2.INTER_AREA, borderValue=215.0)
    img = cv2.GaussianBlur(img, (0, 0), 0.7)
    img += np.random.default_rng(seed).normal(0.0, noise, img.shape)
    # a print pixel's centre is at (i + 0.5) / s squares: corner (c + 1, r + 1) squares is print pixel (c + 1) s - 0.5
    obj = BOARD.object_points()[:, :2] / BOARD.square_m * s - 0.5
    uv = cv2.perspectiveTransform(obj.reshape(-1, 1, 2), H).reshape(-1, 2)
    return np.clip(img, 0, 255).astype(np.uint8), uv


def test_refined_corners_beat_opencvs() -> None:
    """(The covariance against the errors is checked on the simulator's renders, tests/sim/test_sim_charuco.py:
    here the warp's resampling, not the noise, dominates the errors.)"""
    grey, truth = _warped_view(0.6, 2.0)
    det = CharucoCornerDetector(BOARD)
    seen = det.detect(grey)
    assert seen is not None and len(seen.ids) == BOARD.n_corners and seen.cov_px is not None
    corners, ids, _, _ = det._detector.detectBoard(grey)  # OpenCV's own corners, the peer
    cv_err = np.linalg.norm(corners.reshape(-1, 2)[np.argsort(ids.ravel())] - truth, axis=1)
    err = np.linalg.norm(seen.corners_px - truth[seen.ids], axis=1)
    assert np.sqrt(np.mean(err**2)) < 0.5 * np.sqrt(np.mean(cv_err**2)), (err, cv_err)
    assert np.all(np.isfinite(seen.cov_px)) and np.all(np.linalg.eigvalsh(seen.cov_px) > 0)


def test_image_noise_is_measured_beside_edges() -> None:
    grey, _ = _warped_view(0.6, 3.0, seed=1)
    assert 2.4 < image_noise_grey(grey) < 3.6


def test_corners_too_small_for_the_strip_keep_their_seed() -> None:
    grey, truth = _warped_view(0.6, 2.0)
    cols = BOARD.squares_x - 1
    ids = np.arange(BOARD.n_corners)
    H = local_homographies(np.column_stack([ids % cols, ids // cols]).astype(float), truth)
    # a strip of 0.02 squares is under 1 px at 38 px a square: nothing to fit, the seeds stay
    fit = refine_saddles(grey, truth + 0.3, H, 0.02, 0.35)
    assert not fit.ok.any() and np.array_equal(fit.corners_px, truth + 0.3) and np.isnan(fit.cov_px).all()
    fit = refine_saddles(grey, truth + 0.3, H, 0.125, 0.35)
    assert fit.ok.all() and np.abs(fit.corners_px - truth).max() < 0.2  # measured 0.12 px
