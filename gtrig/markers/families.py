"""Square ID marker families: printed cell patterns and decoders.

A marker is an ``n x n`` array of square cells: a black border ``b`` cells wide around a
``d x d`` data grid, so ``n = d + 2 b``. The arrays returned here contain the border and no white
margin, so the array spans exactly the black square whose side is ``Marker.side_m`` in the rig file.
Row 0 is the top of the marker as printed, column 0 its left; cell value 1 is white, 0 black.

==========================  ====  ====  ====  ===========  =========================================
family                        d     b     n   border/side  codes
==========================  ====  ====  ====  ===========  =========================================
artoolkitplus_simple          6     3    12   0.25         512 "simple ID" (ARToolKitPlus default)
artoolkitplus_simple_thin     6     1     8   0.125        the same 512, thin border
artoolkitplus_bch             6     3    12   0.25         4096 "BCH ID" (ARToolKitPlus ``MARKER_ID_BCH``)
artoolkitplus_bch_thin        6     1     8   0.125        the same 4096, thin border (the official images)
apriltag_36h11                6     1     8   0.125        587, OpenCV ``DICT_APRILTAG_36h11``
aruco_4x4_50                  4     1     6   1/6          50, OpenCV ``DICT_4X4_50``
aruco_5x5_100                 5     1     7   1/7          100, OpenCV ``DICT_5X5_100``
aruco_6x6_250                 6     1     8   0.125        250, OpenCV ``DICT_6X6_250``
aruco_original                5     1     7   1/7          1024, OpenCV ``DICT_ARUCO_ORIGINAL``
==========================  ====  ====  ====  ===========  =========================================

(AprilTag's own images add a white ring outside the black border; it is a margin and not part of
these arrays. The "border/side" column is the border width as a fraction of the black square's side,
ARToolKitPlus' ``setBorderWidth`` value.)

ARToolKitPlus simple ID
-----------------------
ARToolKitPlus (Wagner and Schmalstieg, "ARToolKitPlus for pose tracking on mobile devices", CVWW
2007; RAWSEEDS deliverable AD2.3, section "ARToolkit") encodes a 9-bit ID in the 6 x 6 data grid:
the 9 bits are repeated four times to fill the 36 cells and all cells are scrambled with a fixed XOR
mask. Analysing the official images (``id-markers.tar.gz``, which ``tests/markers`` checks bit for
bit) gives the layout: with the data cells numbered ``k = 0..35`` in row-major order (top row first,
left to right),

    white(k) = bit(ID, 8 - k mod 9) XOR MASK(k)

where ``bit(ID, 0)`` is the least significant bit and ``MASK`` is the pattern of ID 0 (white = 1).
Each ID bit therefore controls four cells, so two codes differ in at least 4 cells (in any
rotation); the decoder corrects 1 cell.

ARToolKitPlus BCH ID
--------------------
ARToolKitPlus' second ID system holds 12-bit IDs (0..4095) in a BCH code of 36 cells. Analysing all
4096 official images (``id-markers/bch/BchThin_NNNN.png``, checked bit for bit by ``tests/markers``)
shows a systematic cyclic code behind a fixed XOR mask: with the data cells numbered ``k = 0..35`` in
row-major order and read as the coefficients of ``c(x) = sum_k c_k x^(35 - k)``,

    c(x) = ID(x) x^24 + (ID(x) x^24 mod g(x)),    white(k) = c_k XOR MASK_BCH(k)

where ``ID(x)`` has the ID's bits as coefficients (cells 0..11 hold the ID, most significant bit
first), ``g(x)`` is the degree-24 generator ``0x1DB2777`` (bit ``j`` = coefficient of ``x^j``) and
``MASK_BCH`` is the pattern of ID 0. Two IDs differ in at least 9 cells as printed, but once the
four rotations are counted some are only 2 cells apart (IDs whose rotated code is close to another
ID's code): the decoder's tolerance is therefore set per ID, ``(d_i - 1) // 2`` cells where
``d_i`` is the distance of ID ``i`` to the nearest other ID in any rotation (3 cells for most IDs,
0 for the two IDs at distance 2), so that a pattern it accepts has exactly one code that close.

OpenCV dictionaries
-------------------
AprilTag 36h11 and the ArUco dictionaries come from ``cv2.aruco.getPredefinedDictionary``; patterns
are those of ``cv2.aruco.generateImageMarker`` with a 1-cell border, so IDs agree with OpenCV (and,
for 36h11, with the AprilTag library). The decoder accepts up to the dictionary's
``maxCorrectionBits`` wrong cells, except for ``aruco_original``, whose codes can be a single cell
apart (ID 1023 is even its own 180-degree rotation): it decodes exact patterns only.

In every family a pattern equally close to two different IDs is rejected rather than guessed.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from gtrig.errors import InputError
from gtrig.rig.models import MarkerFamily

# Pattern of ARToolKitPlus simple ID 0 (= the XOR mask), white = 1, read from the official
# SimpleStd_000.png / SimpleThin_000.png; rows top to bottom.
_ARTK_MASK = np.array(
    [
        [0, 1, 1, 0, 1, 1],
        [0, 1, 1, 1, 0, 0],
        [0, 0, 1, 0, 0, 1],
        [1, 0, 1, 0, 0, 1],
        [1, 1, 0, 0, 0, 0],
        [1, 0, 0, 1, 1, 1],
    ],
    dtype=np.uint8,
)

# Pattern of ARToolKitPlus BCH ID 0 (the mask of the BCH system), white = 1, read from the official
# BchThin_0000.png; rows top to bottom.
_BCH_MASK = np.array(
    [
        [1, 0, 0, 0, 1, 1],
        [1, 1, 1, 0, 0, 0],
        [0, 0, 0, 0, 1, 0],
        [1, 1, 1, 0, 0, 0],
        [0, 1, 1, 1, 0, 1],
        [0, 1, 0, 0, 0, 0],
    ],
    dtype=np.uint8,
)
#: generator polynomial of the BCH ID code, bit j = coefficient of x^j (degree 24)
BCH_GENERATOR = 0x1DB2777

_OPENCV_DICTS: dict[str, str] = {
    "apriltag_16h5": "DICT_APRILTAG_16h5",
    "apriltag_25h9": "DICT_APRILTAG_25h9",
    "apriltag_36h10": "DICT_APRILTAG_36h10",
    "apriltag_36h11": "DICT_APRILTAG_36h11",
    "aruco_4x4_50": "DICT_4X4_50",
    "aruco_4x4_100": "DICT_4X4_100",
    "aruco_4x4_250": "DICT_4X4_250",
    "aruco_4x4_1000": "DICT_4X4_1000",
    "aruco_5x5_50": "DICT_5X5_50",
    "aruco_5x5_100": "DICT_5X5_100",
    "aruco_5x5_250": "DICT_5X5_250",
    "aruco_5x5_1000": "DICT_5X5_1000",
    "aruco_6x6_50": "DICT_6X6_50",
    "aruco_6x6_100": "DICT_6X6_100",
    "aruco_6x6_250": "DICT_6X6_250",
    "aruco_6x6_1000": "DICT_6X6_1000",
    "aruco_7x7_50": "DICT_7X7_50",
    "aruco_7x7_100": "DICT_7X7_100",
    "aruco_7x7_250": "DICT_7X7_250",
    "aruco_7x7_1000": "DICT_7X7_1000",
    "aruco_original": "DICT_ARUCO_ORIGINAL",
    "aruco_mip_36h12": "DICT_ARUCO_MIP_36h12",
}

#: the AprilTag families that AprilTag 3 reads, by its names (16h5, 25h9 and 36h11 OpenCV reads too)
AT3_NAMES: dict[str, str] = {
    "apriltag_16h5": "tag16h5",
    "apriltag_25h9": "tag25h9",
    "apriltag_36h11": "tag36h11",
    "apriltag_standard41h12": "tagStandard41h12",
    "apriltag_standard52h13": "tagStandard52h13",
    "apriltag_circle21h7": "tagCircle21h7",
    "apriltag_circle49h12": "tagCircle49h12",
    "apriltag_custom48h12": "tagCustom48h12",
}


@dataclass(frozen=True)
class FamilySpec:
    """Geometry and code size of a marker family.

    Attributes
    ----------
    family : MarkerFamily
    data_cells : int
        ``d``, the side of the data grid in cells.
    border_cells : int
        ``b``, the width of the black border in cells.
    n_ids : int
        Number of valid IDs, ``0 .. n_ids - 1``.
    max_correction : int
        Largest number of wrong data cells the decoder corrects.
    edge_model : bool
        The marker is a black square on white paper holding its data cells (every family but AprilTag 3's
        newer ones, whose square is ringed by data cells): gtrig's edge model refines its corners and gtrig
        reads its cells. For the others ``data_cells`` is the whole printed pattern's side, ``border_cells``
        0, and the detector reports AprilTag 3's own corners and ID.
    """

    family: MarkerFamily
    data_cells: int
    border_cells: int
    n_ids: int
    max_correction: int
    edge_model: bool = True

    @property
    def cells(self) -> int:
        """``n = d + 2 b``, the side of the whole black square in cells."""
        return self.data_cells + 2 * self.border_cells

    @property
    def border_fraction(self) -> float:
        """Border width as a fraction of the marker side (ARToolKitPlus' ``borderWidth``)."""
        return self.border_cells / self.cells


def _family(family: MarkerFamily | str) -> MarkerFamily:
    try:
        return MarkerFamily(family)
    except ValueError:
        names = ", ".join(f.value for f in MarkerFamily)
        raise InputError(f"unknown marker family {family!r}; expected one of {names}") from None


def _is_artk(family: MarkerFamily) -> bool:
    return family.value.startswith("artoolkitplus_simple")


def _is_bch(family: MarkerFamily) -> bool:
    return family.value.startswith("artoolkitplus_bch")


def is_at3_only(family: MarkerFamily | str) -> bool:
    """The family is one of AprilTag 3's newer ones, which OpenCV does not carry and gtrig's edge model
    does not fit (:attr:`FamilySpec.edge_model`)."""
    return _family(family).value in AT3_NAMES and _family(family).value not in _OPENCV_DICTS


def opencv_dictionary_name(family: MarkerFamily | str) -> str | None:
    """OpenCV's predefined dictionary of ``family`` (e.g. ``DICT_4X4_50``), None for the others."""
    return _OPENCV_DICTS.get(_family(family).value)


@functools.cache
def _opencv_dict(family: MarkerFamily) -> Any:
    import cv2

    return cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, _OPENCV_DICTS[family.value]))


