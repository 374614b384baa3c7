"""AprilTag 3 (Wang and Olson, "AprilTag 2: Efficient and robust fiducial detection", IROS 2016; the
``pupil-apriltags`` binding of the AprilRobotics C library): detectors and code tables.

One detector per family and decimation, on the library's default one thread (with two its clustering
races and crashed a test process: AprilRobotics/apriltag#387), is made once per process and never
destroyed: destroying one now and then crashes the process (a double free in ``Detector.__del__``,
pupil-labs/apriltags issues 46 and 52), so at exit each is disarmed (its pointer dropped) and the
operating system frees it. A detector is used by one thread at a time (a lock each): the library keeps a
detection's working state in the detector, and two threads detecting with one detector crashed the process.

The newer families' detectors correct one bit (:data:`NEWER_FAMILY_BITS`) instead of the binding's fixed
two: AprilTag 3 tabulates every code within the corrected bits, and at two bits the tables of
``tagCircle49h12``, ``tagStandard52h13`` and ``tagCustom48h12`` take gigabytes and half a minute to build.

The code tables of the families that OpenCV does not carry (``tagStandard41h12``, ``tagStandard52h13``,
``tagCircle21h7``, ``tagCircle49h12``, ``tagCustom48h12``) are read from the library's family structs:
the printed pattern of each code is laid out from the family's bit positions (:func:`tag_cells`).
"""

from __future__ import annotations

import atexit
import ctypes
import functools
import threading
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

__all__ = ["At3Family", "at3_detect", "at3_family", "tag_cells"]

_LOCK = threading.Lock()
_DETECTORS: dict[tuple[str, float], Any] = {}
_IN_USE: dict[int, threading.Lock] = {}  # id of a detector -> the lock its detections hold
_FAMILIES: dict[str, Any] = {}

#: the families whose detector corrects the binding's two bits (AprilTag 3's defaults)
CLASSIC = ("tag16h5", "tag25h9", "tag36h11")
#: bits the newer families' detectors correct
NEWER_FAMILY_BITS = 1


@dataclass(frozen=True)
class At3Family:
    """The layout of an AprilTag 3 family (the library's ``apriltag_family_t``).

    Attributes
    ----------
    name : str
        The library's name, e.g. ``tagStandard41h12``.
    codes : (N,) uint64
        The code of each ID, bit ``nbits - 1 - i`` for the cell at ``(bit_x[i], bit_y[i])``.
    bit_x, bit_y : (nbits,) int
        Column and row of each bit, cells, from the corner of the border square (may be negative: the
        bits outside it).
    width_at_border : int
        Side of the border square, cells (the square the detector's corners span).
    total_width : int
        Side of the whole printed pattern, cells.
    reversed_border : bool
        The border square is a white ring inside a black one (the newer families) instead of a black ring.
    min_distance : int
        The family's minimum Hamming distance between codes (the ``h`` of its name).
    """

    name: str
    codes: NDArray[np.uint64]
    bit_x: NDArray[np.int64]
    bit_y: NDArray[np.int64]
    width_at_border: int
    total_width: int
    reversed_border: bool
    min_distance: int


def _disarm() -> None:
    """Drop every detector's C pointer so that ``Detector.__del__`` frees nothing at exit."""
    for det in _DETECTORS.values():
        det.tag_detector_ptr = None


atexit.register(_disarm)


def detector(name: str, quad_decimate: float = 2.0) -> Any:
    """The process's AprilTag 3 detector for the family ``name`` (e.g. ``tag36h11``) at ``quad_decimate``,
    on one thread; without its own edge refinement for the classic families (gtrig refines their corners),
    with it for the newer ones (their corners are AprilTag 3's)."""
    key = (name, float(quad_decimate))
    with _LOCK:
        det = _DETECTORS.get(key)
        if det is None:
            from pupil_apriltags import Detector

            if name in CLASSIC:
                det = Detector(families=name, nthreads=1, quad_decimate=float(quad_decimate), refine_edges=0)
            else:
                # made for a small family, then given the newer family at fewer corrected bits
                det = Detector(families="tag16h5", nthreads=1, quad_decimate=float(quad_decimate),
                               refine_edges=1)
                det.libc.apriltag_detector_clear_families.restype = None
                det.libc.apriltag_detector_clear_families(det.tag_detector_ptr)
                det.libc.apriltag_detector_add_family_bits.restype = None
                det.libc.apriltag_detector_add_family_bits(det.tag_detector_ptr, _family_ptr(det.libc, name),
                                                           NEWER_FAMILY_BITS)
            _DETECTORS[key] = det
            _IN_USE[id(det)] = threading.Lock()
        return det


