"""Markers blurred by optics that are not Gaussian: a defocus disk and a linear motion blur over the
whole scene (gtrig.markers.synth.disk_psf, motion_psf), on the bench's cluttered scenes. The detector's
models assume a Gaussian blur; where a marker's cells are lost in such a blur it must read nothing,
never another ID, and a clutter glyph must not read as a marker (3 wrong IDs in 360 markers
before; the second path's read of a square whose blur exceeds a cell, and the pre-decoder's unconfirmed
blur-model reads at the family's full correction; a 20 px tag smeared 6 px read as another
ID with 4 cells corrected, which the solved cells' soft margin refuses, DetectorParams.min_soft_margin)."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from gtrig.markers.detect import MarkerDetector
from gtrig.markers.synth import psf_scene

FAMILY = "apriltag_36h11"
PSFS = ("disk 1", "disk 2", "disk 3", "motion 3", "motion 6")


@pytest.fixture(scope="module")
def outcome() -> tuple[dict[str, list[int]], list[tuple[str, int, int]]]:
    """Over 120 scenes (each PSF, sides 20-70 px, 6 draws): markers of >= 30 px found / there, per PSF,
    and every detection whose ID is not in its scene (PSF, side, ID)."""
    det = MarkerDetector(FAMILY)
    rng = np.random.default_rng(1)
    found = {p: [0, 0] for p in PSFS}
    wrong = []
    for psf, side, _ in itertools.product(PSFS, (20, 30, 45, 70), range(6)):
        img, truths = psf_scene(rng, psf, side, FAMILY)
        ids = {d.id for d in det.detect(img)}
        true_ids = {t.marker_id for t in truths}
        wrong += [(psf, side, i) for i in ids - true_ids]
        if side >= 30:
            found[psf][0] += len(ids & true_ids)
            found[psf][1] += 3
    return found, wrong


def test_no_wrong_id_under_disk_or_motion_blur(outcome) -> None:
    found, wrong = outcome
    assert not wrong, wrong
    # where the cells survive the blur (a disk of up to 2 px, motion of 3 px), every marker of 30 px and up
    for psf in ("disk 1", "disk 2", "motion 3"):
        assert found[psf][0] == found[psf][1], (psf, found[psf])