@functools.cache
def family_spec(family: MarkerFamily | str) -> FamilySpec:
    """The :class:`FamilySpec` of ``family`` (a :class:`MarkerFamily` or its string value)."""
    fam = _family(family)
    if _is_artk(fam):
        border = 1 if fam.value.endswith("_thin") else 3
        return FamilySpec(fam, 6, border, 512, 1)
    if _is_bch(fam):
        # per-ID tolerances (id_correction) are at most 3 cells; see the module docstring
        border = 1 if fam.value.endswith("_thin") else 3
        return FamilySpec(fam, 6, border, 4096, 3)
    if is_at3_only(fam):
        from gtrig.markers.apriltag3 import at3_family

        t = at3_family(AT3_NAMES[fam.value])
        return FamilySpec(fam, t.total_width, 0, len(t.codes), 2, edge_model=False)
    d = _opencv_dict(fam)
    # ARUCO_ORIGINAL has codes 1 cell apart (in some rotation): correcting would mis-identify.
    corr = 0 if fam is MarkerFamily.ARUCO_ORIGINAL else int(d.maxCorrectionBits)
    return FamilySpec(fam, int(d.markerSize), 1, int(d.bytesList.shape[0]), corr)


def _artk_data(ids: NDArray[np.int64]) -> NDArray[np.uint8]:
    """Data grids (K, 6, 6) of ARToolKitPlus simple IDs ``ids`` (K,)."""
    k = np.arange(36)
    bits = (ids[:, None] >> (8 - k % 9)[None, :]) & 1
    return (bits.astype(np.uint8) ^ _ARTK_MASK.ravel()[None, :]).reshape(-1, 6, 6)


