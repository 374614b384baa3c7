"""gtrig's reading of a peer's marker through the refined corners: the cells confirm or refuse the ID.

The data cells are solved from the blurred image through the refined corners' homography
(:func:`.decode.unblur_cells`, the blur and levels of the edge fits), then thresholded. A peer's ID is
refused, and counted as a wrong-ID guard, when gtrig's cells contradict it:

- the cells decode, within the family's correction and unambiguously (:func:`gtrig.markers.families.
  decode_batch`), to another ID; or
- the code nearest the solved cells in the least-squares sense is another ID's and leads the peer's by
  at least ``min_soft_margin`` chi-square units of the cells' residual variance
  (:func:`.decode.soft_code_margin`).

Cells that a blur has lost read as no code and contradict nothing: the peer's ID stands. The rotation
at which the cells are nearest the peer's code gives the corners' printed order.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from gtrig.markers.detect.camera import Undistorter
from gtrig.markers.detect.decode import sample_cells, soft_code_margin, unblur_cells
from gtrig.markers.detect.edges import CLIP_HIGH
from gtrig.markers.detect.refine import Refined
from gtrig.markers.detect.tone import Tone, to_levels
from gtrig.markers.families import FamilySpec, all_codes, decode_batch, marker_cells
from gtrig.rig.models import MarkerFamily

__all__ = ["CodeBook", "Verdict", "code_book", "read_whiteness", "read_whiteness_plain", "verify_ids"]


@dataclass(frozen=True)
class Verdict:
    """gtrig's judgement of K peer IDs.

    ok : (K,) bool, the cells do not contradict the peer's ID; rot : (K,) the rotation ``r`` at which the
    cells read as the peer's code (``np.rot90(cells, r)`` is the printed pattern); hamming : (K,) cells
    that differ from the peer's code at that rotation; reason : (K,) why a refused ID was refused ("" if not).
    """

    ok: NDArray[np.bool_]
    rot: NDArray[np.int64]
    hamming: NDArray[np.int64]
    reason: list[str]

    def take(self, rows: slice | NDArray[np.int64]) -> Verdict:
        """The verdict of the peer IDs ``rows`` (a slice or indices) of these."""
        pick = range(len(self.reason))[rows] if isinstance(rows, slice) else rows
        return Verdict(self.ok[rows], self.rot[rows], self.hamming[rows], [self.reason[k] for k in pick])


@dataclass(frozen=True)
class CodeBook:
    """A family's codes in the forms every detection reads them in (made once per family, :func:`code_book`).

    codes : (4 n_ids, d, d) uint8, every code in each rotation as read in a quad's orientation, index
    ``r n_ids + id`` (:func:`gtrig.markers.families.all_codes`); flat : (4 n_ids, d^2) float64, the same
    rows for the least-squares reading (:func:`.decode.soft_code_margin`); flat_sq : (4 n_ids,) their sums of
    squares; cells : (n_ids, n, n) float64, each ID's printed pattern with its border (1 = white), the edge
    fits' model of its cells.
    """

    codes: NDArray[np.uint8]
    flat: NDArray[np.float64]
    flat_sq: NDArray[np.float64]
    cells: NDArray[np.float64]


@functools.cache
def code_book(family: MarkerFamily) -> CodeBook:
    """The :class:`CodeBook` of an edge-model ``family`` (cached: a detection used to rebuild the rotated
    codes and their float copies on every call, a millisecond for ``aruco_5x5_1000``)."""
    codes = all_codes(family)
    flat = codes.reshape(len(codes), -1).astype(np.float64)
    n_ids = len(codes) // 4
    cells = np.array([marker_cells(family, i) for i in range(n_ids)], np.float64)
    for a in (codes, flat, cells):
        a.setflags(write=False)
    sq = (flat * flat).sum(axis=1)
    sq.setflags(write=False)
    return CodeBook(codes, flat, sq, cells)


def read_whiteness(gray: NDArray[np.uint8], r: Refined, idx: NDArray[np.int64], spec: FamilySpec, tone: Tone,
                   max_blur_px: float, und: Undistorter | None) -> NDArray[np.float64]:
    """The data cells' whiteness (K, d, d) (about 0 black, 1 white, in the quads' orientation) of the refined
    quads ``idx`` of ``r``, solved through the blur model with the edge fits' blur and levels."""
    black, contrast = r.levels
    black, contrast = black[idx], contrast[idx]
    # an over-exposed white level lies beyond 255 (the edge fits censor clipped pixels): the cells are read
    # against the contrast the image can show
    contrast = np.minimum(contrast, CLIP_HIGH + 0.5 - black)
    if tone != "linear":
        # the cells are read in the stored levels
        black_lv = to_levels(black, tone)
        black, contrast = black_lv, to_levels(black + contrast, tone) - black_lv
    sigma = np.clip(r.blur[idx], 0.3, max_blur_px)
    return unblur_cells(gray, r.corners[idx], spec.cells, spec.border_cells, sigma, black, contrast, und)


