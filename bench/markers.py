"""Benchmark of the gtrig marker detector against its peers, OpenCV's ArUco detector and AprilTag 3.

Three tables, every peer measured in the same run on the same images:

- ``--photos``: the real photos of ``../shared/data/markers_real`` (the six top-level photos and the
  five public sets): per set, photos, markers found by gtrig, OpenCV (default parameters), AprilTag 3
  (default parameters; and ``quad_decimate=1``, its small-tag setting) counting the IDs printed in the
  set (a peer's ID off the set is its false reading, and so is an AprilTag 3 reading with two corrected bits
  that no other peer confirms), gtrig's wrong IDs (an ID not printed and that no
  peer reports at that place), milliseconds per photo of each and gtrig / OpenCV; then the board-fit
  residuals of the ChArUco photos and the grid photo for gtrig and each OpenCV corner refinement;
- the renders' accuracy table (default): synthetic 1024 x 768 images (``gtrig.markers.synth``: 8x
  supersampled homography rendering, Gaussian blur, area downsampling, noise 3, a cluttered and unevenly
  lit background) with three AprilTag 36h11 markers each, across marker side, tilt, blur 0-2 px and
  lighting: corner RMS error against the truth (correctly identified markers), detection rate, false
  detections per image, for gtrig, OpenCV with each ``cornerRefinementMethod`` and AprilTag 3 at
  ``quad_decimate=1``;
- the speed tables (``--quick`` or default for the renders, ``--photos`` for each real set): milliseconds
  per image of gtrig, OpenCV's ``ArucoDetector`` (no refinement) and AprilTag 3 at ``quad_decimate=1``,
  each with its default threads, and the budget that applies to the set, decided in the same run: 1.5x
  OpenCV's time, unless gtrig without its AprilTag 3 pass misses on some image of the set a marker that a
  peer finds; then, on the AprilTag images, AprilTag 3's time at ``quad_decimate=1`` (the small-tag setting
  that recall then calls for), and 1.5x OpenCV's on the others. Times are medians of ``--repeat`` runs per
  image (wall clock, and process CPU time of all threads, which a loaded machine disturbs less), summed
  over the set. ``--photos`` then splits gtrig's whole detection by stage (OpenCV's call, AprilTag 3's, the
  edge fits, the rest: ID verification, covariances, lens, Python per marker), CPU time on one thread.

``--hard`` runs the harder simulated set (JPEG 60-95, half Bayer-demosaiced, textured, pale or cluttered
backgrounds, glare, print gain, paper texture, bent prints, markers of 10-70 px, blur 0-1.5 px, noise 2-5)
as a regression check of recall and wrong IDs: some of its markers cannot be read even at their true
corners, and it is not a target.

Usage::

    python bench/markers.py --photos        # the real photos and their speed (--repeat 3: medians of 3 runs)
    python bench/markers.py                 # the renders: accuracy and speed
    python bench/markers.py --quick         # a smaller grid of renders
    python bench/markers.py --hard          # the harder simulated set
    python bench/markers.py --refine-only   # the edge refinement alone, against cornerSubPix
    python bench/markers.py --refine-only --sweep   # its time against accuracy for several settings
    python bench/markers.py --refine-only --photos  # the edge refinement alone on the real photos' quads
    python bench/markers.py --clipped       # sunlit markers of the simulated GT room: error, sigma, NEES
    python bench/markers.py --clipped --synth  # the same on synth renders over clipping degree, blur, smear
"""

from __future__ import annotations

import argparse
import itertools
import json
import os
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import cv2
import numpy as np
from numpy.typing import NDArray

from gtrig.markers.detect import DetectorParams, MarkerDetector, PeerParams
from gtrig.markers.families import marker_cells
from gtrig.markers.synth import clutter_background, homography_from_pose, render, textured_background
from gtrig.rig.models import MarkerFamily

SHAPE = (768, 1024)
FAMILY = MarkerFamily.APRILTAG_36H11
CV_REFINE = {"NONE": cv2.aruco.CORNER_REFINE_NONE, "SUBPIX": cv2.aruco.CORNER_REFINE_SUBPIX,
             "CONTOUR": cv2.aruco.CORNER_REFINE_CONTOUR, "APRILTAG": cv2.aruco.CORNER_REFINE_APRILTAG}
REAL = Path(__file__).resolve().parents[1] / ".." / "shared" / "data" / "markers_real"


@dataclass
class Stats:
    """Detections of one detector against the truth."""

    sq_err: list[float] = field(default_factory=list)
    found: int = 0
    total: int = 0
    false: int = 0
    images: int = 0
    ms: list[float] = field(default_factory=list)

    def add(self, dets: list[tuple[int, np.ndarray]], truths: list, ms: float) -> None:
        self.images += 1
        self.ms.append(ms)
        self.total += len(truths)
        used: set[int] = set()
        for mid, c in dets:
            for k, t in enumerate(truths):
                if k not in used and t.marker_id == mid and np.abs(c - t.corners_px).max() < 5:
                    used.add(k)
                    self.found += 1
                    self.sq_err.extend(np.sum((c - t.corners_px) ** 2, axis=1).tolist())
                    break
            else:
                self.false += 1

    @property
    def rms(self) -> float:
        return float(np.sqrt(np.mean(self.sq_err))) if self.sq_err else float("nan")


def _apriltag3() -> Any:
    """AprilTag 3 for 36h11 at ``quad_decimate=1`` (:mod:`gtrig.markers.apriltag3`: made once, never destroyed)."""
    from gtrig.markers.apriltag3 import detector

    return detector("tag36h11", 1.0)