def _bch_data(ids: NDArray[np.int64]) -> NDArray[np.uint8]:
    """Data grids (K, 6, 6) of ARToolKitPlus BCH IDs ``ids`` (K,): the systematic code word
    ``ID x^24 + (ID x^24 mod g)`` (module docstring), most significant coefficient in cell 0."""
    ids = np.asarray(ids, np.int64)
    rem = ids << 24
    # polynomial long division over GF(2), all IDs at once: clear bits 35..24 from the top
    for j in range(35, 23, -1):
        rem = np.where((rem >> j) & 1, rem ^ (BCH_GENERATOR << (j - 24)), rem)
    word = (ids << 24) | rem
    bits = (word[:, None] >> (35 - np.arange(36))[None, :]) & 1
    return (bits.astype(np.uint8) ^ _BCH_MASK.ravel()[None, :]).reshape(-1, 6, 6)


@functools.cache
def id_correction(family: MarkerFamily | str) -> NDArray[np.int64]:
    """The decoder's tolerance per ID, (n_ids,) cells: the family's ``max_correction`` for every ID,
    except for the BCH family, where it is ``(d_i - 1) // 2`` with ``d_i`` the distance of ID ``i``
    to the nearest other ID in any of its four rotations (capped at ``max_correction``)."""
    fam = _family(family)
    spec = family_spec(fam)
    if not _is_bch(fam):
        return np.full(spec.n_ids, spec.max_correction, np.int64)
    from gtrig.markers.detect._kernels import nearest_codes

    table = _packed_rotations(fam)  # (N, 4)
    _, _, d = nearest_codes(np.ascontiguousarray(table[:, 0]), np.ascontiguousarray(table))
    return np.minimum((d - 1) // 2, spec.max_correction).astype(np.int64)


@functools.cache
def _codebook(family: MarkerFamily) -> NDArray[np.uint8]:
    """All data grids of a family, (n_ids, d, d) uint8, white = 1, as printed (families with
    :attr:`FamilySpec.edge_model`; the others are AprilTag 3's to decode)."""
    spec = family_spec(family)
    if not spec.edge_model:
        raise InputError(f"{family.value}: gtrig does not decode this family's cells (AprilTag 3 does)")
    if _is_artk(family):
        return _artk_data(np.arange(512))
    if _is_bch(family):
        return _bch_data(np.arange(4096))
    import cv2

    d = _opencv_dict(family)
    n = spec.cells
    out = np.empty((spec.n_ids, spec.data_cells, spec.data_cells), np.uint8)
    for i in range(spec.n_ids):
        img = cv2.aruco.generateImageMarker(d, i, n, borderBits=1)
        out[i] = (img[1:-1, 1:-1] > 127).astype(np.uint8)
    return out


def _pack(bits: NDArray[np.uint8]) -> NDArray[np.uint64]:
    """Pack (..., m) bits (m <= 64) into uint64 words, bit j of the word = bits[..., j]."""
    m = bits.shape[-1]
    w = np.left_shift(np.uint64(1), np.arange(m, dtype=np.uint64))
    return (bits.astype(np.uint64) * w).sum(axis=-1, dtype=np.uint64)


_POP8 = np.array([bin(i).count("1") for i in range(256)], dtype=np.uint8)


def _popcount(x: NDArray[np.uint64]) -> NDArray[np.int64]:
    if hasattr(np, "bitwise_count"):
        return np.bitwise_count(x).astype(np.int64)
    b = x[..., None].view(np.uint8) if x.ndim else np.atleast_1d(x).view(np.uint8)
    return _POP8[b.reshape(*x.shape, 8)].sum(-1).astype(np.int64)


@functools.cache
def _packed_rotations(family: MarkerFamily) -> NDArray[np.uint64]:
    """(n_ids, 4) packed codes; column ``r`` is the code as observed after ``np.rot90(printed, -r)``,
    so that ``np.rot90(observed, r)`` gives back the printed grid."""
    book = _codebook(family)
    rots = np.stack([np.rot90(book, -r, axes=(1, 2)) for r in range(4)], axis=1)
    return _pack(rots.reshape(book.shape[0], 4, -1))


def marker_cells(family: MarkerFamily | str, marker_id: int) -> NDArray[np.uint8]:
    """The printed pattern of a marker, border included.

    Parameters
    ----------
    family : MarkerFamily or str
    marker_id : int
        ID in ``0 .. family_spec(family).n_ids - 1``.

    Returns
    -------
    numpy.ndarray, shape (n, n), uint8
        1 = white, 0 = black; row 0 = top of the marker as printed; ``n = d + 2 b`` (see the module
        docstring). The array spans the black square exactly (no white margin).

    Raises
    ------
    InputError
        Unknown family or ID out of range.
    """
    fam = _family(family)
    spec = family_spec(fam)
    if not (0 <= int(marker_id) < spec.n_ids):
        raise InputError(f"marker id {marker_id} out of range for {fam.value} (0..{spec.n_ids - 1})")
    if not spec.edge_model:
        from gtrig.markers.apriltag3 import tag_cells

        return tag_cells(AT3_NAMES[fam.value], int(marker_id))
    out = np.zeros((spec.cells, spec.cells), np.uint8)
    b = spec.border_cells
    out[b:-b, b:-b] = _codebook(fam)[int(marker_id)]
    return out


def decode_batch(
    family: MarkerFamily | str, data: ArrayLike, max_hamming: int | None = None
) -> tuple[NDArray[np.int64], NDArray[np.int64], NDArray[np.int64]]:
    """Decode many observed data grids at once against all IDs in all four rotations.

    Parameters
    ----------
    family : MarkerFamily or str
    data : array_like, shape (K, d, d)
        Observed data cells (1 = white), row 0 = the image-side of the first two detected corners.
    max_hamming : int, optional
        Largest accepted number of wrong cells; default the family's ``max_correction``.

    Returns
    -------
    ids, rotations, hammings : numpy.ndarray, shape (K,), int
        ``ids[k] = -1`` where no code is within ``max_hamming``. ``np.rot90(data[k], rotations[k])``
        is the printed grid of ``ids[k]`` (up to ``hammings[k]`` cells).
    """
    fam = _family(family)
    spec = family_spec(fam)
    obs = np.asarray(data).astype(np.uint8).reshape(-1, spec.data_cells * spec.data_cells)
    lim = spec.max_correction if max_hamming is None else int(max_hamming)
    table = _packed_rotations(fam)  # (N, 4)
    if obs.shape[0] == 0:
        z = np.zeros(0, np.int64)
        return z, z.copy(), z.copy()
    from gtrig.markers.detect._kernels import nearest_codes

    best, h, second = nearest_codes(_pack(obs), np.ascontiguousarray(table))
    ids = best // 4
    rot = best % 4
    # a pattern as close to another ID as to the best is ambiguous
    ambiguous = second <= h if table.shape[0] > 1 else np.zeros_like(h, bool)
    lims = np.full(len(ids), lim)
    if lim <= spec.max_correction:
        # within the family's tolerance each ID has its own (the BCH family; see id_correction)
        lims = np.minimum(lims, id_correction(fam)[ids])
    ids = np.where((h <= lims) & ~ambiguous, ids, -1)
    return ids.astype(np.int64), rot.astype(np.int64), h.astype(np.int64)


def decode_cells(
    family: MarkerFamily | str, cells: ArrayLike, max_hamming: int | None = None
) -> tuple[int, int, int] | None:
    """Decode one observed cell array.

    Parameters
    ----------
    family : MarkerFamily or str
    cells : array_like, shape (n, n) or (d, d)
        Observed cells (1 = white), either the whole black square with its border or only the data
        grid. With the border, more than ``n // 4`` white border cells reject the candidate.
    max_hamming : int, optional
        Largest accepted number of wrong data cells; default the family's ``max_correction``.

    Returns
    -------
    (marker_id, rotation, hamming) or None
        ``np.rot90(cells, rotation)`` is the printed pattern of ``marker_id`` with ``hamming``
        data cells wrong; None when no code is close enough.
    """
    fam = _family(family)
    spec = family_spec(fam)
    c = np.asarray(cells)
    if c.shape == (spec.cells, spec.cells):
        b = spec.border_cells
        border_white = int(c.sum() - c[b:-b, b:-b].sum())
        if border_white > spec.cells // 4:
            return None
        c = c[b:-b, b:-b]
    elif c.shape != (spec.data_cells, spec.data_cells):
        raise InputError(
            f"{fam.value}: expected {spec.cells} x {spec.cells} or {spec.data_cells} x {spec.data_cells} "
            f"cells, got {' x '.join(map(str, c.shape))}"
        )
    ids, rot, ham = decode_batch(fam, c[None], max_hamming)
    if ids[0] < 0:
        return None
    return int(ids[0]), int(rot[0]), int(ham[0])


@functools.cache
def all_codes(family: MarkerFamily | str) -> NDArray[np.uint8]:
    """Every code of ``family`` in its four rotations as read in a quad's orientation, (4 n_ids, d, d):
    index ``r n_ids + id`` holds ``np.rot90(printed data, -r)``."""
    book = _codebook(_family(family))
    return np.ascontiguousarray(np.concatenate([np.rot90(book, -r, axes=(1, 2)) for r in range(4)]))
