"""The instants of a sequence: which images of which cameras GTvision estimates one pose from.

* ``run``: the images of all cameras whose time stamps agree within ``sync_tol_s`` form one instant
  (free-running cameras rarely agree, so an instant is then one camera's frame; GTvision never mixes
  images of a moving robot taken at different times).
* ``validation``: the robot stands still during each interval of ``validation/poses.csv``, so all the
  images of all cameras inside one interval are one instant, stamped at the interval's middle.

A recording of hours has millions of images (8 cameras at 30 Hz for 3 hours: 2.6 million), so the
instants are held as flat arrays (:class:`Instants`, about 30 bytes per instant and image instead of
some 270 as one object per instant) and grouped by array operations and one loop over plain
integers, not over Python tuples of every image.
"""

from __future__ import annotations

from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass
from typing import Any, overload

import numpy as np

from gtrig.errors import InputError
from gtrig.io.frames import FrameIndex


@dataclass(frozen=True, slots=True)  # slots: made one at a time on demand, but many may be alive at once
class Instant:
    """The images that make one instant: ``stamp_s`` and ``(camera, row in its frame index)``."""

    stamp_s: float
    images: tuple[tuple[str, int], ...]


class Instants(Sequence[Instant]):
    """A sequence's instants as flat arrays; item ``i`` is made as an :class:`Instant` when asked for.

    Parameters
    ----------
    cameras : (C,) the camera names, sorted; ``camera`` indexes them.
    stamp_s : (N,) each instant's time, seconds (increasing for ``run``).
    start : (N + 1,) instant ``i``'s images are ``camera[start[i]:start[i + 1]]``, ``row[...]``.
    camera : (M,) each image's camera, into ``cameras``. row : (M,) its row in the camera's frame index.
    """

    def __init__(self, cameras: Sequence[str], stamp_s: np.ndarray, start: np.ndarray, camera: np.ndarray,
                 row: np.ndarray) -> None:
        self.cameras = tuple(cameras)
        self.stamp_s = np.asarray(stamp_s, np.float64)
        self.start = np.asarray(start, np.int64)
        self.camera = np.asarray(camera, np.int16 if len(self.cameras) < 2**15 else np.int64)
        self.row = np.asarray(row, np.int64)

    def __len__(self) -> int:
        return int(self.stamp_s.size)

    @overload
    def __getitem__(self, i: int) -> Instant: ...

    @overload
    def __getitem__(self, i: slice) -> list[Instant]: ...

    def __getitem__(self, i: Any) -> Any:
        if isinstance(i, slice):
            return [self[k] for k in range(*i.indices(len(self)))]
        i = int(i)
        if i < 0:
            i += len(self)
        if not 0 <= i < len(self):
            raise IndexError(i)
        a, b = int(self.start[i]), int(self.start[i + 1])
        return Instant(float(self.stamp_s[i]),
                       tuple((self.cameras[c], r) for c, r in zip(self.camera[a:b].tolist(), self.row[a:b].tolist(),
                                                                  strict=True)))

    def __iter__(self) -> Iterator[Instant]:
        for i in range(len(self)):
            yield self[i]

    def camera_rows(self) -> dict[str, np.ndarray]:
        """Per camera, the rows of its frame index that some instant uses, sorted, each once."""
        used = {name: np.unique(self.row[self.camera == c]) for c, name in enumerate(self.cameras)}
        return {name: r for name, r in used.items() if r.size}

    @staticmethod
    def from_groups(cameras: Sequence[str], stamp_s: Sequence[float],
                    groups: Sequence[Sequence[tuple[int, int]]]) -> Instants:
        """From each instant's ``(camera index, row)`` pairs."""
        sizes = np.array([len(g) for g in groups], np.int64)
        flat = [p for g in groups for p in g]
        cam = np.array([c for c, _ in flat], np.int64).reshape(-1)
        row = np.array([r for _, r in flat], np.int64).reshape(-1)
        return Instants(cameras, np.asarray(stamp_s, float), np.concatenate([[0], np.cumsum(sizes)]), cam, row)


def _validation_instants(indices: Mapping[str, FrameIndex], intervals_s: np.ndarray) -> Instants:
    """One instant per static interval: every image of every camera inside it, at the interval's middle."""
    names = sorted(indices)
    groups = []
    for t0, t1 in intervals_s:
        imgs: list[tuple[int, int]] = []
        for c, name in enumerate(names):
            st = indices[name].stamps_s
            imgs.extend((c, int(i)) for i in np.flatnonzero((st >= t0) & (st <= t1)))
        groups.append(imgs)
    return Instants.from_groups(names, [float(0.5 * (t0 + t1)) for t0, t1 in intervals_s], groups)


def _group_ends(t: np.ndarray, cam: np.ndarray, sync_tol_s: float) -> np.ndarray:
    """Where each instant ends in the time-sorted images (``t``, ``cam``): an image joins the open
    instant unless it is more than ``sync_tol_s`` after the instant's first image or its camera is
    already in it. Returns the (N,) exclusive ends."""
    ends: list[int] = []
    t_l, cam_l = t.tolist(), cam.tolist()
    t0, seen = 0.0, 0
    for k, (tk, ck) in enumerate(zip(t_l, cam_l, strict=True)):
        bit = 1 << ck
        if k and (tk - t0 > sync_tol_s or seen & bit):
            ends.append(k)
            seen = 0
        if not seen:
            t0 = tk
        seen |= bit
    if t_l:
        ends.append(len(t_l))
    return np.array(ends, np.int64)


def make_instants(indices: Mapping[str, FrameIndex], sequence: str, sync_tol_s: float = 0.005,
                  intervals_s: np.ndarray | None = None) -> Instants:
    """Group the images of all cameras into instants (see the module docstring).

    Parameters
    ----------
    indices : each camera's frame index.
    sequence : ``"run"`` or ``"validation"``.
    sync_tol_s : images of different cameras this close (to the instant's first image) are one instant.
    intervals_s : (K, 2) the validation sequence's static intervals, seconds.

    Returns
    -------
    The instants, in time order for ``run``; an instant's time is the mean of its images' stamps.
    """
    if sequence == "validation":
        if intervals_s is None:
            raise InputError("the validation sequence needs its static intervals")
        return _validation_instants(indices, intervals_s)
    names = sorted(indices)
    t = np.concatenate([np.asarray(indices[n].stamps_s, float) for n in names] + [np.zeros(0)])
    cam = np.concatenate([np.full(len(indices[n]), c, np.int64) for c, n in enumerate(names)] + [np.zeros(0, np.int64)])
    row = np.concatenate([np.arange(len(indices[n]), dtype=np.int64) for n in names] + [np.zeros(0, np.int64)])
    order = np.lexsort((row, cam, t))  # by time, then camera name, then row: the order instants are made in
    t, cam, row = t[order], cam[order], row[order]
    ends = _group_ends(t, cam, sync_tol_s)
    start = np.concatenate([[0], ends])
    return Instants(names, _group_means(t, start), start, cam, row)


def _group_means(t: np.ndarray, start: np.ndarray) -> np.ndarray:
    """(N,) the mean of each group ``t[start[i]:start[i + 1]]``, bit for bit as ``np.mean`` of the group:
    the groups of one size are averaged as the rows of one array (``np.add.reduceat`` sums in another
    order and differs in the last bit)."""
    counts = np.diff(start)
    out = np.zeros(counts.size)
    for k in np.unique(counts):
        at = np.flatnonzero(counts == k)
        out[at] = t[start[at][:, None] + np.arange(k)].mean(axis=1)
    return out
