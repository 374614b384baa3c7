"""Markers tracked from image to image (gtrig.vision.track): where each image is searched, and GTvision with
tracking on against every image searched whole on a short rendered run."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest
from vision_synth import write_rendered_run

from gtrig import geometry as geo
from gtrig.errors import InputError
from gtrig.rig.models import Rig
from gtrig.sim.gtroom import VALIDATION_POSES, make_scene
from gtrig.vision.observations import MarkerView
from gtrig.vision.sequence import run_recording
from gtrig.vision.track import CameraTracker, TrackOptions, cell_means, predict_marker, window_for

FRAMES = 8
RATE_HZ = 10.0


def _square(cx: float, cy: float, side: float) -> np.ndarray:
    h = side / 2
    return np.array([[cx - h, cy - h], [cx + h, cy - h], [cx + h, cy + h], [cx - h, cy + h]])


def test_prediction_moves_a_marker_on_at_its_velocity() -> None:
    c2, c1 = _square(100, 200, 40), _square(110, 205, 40)
    c, box = predict_marker((0.1, c1), (0.0, c2), 0.2, TrackOptions(margin_px=5, motion_margin=1, size_margin=0.5))
    np.testing.assert_allclose(c, _square(120, 210, 40))
    # grown by 5 + |(10, 5)| + 20 around both the last and the predicted square
    m = 5 + np.hypot(10, 5) + 20
    np.testing.assert_allclose(box, (90 - m, 185 - m, 140 + m, 230 + m))


def test_windows_hold_the_region_at_fixed_places() -> None:
    size = (1024, 768)
    w = window_for((300.0, 200.0, 400.0, 290.0), size, (256, 384, 512))
    assert w == (256, 192, 512, 448)  # the smallest side, at a multiple of a quarter of it
    w = window_for((900.0, 700.0, 1100.0, 800.0), size, (256, 384, 512))
    assert w == (768, 512, 1024, 768)  # against the image's far edges
    assert window_for((-50.0, -50.0, -1.0, 10.0), size, (256,)) is None  # outside the image
    assert window_for((0.0, 0.0, 600.0, 100.0), size, (256, 384, 512)) == ()  # fits in none


def test_cell_means_are_the_area_resize_of_the_image() -> None:
    rng = np.random.default_rng(2)
    for shape, cell in (((768, 1024), 16), ((48, 80), 16), ((40, 24), 8), ((50, 70), 16), ((45, 60), 15)):
        img = rng.integers(0, 256, shape).astype(np.uint8)
        want = cv2.resize(img.astype(np.float32), (shape[1] // cell, shape[0] // cell), interpolation=cv2.INTER_AREA)
        np.testing.assert_array_equal(cell_means(img, cell), want)
    colour = rng.integers(0, 256, (32, 48, 3)).astype(np.uint8)
    np.testing.assert_allclose(cell_means(colour, 16), cv2.resize(colour.mean(axis=2).astype(np.float32), (3, 2),
                                                                  interpolation=cv2.INTER_AREA), rtol=1e-6)


class _Scripted:
    """A detector that returns given markers (id: corners) per image, those inside the box it is given, and
    records ``(image, box)`` of every call."""

    def __init__(self, per_image: list[dict[int, np.ndarray]]) -> None:
        self.per_image, self.k = per_image, -1
        self.calls: list[tuple[int, tuple[int, int, int, int] | None]] = []

    def __call__(self, image: np.ndarray, box: tuple[int, int, int, int] | None) -> list[MarkerView]:
        self.calls.append((self.k, box))
        out = []
        for mid, c in self.per_image[self.k].items():
            inside = box is None or (c[:, 0].min() >= box[0] and c[:, 1].min() >= box[1]
                                     and c[:, 0].max() < box[2] and c[:, 1].max() < box[3])
            if inside:
                out.append(MarkerView("cam", mid, c, np.tile(np.eye(2) * 0.01, (4, 1, 1))))
        return out

    def whole(self) -> list[int]:
        return sorted({k for k, b in self.calls if b is None})


def _run(tracker: CameraTracker, det: _Scripted, images: list[np.ndarray], stamps: list[float]
         ) -> list[list[MarkerView]]:
    out = []
    for img, t in zip(images, stamps, strict=True):
        det.k += 1
        out.append(tracker.step(img, t))
    return out


def test_tracker_searches_whole_at_start_on_loss_and_once_a_second() -> None:
    rng = np.random.default_rng(0)
    n = 20
    background = rng.normal(90, 2, (768, 1024)).clip(0, 255).astype(np.uint8)
    images, per_image = [], []
    for k in range(n):
        img = background.copy()
        img[280:321, 280 + 4 * k:321 + 4 * k] = 20  # the marker's dark square moves with it
        images.append(img)
        # the marker vanishes from the detector's sight at image 6 (an occlusion)
        per_image.append({} if k == 6 else {7: _square(300 + 4 * k, 300, 40)})
    stamps = [0.1 * k for k in range(n)]
    det = _Scripted(per_image)
    got = _run(CameraTracker(det, (1024, 768), TrackOptions()), det, images, stamps)
    assert [len(v) for v in got] == [0 if k == 6 else 1 for k in range(n)]
    # whole: the start, image 6 (the tracked marker missing from its window), and a second after it; image 7
    # (nothing tracked) is searched where the image changed, and finds the marker again
    assert det.whole() == [0, 6, 16]
    assert [b is None for k, b in det.calls if k == 6] == [False, True]
    windows = [b for _, b in det.calls if b is not None]
    assert len(windows) == n - 2 and all(b[2] - b[0] <= 256 and b[3] - b[1] <= 256 for b in windows)
    # a static scene without markers: searched whole once a second, never in between
    det = _Scripted([{}] * n)
    tk = CameraTracker(det, (1024, 768), TrackOptions())
    _run(tk, det, [background] * n, stamps)
    assert det.whole() == [0, 10] and len(det.calls) == 2 and tk.stats.skipped == n - 2
    # tracking off: every image whole
    det = _Scripted(per_image)
    _run(CameraTracker(det, (1024, 768), TrackOptions(enabled=False)), det, images, stamps)
    assert det.calls == [(k, None) for k in range(n)]


def test_a_tracked_marker_the_peers_miss_is_confirmed_at_its_prediction() -> None:
    rng = np.random.default_rng(1)
    n = 12
    background = rng.normal(90, 2, (768, 1024)).clip(0, 255).astype(np.uint8)
    images, per_image, truth = [], [], []
    for k in range(n):
        img = background.copy()
        img[280:321, 280 + 4 * k:321 + 4 * k] = 20
        images.append(img)
        truth.append(_square(300 + 4 * k, 300, 40))
        # the detector misses the marker in images 4-6 (a motion blur), and marker 9 never was there
        per_image.append({} if 4 <= k <= 6 else {7: truth[k]})
    asked: list[tuple[int, list[int]]] = []

    def expect(image: np.ndarray, predicted: list[tuple[int, np.ndarray]]) -> list[MarkerView]:
        k = next(i for i, im in enumerate(images) if im is image)
        asked.append((k, [m for m, _ in predicted]))
        # confirmed where the prediction is within 3 px of the marker (the edge fit's reach)
        return [MarkerView("cam", m, truth[k], np.tile(np.eye(2) * 0.01, (4, 1, 1))) for m, c in predicted
                if m == 7 and np.abs(c - truth[k]).max() < 3.0]

    det = _Scripted(per_image)
    tk = CameraTracker(det, (1024, 768), TrackOptions(), expect)
    got = _run(tk, det, images, [0.1 * k for k in range(n)])
    # every image has its marker, at its place; searched whole only at the start and a second later
    assert [[v.marker_id for v in g] for g in got] == [[7]] * n
    assert all(np.allclose(g[0].corners_px, truth[k]) for k, g in enumerate(got))
    assert det.whole() == [0, 10] and tk.stats.lost == 0 and tk.stats.confirmed == 3
    # asked once per image where the peers missed it, for the tracked marker only
    assert asked == [(4, [7]), (5, [7]), (6, [7])]
    # a confirmation that fails: the image is searched whole, as without one
    det = _Scripted(per_image)
    tk = CameraTracker(det, (1024, 768), TrackOptions(), lambda image, predicted: [])
    got = _run(tk, det, images, [0.1 * k for k in range(n)])
    assert [len(g) for g in got] == [0 if 4 <= k <= 6 else 1 for k in range(n)] and det.whole() == [0, 4]


def test_options_refuse_nonsense() -> None:
    with pytest.raises(InputError, match="full_every_s"):
        TrackOptions(full_every_s=0.0)
    with pytest.raises(InputError, match="margin_px"):
        TrackOptions(margin_px=-1.0)


def _run_poses() -> tuple[Rig, list[np.ndarray]]:
    """The simulated room's true rig and the short run's robot poses ``T_world_robot``, one per image."""
    scene = make_scene(0)
    x, y, th = VALIDATION_POSES[3]
    Ts = []
    for k in range(FRAMES):
        a = th + 0.04 * k
        Ts.append(scene.T_world_robot(x + 0.03 * k * np.cos(a), y + 0.03 * k * np.sin(a), a))
    return scene.rig_true, Ts


@pytest.fixture(scope="module")
def run_rec(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, object]:
    """A short run, rendered: the robot driving and turning past validation pose 4 at 0.3 m/s."""
    rig, Ts = _run_poses()
    out = tmp_path_factory.mktemp("rec")
    write_rendered_run(out, rig, Ts, np.arange(FRAMES) / RATE_HZ, np.random.default_rng(3))
    return out, rig


def test_tracking_localizes_the_same_instants_at_the_same_poses(run_rec, monkeypatch: pytest.MonkeyPatch) -> None:
    from gtrig.vision.detect import UNSEEN_CORNER_SIGMA_PX, GtrigDetector, measured_corners
    from gtrig.vision.synthetic import visible_views

    path, rig = run_rec
    tracked_size = {c.name: (int(c.resolution[0]), int(c.resolution[1])) for c in rig.cameras}
    kw = {"workers": 1, "detector": "gtrig", "chunk_size": FRAMES}
    whole = run_recording(path, rig, "run", True, track=TrackOptions(enabled=False), **kw)
    boxes = []
    call = GtrigDetector.__call__

    def recorded(self, image, camera, tone="linear", box=None):  # type: ignore[no-untyped-def]
        boxes.append(box)
        return call(self, image, camera, tone, box)

    monkeypatch.setattr(GtrigDetector, "__call__", recorded)
    tracked = run_recording(path, rig, "run", True, **kw)  # tracking is the default
    n_images = sum(tracked.images_per_camera.values())
    # most images searched in a window or not at all: whole at the chunk's start, and again only where a
    # tracked marker was not found in its window
    n_cams = len(tracked.images_per_camera)
    extra_whole = boxes.count(None) - n_cams  # a window that missed a tracked marker, then the whole image
    assert 0 <= extra_whole <= 2 and 0 < len(boxes) <= n_images + extra_whole
    assert len(boxes) - boxes.count(None) >= n_images // 2
    ok_whole = [e.stamp_s for e in whole.estimates if e.ok]
    assert len(ok_whole) >= FRAMES - 1, [e.reason for e in whole.estimates]
    assert [e.stamp_s for e in tracked.estimates if e.ok] == ok_whole
    views = lambda r: [{(v.camera, v.marker_id): v for v in o.views} for o in r.observations]  # noqa: E731
    # every marker of the whole images, and those the peers missed but the tracker confirmed at their
    # predicted corners: there, at the markers' true corners (those inside the image; a corner outside is
    # released, gtrig.vision.detect.release_unseen_corners)
    _, Ts = _run_poses()
    assert len(tracked.observations) == len(Ts)
    n_more = 0
    for T, a, b in zip(Ts, views(whole), views(tracked), strict=True):
        truth = {(c, m): uv for c, m, uv in visible_views(rig, T, margin_px=-100.0, min_side_px=0.0)}
        assert set(a) <= set(b)
        for k in set(b) - set(a):
            n_more += 1
            seen = measured_corners(b[k].corners_px, tracked_size[k[0]])
            assert seen.sum() >= 3 and np.abs(b[k].corners_px - truth[k])[seen].max() < 0.5
            assert np.all(b[k].corner_cov[~seen].diagonal(axis1=1, axis2=2) == UNSEEN_CORNER_SIGMA_PX**2)
    assert n_more <= 6
    for a, b in zip(whole.localized(), tracked.localized(), strict=True):
        d = geo.inv_T(a.T_world_robot) @ b.T_world_robot
        # the same markers, read from a crop: corners within a tenth of a pixel, poses within a millimetre
        assert np.linalg.norm(d[:3, 3]) < 1e-3
        assert np.degrees(np.arccos(np.clip((np.trace(d[:3, :3]) - 1) / 2, -1, 1))) < 0.05


def test_a_marker_that_appeared_is_found_back_in_the_images_before() -> None:
    from gtrig.vision.backfill import track_with_backfill

    rng = np.random.default_rng(2)
    n = 10
    background = rng.normal(90, 2, (768, 1024)).clip(0, 255).astype(np.uint8)
    images, per_image, truth = [], [], []
    for k in range(n):
        img = background.copy()
        x = 10 + 30 * k  # coming in from the left edge: fully inside from image 1 on
        img[280:321, max(0, x - 20):x + 21] = 20
        images.append(img)
        truth.append(_square(x, 300, 40))
        # the peers find it from image 4 on only
        per_image.append({7: truth[k]} if k >= 4 else {})
    asked: list[int] = []

    def expect(image: np.ndarray, predicted: list[tuple[int, np.ndarray]]) -> list[MarkerView]:
        k = next(i for i, im in enumerate(images) if im is image)
        asked.append(k)
        return [MarkerView("cam", m, truth[k], np.tile(np.eye(2) * 0.01, (4, 1, 1))) for m, c in predicted
                if m == 7 and np.abs(c - truth[k]).max() < 3.0]

    det = _Scripted(per_image)
    tk = CameraTracker(det, (1024, 768), TrackOptions(), expect)
    stamps = [0.1 * k for k in range(n)]

    def frames():  # type: ignore[no-untyped-def]
        for img, t in zip(images, stamps, strict=True):
            det.k += 1
            yield img, t

    got = list(track_with_backfill(tk, frames(), lookback=2))
    # found back in images 3 and 2 (two back from where it appeared), at its corners; never in images 0-1
    assert [[v.marker_id for v in g] for g in got] == [[], [], [7], [7]] + [[7]] * (n - 4)
    assert all(np.allclose(g[0].corners_px, truth[k]) for k, g in enumerate(got) if g)
    assert tk.stats.confirmed_back == 2 and sorted(asked) == [2, 3]
    # with enough look-back, back to the first image where it is inside the image by 2 px (image 1)
    det = _Scripted(per_image)
    tk = CameraTracker(det, (1024, 768), TrackOptions(), expect)
    got = list(track_with_backfill(tk, frames(), lookback=5))
    assert [len(g) for g in got] == [0] + [1] * (n - 1) and tk.stats.confirmed_back == 3
    # without a confirmation, the tracker's own output, image by image
    det = _Scripted(per_image)
    tk = CameraTracker(det, (1024, 768), TrackOptions())
    assert [len(g) for g in track_with_backfill(tk, frames())] == [0] * 4 + [1] * (n - 4)


def test_prepared_lens_maps_serve_the_whole_image_and_every_window(monkeypatch: pytest.MonkeyPatch) -> None:
    """The maps a client prepares before its pool forks are those its detectors look up: once prepared, a
    camera's whole-image and window detectors compute no maps of their own (a key that differed would)."""
    from gtrig.markers.detect.camera import Undistorter
    from gtrig.vision.detect import make_detector
    from gtrig.vision.observations import VisionModel
    from gtrig.vision.synthetic import render_markers, visible_views

    scene = make_scene(0)
    T = scene.T_world_robot(*VALIDATION_POSES[4])
    seen = {c for c, _, _ in visible_views(scene.rig_true, T)}
    cam0 = next(c for c in scene.rig_true.cameras if any(c.dist_coeffs) and c.name in seen)
    # a focal length no other test uses: this camera's maps are not in the process's cache already
    (fx, s, cx), (_, fy, cy), last = cam0.camera_matrix
    cam0 = cam0.model_copy(update={"camera_matrix": ((fx + 0.371, s, cx), (0.0, fy + 0.371, cy), last)})
    rig = scene.rig_true.model_copy(update={"cameras": (cam0,)})
    camera = VisionModel.from_rig(rig).cameras[cam0.name]
    image = render_markers(rig, cam0.name, T, np.random.default_rng(0), supersample=1)
    det = make_detector(rig, "gtrig")
    det.prepare_lens_maps([camera])  # type: ignore[union-attr]
    computed: list[tuple[int, int]] = []
    compute = Undistorter._compute

    def counted(K: np.ndarray, dist: np.ndarray, shape: tuple[int, int]) -> tuple[np.ndarray, np.ndarray]:
        computed.append(shape)
        return compute(K, dist, shape)

    monkeypatch.setattr(Undistorter, "_compute", staticmethod(counted))
    found = det(image, camera, "linear")
    w, h = camera.size
    found_in_window = det(image, camera, "linear", (w // 8, h // 8, w - w // 8, h - h // 8))
    assert found and {v.marker_id for v in found_in_window} == {v.marker_id for v in found}
    assert not computed
    # the check itself can fail: another camera matrix's maps are computed on first use
    Undistorter(camera.K + 0.5 * np.eye(3), np.asarray(camera.dist, float), (h, w))
    assert computed
