"""Every real photo of ../shared/data/markers_real (the six top-level photos and the five public sets): per
photo, gtrig finds at least the markers each peer finds, computed here on the same image with OpenCV's
``ArucoDetector`` (default parameters) and AprilTag 3 (``pupil-apriltags``, default parameters and with
``quad_decimate=1``), and never reports a wrong ID: one that is not printed in the photo's set and that no
peer reports at that place. The IDs printed are known for the boards and fields (FRC 2024: 36h11 IDs 1-16,
FRC 2023: 16h5 IDs 1-8, the ChArUco boards' markers); elsewhere the peers' IDs stand for them. A peer's
ID outside the printed set is a peer's false reading and is not asked of gtrig; so is an AprilTag 3 reading
with two corrected bits that no other peer confirms (on the FRC field's 16h5 photos it reads many IDs off
the field so, and with ``quad_decimate=1`` one on it, 3, where neither OpenCV nor its default finds a tag)."""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np
import pytest

from gtrig.io.imagetone import declared_tone
from gtrig.markers.apriltag3 import at3_detect
from gtrig.markers.detect import DetectorParams, MarkerDetector

REAL = Path(__file__).parents[2] / ".." / "shared" / "data" / "markers_real"
pytestmark = pytest.mark.skipif(not REAL.is_dir(), reason="../shared/data/markers_real is not beside the repo")

SETS = ("top", "photonvision", "ubiquityrobotics-fiducials", "moveit-calibration", "tinker-twins-apriltag",
        "junkybyte-deepcharuco")
#: the top-level photos: file -> OpenCV dictionary, IDs printed
TOP = {
    "img_00.jpg": ("DICT_6X6_250", set(range(17))),
    "img_01.jpg": ("DICT_6X6_250", set(range(17))),
    "img_02.jpg": ("DICT_6X6_250", set(range(17))),
    "img_03.jpg": ("DICT_6X6_250", set(range(17))),
    "tagtest.jpg": ("DICT_APRILTAG_36h11", {5, 6, 9}),
    "taggridphoto.jpg": ("DICT_APRILTAG_36h11", set(range(1, 41))),
}
#: IDs printed per (set, dictionary), where the board or field is known (README and SOURCE.md of each set)
PRINTED = {
    ("photonvision", "DICT_APRILTAG_36h11"): set(range(1, 17)),
    ("photonvision", "DICT_APRILTAG_16h5"): set(range(1, 9)),
    ("photonvision", "DICT_4X4_50"): set(range(32)),
    ("junkybyte-deepcharuco", "DICT_4X4_50"): set(range(50)),
}
AT3 = {"DICT_APRILTAG_36h11": "tag36h11", "DICT_APRILTAG_16h5": "tag16h5"}


def family_of(dictionary: str) -> str:
    """gtrig's family of an OpenCV dictionary name."""
    return {"DICT_APRILTAG_36h11": "apriltag_36h11", "DICT_APRILTAG_16h5": "apriltag_16h5"}.get(
        dictionary, "aruco_" + dictionary[5:].lower())


def photos(name: str) -> list[tuple[Path, str]]:
    """(photo, OpenCV dictionary) of one set."""
    if name == "top":
        return [(REAL / f, d) for f, (d, _) in TOP.items()]
    doc = json.loads((REAL / name / "peers.json").read_text())
    return [(REAL / name / p["file"], p["dictionary"]) for p in doc["photos"]]


@dataclass
class Seen:
    """One photo: gtrig's and each peer's markers (ID -> centre, px)."""

    gtrig: dict[int, np.ndarray]
    peers: dict[str, dict[int, np.ndarray]]


def _opencv(gray: np.ndarray, dictionary: str) -> dict[int, np.ndarray]:
    det = cv2.aruco.ArucoDetector(cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, dictionary)),
                                  cv2.aruco.DetectorParameters())
    corners, ids, _ = det.detectMarkers(gray)
    if ids is None:
        return {}
    return {int(i): np.asarray(c, float).reshape(4, 2).mean(axis=0) for i, c in zip(ids.ravel(), corners, strict=True)}


def see(path: Path, dictionary: str, detectors: dict[tuple[str, str], MarkerDetector]) -> Seen:
    gray = cv2.imread(str(path), cv2.IMREAD_GRAYSCALE)
    family, tone = family_of(dictionary), declared_tone(path)
    det = detectors.setdefault((family, tone), MarkerDetector(family, params=DetectorParams(tone=tone)))
    dets = det.detect(gray)
    assert len({d.id for d in dets}) == len(dets), f"{path.name}: an ID detected twice"
    peers = {"OpenCV": _opencv(gray, dictionary)}
    if dictionary in AT3:
        at3 = {label: at3_detect(gray, AT3[dictionary], qd) for label, qd in (("AprilTag 3", 2.0),
                                                                             ("AprilTag 3 qd=1", 1.0))}
        sure = set(peers["OpenCV"]) | {i for res in at3.values() for i, h, _ in res if h <= 1}
        for label, res in at3.items():
            peers[label] = {i: c.mean(axis=0) for i, h, c in res if h <= 1 or i in sure}
    return Seen({d.id: d.corners_px.mean(axis=0) for d in dets}, peers)


@pytest.fixture(scope="module")
def seen() -> dict[str, list[tuple[Path, str, Seen]]]:
    detectors: dict[tuple[str, str], MarkerDetector] = {}
    return {name: [(p, d, see(p, d, detectors)) for p, d in photos(name)] for name in SETS}


def printed(name: str, path: Path, dictionary: str, s: Seen) -> set[int]:
    """The IDs printed in the photo's set (the peers' where the set is not known)."""
    if name == "top":
        return TOP[path.name][1]
    known = PRINTED.get((name, dictionary))
    return known if known is not None else set().union(*(set(p) for p in s.peers.values()))


@pytest.mark.parametrize("name", SETS)
def test_recall_at_least_every_peer_per_photo(seen, name: str) -> None:
    short = []
    for path, dictionary, s in seen[name]:
        ids = printed(name, path, dictionary, s)
        for peer, found in s.peers.items():
            want = set(found) & ids
            if not want <= set(s.gtrig):
                short.append(f"{path.name}: {peer} finds {sorted(want - set(s.gtrig))}, gtrig does not")
    assert not short, "\n".join(short)


@pytest.mark.parametrize("name", SETS)
def test_no_wrong_id(seen, name: str) -> None:
    wrong = []
    for path, dictionary, s in seen[name]:
        ids = printed(name, path, dictionary, s)
        for mid, c in s.gtrig.items():
            if mid in ids:
                continue
            # a peer's reading at the same place (within 10 px of the centre) vouches for it
            if not any(mid in p and np.linalg.norm(p[mid] - c) < 10.0 for p in s.peers.values()):
                wrong.append(f"{path.name}: ID {mid} at {np.round(c)}")
    assert not wrong, "\n".join(wrong)


def test_sets_are_all_read(seen) -> None:
    """The sets hold what their README says (a guard against a moved folder reading as nothing)."""
    assert len(seen["photonvision"]) == 85
    assert sum(len(s.gtrig) for _, _, s in seen["photonvision"]) >= 1940
