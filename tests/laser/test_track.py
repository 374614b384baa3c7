from __future__ import annotations

import numpy as np
import pytest

from gtrig.errors import GtrigError
from gtrig.geometry import wrap_angle
from gtrig.io.posetrack import read_pose_track
from gtrig.io.scans import ScanLog, write_scans
from gtrig.laser import synth
from gtrig.laser.background import build_background
from gtrig.laser.foreground import foreground_mask, foreground_threshold
from gtrig.laser.fuse import frame_points
from gtrig.laser.hull_icp import HullModel
from gtrig.laser.recording import load_backgrounds, track_recording, write_track
from gtrig.laser.track import OK, track_frames
from gtrig.rig.load import dump_rig
from gtrig.rig.models import Rig, Robot


def _pose_at(t):
    # integrate the arc exactly: x' = v cos th, y' = v sin th with th = 0.3 + 0.15 t
    v, w, th0 = 0.3, 0.15, 0.3
    return np.array(
        [
            -1.0 + v / w * (np.sin(th0 + w * t) - np.sin(th0)),
            -0.5 - v / w * (np.cos(th0 + w * t) - np.cos(th0)),
            th0 + w * t,
        ]
    )


@pytest.fixture(scope="module")
def sequence(room):
    rng = np.random.default_rng(3)
    scs = room["scanners"]
    bst = [np.arange(0, 1.0, 1 / 75) + 0.002 * i for i in range(4)]
    bg = synth.scan_sequence(
        scs, room["static"], None, None, bst, rng, person_at=lambda t: np.array([-2 + 2 * t, 1.5])
    )
    st = [np.arange(0, 2.0, 1 / 75) + 0.0031 * i for i in range(4)]
    run = synth.scan_sequence(
        scs, room["static"], room["hull"], _pose_at, st, rng, person_at=lambda t: np.array([1.5, -2.0 + t])
    )
    return bst, bg, st, run


def test_tracks_synthetic_sequence(room, sequence):
    bst, bg, st, run = sequence
    scs = room["scanners"]
    models = [build_background(b, s) for b, s in zip(bg, scs, strict=True)]
    masks = [foreground_mask(r, foreground_threshold(m)) for r, m in zip(run, models, strict=True)]
    fp = frame_points(scs, st, run, masks)
    res = track_frames(fp, HullModel.from_hull(room["hull"]))
    ok = res.status == OK
    assert ok.mean() > 0.95
    truth = np.array([_pose_at(t) for t in res.stamps_s])
    e = np.hypot(*(res.xytheta[ok, :2] - truth[ok, :2]).T)
    ey = np.abs(wrap_angle(res.xytheta[ok, 2] - truth[ok, 2]))
    # heading resolved from the direction of motion, millimetre accuracy
    assert e.mean() < 0.004 and e.max() < 0.02
    assert np.degrees(ey.mean()) < 0.3
    # a calibration covariance of the scanners is added to every pose's, after smoothing
    cal = np.diag(np.tile([1e-6, 1e-6, np.radians(0.02) ** 2], len(scs)))
    res_c = track_frames(fp, HullModel.from_hull(room["hull"]), scanner_cov=cal)
    assert np.allclose(res_c.xytheta[ok], res.xytheta[ok])
    added = res_c.cov_xytheta[ok] - res.cov_xytheta[ok]
    assert np.allclose(added, res_c.cov_calibration[ok])
    # four scanners with independent errors: more than a quarter of one scanner's (plus the yaw lever)
    assert np.all((added[:, 0, 0] > 0.2e-6) & (added[:, 0, 0] < 3e-6))


def _write_recording(root, room, sequence, beams_override=None, shuffle=False, drop_bg=None):
    bst, bg, st, run = sequence
    rig = Rig(laser_scanners=room["scanners"], robot=Robot(hull=room["hull"]))
    dump_rig(rig, root / "rig.yaml")
    for s, b_st, b, r_st, r in zip(room["scanners"], bst, bg, st, run, strict=True):
        if s.name != drop_bg:
            write_scans(root / "background" / "lasers" / f"{s.name}.csv", ScanLog(b_st, b))
        rr = r if beams_override is None else r[:, :beams_override]
        rs = r_st.copy()
        if shuffle:
            rs[10], rs[11] = rs[11], rs[10]
        write_scans(root / "run" / "lasers" / f"{s.name}.csv", ScanLog(rs, rr))
    return rig


