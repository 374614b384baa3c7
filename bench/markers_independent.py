"""The marker detector on renders made apart from gtrig: ``tests/markers/independent_render``
imports only NumPy and OpenCV, and draws OpenCV's own markers (ArUco 4x4_50, 5x5_100, 6x6_250, AprilTag
36h11) the way a camera sees a print: 3D pose up to 60 deg, a bowed print, paper grain, glare, a
Gaussian, defocus-disk or motion point-spread function applied at 6x the resolution, vignetting,
photon and read noise, a Bayer mosaic demosaiced by OpenCV on half the frames, an sRGB or filmic tone
curve and JPEG at quality 60-95, on backgrounds of shapes, strokes, text and texture.

For each family and detector it prints the markers found by side bin (sqrt of the imaged area, px),
wrong IDs (an ID not in the image, or a right ID away from its marker), the corner RMS against the
truth (markers of 20 px and more that the detector found) and the median ms per image. gtrig reads
the frames with ``tone="srgb"``, as ``gtrig markers detect`` reads a JPEG that declares no other tone;
OpenCV's ArucoDetector runs with default parameters and each corner refinement; AprilTag 3
(pupil-apriltags) on the 36h11 frames. All detectors run on the same images in one run.

Usage::

    python bench/markers_independent.py                 # 40 frames per family, seed 0
    python bench/markers_independent.py --frames 100 --seed 3
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import cv2
import numpy as np

sys.path.insert(0, str(Path(__file__).parents[1] / "tests" / "markers"))
import independent_render as ir  # noqa: E402
from markers import _apriltag3, _run  # noqa: E402  (bench/markers.py: the same detectors' calls)

from gtrig.markers.detect import DetectorParams, MarkerDetector  # noqa: E402

REFINE = ("NONE", "SUBPIX", "CONTOUR", "APRILTAG")


def _detectors(family: str) -> dict[str, object]:
    dets: dict[str, object] = {"gtrig": MarkerDetector(family, params=DetectorParams(tone="srgb"))}
    d = cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, ir.FAMILIES[family][0]))
    for name in REFINE:
        p = cv2.aruco.DetectorParameters()
        p.cornerRefinementMethod = getattr(cv2.aruco, f"CORNER_REFINE_{name}")
        dets[f"cv2 {name}"] = cv2.aruco.ArucoDetector(d, p)
    at3 = _apriltag3() if family == "apriltag_36h11" else None  # one for the run: see markers._apriltag3
    if at3 is not None:
        dets["apriltag3"] = at3
    return dets


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--frames", type=int, default=40, help="frames per family (3 markers each)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--families", default=",".join(ir.FAMILIES))
    ap.add_argument("--misses", action="store_true", help="list gtrig's misses that OpenCV found")
    a = ap.parse_args()
    bins = ir.Score().bins
    heads = [f"{bins[i]:.0f}-{bins[i + 1]:.0f}" if bins[i + 1] < 1e8 else f">={bins[i]:.0f}"
             for i in range(len(bins) - 1)]
    print(f"independent renders, {a.frames} frames x 3 markers per family, seed {a.seed}; found/total by side "
          "(px); wrong IDs; corner RMS px at >= 20 px; median ms per 1024 x 768 frame")
    print(f"{'family':15s} {'detector':13s} " + " ".join(f"{h:>9s}" for h in heads)
          + f" {'>=20 %':>7s} {'wrong':>5s} {'RMS':>7s} {'ms':>6s}")
    for fam in a.families.split(","):
        rng = np.random.default_rng([a.seed, list(ir.FAMILIES).index(fam)])
        dets = _detectors(fam)
        scores = {n: ir.Score() for n in dets}
        for k in range(a.frames):
            frame = ir.render(rng, fam)
            found: dict[str, set[int]] = {}
            for n, det in dets.items():
                out, ms = _run(n, det, frame.gray)
                found[n] = scores[n].add(frame, out, ms)
            if a.misses:
                for t in frame.truths:
                    if t.id in found["cv2 NONE"] and t.id not in found["gtrig"]:
                        print(f"  miss: frame {k} id {t.id} side {t.side_px:.1f} {t.psf} {t.blur_px:.2f} "
                              f"bayer {frame.bayer} q {frame.jpeg_quality} {frame.tone}")
        for n, s in scores.items():
            cells = " ".join(f"{f:>4d}/{t:<4d}" for f, t in zip(s.found, s.total, strict=True))
            print(f"{fam:15s} {n:13s} {cells} {100 * s.recall(20.0):7.2f} {s.wrong:5d} {s.rms(20.0):7.4f} "
                  f"{np.median(s.ms):6.1f}")
        g, c = np.median(scores["gtrig"].ms), np.median(scores["cv2 NONE"].ms)
        print(f"{fam:15s} time gtrig / cv2 NONE: {g / c:.2f}x")


if __name__ == "__main__":
    main()
