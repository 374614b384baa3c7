"""Markers looked for back in the images before the one where they appeared.

A marker coming into a camera's view is often missed by the peers (OpenCV, AprilTag 3) in its first images:
its white margin is cut by the image's edge or merged with a neighbour's black, and the candidate stage
finds no closed contour, while the marker is whole and its edges and cells are in the image. Once it has
been found in two consecutive images, its corners are predicted back in time from their motion between
them (constant velocity in the image, like :func:`gtrig.vision.track.predict_marker` forward) into the
images before, which are still held, and the marker is confirmed there by ``expect``
(:data:`gtrig.vision.track.ExpectFn`: the edge model refined from the prediction, the marker kept only
when its cells read its ID). Each confirmed image gives the motion for the one before, up to
``lookback`` images back; a prediction with fewer than three corners inside the image by 2 px ends the
walk (a marker cut by the image's edge is kept on its corners inside the image, :mod:`gtrig.vision.detect`).

Only the images of one chunk are used (the first ones of a chunk have no earlier images to fill), so the
detections do not depend on how the work is split; deterministic like the forward tracker.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Iterable, Iterator
from dataclasses import dataclass

import numpy as np

from gtrig.vision.observations import MarkerView
from gtrig.vision.track import CONFIRM_CORNERS, CameraTracker, ExpectFn, inside_image

__all__ = ["track_with_backfill"]


@dataclass
class _Held:
    """One image kept for the look-back, with its stamp and the markers found in it so far."""

    image: np.ndarray
    stamp_s: float
    views: list[MarkerView]

    def has(self, marker_id: int) -> bool:
        return any(v.marker_id == marker_id for v in self.views)

    def corners(self, marker_id: int) -> np.ndarray:
        return next(v.corners_px for v in self.views if v.marker_id == marker_id)


def _predict_back(near: _Held, far: _Held, marker_id: int, stamp_s: float) -> np.ndarray:
    """The marker's corners (4, 2) at ``stamp_s`` (before ``near``'s stamp), moving from ``far`` to ``near``
    at constant velocity."""
    c1, c2 = near.corners(marker_id), far.corners(marker_id)
    return c1 + (c1 - c2) * ((stamp_s - near.stamp_s) / (near.stamp_s - far.stamp_s))


def _fill_back(held: deque[_Held], expect: ExpectFn, size: tuple[int, int], lookback: int) -> int:
    """Markers of the newest two held images that the one before them lacks, looked for back through up to
    ``lookback`` held images before them (module docstring); the views found are added to those images.
    Returns how many."""
    if len(held) < 3:
        return 0
    new, last, before = held[-1], held[-2], held[-3]
    appeared = [v.marker_id for v in last.views if new.has(v.marker_id) and not before.has(v.marker_id)]
    n = 0
    for mid in appeared:
        near, far = last, new
        for k in range(len(held) - 3, max(-1, len(held) - 3 - lookback), -1):
            h = held[k]
            if h.has(mid) or near.stamp_s <= h.stamp_s or far.stamp_s <= near.stamp_s:
                break
            c = _predict_back(near, far, mid, h.stamp_s)
            if not inside_image(c, size, at_least=CONFIRM_CORNERS):
                break
            got = [v for v in expect(h.image, [(mid, c)]) if v.marker_id == mid]
            if not got:
                break
            h.views.append(got[0])
            n += 1
            near, far = h, near
    return n


def track_with_backfill(tracker: CameraTracker, frames: Iterable[tuple[np.ndarray, float]], lookback: int = 3
                        ) -> Iterator[list[MarkerView]]:
    """The markers of each of a camera's consecutive images ``(image, stamp_s)``, in order: ``tracker``'s
    (:meth:`CameraTracker.step`), and markers that appeared looked for up to ``lookback`` images back
    (module docstring; none without ``tracker.expect``). Each image's list is yielded once no later image
    can add to it, so at most ``lookback + 2`` images are held."""
    held: deque[_Held] = deque()
    for image, stamp_s in frames:
        held.append(_Held(image, stamp_s, list(tracker.step(image, stamp_s))))
        if tracker.expect is not None and tracker.options.enabled:
            tracker.stats.confirmed_back += _fill_back(held, tracker.expect, tracker.size, lookback)
        while len(held) > lookback + 1:
            yield sorted(held.popleft().views, key=lambda v: v.marker_id)
    while held:
        yield sorted(held.popleft().views, key=lambda v: v.marker_id)