def test_track_recording_writes_tum_and_covariance(tmp_path, room, sequence):
    rig = _write_recording(tmp_path, room, sequence)
    res = track_recording(tmp_path, "run", rig=rig, out_tum=tmp_path / "gt.tum", out_cov=tmp_path / "cov.csv")
    # the one pose-track layout (gtrig.io.posetrack): the OK frames, their covariances to the last digit
    track = read_pose_track(tmp_path / "gt.tum", tmp_path / "cov.csv")
    ok = res.ok
    assert len(track) == int(ok.sum()) and track.source == "GTlaser" and track.cov_kind == "xyyaw"
    np.testing.assert_allclose(track.stamps_s, res.stamps_s[ok], atol=5e-7)
    np.testing.assert_array_equal(track.cov, res.cov_xytheta[ok])
    np.testing.assert_allclose(track.xytheta(), res.xytheta[ok], atol=2e-9)
    assert (track.status == 0).all()


def _one_line(e: BaseException) -> str:
    msg = str(e)
    assert "\n" not in msg
    return msg


def test_error_beam_count(tmp_path, room, sequence):
    rig = _write_recording(tmp_path, room, sequence, beams_override=170)
    with pytest.raises(GtrigError) as e:
        track_recording(tmp_path, "run", rig=rig)
    assert "beams" in _one_line(e.value) and "180" in str(e.value)


def test_error_non_monotonic_stamps(tmp_path, room, sequence):
    rig = _write_recording(tmp_path, room, sequence, shuffle=True)
    with pytest.raises(GtrigError) as e:
        track_recording(tmp_path, "run", rig=rig)
    assert "increase" in _one_line(e.value)


def test_error_scanner_without_background(tmp_path, room, sequence):
    rig = _write_recording(tmp_path, room, sequence, drop_bg="c")
    with pytest.raises(GtrigError) as e:
        load_backgrounds(tmp_path / "background", rig)
    assert "scanner c" in _one_line(e.value) and "background" in str(e.value)


def test_write_track_refuses_empty(tmp_path, room, sequence):
    bst, bg, st, run = sequence
    scs = room["scanners"]
    masks = [np.zeros_like(r, dtype=bool) for r in run]
    res = track_frames(frame_points(scs, st, run, masks), HullModel.from_hull(room["hull"]))
    assert not res.ok.any()
    with pytest.raises(GtrigError):
        write_track(res, tmp_path / "x.tum")


def test_track_recording_parses_each_log_once(tmp_path, room, sequence, monkeypatch):
    """With a cache folder (what ``gtrig run`` passes) the first run parses each log once (its index) and
    a second one none, with the same result bit for bit as parsing every window's text (``scan_cache=
    False``); without one, the call's temporary folder is gone when it returns."""
    import tempfile

    import gtrig.io.scans as scans

    rig = _write_recording(tmp_path / "rec", room, sequence)
    text = track_recording(tmp_path / "rec", "run", rig=rig, scan_cache=False)
    parsed = []
    parse = scans.ScanRows._parse
    monkeypatch.setattr(scans.ScanRows, "_parse", lambda self, lo, hi: parsed.append(hi - lo) or parse(self, lo, hi))
    first = track_recording(tmp_path / "rec", "run", rig=rig, scan_cache=tmp_path / "cache")
    assert not parsed and len(list((tmp_path / "cache").glob("*.f8"))) == len(rig.laser_scanners)

    def no_index(*a, **k):
        raise AssertionError("a log was indexed again")

    monkeypatch.setattr(scans, "_Indexer", no_index)
    again = track_recording(tmp_path / "rec", "run", rig=rig, scan_cache=tmp_path / "cache")
    assert not parsed
    for r in (first, again):
        assert r.xytheta.tobytes() == text.xytheta.tobytes() and r.cov_xytheta.tobytes() == text.cov_xytheta.tobytes()
    monkeypatch.undo()
    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path / "tmp"))
    (tmp_path / "tmp").mkdir()
    tmp = track_recording(tmp_path / "rec", "run", rig=rig)
    assert tmp.xytheta.tobytes() == text.xytheta.tobytes() and not list((tmp_path / "tmp").iterdir())
