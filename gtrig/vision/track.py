"""Markers tracked through one camera's consecutive images, so that most images are searched in a small
region instead of whole.

Each image of a camera is searched where its markers are expected and where it changed:

* **Tracked markers**: every marker seen in the camera's previous image is predicted by its corners'
  motion over the two previous images (constant velocity in the image; one image: where it was), and
  searched in the predicted square grown by a margin (a fixed part, the predicted displacement and a
  share of the marker's side). A marker predicted inside the image that the peers (OpenCV, AprilTag 3)
  gave no candidate for, typically one smeared by motion, is looked for at its predicted corners: the edge
  model is refined from them and the marker kept only when its cells, read through the refined corners,
  give its ID (``MarkerDetector.detect_expected``). One still missing makes the image searched whole again.
  A marker leaving the image, predicted with three corners inside it, is looked for the same way (the
  peers find no closed outline for it) and kept on its corners inside the image.
* **Change**: the image is reduced to the mean grey level of cells of ``cell_px`` pixels; a cell whose
  mean moved by more than ``change_level`` from the last time that place was searched (a marker coming
  into view, the robot moving or turning) is searched, with a margin of ``change_margin_px``. A fixed
  camera's unchanged background is not searched again until the next whole-image pass.
* **Whole-image pass**: at the first image of a chunk (chunks never depend on each other, so the
  detections do not depend on how the work is split), at least every ``full_every_s`` seconds, when a
  tracked marker is lost, and when the region to search fits in no window.

The region searched in one image is one window holding the union of the above: a square of
``window_px / 2``, ``3 window_px / 4``, ``window_px``, ``5 window_px / 4`` or ``3 window_px / 2`` pixels (the
smallest that holds it, clipped to the image) at a fixed place, on a grid of a quarter of its side. A robot
near a camera, whose moving body changes the cells around its markers, makes regions of 500-600 px: a window
of 640 or 768 px costs OpenCV's candidate stage a half or three quarters of the whole image's. The detector
of a window (its camera matrix shifted by the window's corner; the distortion coefficients are unchanged,
which is exact) is made once per process and camera, its undistortion maps cut from the whole image's
(:func:`gtrig.markers.detect.camera.declare_crop`). Deterministic: the same images in the same order give
the same detections.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import cv2
import numpy as np

from gtrig.errors import InputError
from gtrig.vision.detect import Box, measured_corners
from gtrig.vision.observations import MarkerView

log = logging.getLogger(__name__)

#: ``detect(image, box)``: the markers of ``image`` inside ``box`` (None: the whole image), their corners in
#: the whole image's pixel frame.
RegionDetectFn = Callable[[np.ndarray, Box | None], list[MarkerView]]

#: ``expect(image, [(marker_id, corners_px), ...])``: of markers predicted at corners (4, 2) (the whole
#: image's pixels, printed order), those confirmed there (refined from the prediction, their ID read).
ExpectFn = Callable[[np.ndarray, Sequence[tuple[int, np.ndarray]]], list[MarkerView]]

#: ``siblings(views)``: from the markers found in an image, other markers predicted there
#: ``[(marker_id, corners_px), ...]`` (:func:`gtrig.vision.siblings.cut_siblings`).
SiblingsFn = Callable[[list[MarkerView]], list[tuple[int, np.ndarray]]]


#: Version of the tracking rules (what is looked for where), part of :meth:`TrackOptions.key`: 2 looks for
#: markers cut by the image's edge, 3 has windows up to ``3 window_px / 2``.
TRACK_RULES = 3


@dataclass(frozen=True)
class TrackOptions:
    """How markers are tracked through a camera's images (:class:`CameraTracker`).

    Attributes
    ----------
    enabled : bool
        Track; False: every image is searched whole.
    full_every_s : float
        A whole-image pass at least this often per camera, seconds.
    margin_px : float
        Fixed part of a tracked marker's search margin, pixels.
    motion_margin : float
        A tracked marker's margin grows by this times its predicted corner displacement since the
        previous image (the prediction's uncertainty: a constant-velocity guess errs by about the
        velocity's change).
    size_margin : float
        ... and by this times the marker's side in the previous image (its pose may change its outline).
    cell_px : int
        Side of the cells whose mean grey level is compared, pixels.
    change_level : float
        A cell whose mean grey level moved by more than this (0-255 scale) from when its place was last
        searched has changed (sensor noise of sigma 2 gives cell means of sigma 0.13 at 16 px).
    change_margin_px : float
        A changed area is searched this far around it (a marker only partly inside it).
    window_px : int
        The windows' sides are a half, three quarters, one, five quarters and three halves of this, pixels
        (module docstring); a region that fits in none is searched whole.
    """

    enabled: bool = True
    full_every_s: float = 1.0
    margin_px: float = 12.0
    motion_margin: float = 1.0
    size_margin: float = 0.5
    cell_px: int = 16
    change_level: float = 4.0
    change_margin_px: float = 64.0
    window_px: int = 512

    def __post_init__(self) -> None:
        positive = {"full_every_s": self.full_every_s, "cell_px": self.cell_px, "change_level": self.change_level,
                    "window_px": self.window_px // 8}
        for name, v in positive.items():
            if not v > 0:
                raise InputError(f"tracking: {name} must be > 0 (got {v})")
        for name, v in {"margin_px": self.margin_px, "motion_margin": self.motion_margin,
                        "size_margin": self.size_margin, "change_margin_px": self.change_margin_px}.items():
            if not v >= 0:
                raise InputError(f"tracking: {name} must be >= 0 (got {v})")

    def key(self) -> str:
        """What the detections depend on (a checkpoint's key): "whole" when not tracking; tracking's rules
        carry :data:`TRACK_RULES` (raised when they change which markers are looked for)."""
        if not self.enabled:
            return "whole"
        return (f"track{TRACK_RULES}/{self.full_every_s!r}/{self.margin_px!r}/{self.motion_margin!r}/"
                f"{self.size_margin!r}/{self.cell_px}/{self.change_level!r}/{self.change_margin_px!r}/{self.window_px}")

    @property
    def windows_px(self) -> tuple[int, ...]:
        """The windows' sides, pixels, smallest first."""
        w = self.window_px
        return w // 2, 3 * w // 4, w, 5 * w // 4, 3 * w // 2


@dataclass
class TrackStats:
    """How the images of a camera were searched: ``whole``, in a ``region``, or ``skipped`` (nothing
    expected, nothing changed); ``lost``: whole-image passes made because a tracked marker was missing;
    ``confirmed``: tracked markers the peers missed, found at their predicted corners;
    ``confirmed_back``: markers found in the images before they appeared (:mod:`gtrig.vision.backfill`);
    ``confirmed_siblings``: markers cut by the image's edge found where the image's other markers place
    them (:mod:`gtrig.vision.siblings`)."""

    whole: int = 0
    region: int = 0
    skipped: int = 0
    lost: int = 0
    region_area_px: int = 0
    confirmed: int = 0
    confirmed_back: int = 0
    confirmed_siblings: int = 0

    def add(self, other: TrackStats) -> None:
        self.whole += other.whole
        self.region += other.region
        self.skipped += other.skipped
        self.lost += other.lost
        self.region_area_px += other.region_area_px
        self.confirmed += other.confirmed
        self.confirmed_back += other.confirmed_back
        self.confirmed_siblings += other.confirmed_siblings


@dataclass(frozen=True)
class _Expected:
    """A tracked marker's predicted corners (4, 2) and its search box (float, unclipped)."""

    marker_id: int
    corners_px: np.ndarray
    box: tuple[float, float, float, float]


def cell_means(image: np.ndarray, cell_px: int) -> np.ndarray:
    """The mean grey level (float32, (H // cell, W // cell)) of ``image``'s cells (a colour image: its
    channels' mean)."""
    g = image if image.ndim == 2 else image.mean(axis=2)
    h, w = g.shape[:2]
    size = (max(1, w // cell_px), max(1, h // cell_px))
    if g.dtype == np.uint8 and w % cell_px == 0 and h % cell_px == 0 and not cell_px & (cell_px - 1):
        from gtrig.vision.cell_kernel import cell_means_into

        out = np.empty((size[1], size[0]), np.float32)
        cell_means_into(g, cell_px, out)  # the area resize's values (a power of two divides exactly), faster
        return out
    return cv2.resize(np.asarray(g, np.float32), size, interpolation=cv2.INTER_AREA)


def predict_marker(prev: tuple[float, np.ndarray], before: tuple[float, np.ndarray] | None, stamp_s: float,
                   opts: TrackOptions) -> tuple[np.ndarray, tuple[float, float, float, float]]:
    """A marker's corners (4, 2) at ``stamp_s`` from ``(stamp_s, corners)`` in the previous image and the
    one before (None: unknown, the marker is searched where it was), and its search box
    ``(x0, y0, x1, y1)``: the predicted square grown by the margin of :class:`TrackOptions`."""
    t1, c1 = prev
    side = _longest(c1 - c1[_PREVIOUS_CORNER])
    if before is None or before[0] >= t1:
        c, disp = c1, 0.5 * side  # no velocity: its motion is unknown, half a side of it allowed
    else:
        t2, c2 = before
        c = c1 + (c1 - c2) * ((stamp_s - t1) / (t1 - t2))
        disp = _longest(c - c1)
    m = opts.margin_px + opts.motion_margin * disp + opts.size_margin * side
    both = np.concatenate([c, c1])
    lo, hi = both.min(axis=0) - m, both.max(axis=0) + m
    return c, (float(lo[0]), float(lo[1]), float(hi[0]), float(hi[1]))


#: each corner's predecessor around the quad (``np.roll(c, 1, axis=0)``'s order)
_PREVIOUS_CORNER = np.array([3, 0, 1, 2])


def _longest(v: np.ndarray) -> float:
    """The longest of the 2-vectors ``v`` (N, 2): ``np.linalg.norm``'s values without its per-call overhead
    (every tracked marker of every image passes here)."""
    return float(np.sqrt(np.max(v[:, 0] * v[:, 0] + v[:, 1] * v[:, 1])))


def window_for(region: tuple[float, float, float, float], size: tuple[int, int], sides_px: Sequence[int]
               ) -> Box | None | tuple[()]:
    """The smallest window (module docstring) of an image of ``size`` (w, h) that holds ``region``
    (clipped to the image): a square of one of ``sides_px`` (ascending) at a multiple of a quarter of its
    side (or against the image's far edge), clipped to the image. None: the region is outside the image;
    ``()``: it fits in no window."""
    w, h = size
    a = (max(0.0, region[0]), max(0.0, region[1]), min(float(w), region[2]), min(float(h), region[3]))
    if a[2] <= a[0] or a[3] <= a[1]:
        return None
    for side in sides_px:
        x0, y0 = _origin(a[0], a[2], side, w), _origin(a[1], a[3], side, h)
        if x0 is not None and y0 is not None:
            return x0, y0, min(w, x0 + side), min(h, y0 + side)
    return ()


def _origin(lo: float, hi: float, side: int, n: int) -> int | None:
    """The start of a window of ``side`` on an axis of ``n`` pixels holding ``[lo, hi]``, or None."""
    if side >= n:
        return 0
    step = max(1, side // 4)
    o = min(int(lo // step) * step, n - side)
    return o if o + side >= hi else None


def _union(boxes: Sequence[tuple[float, float, float, float]]) -> tuple[float, float, float, float] | None:
    if not boxes:
        return None
    b = np.array(boxes)
    return float(b[:, 0].min()), float(b[:, 1].min()), float(b[:, 2].max()), float(b[:, 3].max())


def inside_image(corners: np.ndarray, size: tuple[int, int], border: float = 2.0, at_least: int = 4) -> bool:
    """At least ``at_least`` of the corners (4, 2) (all of them by default) ``border`` pixels or more inside
    an image of ``size`` (w, h)."""
    # measured_corners counts its border from the image's outer edge, half a pixel before the first centre
    return int(measured_corners(np.asarray(corners, float), size, border + 0.5).sum()) >= at_least


#: A tracked marker predicted with this many corners inside the image is looked for at its predicted corners
#: (one cut by the image's edge is kept on its corners inside the image, :mod:`gtrig.vision.detect`).
CONFIRM_CORNERS = 3


@dataclass
class CameraTracker:
    """Tracks one camera's markers through its consecutive images of one chunk (module docstring).

    Parameters
    ----------
    detect : ``detect(image, box)`` the markers inside ``box`` (None: the whole image), corners in the
        whole image's pixels.
    size : (w, h) of the camera's images, pixels.
    options : TrackOptions
    expect : ``expect(image, predicted)`` (:data:`ExpectFn`), or None. A tracked marker predicted inside
        the image that the search (of a region or of the whole image) did not find is looked for at its
        predicted corners with it: a motion blur can leave the peers without a candidate where the edge
        model still fits the marker's edges and its cells still read as its ID. A marker predicted across
        the image's edge with :data:`CONFIRM_CORNERS` corners inside it is looked for too (the peers find no
        closed outline there); ``expect`` keeps it on its corners inside the image (its corners outside
        would be extrapolated from short edges, with errors of most of a pixel that their covariances do
        not show). Such a marker, when not found, does not make the image searched whole.
    siblings : ``siblings(views)`` (:data:`SiblingsFn`), or None: with ``expect``, when tracking, the markers
        the image's found markers place across its edge are looked for there too.
    """

    detect: RegionDetectFn
    size: tuple[int, int]
    options: TrackOptions = TrackOptions()
    expect: ExpectFn | None = None
    siblings: SiblingsFn | None = None
    stats: TrackStats = field(default_factory=TrackStats)
    _last_whole_s: float | None = None
    _prev: dict[int, tuple[float, np.ndarray]] = field(default_factory=dict)
    _before: dict[int, tuple[float, np.ndarray]] = field(default_factory=dict)
    _searched: np.ndarray | None = None  # cell means of each cell's content when it was last searched

    def step(self, image: np.ndarray, stamp_s: float) -> list[MarkerView]:
        """The markers of the next image (stamped ``stamp_s``, after the previous one)."""
        o = self.options
        h, w = image.shape[:2]
        if (w, h) != self.size:
            self.size = (w, h)
            self._last_whole_s = None  # another image size: start afresh
            self._prev, self._before = {}, {}
        cells = cell_means(image, o.cell_px) if o.enabled else None
        whole = (not o.enabled or self._last_whole_s is None or self._searched is None
                 or self._searched.shape != cells.shape  # type: ignore[union-attr]
                 or stamp_s - self._last_whole_s >= o.full_every_s - 1e-9)
        expected = self._expected(stamp_s) if o.enabled else []
        tried: dict[int, MarkerView | None] = {}
        views: list[MarkerView] = []
        if not whole:
            assert cells is not None
            views, whole = self._search_region(image, expected, cells, tried)
        if whole:
            views = self.detect(image, None)
            views = views + self._confirm(image, expected, {v.marker_id for v in views}, tried)
            self.stats.whole += 1
            self._last_whole_s = stamp_s
            self._searched = cells
        kept = {id(v) for v in views}
        self.stats.confirmed += sum(v is not None and id(v) in kept for v in tried.values())
        if o.enabled:
            views = views + self._confirm_siblings(image, views, tried)
        self._before = self._prev
        self._prev = {v.marker_id: (stamp_s, v.corners_px) for v in views}
        return views

    def _expected(self, stamp_s: float) -> list[_Expected]:
        """The markers of the previous image, predicted at ``stamp_s`` (:func:`predict_marker`)."""
        out = []
        for mid, prev in self._prev.items():
            c, around = predict_marker(prev, self._before.get(mid), stamp_s, self.options)
            out.append(_Expected(mid, c, around))
        return out

    def _confirm(self, image: np.ndarray, expected: Sequence[_Expected], found: set[int],
                 tried: dict[int, MarkerView | None]) -> list[MarkerView]:
        """The expected markers predicted inside the image, not in ``found``, confirmed at their predicted
        corners by ``expect`` (each tried once per image: ``tried`` holds the outcomes)."""
        if self.expect is None:
            return []
        todo = [e for e in expected if e.marker_id not in found and e.marker_id not in tried
                and inside_image(e.corners_px, self.size, at_least=CONFIRM_CORNERS)]
        if todo:
            got = {v.marker_id: v for v in self.expect(image, [(e.marker_id, e.corners_px) for e in todo])}
            tried.update({e.marker_id: got.get(e.marker_id) for e in todo})
        return [v for e in expected if e.marker_id not in found
                and (v := tried.get(e.marker_id)) is not None]

    def _confirm_siblings(self, image: np.ndarray, views: list[MarkerView], tried: dict[int, MarkerView | None]
                          ) -> list[MarkerView]:
        """Markers that ``views`` (the image's found markers) place across the image's edge, not tried in
        this image yet, confirmed there by ``expect``."""
        if self.expect is None or self.siblings is None or not views:
            return []
        todo = [(m, c) for m, c in self.siblings(views) if m not in tried]
        if not todo:
            return []
        got = [v for v in self.expect(image, todo) if v.marker_id in {m for m, _ in todo}]
        self.stats.confirmed_siblings += len(got)
        return got

    def _search_region(self, image: np.ndarray, expected: Sequence[_Expected], cells: np.ndarray,
                       tried: dict[int, MarkerView | None]) -> tuple[list[MarkerView], bool]:
        """The markers found in the region of tracked and changed places, and whether the image must be
        searched whole instead (a tracked marker missing, or a region too large)."""
        o = self.options
        changed = self._changed_box(cells)
        region = _union([e.box for e in expected] + ([changed] if changed is not None else []))
        box = None if region is None else window_for(region, self.size, o.windows_px)
        if box is None:
            self.stats.skipped += 1
            return [], False
        if box == ():
            return [], True
        assert len(box) == 4
        area = (box[2] - box[0]) * (box[3] - box[1])
        views = self.detect(image, box)
        views = views + self._confirm(image, expected, {v.marker_id for v in views}, tried)
        found = {v.marker_id for v in views}
        if any(e.marker_id not in found and inside_image(e.corners_px, self.size) for e in expected):
            self.stats.lost += 1
            return [], True
        self.stats.region += 1
        self.stats.region_area_px += area
        self._mark_searched(cells, box)
        return views, False

    def _changed_box(self, cells: np.ndarray) -> tuple[float, float, float, float] | None:
        """The pixels box around the cells that changed since their place was last searched (grown by
        ``change_margin_px``), or None."""
        assert self._searched is not None
        diff = np.abs(cells - self._searched) > self.options.change_level
        if not diff.any():
            return None
        rows, cols = np.nonzero(diff)
        sx, sy = self.size[0] / cells.shape[1], self.size[1] / cells.shape[0]
        m = self.options.change_margin_px
        return (cols.min() * sx - m, rows.min() * sy - m, (cols.max() + 1) * sx + m, (rows.max() + 1) * sy + m)

    def _mark_searched(self, cells: np.ndarray, box: Box) -> None:
        """The cells searched in ``box`` hold the current content: all of them at least
        ``change_margin_px`` inside it (a marker across the box's edge was not readable there), or at the
        image's edge."""
        assert self._searched is not None
        m = self.options.change_margin_px
        w, h = self.size
        x0 = box[0] + (m if box[0] > 0 else 0)
        y0 = box[1] + (m if box[1] > 0 else 0)
        x1 = box[2] - (m if box[2] < w else 0)
        y1 = box[3] - (m if box[3] < h else 0)
        sx, sy = w / cells.shape[1], h / cells.shape[0]
        c0, r0 = int(np.ceil(x0 / sx)), int(np.ceil(y0 / sy))
        c1, r1 = int(np.floor(x1 / sx)), int(np.floor(y1 / sy))
        if c1 > c0 and r1 > r0:
            self._searched[r0:r1, c0:c1] = cells[r0:r1, c0:c1]