def _family_ptr(libc: Any, name: str) -> Any:
    """The library's family struct ``name`` (made once, never destroyed)."""
    fam = _FAMILIES.get(name)
    if fam is None:
        from pupil_apriltags.bindings import _ApriltagFamily

        create = getattr(libc, f"{name}_create")
        create.restype = ctypes.POINTER(_ApriltagFamily)
        fam = _FAMILIES[name] = create()
    return fam


def at3_detect(gray: NDArray[np.uint8], name: str, quad_decimate: float = 2.0
               ) -> list[tuple[int, int, NDArray[np.float64]]]:
    """AprilTag 3's detections of the family ``name`` in ``gray`` (H, W) uint8 (on the calling thread; it
    releases the GIL).

    Returns
    -------
    list of (id, hamming, corners (4, 2)): corners in OpenCV's pixel convention (pixel centres at integer
    coordinates, as the library's), top-left, top-right, bottom-right, bottom-left as printed (the library
    lists them counter-clockwise on the page, from the printed top-right for the classic families and from
    the bottom-left for the newer ones, whose patterns :func:`tag_cells` lays out; measured on rendered tags).
    """
    det = detector(name, quad_decimate)
    order = [1, 0, 3, 2] if name in CLASSIC else [3, 2, 1, 0]
    out = []
    with _IN_USE[id(det)]:
        found = det.detect(np.ascontiguousarray(gray, np.uint8))
    for d in found:
        c = np.asarray(d.corners, np.float64)
        out.append((int(d.tag_id), int(d.hamming), c[order].copy()))
    return out


@functools.cache
def at3_family(name: str) -> At3Family:
    """The layout and code table of the AprilTag 3 family ``name`` read from the library."""
    libc = detector("tag16h5").libc
    with _LOCK:
        fam = _family_ptr(libc, name).contents
    n = int(fam.nbits)
    return At3Family(
        name=name,
        codes=np.ctypeslib.as_array(fam.codes, shape=(int(fam.ncodes),)).astype(np.uint64).copy(),
        bit_x=np.array([ctypes.c_int32(fam.bit_x[i]).value for i in range(n)], np.int64),
        bit_y=np.array([ctypes.c_int32(fam.bit_y[i]).value for i in range(n)], np.int64),
        width_at_border=int(fam.width_at_border),
        total_width=int(fam.total_width),
        reversed_border=bool(fam.reversed_border),
        min_distance=int(fam.h),
    )


def tag_cells(name: str, tag_id: int) -> NDArray[np.uint8]:
    """The printed pattern (total_width, total_width) of ``tag_id`` of the family ``name``, 1 = white,
    row 0 at the top: black everywhere but the white bits and, in the reversed-border families, the
    white ring of the border square (the classic families' white ring lies outside the square and is a
    margin)."""
    fam = at3_family(name)
    w = fam.total_width
    start = (w - fam.width_at_border) // 2
    out = np.zeros((w, w), np.uint8)
    if fam.reversed_border:
        a, b = start, start + fam.width_at_border - 1
        out[a, a:b + 1] = out[b, a:b + 1] = out[a:b + 1, a] = out[a:b + 1, b] = 1
    code = int(fam.codes[int(tag_id)])
    nbits = len(fam.bit_x)
    for i in range(nbits):
        if (code >> (nbits - 1 - i)) & 1:
            out[fam.bit_y[i] + start, fam.bit_x[i] + start] = 1
    return out
