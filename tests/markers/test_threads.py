"""The detector's threading helpers (speed): the results never depend on the threads."""

from __future__ import annotations

import threading
import time

import cv2
import numpy as np
import pytest

from gtrig.markers.detect import DetectorParams, MarkerDetector, _threads
from gtrig.markers.synth import clutter_background, homography_from_pose, render
from gtrig.rig.models import MarkerFamily


def _slow_square(k: int) -> tuple[int, str]:
    time.sleep(0.002 * (k % 3))  # uneven tasks: the helper and the caller overtake each other
    return k * k, threading.current_thread().name


@pytest.mark.parametrize("threads", [1, 2, 3])
def test_ordered_map_keeps_the_order(threads: int) -> None:
    out = list(_threads.ordered_map(_slow_square, [(k,) for k in range(40)], threads))
    assert [v for v, _ in out] == [k * k for k in range(40)]
    if threads == 1:
        assert {name for _, name in out} == {threading.current_thread().name}


def test_ordered_map_raises_where_the_result_is_taken() -> None:
    def f(k: int) -> int:
        if k == 5:
            raise ValueError("task 5")
        return k

    got = []
    with pytest.raises(ValueError, match="task 5"):
        for v in _threads.ordered_map(f, [(k,) for k in range(10)], 2):
            got.append(v)
    assert got == [0, 1, 2, 3, 4]


def test_two_threads_give_the_same_detections_on_clutter() -> None:
    """Large, small and blurred markers on clutter, in dim light: one thread and two give the same
    detections, bit for bit (the edge fits split between the threads)."""
    rng = np.random.default_rng(8)
    fam = MarkerFamily.APRILTAG_36H11
    shape = (480, 640)
    cases = [(22, (90, 90), 1.8), (60, (300, 150), 0.5), (21, (520, 120), 1.2), (120, (250, 360), 1.0),
             (24, (540, 380), 2.0)]
    markers = [(fam, 3 + 97 * i, homography_from_pose(s, c, 25, 40 * i, 70 * i)) for i, (s, c, _) in enumerate(cases)]
    got = {}
    for blur in (0.8, 1.8):
        img, truths = render(shape, markers, blur_px=blur, noise=3.0, gain=80.0, gradient=0.4,
                             background=clutter_background(shape, rng, n_shapes=30), rng=rng)
        for threads in (1, 2):
            det = MarkerDetector(fam, params=DetectorParams(threads=threads))
            got[blur, threads] = det.detect(img)
        assert len(got[blur, 1]) >= 2 and {d.id for d in got[blur, 1]} <= {t.marker_id for t in truths}
        a, b = got[blur, 1], got[blur, 2]
        assert [d.id for d in a] == [d.id for d in b]
        for x, y in zip(a, b, strict=True):
            np.testing.assert_array_equal(x.corners_px, y.corners_px)
            np.testing.assert_array_equal(x.corner_cov, y.corner_cov)


def test_opencv_pool_held_to_one_thread_inside_and_restored() -> None:
    """A detection holds OpenCV's pool to one thread while it runs (its own threads share the work) and
    restores the caller's setting, also when detections overlap in two threads; the default threads
    (0) follow the setting as it was on the call."""
    before = cv2.getNumThreads()
    seen: list[int] = []
    try:
        cv2.setNumThreads(2)
        with _threads.opencv_one_thread():
            seen.append(cv2.getNumThreads())
            with _threads.opencv_one_thread():  # nested (another detection in another thread)
                seen.append(cv2.getNumThreads())
            seen.append(cv2.getNumThreads())
        assert seen == [1, 1, 1]
        assert cv2.getNumThreads() == 2
        img = np.full((120, 160), 200, np.uint8)
        workers = [threading.Thread(target=MarkerDetector(MarkerFamily.APRILTAG_36H11).detect, args=(img,))
                   for _ in range(3)]
        for w in workers:
            w.start()
        for w in workers:
            w.join()
        assert cv2.getNumThreads() == 2
        assert _threads.threads(0) == 2
    finally:
        cv2.setNumThreads(before)
