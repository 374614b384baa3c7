"""Validation stops, mounting and map alignment against simulated truth (truth only scores)."""

from __future__ import annotations

import numpy as np

from gtrig.io.rosmap import read_map
from gtrig.rig.load import load_rig
from gtrig.scanmatch import se2
from gtrig.scanmatch.mapmatch import map_points, match_to_map
from gtrig.scanmatch.mounting import calibrate_mounting
from gtrig.scanmatch.validate import load_stop_scans, scanner_pose_xyth, validate_stops
from gtrig.sim.map import write_maps


def test_stops_within_5mm_and_nees(stop_rec):
    rec, truth, _ = stop_rec
    rig = load_rig(rec / "rig.yaml")
    stops = load_stop_scans(rec, rig)
    rng = np.random.default_rng(3)
    rough = truth + rng.normal(0, [0.02, 0.02, 0.01], truth.shape)
    res = validate_stops(stops, 1, rig, rough)
    rel = se2.relative(truth[0], truth)
    e = se2.relative(rel[1:], res.track.xytheta()[1:])
    assert res.track.ok.all()
    assert np.mean(np.hypot(e[:, 0], e[:, 1])) < 0.005
    assert np.degrees(np.mean(np.abs(e[:, 2]))) < 0.1
    nees = np.array([x @ np.linalg.solve(c, x) for x, c in zip(e, res.track.cov[1:], strict=True)])
    # ten stops: a loose band (the 3-seed figure is in docs/scanmatch.md)
    assert 0.1 < nees.mean() / 3 < 2.5


def test_stops_without_guess_by_the_genetic_matcher(stop_rec):
    rec, truth, _ = stop_rec
    rig = load_rig(rec / "rig.yaml")
    stops = load_stop_scans(rec, rig)
    # neighbours of the reference only: the room-wide search is the slow path
    sub = type(stops)(stops.pose_ids[:3], stops.stamps_s[:3], stops.merged[:3], {})
    res = validate_stops(sub, 1, rig, None)
    rel = se2.relative(truth[0], truth[:3])
    e = se2.relative(rel, res.track.xytheta())
    assert np.all(np.hypot(e[:, 0], e[:, 1]) < 0.01)


def test_mounting_recovered(stop_rec):
    rec, truth, _ = stop_rec
    rig = load_rig(rec / "rig.yaml")
    stops = load_stop_scans(rec, rig)
    rng = np.random.default_rng(4)
    # the survey's poses: truth with the survey's own errors (0.5 mm, 0.02 deg)
    sv = truth + rng.normal(0, [0.0005, 0.0005, np.radians(0.02)], truth.shape)
    cov = np.tile(np.diag([0.0005**2, 0.0005**2, np.radians(0.02) ** 2]), (len(truth), 1, 1))
    sc = rig.robot.onboard_scanners[0]
    true_m = scanner_pose_xyth(sc)
    res, n_try, n_acc = calibrate_mounting(stops.per_scanner[sc.name], sv, cov, true_m + [0.02, -0.02, 0.02])
    e = res.mounting - true_m
    assert n_acc >= 5
    assert np.hypot(e[0], e[1]) < 0.003
    assert abs(np.degrees(se2.wrap(e[2]))) < 0.1


def test_map_moved_wall_named_not_absorbed(stop_rec, tmp_path):
    rec, truth, scene = stop_rec
    write_maps(scene, tmp_path)
    import yaml

    err = yaml.safe_load((tmp_path / "truth" / "map_errors.yaml").read_text())["blueprint"]
    rig = load_rig(rec / "rig.yaml")
    stops = load_stop_scans(rec, rig)
    mp = map_points(read_map(tmp_path / "map" / "blueprint.yaml"))
    rng = np.random.default_rng(5)
    r = 0.3 * np.sqrt(rng.uniform(0, 1, len(truth)))
    a = rng.uniform(0, 2 * np.pi, len(truth))
    init = truth + np.column_stack([r * np.cos(a), r * np.sin(a), rng.uniform(-1, 1, len(truth)) * np.radians(15)])
    res = match_to_map(mp, list(stops.merged), init)
    e = se2.relative(truth, res.poses)
    assert np.max(np.hypot(e[:, 0], e[:, 1])) < 0.01
    assert np.degrees(np.max(np.abs(e[:, 2]))) < 0.2
    flagged = res.flagged
    assert len(flagged) >= 1
    f = flagged[0]
    mid = 0.5 * (np.array(err["wall_from_xy"]) + np.array(err["wall_to_xy"]))
    d = np.array(err["wall_to_xy"]) - np.array(err["wall_from_xy"])
    n = np.array([d[1], -d[0]]) / np.linalg.norm(d)
    # the flagged surface is the moved wall (its ends on the wall's line) and its offset ~ the shift
    assert np.all(np.abs((f.ends_xy - mid) @ n) < 0.1)
    assert abs(f.offset_m - err["shift_m"]) < 0.01
