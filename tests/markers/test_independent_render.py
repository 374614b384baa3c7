"""The detector on camera images made apart from gtrig (:mod:`independent_render`: NumPy and OpenCV only,
OpenCV's own markers), against OpenCV's ArucoDetector run here on the same images: recall at least
OpenCV's in every family, most markers of 20 px and up found, no wrong ID, corners well inside
OpenCV's best refinement. gtrig reads the frames as ``gtrig markers detect`` reads a JPEG
(``tone="srgb"``). ``bench/markers_independent.py`` prints the same figures by side bin on more frames.
"""

from __future__ import annotations

import cv2
import independent_render as ir
import numpy as np
import pytest

from gtrig.markers.detect import DetectorParams, MarkerDetector

FRAMES = 12  # per family, three markers each
REFINE = ("NONE", "SUBPIX", "CONTOUR", "APRILTAG")


def _opencv(dictionary: str, refine: str) -> cv2.aruco.ArucoDetector:
    p = cv2.aruco.DetectorParameters()
    p.cornerRefinementMethod = getattr(cv2.aruco, f"CORNER_REFINE_{refine}")
    return cv2.aruco.ArucoDetector(cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, dictionary)), p)


def _cv_dets(det: cv2.aruco.ArucoDetector, gray: np.ndarray) -> list[tuple[int, np.ndarray]]:
    corners, ids, _ = det.detectMarkers(gray)
    if ids is None:
        return []
    return [(int(i), c.reshape(4, 2).astype(float)) for i, c in zip(ids.ravel(), corners, strict=True)]


@pytest.fixture(scope="module")
def scores() -> dict[str, dict[str, ir.Score]]:
    """family -> detector -> tally over the family's frames (seed 7: apart from the bench's default)."""
    out: dict[str, dict[str, ir.Score]] = {}
    for k, fam in enumerate(ir.FAMILIES):
        rng = np.random.default_rng([7, k])
        gt = MarkerDetector(fam, params=DetectorParams(tone="srgb"))
        cvs = {r: _opencv(ir.FAMILIES[fam][0], r) for r in REFINE}
        s = {"gtrig": ir.Score(), **{f"cv2 {r}": ir.Score() for r in REFINE}}
        for _ in range(FRAMES):
            frame = ir.render(rng, fam)
            s["gtrig"].add(frame, [(d.id, d.corners_px) for d in gt.detect(frame.gray)], 0.0)
            for r, det in cvs.items():
                s[f"cv2 {r}"].add(frame, _cv_dets(det, frame.gray), 0.0)
        out[fam] = s
    return out


def test_renders_have_the_hard_cases(scores: dict[str, dict[str, ir.Score]]) -> None:
    """The set is not easy: OpenCV misses a good share of the markers of 20 px and up."""
    cv = [s["cv2 NONE"].recall(20.0) for s in scores.values()]
    assert np.mean(cv) < 0.9, cv


@pytest.mark.parametrize("family", list(ir.FAMILIES))
def test_recall_at_least_opencv(scores: dict[str, dict[str, ir.Score]], family: str) -> None:
    s = scores[family]
    g = s["gtrig"]
    best_cv = max(sum(s[f"cv2 {r}"].found) for r in REFINE)
    assert sum(g.found) >= best_cv, (family, g.found, best_cv)


def test_recall_from_20_px(scores: dict[str, dict[str, ir.Score]]) -> None:
    """Markers of 20 px and up, all families together: the peers give the candidates, so gtrig's recall is
    OpenCV's and AprilTag 3's pooled (70 % here against OpenCV's best 67 %): a regression floor."""
    def pooled(name: str) -> float:
        found = sum(sum(s[name].found[2:]) for s in scores.values())
        return found / sum(sum(s[name].total[2:]) for s in scores.values())

    g = pooled("gtrig")
    best_cv = max(pooled(f"cv2 {r}") for r in REFINE)
    assert g >= 0.68 and g >= best_cv, (g, best_cv)


@pytest.mark.parametrize("family", ["aruco_5x5_100", "aruco_6x6_250", "apriltag_36h11"])
def test_no_wrong_id(scores: dict[str, dict[str, ir.Score]], family: str) -> None:
    assert scores[family]["gtrig"].wrong == 0


def test_4x4_wrong_ids_are_glyphs(scores: dict[str, dict[str, ir.Score]]) -> None:
    """ArUco 4x4_50 has 16 data cells: on the renders' text, letters of 15-19 px with one hole read as
    ID 17 (a black square with a 2 x 2 white block off its centre), an exact code (4 of 60 frames on the
    bench, seed 0; OpenCV reports none). Nothing else is
    read wrongly, and nothing of 20 px or more."""
    bad = scores["aruco_4x4_50"]["gtrig"].wrong_dets
    assert all(mid == 17 and side < 20.0 for mid, side in bad), bad


def test_corners_beat_opencv(scores: dict[str, dict[str, ir.Score]]) -> None:
    """Corner RMS against the truth, markers of 20 px and up that each detector found: on the bench
    0.28-0.34 px against OpenCV's best refinement's 0.77-0.97 px."""
    for fam, s in scores.items():
        g = s["gtrig"].rms(20.0)
        best = min(s[f"cv2 {r}"].rms(20.0) for r in REFINE)
        assert g < 0.5 and g < 0.6 * best, (fam, g, best)