def _run(name: str, det: Any, img: np.ndarray) -> tuple[list[tuple[int, np.ndarray]], float]:
    """Detections (ID, corners TL, TR, BR, BL) and wall-clock ms of one detector on one image."""
    t0 = time.perf_counter()
    if name.startswith("gtrig"):
        out = [(d.id, d.corners_px) for d in det.detect(img)]
    elif name == "apriltag3":
        # the library lists a classic family's corners from the printed top-right, counter-clockwise on the page
        out = [(int(r.tag_id), np.asarray(r.corners, float)[[1, 0, 3, 2]]) for r in det.detect(img)]
    else:
        corners, ids, _ = det.detectMarkers(img)
        out = [] if ids is None else [(int(i), c.reshape(4, 2).astype(float))
                                      for i, c in zip(ids.ravel(), corners, strict=True)]
    return out, (time.perf_counter() - t0) * 1000.0


def _timed(fn: Any, repeat: int) -> tuple[Any, float, float]:
    """``fn()``'s result and its median wall-clock and process CPU (every thread) times over ``repeat`` runs, ms."""
    ms, cpu = [], []
    out = None
    for _ in range(max(1, repeat)):
        t0, c0 = time.perf_counter(), time.process_time()
        out = fn()
        ms.append((time.perf_counter() - t0) * 1000.0)
        cpu.append((time.process_time() - c0) * 1000.0)
    return out, float(np.median(ms)), float(np.median(cpu))


@dataclass
class Budget:
    """One set's time, its peers' and its budget (:func:`_speed_row`), ms summed over its images."""

    images: int = 0
    gtrig: float = 0.0
    opencv: float = 0.0
    at3_qd1: float = 0.0  # on the AprilTag images
    at3_images: int = 0
    opencv_at3_images: float = 0.0  # OpenCV's time on the AprilTag images
    needs_at3: bool = False  # gtrig without its AprilTag 3 pass misses a marker a peer finds somewhere

    def add(self, gtrig: float, opencv: float, at3_qd1: float | None, missed: bool) -> None:
        self.images += 1
        self.gtrig += gtrig
        self.opencv += opencv
        if at3_qd1 is not None:
            self.at3_images += 1
            self.at3_qd1 += at3_qd1
            self.opencv_at3_images += opencv
        self.needs_at3 |= missed

    @property
    def budget(self) -> float:
        """ms: 1.5x OpenCV's, or AprilTag 3's at qd=1 on the AprilTag images where recall needs it."""
        if self.needs_at3 and self.at3_images:
            return self.at3_qd1 + 1.5 * (self.opencv - self.opencv_at3_images)
        return 1.5 * self.opencv


SPEED_HEADER = (f"{'set':28s} {'images':>6s} {'gtrig ms':>9s} {'OpenCV ms':>9s} {'AT3qd1 ms':>9s} {'gtrig/cv':>8s} "
                f"{'budget':>10s} {'budget ms':>9s} {'gtrig/budget':>12s} {'met':>4s} {'CPU gtrig/budget':>16s} "
                f"{'met':>4s}")


def _speed_row(name: str, b: Budget, cpu: Budget) -> str:
    """One row of the speed table: wall-clock ms per image (means of the per-image medians), the budget and
    whether it is met; then the same by process CPU time (all threads), which a loaded machine disturbs less."""
    n = max(b.images, 1)
    at3 = f"{b.at3_qd1 / b.at3_images:9.1f}" if b.at3_images else f"{'-':>9s}"
    kind = "AT3 qd=1" if b.needs_at3 and b.at3_images else "1.5x cv"
    return (f"{name:28s} {b.images:6d} {b.gtrig / n:9.1f} {b.opencv / n:9.1f} {at3} {b.gtrig / b.opencv:8.2f} "
            f"{kind:>10s} {b.budget / n:9.1f} {b.gtrig / b.budget:12.2f} {'yes' if b.gtrig <= b.budget else 'no':>4s} "
            f"{cpu.gtrig / cpu.budget:16.2f} {'yes' if cpu.gtrig <= cpu.budget else 'no':>4s}")


def _opencv(dictionary: str, refine: str = "NONE") -> Any:
    p = cv2.aruco.DetectorParameters()
    p.cornerRefinementMethod = CV_REFINE[refine]
    return cv2.aruco.ArucoDetector(cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, dictionary)), p)


# ---------------------------------------------------------------------------------------------- renders


def _scene(rng: np.random.Generator, side: float, tilt: float, blur: float, light: str) -> tuple[np.ndarray, list]:
    centres = [(220, 250), (520, 520), (800, 260)]
    ids = rng.choice(587, 3, replace=False)
    markers = []
    for c, mid in zip(centres, ids, strict=True):
        jit = rng.uniform(-40, 40, 2)
        H = homography_from_pose(side, (c[0] + jit[0], c[1] + jit[1]), tilt, rng.uniform(0, 360), rng.uniform(0, 360))
        markers.append((FAMILY, int(mid), H))
    bg = clutter_background(SHAPE, rng, n_shapes=40)
    gain, grad = {"uniform": (230.0, 0.0), "gradient": (200.0, 0.8), "dim": (70.0, 0.3)}[light]
    return render(SHAPE, markers, blur_px=blur, noise=3.0, gain=gain, gradient=grad, background=bg, rng=rng)