def read_whiteness_plain(gray: NDArray[np.uint8], quads: NDArray[np.float64], spec: FamilySpec,
                         und: Undistorter | None) -> NDArray[np.float64]:
    """The data cells' whiteness (K, d, d) read through quads (K, 4, 2) (fit coordinates) whose edges the
    model could not fit: each cell's mean scaled between the border's median (black) and the median of the
    ring of paper outside the square (white)."""
    n, b = spec.cells, spec.border_cells
    v = np.asarray(sample_cells(gray, quads, n, und, ring=1))
    inner = v[:, 1:-1, 1:-1]
    ring = np.concatenate([v[:, 0, :], v[:, -1, :], v[:, 1:-1, 0], v[:, 1:-1, -1]], axis=1)
    border = np.ones((n, n), bool)
    border[b:-b, b:-b] = False
    black = np.median(inner[:, border], axis=1)[:, None, None]
    white = np.median(ring, axis=1)[:, None, None]
    return np.asarray((inner[:, b:-b, b:-b] - black) / np.maximum(white - black, 1.0), np.float64)


def verify_ids(whiteness: NDArray[np.float64], peer_ids: NDArray[np.int64], spec: FamilySpec,
               book: CodeBook, min_soft_margin: float) -> Verdict:
    """Judge the peer IDs ``peer_ids`` (K,) against gtrig's cells ``whiteness`` (K, d, d).

    ``book`` holds the family's codes (:func:`code_book`): ``book.codes`` (4 n_ids, d, d), every code in each
    rotation as read in a quad's orientation, index ``r n_ids + id`` (rotation ``r``: the code after
    ``np.rot90(printed, -r)``).
    """
    codes = book.codes
    K = len(peer_ids)
    n_ids = spec.n_ids
    bits = (whiteness > 0.5).astype(np.uint8)
    ids, _, _ = decode_batch(spec.family, bits, spec.max_correction)
    # the peer's code in its four rotations against the cells read
    own = codes[np.arange(4)[None, :] * n_ids + peer_ids[:, None]]  # (K, 4, d, d)
    ham4 = (own != bits[:, None]).reshape(K, 4, -1).sum(axis=2)
    rot = np.argmin(ham4, axis=1)
    ham = ham4[np.arange(K), rot]
    ok = np.ones(K, bool)
    reason = [""] * K
    hard = (ids >= 0) & (ids != peer_ids)
    nearest, lead = (soft_code_margin(whiteness, book.flat, book.flat_sq) if K and min_soft_margin > 0
                     else (np.full(K, -1), np.zeros(K)))
    soft_id = np.where(nearest >= 0, nearest % n_ids, -1)
    soft = (min_soft_margin > 0) & (soft_id != peer_ids) & (lead >= min_soft_margin)
    for k in np.flatnonzero(hard | soft):
        ok[k] = False
        reason[k] = (f"gtrig's cells read ID {ids[k]}, not {peer_ids[k]}" if hard[k]
                     else f"gtrig's cells single out ID {soft_id[k]} (lead {lead[k]:.0f}), not {peer_ids[k]}")
    return Verdict(ok, rot.astype(np.int64), ham.astype(np.int64), reason)
