from __future__ import annotations

import numpy as np

from gtrig.laser import synth
from gtrig.laser.background import build_background
from gtrig.laser.foreground import foreground_mask, foreground_threshold


def test_background_robust_to_a_passing_person(room):
    s = room["scanners"][0]
    rng = np.random.default_rng(0)
    clean = synth.scan(s, room["static"])
    scans = []
    for k in range(200):
        # a person walks across the scanner's view during 40 % of the sequence
        person = synth.person_segments([-2.0 + 0.03 * k, -1.0]) if 40 <= k < 120 else np.zeros((0, 2, 2))
        scans.append(synth.scan(s, np.concatenate([room["static"], person]), rng))
    bg = build_background(np.array(scans), s)
    ok = np.isfinite(clean)
    assert np.nanmax(np.abs(bg.ranges_m[ok] - clean[ok])) < 0.004
    # the person is foreground, the empty room is not
    th = foreground_threshold(bg)
    person_scan = synth.scan(s, np.concatenate([room["static"], synth.person_segments([-1.0, -1.0])]), rng)
    empty_scan = synth.scan(s, room["static"], rng)
    assert foreground_mask(person_scan[None], th).sum() >= 3
    assert foreground_mask(empty_scan[None], th).sum() == 0


def test_mixed_pixels_at_furniture_edges_are_not_foreground(room):
    s = room["scanners"][1]
    rng = np.random.default_rng(1)
    clean = synth.scan(s, room["static"])
    scans = np.tile(clean, (50, 1)) + rng.normal(0, 0.01, (50, clean.size))
    bg = build_background(scans, s)
    # a return halfway between a box edge and the wall behind it, on the edge beam
    jumps = np.flatnonzero(np.abs(np.diff(clean)) > 0.5)
    assert jumps.size
    test = clean.copy()
    for j in jumps:
        near, far = (j, j + 1) if clean[j] < clean[j + 1] else (j + 1, j)
        test[far] = 0.5 * (clean[near] + clean[far])
    assert foreground_mask(test[None], foreground_threshold(bg)).sum() == 0