def _bench_renders(rng: np.random.Generator, quick: bool) -> None:
    no_at3 = DetectorParams(peers=PeerParams(apriltag3=False))
    dets: dict[str, Any] = {"gtrig": MarkerDetector(FAMILY), "gtrig no AT3": MarkerDetector(FAMILY, params=no_at3)}
    dets.update({f"cv2 {k}": _opencv("DICT_APRILTAG_36h11", k) for k in CV_REFINE})
    dets["apriltag3"] = _apriltag3()  # quad_decimate 1: the time budget where recall needs its small tags
    sides = [20, 35, 60, 120] if quick else [20, 30, 45, 70, 120, 200]
    tilts = [0, 45] if quick else [0, 30, 60]
    blurs = [0.0, 0.5, 1.0, 2.0]
    lights = ["uniform", "dim"] if quick else ["uniform", "gradient", "dim"]
    by_blur: dict[tuple[str, float], Stats] = {}
    every: dict[str, Stats] = {k: Stats() for k in dets}
    cpu: dict[str, float] = {k: 0.0 for k in dets}  # process CPU (every thread), s
    speed, speed_cpu = Budget(), Budget()
    _run("gtrig", dets["gtrig"], _scene(rng, 60, 0, 1.0, "uniform")[0])  # compile the kernels first
    for side, tilt, blur, light in itertools.product(sides, tilts, blurs, lights):
        img, truths = _scene(rng, side, tilt, blur, light)
        found: dict[str, set[int]] = {}
        ms_of: dict[str, float] = {}
        cpu_of: dict[str, float] = {}
        for name, det in dets.items():
            c0 = time.process_time()
            out, ms = _run(name, det, img)
            cpu[name] += time.process_time() - c0
            cpu_of[name] = (time.process_time() - c0) * 1000.0
            by_blur.setdefault((name, blur), Stats()).add(out, truths, ms)
            every[name].add(out, truths, ms)
            found[name], ms_of[name] = _found(out, truths), ms
        missed = bool((found["cv2 NONE"] | found["apriltag3"]) - found["gtrig no AT3"])
        speed.add(ms_of["gtrig"], ms_of["cv2 NONE"], ms_of["apriltag3"], missed)
        speed_cpu.add(cpu_of["gtrig"], cpu_of["cv2 NONE"], cpu_of["apriltag3"], missed)
    n = len(sides) * len(tilts) * len(blurs) * len(lights)
    print(f"renders: {n} images 1024 x 768, 3 AprilTag 36h11 each, sides {sides} px, tilts {tilts} deg, "
          f"lights {lights}, noise 3")
    print(f"{'detector':14s} {'blur':>5s} {'RMS px':>8s} {'det %':>7s} {'false/img':>9s}")
    for blur in blurs:
        for k in dets:
            s = by_blur[(k, blur)]
            print(f"{k:14s} {blur:5.1f} {s.rms:8.4f} {100 * s.found / s.total:7.2f} {s.false / s.images:9.3f}")
        best = min(by_blur[(k, blur)].rms for k in dets if k.startswith("cv2"))
        print(f"{'':14s} {'':5s} best OpenCV / gtrig RMS = {best / by_blur[('gtrig', blur)].rms:.2f}")
    acc = max(by_blur[("gtrig", b)].rms for b in blurs if b <= 1.0)
    gain = min(min(by_blur[(k, b)].rms for k in dets if k.startswith("cv2")) / by_blur[("gtrig", b)].rms
               for b in blurs if b <= 1.0)
    print(f"gtrig RMS at blur <= 1 px: {acc:.4f} px (target <= 0.10); best OpenCV / gtrig >= {gain:.2f} (target >= 3)")
    g, c, a = (np.median(every[k].ms) for k in ("gtrig", "cv2 NONE", "apriltag3"))
    n_found = {k: every[k].found for k in ("gtrig", "gtrig no AT3", "cv2 NONE", "apriltag3")}
    print(f"\nspeed, renders 1024 x 768 ({n} images; OpenCV's default threads {cv2.getNumThreads()}, AprilTag 3 "
          f"quad_decimate 1 with its default one): wall medians gtrig {g:.1f} ms, OpenCV {c:.1f} ms, AprilTag 3 "
          f"{a:.1f} ms; process CPU per image gtrig / OpenCV {cpu['gtrig'] / cpu['cv2 NONE']:.2f}; markers found "
          f"gtrig {n_found['gtrig']}, without its AprilTag 3 pass {n_found['gtrig no AT3']}, OpenCV "
          f"{n_found['cv2 NONE']}, AprilTag 3 {n_found['apriltag3']} of {every['gtrig'].total}")
    print(SPEED_HEADER)
    print(_speed_row("renders", speed, speed_cpu))


def _found(out: list[tuple[int, np.ndarray]], truths: list) -> set[int]:
    """Indices of the true markers that ``out`` finds (ID and corners within 5 px)."""
    return {k for k, t in enumerate(truths)
            if any(mid == t.marker_id and np.abs(c - t.corners_px).max() < 5 for mid, c in out)}


# ---------------------------------------------------------------------------------------------- photos

_TOP = {"img_00.jpg": ("DICT_6X6_250", set(range(17))), "img_01.jpg": ("DICT_6X6_250", set(range(17))),
        "img_02.jpg": ("DICT_6X6_250", set(range(17))), "img_03.jpg": ("DICT_6X6_250", set(range(17))),
        "tagtest.jpg": ("DICT_APRILTAG_36h11", {5, 6, 9}),
        "taggridphoto.jpg": ("DICT_APRILTAG_36h11", set(range(1, 41)))}
_PRINTED = {("photonvision", "DICT_APRILTAG_36h11"): set(range(1, 17)),
            ("photonvision", "DICT_APRILTAG_16h5"): set(range(1, 9)),
            ("photonvision", "DICT_4X4_50"): set(range(32)),
            ("junkybyte-deepcharuco", "DICT_4X4_50"): set(range(50))}
_AT3 = {"DICT_APRILTAG_36h11": "tag36h11", "DICT_APRILTAG_16h5": "tag16h5"}


