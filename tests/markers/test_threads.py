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


def test_beside_hands_back_the_result_or_the_error_once() -> None:
    calls: list[int] = []

    def f(k: int) -> tuple[int, str]:
        calls.append(k)
        if k < 0:
            raise ValueError("negative")
        return k * k, threading.current_thread().name

    jobs = [_threads.Beside(f, k) for k in range(8)]
    assert [j.result()[0] for j in jobs] == [k * k for k in range(8)]
    assert [j.result()[0] for j in jobs] == [k * k for k in range(8)]  # taken again: not run again
    bad = _threads.Beside(f, -1)
    with pytest.raises(ValueError, match="negative"):
        bad.result()
    time.sleep(0.05)  # the helpers have reached every job by now
    assert sorted(calls) == [-1, *range(8)]


def test_beside_runs_in_the_caller_when_no_helper_is_free() -> None:
    """With both helper threads held by other work, the result is computed by the caller, at once."""
    release = threading.Event()
    held = [_threads.helper_pool().submit(release.wait, 10.0) for _ in range(2)]
    try:
        job = _threads.Beside(lambda: threading.current_thread().name)
        t0 = time.perf_counter()
        assert job.result() == threading.current_thread().name
        assert time.perf_counter() - t0 < 1.0
    finally:
        release.set()
        for h in held:
            h.result()


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


def test_detection_never_resets_opencvs_threads(monkeypatch: pytest.MonkeyPatch) -> None:
    """Detections in three threads at once leave OpenCV's thread setting alone (setting it stops and
    restarts OpenCV's workers, milliseconds on a loaded machine), and the default threads (0) follow it."""
    before = cv2.getNumThreads()
    calls: list[int] = []
    real = cv2.setNumThreads
    try:
        real(2)
        monkeypatch.setattr(cv2, "setNumThreads", lambda n: calls.append(n))
        rng = np.random.default_rng(2)
        fam = MarkerFamily.APRILTAG_36H11
        markers = [(fam, 5 + i, homography_from_pose(50, (120 + 200 * i, 200), 20, 30 * i, 0)) for i in range(3)]
        img, _ = render((400, 640), markers, blur_px=0.8, noise=2.0, rng=rng)
        found: list[int] = []
        workers = [threading.Thread(target=lambda: found.append(len(MarkerDetector(fam).detect(img))))
                   for _ in range(3)]
        for w in workers:
            w.start()
        for w in workers:
            w.join()
        assert found == [3, 3, 3]
        assert calls == [] and cv2.getNumThreads() == 2
        assert _threads.threads(0) == 2
    finally:
        real(before)


def test_few_quads_fit_in_the_calling_thread() -> None:
    assert _threads.fit_threads(2, _threads.MIN_SPLIT_QUADS - 1) == 1
    assert _threads.fit_threads(2, _threads.MIN_SPLIT_QUADS) == 2
    assert _threads.fit_threads(0, 50) == _threads.threads(0)
