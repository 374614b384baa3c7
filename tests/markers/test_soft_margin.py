"""The soft check of a blur-model reading (gtrig.markers.detect.decode.soft_code_margin): a marker whose
solved cells lie near its code passes it, a pattern whose cells a blur has scattered (the 20 px tag
smeared 6 px by motion of test_psf.py, read as another ID with 4 cells corrected) rarely does, even when
the hard decoder accepts it."""

from __future__ import annotations

import numpy as np
import pytest

from gtrig.markers.detect import DetectorParams
from gtrig.markers.detect.decode import soft_code_margin
from gtrig.markers.families import _codebook, decode_batch, family_spec
from gtrig.rig.models import MarkerFamily

K = DetectorParams().min_soft_margin


def _codes(family: MarkerFamily) -> np.ndarray:
    book = _codebook(family)
    return np.concatenate([np.rot90(book, -r, axes=(1, 2)) for r in range(4)])


@pytest.mark.parametrize("family", [MarkerFamily.APRILTAG_36H11, MarkerFamily.ARTOOLKITPLUS_BCH,
                                    MarkerFamily.ARUCO_6X6_250])
def test_noisy_codes_pass_and_scattered_cells_fail(family: MarkerFamily) -> None:
    codes = _codes(family)
    rng = np.random.default_rng(3)
    idx = rng.integers(len(codes), size=1500)
    # cells solved with an error of SD 0.2 (the benches' true readings: residual RMS up to 0.43 at
    # 13-27 px): found, and ahead of the runner-up by the margin
    w = codes[idx] + rng.normal(0.0, 0.2, (len(idx),) + codes.shape[1:])
    best, lead = soft_code_margin(w, codes)
    assert np.array_equal(best, idx)
    assert np.mean(lead >= K) >= 0.99
    # exact cells: a residual of zero leads by any margin
    best, lead = soft_code_margin(codes[idx[:20]].astype(float), codes)
    assert np.array_equal(best, idx[:20]) and np.all(lead > 1e6)
    # cells scattered across and beyond [0, 1]: of those the hard decoder takes for a code, most fail
    # (a third to a quarter pass; the rest of the gap to a wrong ID is the family's distance)
    spec = family_spec(family)
    w = rng.uniform(-0.4, 1.4, (20000,) + codes.shape[1:])
    ids, rot, _ = decode_batch(family, (w > 0.5).astype(np.uint8))
    best, lead = soft_code_margin(w, codes)
    hard = ids >= 0
    both = hard & (best == rot * spec.n_ids + ids) & (lead >= K)
    assert hard.sum() >= 20, hard.sum()  # enough accepted patterns to judge
    assert both.sum() <= 0.5 * hard.sum(), (both.sum(), hard.sum())  # (36h11: 64 of 293, BCH: 12 of 29)


def test_runner_up_is_measured_in_residual_units() -> None:
    codes = np.array([np.zeros((2, 2)), np.eye(2), np.ones((2, 2))], np.uint8)
    w = np.array([[[0.1, 0.0], [0.0, 0.1]]])  # D1 = 0.02 (code 0), D2 = 1.62 (code 1)
    best, lead = soft_code_margin(w, codes)
    assert best[0] == 0
    assert lead[0] == pytest.approx((1.62 - 0.02) / (0.02 / 4))


@pytest.mark.parametrize("family", [MarkerFamily.APRILTAG_16H5, MarkerFamily.ARUCO_5X5_1000])
def test_code_book_holds_the_familys_codes(family: MarkerFamily) -> None:
    """The detector's per-family tables (made once) are the family's codes and printed cells, and the soft
    reading through them is the one from the plain codes."""
    from gtrig.markers.detect.verify import code_book
    from gtrig.markers.families import all_codes, marker_cells

    book = code_book(family)
    spec = family_spec(family)
    assert np.array_equal(book.codes, all_codes(family))
    assert np.array_equal(book.flat, book.codes.reshape(len(book.codes), -1))
    ids = np.random.default_rng(1).integers(spec.n_ids, size=5)
    assert np.array_equal(book.cells[ids], [marker_cells(family, int(i)) for i in ids])
    w = book.codes[ids].astype(float) + np.random.default_rng(2).normal(0.0, 0.2, (5,) + book.codes.shape[1:])
    best, lead = soft_code_margin(w, book.flat, book.flat_sq)
    best0, lead0 = soft_code_margin(w, book.codes)
    assert np.array_equal(best, ids) and np.array_equal(best, best0)
    np.testing.assert_allclose(lead, lead0, rtol=1e-12)