def _family_of(dictionary: str) -> str:
    return {"DICT_APRILTAG_36h11": "apriltag_36h11", "DICT_APRILTAG_16h5": "apriltag_16h5"}.get(
        dictionary, "aruco_" + dictionary[5:].lower())


def _sets() -> dict[str, list[tuple[Path, str]]]:
    out = {"top-level": [(REAL / f, d) for f, (d, _) in _TOP.items()]}
    for f in sorted(REAL.glob("*/peers.json")):
        doc = json.loads(f.read_text())
        out[f.parent.name] = [(f.parent / p["file"], p["dictionary"]) for p in doc["photos"]]
    return out


@dataclass
class _Row:
    photos: int = 0
    found: dict[str, int] = field(default_factory=dict)
    ms: dict[str, list[float]] = field(default_factory=dict)
    wrong: int = 0
    speed: Budget = field(default_factory=Budget)
    speed_cpu: Budget = field(default_factory=Budget)


def _photo(path: Path, dictionary: str, set_name: str, row: _Row, dets: dict[tuple[str, str, bool], MarkerDetector],
           repeat: int) -> None:
    """One photo into ``row``: every detector's valid IDs and time (median of ``repeat`` runs), and whether
    gtrig without its AprilTag 3 pass misses a marker a peer finds."""
    from gtrig.io.imagetone import declared_tone
    from gtrig.markers.apriltag3 import at3_detect

    gray = cv2.imread(str(path), cv2.IMREAD_GRAYSCALE)
    fam, tone = _family_of(dictionary), declared_tone(path)

    def detector(at3: bool) -> MarkerDetector:
        return dets.setdefault((fam, tone, at3), MarkerDetector(fam, params=DetectorParams(
            tone=tone, peers=PeerParams(apriltag3=at3))))

    seen: dict[str, dict[int, np.ndarray]] = {}
    times: dict[str, float] = {}
    cpu: dict[str, float] = {}
    res, times["gtrig"], cpu["gtrig"] = _timed(lambda: detector(True).detect(gray), repeat)
    seen["gtrig"] = {d.id: d.corners_px.mean(axis=0) for d in res}
    cvd = _opencv(dictionary)
    (out, _), times["OpenCV"], cpu["OpenCV"] = _timed(lambda: _run("cv2", cvd, gray), repeat)
    seen["OpenCV"] = {i: c.mean(axis=0) for i, c in out}
    without_at3 = set(seen["gtrig"])
    if dictionary in _AT3:
        at3 = {}
        for label, qd in (("AT3", 2.0), ("AT3 qd=1", 1.0)):
            at3[label], times[label], cpu[label] = _timed(lambda q=qd: at3_detect(gray, _AT3[dictionary], q), repeat)
        # a reading with two corrected bits counts where another peer confirms it (16h5: many are false)
        sure = set(seen["OpenCV"]) | {i for res in at3.values() for i, h, _ in res if h <= 1}
        for label, res in at3.items():
            seen[label] = {i: c.mean(axis=0) for i, h, c in res if h <= 1 or i in sure}
        without_at3 = {d.id for d in detector(False).detect(gray)}
    printed = (_TOP[path.name][1] if set_name == "top-level" else
               _PRINTED.get((set_name, dictionary), set().union(*(set(v) for k, v in seen.items() if k != "gtrig"))))
    row.photos += 1
    for k, v in seen.items():
        row.found[k] = row.found.get(k, 0) + len(set(v) & printed)
        row.ms.setdefault(k, []).append(times[k])
    peers = [v for k, v in seen.items() if k != "gtrig"]
    row.wrong += sum(1 for i, c in seen["gtrig"].items() if i not in printed
                     and not any(i in p and np.linalg.norm(p[i] - c) < 10 for p in peers))
    missed = any((set(p) & printed) - without_at3 for p in peers)
    row.speed.add(times["gtrig"], times["OpenCV"], times.get("AT3 qd=1"), missed)
    row.speed_cpu.add(cpu["gtrig"], cpu["OpenCV"], cpu.get("AT3 qd=1"), missed)


