"""Markers cut by the image's edge: confirmed at their predicted corners and kept on their corners inside the
image (gtrig.vision.detect.release_unseen_corners), followed by the tracker while three corners are inside."""

from __future__ import annotations

import numpy as np

from gtrig.markers.detect import MarkerDetector
from gtrig.markers.synth import clutter_background, homography_from_pose, render
from gtrig.rig.models import MarkerFamily
from gtrig.vision.detect import UNSEEN_CORNER_SIGMA_PX, measured_corners, release_unseen_corners
from gtrig.vision.observations import MarkerView, views_from_detections
from gtrig.vision.track import CameraTracker, TrackOptions

FAM = MarkerFamily.ARTOOLKITPLUS_SIMPLE


def _cut_scene(seed: int, cut_x: int) -> tuple[np.ndarray, np.ndarray]:
    """A 70 px marker turned by 30 degrees, rendered whole, and the image from column ``cut_x`` on: its
    grey image and the marker's true corners (4, 2) in the cut image's pixels."""
    rng = np.random.default_rng(seed)
    shape = (360, 480)
    bg = clutter_background(shape, rng, n_shapes=12)
    img, truths = render(shape, [(FAM, 7, homography_from_pose(70, (120, 180), 20, 10, 30))], blur_px=0.8,
                         noise=2.0, background=bg, rng=rng)
    return np.ascontiguousarray(img[:, cut_x:]), truths[0].corners_px - np.array([cut_x, 0.0])


def test_a_cut_marker_is_kept_on_its_corners_inside_the_image() -> None:
    # the marker's leftmost corner (near x = 73 whole) is 10 px outside the cut image
    img, truth = _cut_scene(0, cut_x=83)
    h, w = img.shape
    seen = measured_corners(truth, (w, h))
    assert seen.sum() == 3
    det = MarkerDetector(FAM)
    assert det.detect(img) == []  # the peers find no closed outline
    got = det.detect_expected(img, (truth + np.array([1.2, -0.8]))[None], np.array([7]))
    assert [d.id for d in got] == [7]
    view = release_unseen_corners(views_from_detections("cam", got)[0], (w, h))
    assert view is not None
    err = np.linalg.norm(view.corners_px - truth, axis=1)
    # the corners inside the image, whose edges run into it, are measured about as well as a whole marker's
    assert err[seen].max() < 0.15
    # the corner outside is extrapolated from two short edges: it carries no weight, the others keep the fit's
    sig = np.sqrt(np.linalg.eigvalsh(view.corner_cov)[:, 1])
    np.testing.assert_allclose(sig[~seen], UNSEEN_CORNER_SIGMA_PX)
    np.testing.assert_allclose(view.corner_cov[seen], got[0].corner_cov[seen])
    assert np.all(sig[seen] < 0.1)


def test_corners_release_and_refusal() -> None:
    size = (200, 100)
    c = np.array([[-3.0, 40.0], [30.0, 10.0], [60.0, 40.0], [30.0, 70.0]])
    v = MarkerView("cam", 7, c, np.tile(np.eye(2) * 0.01, (4, 1, 1)))
    r = release_unseen_corners(v, size)
    assert r is not None
    np.testing.assert_allclose(np.diag(r.corner_cov[0]), UNSEEN_CORNER_SIGMA_PX**2)
    np.testing.assert_allclose(r.corner_cov[1:], v.corner_cov[1:])
    # a whole marker is returned as it is; one with two corners inside is not kept
    whole = MarkerView("cam", 7, c + np.array([10.0, 0.0]), v.corner_cov)
    assert release_unseen_corners(whole, size) is whole
    assert release_unseen_corners(MarkerView("cam", 7, c - np.array([40.0, 0.0]), v.corner_cov), size) is None
    # a corner less than a pixel inside the image is not measured either (its edges' bands are cut)
    assert measured_corners(c + np.array([3.4, 0.0]), size).tolist() == [False, True, True, True]
    assert measured_corners(c + np.array([3.6, 0.0]), size).all()


def _diamond(cx: float, cy: float, r: float) -> np.ndarray:
    return np.array([[cx - r, cy], [cx, cy - r], [cx + r, cy], [cx, cy + r]])


def test_the_tracker_follows_a_marker_out_of_the_image_while_three_corners_are_inside() -> None:
    n = 6
    images = [np.full((768, 1024), 90, np.uint8) for _ in range(n)]  # distinct arrays, nothing to find
    truth = [_diamond(40.0 - 8.0 * k, 300.0, 30.0) for k in range(n)]  # leaving to the left
    inside = [int(measured_corners(t, (1024, 768)).sum()) for t in truth]
    assert inside == [4, 4, 3, 3, 3, 1]
    asked: list[int] = []

    def detect(image: np.ndarray, box: tuple[int, int, int, int] | None) -> list[MarkerView]:
        k = next(i for i, im in enumerate(images) if im is image)
        return [MarkerView("cam", 7, truth[k], np.tile(np.eye(2) * 0.01, (4, 1, 1)))] if inside[k] == 4 else []

    def expect(image: np.ndarray, predicted: list[tuple[int, np.ndarray]]) -> list[MarkerView]:
        k = next(i for i, im in enumerate(images) if im is image)
        asked.append(k)
        return [MarkerView("cam", m, truth[k], np.tile(np.eye(2) * 0.01, (4, 1, 1))) for m, c in predicted
                if np.abs(c - truth[k]).max() < 3.0]

    tk = CameraTracker(detect, (1024, 768), TrackOptions(), expect)
    got = [tk.step(img, 0.1 * k) for k, img in enumerate(images)]
    # confirmed while its prediction has three corners 2 px inside; the last one, with one, is not asked for
    assert [len(g) for g in got] == [1] * 5 + [0]
    assert all(np.allclose(g[0].corners_px, truth[k]) for k, g in enumerate(got) if g)
    assert asked == [2, 3, 4] and tk.stats.confirmed == 3
    # a cut marker missing does not make the image searched whole (only the start is)
    assert tk.stats.lost == 0 and tk.stats.whole == 1


def test_the_second_start_band_ends_before_the_surround_of_a_narrow_margin() -> None:
    from gtrig.markers.detect import DetectorParams
    from gtrig.vision.detect import RETRY_BAND_PX

    # a marker printed with a one-cell white margin on a light grey surround (reflectance 0.75), sharp
    # (blur 0.3 px), refitted from corners within half a pixel, as the second start does
    rng = np.random.default_rng(0)
    img, truths = render((300, 400), [(FAM, 30, homography_from_pose(62, (200, 150), 30, 20, 15))], blur_px=0.3,
                         noise=2.0, quiet_cells=1.0, background=np.full((300, 400), 0.75), rng=rng)
    t = truths[0].corners_px
    start = (t + np.array([[0.4, -0.3], [-0.2, 0.4], [0.3, 0.3], [-0.4, -0.2]]))[None]
    rms = {}
    for band in (RETRY_BAND_PX, DetectorParams().band_px):
        got = MarkerDetector(FAM, params=DetectorParams(band_px=band)).detect_expected(img, start, np.array([30]))
        assert [d.id for d in got] == [30]
        rms[band] = float(np.sqrt(np.mean(np.sum((got[0].corners_px - t) ** 2, axis=1))))
    # the default band reaches past the margin into the surround and moves the lines by a few hundredths of
    # a pixel; the second start's band stays on the margin
    assert rms[RETRY_BAND_PX] < 0.02 and rms[DetectorParams().band_px] > 2 * rms[RETRY_BAND_PX]