def _refine_inputs(img: NDArray[np.uint8], truths: list, cvd: Any
                   ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """``--refine-only``'s quads: OpenCV's (no refinement) markers of ``img`` that match a true marker,
    their corners turned to the true corners' order, the true code's white cells and the true corners."""
    corners, ids, _ = cvd.detectMarkers(img)
    quads, white, true = [], [], []
    for c, i in zip(corners, [] if ids is None else ids.ravel(), strict=True):
        for t in truths:
            if t.marker_id != int(i):
                continue
            q = np.asarray(c, np.float64).reshape(4, 2)
            q = min((np.roll(q, -s, axis=0) for s in range(4)), key=lambda r: float(np.abs(r - t.corners_px).sum()))
            if np.abs(q - t.corners_px).max() < 5:
                quads.append(q)
                white.append(marker_cells(FAMILY, t.marker_id).astype(np.float64))
                true.append(t.corners_px)
    return np.array(quads).reshape(-1, 4, 2), np.array(white), np.array(true).reshape(-1, 4, 2)


def _bench_refine(scenes: list[tuple[NDArray[np.uint8], list, float]]) -> None:
    """``--refine-only``: the edge refinement alone on OpenCV's quads of the renders, per marker the process
    CPU time (every thread) and the wall-clock time, and corner RMS against the truth: gtrig's compiled
    refinement in one thread and in two (the detector's split of the quads), the same through the step
    functions (its reference), and OpenCV's cornerSubPix on the same quads (one thread)."""
    from gtrig.markers.detect.edges import RefineParams, refine_quads, refine_quads_stepwise
    from gtrig.markers.families import family_spec

    cvd = _opencv("DICT_APRILTAG_36h11")
    bc = family_spec(FAMILY).border_cells
    prm = RefineParams()
    crit = (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 30, 0.01)
    default = cv2.getNumThreads()
    cv2.setNumThreads(1)
    names = ["start (OpenCV NONE)", "cornerSubPix 5x5", "gtrig stepwise", "gtrig compiled", "gtrig compiled 2 thr"]
    runs = {names[1]: lambda img, Q, W: cv2.cornerSubPix(img, Q.reshape(-1, 1, 2).astype(np.float32), (5, 5), (-1, -1),
                                                          crit).reshape(-1, 4, 2).astype(np.float64),
            names[2]: lambda img, Q, W: refine_quads_stepwise(img, Q, W, bc, prm)[1],
            names[3]: lambda img, Q, W: refine_quads(img, Q, W, bc, prm)[1],
            names[4]: lambda img, Q, W: refine_quads(img, Q, W, bc, prm, threads=2)[1]}
    cpu = {k: 0.0 for k in names}
    wall = {k: 0.0 for k in names}
    err: dict[tuple[str, bool], list[float]] = {(k, lo): [] for k in names for lo in (True, False)}
    n_markers = 0
    worst = 0.0
    same = True
    try:
        for img, truths, _blur in scenes[:2]:  # compiled kernels warm
            Q, W, _T = _refine_inputs(img, truths, cvd)
            if len(Q):
                refine_quads(img, Q, W, bc, prm, threads=2)
        for img, truths, blur in scenes:
            Q, W, T = _refine_inputs(img, truths, cvd)
            if not len(Q):
                continue
            n_markers += len(Q)
            out = {names[0]: Q}
            for k, run in runs.items():
                t0, w0 = time.process_time(), time.perf_counter()
                out[k] = run(img, Q, W)
                cpu[k] += time.process_time() - t0
                wall[k] += time.perf_counter() - w0
            worst = max(worst, float(np.nanmax(np.abs(out[names[3]] - out[names[2]]))))
            same &= bool(np.array_equal(out[names[3]], out[names[4]]))
            for k, c in out.items():
                e2 = np.sum((c - T) ** 2, axis=2).ravel().tolist()
                err[(k, blur <= 1.0)].extend(e2)
    finally:
        cv2.setNumThreads(default)
    print(f"{len(scenes)} images 1024 x 768, {n_markers} markers found by OpenCV (its quads, the true code's cells); "
          "CPU: process CPU time (every thread); wall: wall-clock time")
    print(f"{'refinement':24s} {'CPU ms/marker':>13s} {'wall ms/marker':>14s} {'CPU x subpix':>12s} "
          f"{'RMS blur<=1':>11s} {'RMS blur 2':>10s}")
    for k in names:
        ms, ms_wall = (1000.0 * t[k] / max(n_markers, 1) for t in (cpu, wall))
        ratio = cpu[k] / cpu[names[1]] if cpu[names[1]] > 0 else float("nan")
        lo, hi = (float(np.sqrt(np.mean(err[(k, b)]))) if err[(k, b)] else float("nan") for b in (True, False))
        print(f"{k:24s} {ms:13.3f} {ms_wall:14.3f} {ratio:12.1f} {lo:11.4f} {hi:10.4f}")
    print(f"compiled against stepwise: largest corner difference {worst:.2e} px; two threads "
          f"{'give' if same else 'do NOT give'} the corners of one to the last bit; target: the compiled refinement "
          "at most 0.2 ms per marker")


#: ``--refine-only --sweep``'s settings of the edge refinement (:class:`.edges.RefineParams` fields)
SWEEP: list[dict[str, Any]] = [{}, {"settle_px": 0.0, "first_columns": 0}, {"settle_px": 0.2}, {"passes": 2},
                               {"max_columns": 32}, {"max_columns": 24}, {"max_columns": 16}, {"max_columns": 12},
                               {"max_columns": 8}, {"max_columns": 8, "passes": 2}]


def _bench_refine_sweep(scenes: list[tuple[NDArray[np.uint8], list, float]]) -> None:
    """``--refine-only --sweep``: time against accuracy of the compiled refinement for the settings
    :data:`SWEEP`, each against cornerSubPix timed in the same loop (one thread, CPU time of this thread,
    three rounds, the median); corner RMS against the truth, and the corners' normalised squared errors
    ``e^T C^-1 e`` (chi-square with 2 degrees of freedom if the covariances are right: median 1.39)."""
    import dataclasses

    from gtrig.markers.detect.edges import RefineParams, refine_quads
    from gtrig.markers.families import family_spec

    cvd = _opencv("DICT_APRILTAG_36h11")
    bc = family_spec(FAMILY).border_cells
    crit = (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 30, 0.01)
    inputs = [(img, *_refine_inputs(img, truths, cvd), blur) for img, truths, blur in scenes]
    inputs = [x for x in inputs if len(x[1])]
    n_markers = sum(len(x[1]) for x in inputs)
    default = cv2.getNumThreads()
    cv2.setNumThreads(1)
    print(f"{'settings':40s} {'ms/marker':>9s} {'x subpix':>8s} {'RMS blur<=1':>11s} {'RMS blur 2':>10s} "
          f"{'NEES med':>8s} {'in 95%':>6s}")
    try:
        for kw in SWEEP:
            prm = dataclasses.replace(RefineParams(), **kw)
            for img, Q, W, _T, _b in inputs[:2]:
                refine_quads(img, Q, W, bc, prm)  # compiled kernels warm
            cpu, sub = [], []
            for _round in range(3):
                c = d = 0.0
                for img, Q, W, _T, _b in inputs:
                    t0 = time.thread_time()
                    cv2.cornerSubPix(img, Q.reshape(-1, 1, 2).astype(np.float32), (5, 5), (-1, -1), crit)
                    d += time.thread_time() - t0
                    t0 = time.thread_time()
                    refine_quads(img, Q, W, bc, prm)
                    c += time.thread_time() - t0
                cpu.append(c)
                sub.append(d)
            err: dict[bool, list[float]] = {True: [], False: []}
            z2: list[float] = []
            for img, Q, W, T, blur in inputs:
                _fit, corners, cov = refine_quads(img, Q, W, bc, prm)
                err[blur <= 1.0].extend(np.sum((corners - T) ** 2, axis=2).ravel().tolist())
                r = (corners - T).reshape(-1, 2)
                z2.extend(np.einsum("ni,ni->n", r, np.linalg.solve(cov.reshape(-1, 2, 2), r[..., None])[..., 0]))
            z = np.asarray(z2)
            print(f"{str(kw or 'default'):40s} {1000 * np.median(cpu) / n_markers:9.3f} "
                  f"{np.median(cpu) / np.median(sub):8.1f} {np.sqrt(np.mean(err[True])):11.4f} "
                  f"{np.sqrt(np.mean(err[False])):10.4f} {np.median(z):8.2f} {np.mean(z < 5.991):6.2f}")
    finally:
        cv2.setNumThreads(default)


def _bench_refine_only(rng: np.random.Generator, sweep: bool) -> None:
    """``--refine-only`` on the quick grid of renders (with ``sweep``, :func:`_bench_refine_sweep`)."""
    scenes = []
    for side, tilt, blur, light in itertools.product([20, 35, 60, 120], [0, 45], [0.0, 0.5, 1.0, 2.0],
                                                     ["uniform", "dim"]):
        img, truths = _scene(rng, side, tilt, blur, light)
        scenes.append((img, truths, blur))
    if sweep:
        _bench_refine_sweep(scenes)
    else:
        _bench_refine(scenes)


def _bench_refine_photos(repeat: int) -> None:
    """``--refine-only --photos``: the compiled edge refinement alone on the real photos, per set the CPU time
    of this thread per marker (the fastest of ``repeat`` rounds) of the refinement calls the detector makes
    (the quads of every candidate it refines, on each photo's own tone), captured from a detection of each
    photo and replayed."""
    from gtrig.io.imagetone import declared_tone
    from gtrig.markers.detect import _edge_kernels

    if not REAL.is_dir():
        print(f"{REAL}: not found, real photos left out")
        return
    run = _edge_kernels.refine_all
    calls: list[tuple[Any, ...]] = []

    def capture(*args: Any) -> Any:
        calls.append(args)
        return run(*args)

    print(f"edge refinement alone on the real photos: CPU ms per refined quad (one thread, the fastest of {repeat})")
    print(f"{'set':28s} {'quads':>6s} {'calls':>6s} {'ms/quad':>8s}")
    for name, photos in _sets().items():
        calls.clear()
        _edge_kernels.refine_all = capture  # type: ignore[assignment]
        try:
            for path, dictionary in photos:
                gray = cv2.imread(str(path), cv2.IMREAD_GRAYSCALE)
                if gray is None:
                    raise SystemExit(f"{path}: not a readable image")
                MarkerDetector(_family_of(dictionary), params=DetectorParams(tone=declared_tone(path))).detect(gray)
        finally:
            _edge_kernels.refine_all = run
        n_quads = sum(len(c[6]) for c in calls)
        best = np.inf
        for _round in range(repeat):
            t0 = time.thread_time()
            for c in calls:
                run(*c)
            best = min(best, time.thread_time() - t0)
        print(f"{name:28s} {n_quads:6d} {len(calls):6d} {1000.0 * best / max(n_quads, 1):8.3f}")


STAGES = ("OpenCV", "AprilTag 3", "edge fits", "the rest")


class _StageClock:
    """CPU time of one thread spent in the peers' calls and the edge fits of the detections run inside it
    (the module functions timed in place and put back on exit); the rest is the whole less these."""

    def __init__(self) -> None:
        import gtrig.markers.detect as detect_mod
        from gtrig.markers.detect import peers

        self.spent: dict[str, float] = {}
        self._patched = [(peers, "opencv_candidates", "OpenCV"), (peers, "apriltag3_candidates", "AprilTag 3"),
                         (detect_mod, "refine_quads", "edge fits")]
        self._saved: list[Any] = []

    def _timed(self, fn: Any, stage: str) -> Any:
        def run(*args: Any, **kwargs: Any) -> Any:
            t0 = time.thread_time()
            try:
                return fn(*args, **kwargs)
            finally:
                self.spent[stage] = self.spent.get(stage, 0.0) + time.thread_time() - t0
        return run

    def __enter__(self) -> _StageClock:
        for mod, name, stage in self._patched:
            self._saved.append(getattr(mod, name))
            setattr(mod, name, self._timed(getattr(mod, name), stage))
        return self

    def __exit__(self, *exc: object) -> None:
        for (mod, name, _), fn in zip(self._patched, self._saved, strict=True):
            setattr(mod, name, fn)


def _stage_table(repeat: int) -> None:
    """Where a whole detection's time goes, per set: CPU ms per photo on one thread (OpenCV's threads and the
    detector's at 1, so that every stage is timed where it runs), the fastest of ``repeat`` runs per photo."""
    from gtrig.io.imagetone import declared_tone

    print(f"\nwhole detection by stage, per set: CPU ms per photo, one thread (OpenCV and the detector), the fastest "
          f"of {repeat} runs per photo")
    print(f"{'set':28s} {'whole':>8s} " + " ".join(f"{s:>10s}" for s in STAGES))
    threads = cv2.getNumThreads()
    cv2.setNumThreads(1)
    try:
        for name, photos in _sets().items():
            total = dict.fromkeys(("whole",) + STAGES, 0.0)
            for path, dictionary in photos:
                gray = np.asarray(cv2.imread(str(path), cv2.IMREAD_GRAYSCALE), np.uint8)
                det = MarkerDetector(_family_of(dictionary), params=DetectorParams(tone=declared_tone(path), threads=1))
                det.detect(gray)
                best: tuple[float, dict[str, float]] | None = None
                for _ in range(max(1, repeat)):
                    with _StageClock() as clock:
                        t0 = time.thread_time()
                        det.detect(gray)
                        whole = time.thread_time() - t0
                    if best is None or whole < best[0]:
                        best = (whole, clock.spent)
                assert best is not None
                total["whole"] += best[0]
                for stage in STAGES[:3]:
                    total[stage] += best[1].get(stage, 0.0)
                total["the rest"] += best[0] - sum(best[1].values())
            n = max(len(photos), 1)
            print(f"{name:28s} {1000 * total['whole'] / n:8.2f} "
                  + " ".join(f"{1000 * total[s] / n:10.2f}" for s in STAGES))
    finally:
        cv2.setNumThreads(threads)


def _bench_photos(repeat: int) -> None:
    if not REAL.is_dir():
        print(f"{REAL}: not found, real photos left out")
        return
    dets: dict[tuple[str, str, bool], MarkerDetector] = {}
    MarkerDetector("aruco_4x4_50").detect(_scene(np.random.default_rng(0), 60, 0, 1.0, "uniform")[0])  # compile
    print("real photos (../shared/data/markers_real): markers found with an ID printed in the set; wrong: gtrig's "
          "IDs not printed and not reported there by a peer; ms per photo (mean of each photo's median of "
          f"{repeat}); OpenCV: ArucoDetector defaults; AT3: AprilTag 3 defaults (qd=1: quad_decimate 1), AprilTag "
          f"families only; OpenCV threads {cv2.getNumThreads()}, AprilTag 3 one thread (its default)")
    cols = ["gtrig", "OpenCV", "AT3", "AT3 qd=1"]
    print(f"{'set':28s} {'photos':>6s} " + " ".join(f"{c:>9s}" for c in cols) + f" {'wrong':>5s} "
          + " ".join(f"{c + ' ms':>12s}" for c in cols) + f" {'gtrig/OpenCV':>12s}")
    speed = {}
    for name, photos in _sets().items():
        row = _Row()
        for path, dictionary in photos:
            _photo(path, dictionary, name, row, dets, repeat)
        found = " ".join(f"{row.found[c]:9d}" if c in row.found else f"{'-':>9s}" for c in cols)
        ms = {c: float(np.mean(row.ms[c])) for c in cols if c in row.ms}
        times = " ".join(f"{ms[c]:12.1f}" if c in ms else f"{'-':>12s}" for c in cols)
        print(f"{name:28s} {row.photos:6d} {found} {row.wrong:5d} {times} {ms['gtrig'] / ms['OpenCV']:12.2f}")
        speed[name] = (row.speed, row.speed_cpu)
    print("\nspeed per set (budget: 1.5x OpenCV, or AprilTag 3 qd=1's time on the AprilTag photos where gtrig "
          "without its AprilTag 3 pass misses a marker a peer finds on some photo of the set)")
    print(SPEED_HEADER)
    for name, (b, c) in speed.items():
        print(_speed_row(name, b, c))
    _stage_table(repeat)
    _board_fits()


def _board_fits() -> None:
    """Board-fit residuals of the ChArUco photos (one planar pose through the tutorial's lens) and the grid
    photo (the 8 x 5 grid's homography with two radial terms / a homography per 2 x 2 block of tags)."""
    from gtrig.io.imagetone import declared_tone
    from gtrig.markers.detect.boardfit import charuco_marker_corners, grid_fit_rms, grid_local_rms, pose_fit_rms

    K = np.array([[452.51, 0.0, 317.70], [0.0, 456.77, 277.75], [0.0, 0.0, 1.0]])
    dist = np.array([0.1214, -1.0855, 0.000118, -0.000462, 2.9543])
    board = charuco_marker_corners((5, 7), 0.04, 0.02)
    grid = {i: ((i - 1) // 5, (i - 1) % 5) for i in range(1, 41)}
    names = ["gtrig"] + [f"cv2 {k}" for k in CV_REFINE]
    print("\nboard-fit RMS residual, px (markers found)")
    print(f"{'photo':18s} " + " ".join(f"{n:>20s}" for n in names))
    for photo in ("img_00.jpg", "img_01.jpg", "img_02.jpg", "img_03.jpg", "taggridphoto.jpg"):
        dictionary = _TOP[photo][0]
        gray = cv2.imread(str(REAL / photo), cv2.IMREAD_GRAYSCALE)
        tone = declared_tone(REAL / photo)
        res = {"gtrig": {d.id: d.corners_px for d in
                         MarkerDetector(_family_of(dictionary), params=DetectorParams(tone=tone)).detect(gray)}}
        for k in CV_REFINE:
            res[f"cv2 {k}"] = dict(_run("cv2", _opencv(dictionary, k), gray)[0])
        cells = []
        for n in names:
            r = res[n]
            if photo.startswith("img_"):
                cells.append(f"{pose_fit_rms(r, board, K, dist):.3f} ({len(r)})".rjust(20))
            else:
                size = (gray.shape[1], gray.shape[0])
                cells.append(f"{grid_fit_rms(r, grid, size):.3f}/{grid_local_rms(r, grid):.3f} ({len(r)})".rjust(20))
        print(f"{photo:18s} " + " ".join(cells))


# ---------------------------------------------------------------------------------------------- harder set


def _hard_scene(rng: np.random.Generator, side: float) -> tuple[np.ndarray, list]:
    """One image of the harder set (module docstring): three markers of about ``side`` px, grey."""
    centres = [(220, 250), (520, 520), (800, 260)]
    ids = rng.choice(587, 3, replace=False)
    markers, glare = [], []
    for c, mid in zip(centres, ids, strict=True):
        jit = rng.uniform(-40, 40, 2)
        H = homography_from_pose(side * rng.uniform(0.9, 1.1), (c[0] + jit[0], c[1] + jit[1]), rng.uniform(0, 60),
                                 rng.uniform(0, 360), rng.uniform(0, 360))
        markers.append((FAMILY, int(mid), H))
        if rng.random() < 0.5:  # a highlight somewhere on the marker
            off = rng.uniform(-0.4, 0.4, 2) * side
            glare.append((c[0] + jit[0] + off[0], c[1] + jit[1] + off[1], side * rng.uniform(0.2, 0.8),
                          rng.uniform(0.1, 0.35)))
    kind = str(rng.choice(["clutter", "textured", "pale"]))
    bg = (clutter_background(SHAPE, rng, n_shapes=40) if kind == "clutter"
          else textured_background(SHAPE, rng, light=kind == "pale"))
    img, truths = render(SHAPE, markers, blur_px=float(rng.uniform(0.0, 1.5)), noise=float(rng.uniform(2.0, 5.0)),
                         gain=float(rng.uniform(120.0, 260.0)), gradient=float(rng.uniform(0.0, 0.8)),
                         quiet_cells=float(rng.uniform(1.0, 2.0)), background=bg, rng=rng,
                         ink=float(rng.uniform(0.08, 0.3)), paper=float(rng.uniform(0.7, 0.92)), paper_texture=0.04,
                         bend_px=float(rng.uniform(0.0, 0.5)), glare=glare, bayer=bool(rng.random() < 0.5),
                         jpeg_quality=int(rng.integers(60, 96)))
    if img.ndim == 3:  # every detector gets the same grey image (OpenCV's conversion)
        img = cv2.cvtColor(img, cv2.COLOR_BGR2GRAY)
    return img, truths


def hard_set_scores(rng: np.random.Generator, n_per_side: int, sides: tuple[int, ...] = (10, 14, 20, 30, 45, 70)
                    ) -> dict[str, Stats]:
    """gtrig's, OpenCV's and AprilTag 3's (qd=1) tallies on the harder set's markers of 20 px and up."""
    dets: dict[str, Any] = {"gtrig": MarkerDetector(FAMILY), "cv2 NONE": _opencv("DICT_APRILTAG_36h11"),
                            "apriltag3": _apriltag3()}
    big = {k: Stats() for k in dets}
    for side in sides:
        for _ in range(n_per_side):
            img, truths = _hard_scene(rng, side)
            for name, det in dets.items():
                out, ms = _run(name, det, img)
                if side >= 20:
                    big[name].add(out, truths, ms)
    return big


def _bench_hard(rng: np.random.Generator, n_per_side: int) -> None:
    big = hard_set_scores(rng, n_per_side)
    print(f"harder simulated set: {6 * n_per_side} images 1024 x 768, 3 AprilTag 36h11 each; markers >= 20 px "
          "(a regression check of recall and wrong IDs, not a target)")
    print(f"{'detector':14s} {'RMS px':>8s} {'det %':>7s} {'false':>6s}")
    for k, s in big.items():
        print(f"{k:14s} {s.rms:8.4f} {100 * s.found / s.total:7.2f} {s.false:6d}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--quick", action="store_true", help="a smaller grid of renders")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--photos", action="store_true", help="the real photos of ../shared/data/markers_real")
    ap.add_argument("--repeat", type=int, default=3, help="--photos: runs per photo and detector (the median is kept)")
    ap.add_argument("--hard", action="store_true", help="the harder simulated set (JPEG, Bayer, glare, ...)")
    ap.add_argument("--per-side", type=int, default=50, help="--hard: images per marker side")
    ap.add_argument("--refine-only", action="store_true",
                    help="the edge refinement alone on OpenCV's quads of the renders, against cornerSubPix")
    ap.add_argument("--sweep", action="store_true",
                    help="--refine-only: time against accuracy for several settings of the refinement")
    ap.add_argument("--clipped", action="store_true",
                    help="sunlit (clipped) markers of the simulated GT room, still and moving: corner error, "
                         "stated sigma and NEES per class (bench/markers_clipped.py; --seed, 60 robot poses)")
    ap.add_argument("--synth", action="store_true",
                    help="--clipped: synth renders over the clipping degree, blur and motion smear instead")
    a = ap.parse_args()
    rng = np.random.default_rng(a.seed)
    if a.clipped:
        from markers_clipped import run as clipped_run
        from markers_clipped import run_synth

        if a.synth:
            run_synth()
        else:
            clipped_run(a.seed, 60)
    elif a.photos and a.refine_only:
        _bench_refine_photos(a.repeat)
    elif a.photos:
        _bench_photos(a.repeat)
    elif a.hard:
        _bench_hard(rng, a.per_side)
    elif a.refine_only:
        _bench_refine_only(rng, a.sweep)
    else:
        _bench_renders(rng, a.quick)


if __name__ == "__main__":
    main()
    sys.stdout.flush()
    os._exit(0)
