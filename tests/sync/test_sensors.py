"""Per-scanner and per-camera clock offsets: known offsets recovered within 1 ms from synthetic returns
and poses, intervals covering them; a sensor that never sees the robot move is refused."""

import numpy as np
import pytest

from gtrig.fusion.measurements import fixes_from_track
from gtrig.sync.cameras import camera_membership, camera_offsets, checkpoint_membership
from gtrig.sync.reference import Reference, jump_stamps, near_reference, reference_track
from gtrig.sync.returns import ScannerReturns, recording_returns
from gtrig.sync.scanners import hull_distances, restamp_laser, scanner_offsets
from gtrig.trajectory import PoseTrack

HULL = np.array([[-0.3, -0.25], [0.3, -0.25], [0.3, 0.25], [-0.3, 0.25]])  # counter-clockwise, robot frame
SCANNERS = np.array([[-4.0, -4.0], [5.0, -3.0], [0.0, 6.0]])
OFFSETS = np.array([0.004, 0.0, -0.0035])  # each scanner's stamps minus the true firing times


def _truth_reference(run) -> Reference:  # noqa: ANN001
    t = np.arange(run.motion.stamps_s[0], run.motion.stamps_s[-1], 0.005)
    xyt = run.motion.planar(t)
    xyt[:, 2] = np.unwrap(xyt[:, 2])
    return Reference(t, xyt, np.gradient(xyt, t, axis=0), np.zeros((t.size, 3, 3)))


def _returns(run, rng: np.random.Generator, offsets: np.ndarray, static: bool = False) -> ScannerReturns:  # noqa: ANN001
    """Returns of the hull's visible sides, 15 per side and scan, 3 mm range noise, 75 Hz per scanner."""
    t0, t1 = run.motion.stamps_s[0] + 1.0, run.motion.stamps_s[-1] - 1.0
    pts, st, sid, dirs = [], [], [], []
    u = np.linspace(0.05, 0.95, 15)
    for s, (o, tau) in enumerate(zip(SCANNERS, offsets, strict=True)):
        tt = np.arange(t0 + 0.003 * s, t1, 1 / 75)
        P = run.motion.planar(np.full(tt.size, t0) if static else tt)
        for k in range(4):
            a, b = HULL[k], HULL[(k + 1) % 4]
            c, sn = np.cos(P[:, 2]), np.sin(P[:, 2])
            R = np.stack([np.stack([c, -sn], -1), np.stack([sn, c], -1)], -2)  # (T, 2, 2)
            local = a + u[:, None] * (b - a)  # (40, 2)
            w = P[:, None, :2] + np.einsum("tij,uj->tui", R, local)
            n_r = np.array([(b - a)[1], -(b - a)[0]])
            n_w = np.einsum("tij,j->ti", R, n_r)
            facing = np.einsum("ti,ti->t", n_w, o - P[:, :2]) > 0
            w = w[facing]
            d = w - o
            d /= np.linalg.norm(d, axis=-1, keepdims=True)
            w = w + d * rng.normal(0, 0.003, w.shape[:2])[..., None]
            pts.append(w.reshape(-1, 2))
            dirs.append(d.reshape(-1, 2))
            st.append(np.repeat(tt[facing] + tau, u.size))
            sid.append(np.full(w.shape[0] * u.size, s))
    p = np.concatenate(pts)
    n = p.shape[0]
    return ScannerReturns(("a", "b", "c"), np.concatenate(st), p, np.concatenate(sid), np.concatenate(dirs), SCANNERS,
                          np.full(3, 0.003), np.zeros(n, np.int64), np.zeros(1))


def test_hull_distance_of_a_point_on_a_side_is_zero() -> None:
    pose = np.array([[1.0, 2.0, 0.3]])
    c, s = np.cos(0.3), np.sin(0.3)
    p = pose[:, :2] + np.array([[c * 0.3 - s * 0.1, s * 0.3 + c * 0.1]])  # on the front side (x = 0.3)
    d, k, J, over = hull_distances(HULL, pose, p + 0.01 * np.array([[c, s]]), np.array([[10.0, 2.0]]))
    assert k[0] == 1 and d[0] == pytest.approx(0.01, abs=1e-12) and over[0] == 0.0
    # the derivative by the pose: moving the robot forward by 1 mm brings the side 1 mm closer
    d2, _, _, _ = hull_distances(HULL, pose + [[c * 1e-3, s * 1e-3, 0]], p + 0.01 * np.array([[c, s]]),
                                 np.array([[10.0, 2.0]]))
    assert d2[0] - d[0] == pytest.approx(J[0] @ [c * 1e-3, s * 1e-3, 0], abs=1e-9)


def test_scanner_offsets_recovered(run) -> None:  # noqa: ANN001
    ret = _returns(run, np.random.default_rng(3), OFFSETS)
    # the reference: poses with 1 mm / 1 mrad noise at 30 Hz, smoothed (as GTvision's would be)
    rng = np.random.default_rng(4)
    t = np.arange(run.motion.stamps_s[0], run.motion.stamps_s[-1], 1 / 30)
    z = run.motion.planar(t) + rng.normal(0, 1, (t.size, 3)) * [0.001, 0.001, 0.001]
    cov = np.tile(np.diag([1e-6, 1e-6, 1e-6]), (t.size, 1, 1))
    ref = reference_track([fixes_from_track(PoseTrack.from_xytheta(t, z, cov=cov, source="v"), "v")])
    est = scanner_offsets(ret, ref, HULL, block_s=3.0)
    for e, tau in zip(est, OFFSETS, strict=True):
        assert e.verdict == "ok", e.reason
        assert abs(e.offset_s - tau) < 0.001
        assert e.ci95_s[0] <= tau <= e.ci95_s[1]
        assert e.ci95_s[1] - e.ci95_s[0] < 0.003
        assert e.lags_s.size == e.corr.size and np.nanmax(e.corr) == pytest.approx(1.0)


def test_scanner_that_never_sees_motion_is_unobservable(run) -> None:  # noqa: ANN001
    ret = _returns(run, np.random.default_rng(3), OFFSETS, static=True)
    est = scanner_offsets(ret, _truth_reference(run), HULL, block_s=3.0)
    assert all(e.verdict == "unobservable" and np.isnan(e.offset_s) for e in est)


def test_camera_offsets_recovered(run) -> None:  # noqa: ANN001
    """Three free-running 10 Hz cameras, +2 / 0 / -1.5 ms, each with its own bias; some instants shared."""
    rng = np.random.default_rng(8)
    t0, t1 = run.motion.stamps_s[0] + 0.5, run.motion.stamps_s[-1] - 0.5
    taus = {"c0": 0.002, "c1": 0.0, "c2": -0.0015}
    phase = {"c0": 0.0, "c1": 0.033, "c2": 0.0351}  # c1 and c2 within 5 ms: their instants are shared
    stamps = {c: np.arange(t0 + phase[c], t1, 0.1) + taus[c] for c in taus}
    bias = {"c0": [0.002, -0.001, 0.001], "c1": [0.0, 0.001, -0.0005], "c2": [-0.001, 0.0, 0.0]}
    inst_t, inst_z = [], []
    for c in ("c0",):
        inst_t.append(stamps[c])
        inst_z.append(run.motion.planar(stamps[c] - taus[c]) + bias[c])
    pair = 0.5 * (stamps["c1"] + stamps["c2"])  # GTvision stamps a group at its images' mean
    inst_t.append(pair)
    inst_z.append(0.5 * (run.motion.planar(stamps["c1"] - taus["c1"]) + run.motion.planar(stamps["c2"] - taus["c2"]))
                  + 0.5 * (np.array(bias["c1"]) + bias["c2"]))
    t = np.concatenate(inst_t)
    z = np.concatenate(inst_z)
    order = np.argsort(t)
    t, z = t[order], z[order] + rng.normal(0, 1, z.shape) * [0.0005, 0.0005, 0.0003]
    cov = np.tile(np.diag([0.0005**2, 0.0005**2, 0.0003**2]), (t.size, 1, 1))
    vision = PoseTrack.from_xytheta(t, z, cov=cov, source="vision")
    share = camera_membership(t, stamps)
    assert np.allclose(share[np.isin(t, pair)], [0.0, 0.5, 0.5]) and np.allclose(share.sum(axis=1), 1.0)
    est = camera_offsets(vision, stamps, _truth_reference(run), block_s=3.0, relative=False)
    e0 = est[0]
    assert e0.verdict == "ok" and abs(e0.offset_s - taus["c0"]) < 0.001 and e0.ci95_s[0] <= taus["c0"] <= e0.ci95_s[1]
    # c1 and c2 only ever appear together: only their mean is observable, so neither gets a number
    assert [e.verdict for e in est[1:]] == ["unobservable", "unobservable"]


def test_camera_normal_equations_in_blocks_of_instants_are_the_whole_sums() -> None:
    """The per-camera fit forms its normal equations a block of instants at a time (an hour's instants at
    once held ~300 MB): the same sums, to the bit, whatever the block."""
    import gtrig.sync.cameras as ss

    rng = np.random.default_rng(3)
    M, C, G, B = 1000, 4, 3, 7
    n = C + 3 * G
    V, e = rng.normal(size=(M, 3)), rng.normal(size=(M, 3))
    share = rng.random((M, C)) * (rng.random((M, C)) < 0.5)
    group, blocks = rng.integers(0, G, M), np.sort(rng.integers(0, B, M))
    a = rng.normal(size=(M, 3, 3))
    W, hub = a @ a.transpose(0, 2, 1), rng.random(M)
    whole = ss._camera_normal_equations(V, share, group, hub, W, e, blocks, B, n)
    old = ss.CAMERA_ROWS_PER_BLOCK
    try:
        for rows in (1, 97, 999):
            ss.CAMERA_ROWS_PER_BLOCK = rows
            parts = ss._camera_normal_equations(V, share, group, hub, W, e, blocks, B, n)
            assert all(np.array_equal(x, y) for x, y in zip(whole, parts, strict=True))
    finally:
        ss.CAMERA_ROWS_PER_BLOCK = old
    # and they are the design's: sum over the block's instants of hub A^T W A
    A = np.zeros((M, 3, n))
    A[:, :, :C] = V[:, :, None] * share[:, None, :]
    for i in range(3):
        A[np.arange(M), i, C + 3 * group + i] = -1.0
    H0 = np.einsum("m,mia,mij,mjb->ab", hub * (blocks == 0), A, W, A)
    assert np.allclose(whole[0][0], H0, rtol=1e-12, atol=1e-9)


def test_camera_offsets_to_the_cameras_mean_ignore_a_reference_shifted_along_the_motion(run) -> None:  # noqa: ANN001
    """A reference whose robot frame sits 0.8 mm ahead of the truth (GTlaser's hull frame shifted by its
    range biases) looks, at a steady speed, like a clock offset of the reference: the same for every
    camera. To GTvision's clock (the cameras' mean) it cancels; to the reference's clock it does not."""
    rng = np.random.default_rng(9)
    t0, t1 = run.motion.stamps_s[0] + 0.5, run.motion.stamps_s[-1] - 0.5
    taus = {"c0": 0.001, "c1": -0.001}
    stamps = {c: np.arange(t0 + ph, t1, 0.1) + taus[c] for c, ph in (("c0", 0.0), ("c1", 0.05))}
    t = np.concatenate([stamps["c0"], stamps["c1"]])
    z = np.concatenate([run.motion.planar(stamps[c] - taus[c]) for c in ("c0", "c1")])
    order = np.argsort(t)
    t, z = t[order], z[order] + rng.normal(0, 1, z.shape) * [0.0005, 0.0005, 0.0003]
    cov = np.tile(np.diag([0.0005**2, 0.0005**2, 0.0003**2]), (t.size, 1, 1))
    vision = PoseTrack.from_xytheta(t, z, cov=cov, source="vision")
    ref = _truth_reference(run)
    th = ref.xytheta[:, 2]
    shifted = ref.xytheta.copy()
    shifted[:, 0] += 0.0008 * np.cos(th)
    shifted[:, 1] += 0.0008 * np.sin(th)
    ref = Reference(ref.stamps_s, shifted, np.gradient(shifted, ref.stamps_s, axis=0), ref.cov)
    share = camera_membership(t, stamps)
    mean = float(share.mean(axis=0) @ [taus["c0"], taus["c1"]])
    rel = camera_offsets(vision, stamps, ref, block_s=3.0)
    for e, c in zip(rel, ("c0", "c1"), strict=True):
        truth = taus[c] - mean
        assert e.verdict == "ok" and abs(e.offset_s - truth) < 3e-4 and e.ci95_s[0] <= truth <= e.ci95_s[1], e
    assert abs(share.mean(axis=0) @ [e.offset_s for e in rel]) < 1e-9
    absolute = camera_offsets(vision, stamps, ref, block_s=3.0, relative=False)
    common = np.mean([e.offset_s - taus[c] for e, c in zip(absolute, ("c0", "c1"), strict=True)])
    assert abs(common) > 4e-4  # the shift shows as the reference's clock error when not taken out


def test_restamp_laser_by_the_frames_shares() -> None:
    frames = np.array([10.0, 10.1, 10.2])
    # frame 0: only scanner a; frame 1: a and b half each; frame 2: none
    ret = ScannerReturns(("a", "b"), np.zeros(4), np.zeros((4, 2)), np.array([0, 0, 1, 0]), np.zeros((4, 2)),
                         np.zeros((2, 2)), np.ones(2), np.array([0, 1, 1, 0]), frames)
    track = PoseTrack.from_xytheta(frames, np.zeros((3, 3)), source="laser")
    out = restamp_laser(track, ret, {"a": 0.004, "b": -0.002})
    shares = ret.frame_shares()
    assert np.allclose(shares, [[1.0, 0.0], [0.5, 0.5], [0.0, 0.0]])
    assert np.allclose(out.stamps_s, [10.0 - 0.004, 10.1 - 0.001, 10.2])


def test_restamp_laser_finds_the_frames_of_stamps_rounded_up_or_down() -> None:
    """A GTlaser track read back from its TUM file carries stamps rounded to the microsecond; a pose
    rounded up lies after its frame's stamp and must still be that frame's (before, the next frame up was
    looked at only: 2114 of seed 0's 5614 poses kept their stamp, and the cameras' reference mixed clocks)."""
    frames = np.array([10.0000004, 10.1000006, 10.2000004])  # written as 10.000000, 10.100001, 10.200000
    ret = ScannerReturns(("a", "b"), np.zeros(4), np.zeros((4, 2)), np.array([0, 0, 1, 0]), np.zeros((4, 2)),
                         np.zeros((2, 2)), np.ones(2), np.array([0, 1, 1, 0]), frames)
    read_back = np.round(frames, 6)
    assert np.any(read_back < frames) and np.any(read_back > frames)
    track = PoseTrack.from_xytheta(read_back, np.zeros((3, 3)), source="laser")
    out = restamp_laser(track, ret, {"a": 0.004, "b": -0.002})
    assert np.allclose(out.stamps_s, read_back - [0.004, 0.001, 0.0], atol=1e-9)
    k, hit = ret.frame_of(np.r_[read_back, 10.15])
    assert list(k[:3]) == [0, 1, 2] and list(hit) == [True, True, True, False]


def test_checkpoint_membership_takes_a_one_camera_pose_at_its_camera_stamp(tmp_path) -> None:
    """GTvision stamps an instant at its images' mean; a pose from one camera's view holds at that camera's
    stamp, a pose of two cameras' views at the instant's stamp (GTvision moves the views there)."""
    import json

    cams = {"a": np.array([10.000, 10.100]), "b": np.array([10.004, 10.104])}
    view = [[0.0, 0.0]] * 4
    obs = [{"stamp_s": 10.002, "cameras": ["a", "b"], "frames": [["a", 0], ["b", 0]],
            "views": [["b", 3, view, None, 0]]},
           {"stamp_s": 10.102, "cameras": ["a", "b"], "frames": [["a", 1], ["b", 1]],
            "views": [["a", 3, view, None, 1], ["b", 5, view, None, 1]]}]
    p = tmp_path / "gt_vision_run.checkpoint"
    p.write_text(json.dumps({"key": "k", "version": 4}) + "\n"
                 + json.dumps({"chunk": 0, "items": [{"obs": o} for o in obs]}) + "\n")
    when, share = checkpoint_membership(np.array([10.002, 10.102, 11.0]), p, cams)
    assert when == pytest.approx([10.004, 10.102, 11.0], abs=1e-9)
    assert np.allclose(share, [[0.0, 1.0], [0.5, 0.5], [0.0, 0.0]])


def test_checkpoint_membership_reads_the_per_camera_checkpoint(tmp_path) -> None:
    """The same instants from GTvision's checkpoint of one camera's detections per time window (version 5),
    whose instants are rebuilt from the frame stamps as GTvision groups them."""
    import json

    cams = {"a": np.array([10.000, 10.100]), "b": np.array([10.004, 10.104])}
    det = [[3, [[0.0, 0.0]] * 4, [[[1.0, 0.0], [0.0, 1.0]]] * 4]]
    p = tmp_path / "gt_vision_run.checkpoint"
    p.write_text(json.dumps({"key": "k", "version": 5}) + "\n"
                 + json.dumps({"camera": "a", "frames": [[0, []], [1, det]]}) + "\n"
                 + json.dumps({"camera": "b", "frames": [[0, det], [1, det]]}) + "\n")
    when, share = checkpoint_membership(np.array([10.002, 10.102, 11.0]), p, cams)
    assert when == pytest.approx([10.004, 10.102, 11.0], abs=1e-9)
    assert np.allclose(share, [[0.0, 1.0], [0.5, 0.5], [0.0, 0.0]])


def test_laser_clock_is_the_poses_mean_share_weighted_scanner_offset() -> None:
    from gtrig.sync.offset import OffsetEstimate
    from gtrig.sync.sensors import laser_clock

    frames = np.array([10.0, 10.1, 10.2])
    # frame 0: only scanner a; frame 1: a and b half each; frame 2: only b
    ret = ScannerReturns(("a", "b"), np.zeros(4), np.zeros((4, 2)), np.array([0, 0, 1, 1]), np.zeros((4, 2)),
                         np.zeros((2, 2)), np.ones(2), np.array([0, 1, 1, 2]), frames)
    track = PoseTrack.from_xytheta(frames, np.zeros((3, 3)), source="laser")

    def est(name: str, tau: float, half: float, verdict: str = "ok") -> OffsetEstimate:
        return OffsetEstimate(f"laser/{name}", verdict, tau, (tau - half, tau + half), np.nan, 1.0, np.nan,
                              np.zeros(0), np.zeros(0), 5, "")

    z = 1.959963984540054
    clock, sigma = laser_clock(ret, track, [est("a", 0.004, 0.001 * z), est("b", -0.002, 0.002 * z)])
    # mean shares over the three poses: a (1 + 0.5) / 3 = 0.5, b 0.5
    assert clock == pytest.approx(0.5 * 0.004 - 0.5 * 0.002)
    assert sigma == pytest.approx(np.hypot(0.5 * 0.001, 0.5 * 0.002))
    assert np.isnan(laser_clock(ret, track, [est("a", 0.004, 0.001), est("b", 0.0, 0.0, "ambiguous")])[0])


def _logged_recording(folder):  # noqa: ANN001, ANN202
    """Two scanners' background and run logs (1 s at 75 Hz, a hull driving by) in ``folder``; returns the
    rig and the run's returns read from the whole logs at once (:func:`frame_points`)."""
    from types import SimpleNamespace

    from gtrig.io.scans import ScanLog, read_scans, write_scans
    from gtrig.laser import synth
    from gtrig.laser.background import build_background
    from gtrig.laser.foreground import foreground_mask, foreground_threshold
    from gtrig.laser.fuse import frame_points
    from gtrig.rig.models import Hull
    from tests.laser.conftest import make_scanner

    walls = synth.rectangle_segments([[-4, -3], [4, -3], [4, 3], [-4, 3]])
    scs = (make_scanner("a", -3.6, -2.6, np.radians(35)), make_scanner("b", 3.6, -2.2, np.radians(150)))
    hull = Hull(length_m=0.78, width_m=0.57, z_min_m=0.05, z_max_m=0.55)
    rng = np.random.default_rng(6)
    bst = [np.arange(0, 0.4, 1 / 75) + 0.002 * i for i in range(2)]
    st = [np.arange(0, 1.0, 1 / 75) + 0.003 * i for i in range(2)]
    for sub, stamps, ranges in (
            ("background", bst, synth.scan_sequence(scs, walls, None, None, bst, rng)),
            ("run", st, synth.scan_sequence(scs, walls, hull, _drive, st, rng))):
        (folder / sub / "lasers").mkdir(parents=True)
        for s, t, r in zip(scs, stamps, ranges, strict=True):
            write_scans(folder / sub / "lasers" / f"{s.name}.csv", ScanLog(t, r))
    rig = SimpleNamespace(laser_scanners=list(scs), hull=hull)
    logs = [read_scans(folder / "run" / "lasers" / f"{s.name}.csv", s) for s in scs]
    bg = [build_background(read_scans(folder / "background" / "lasers" / f"{s.name}.csv", s).ranges_m, s)
          for s in scs]
    masks = [foreground_mask(g.ranges_m, foreground_threshold(b)) for g, b in zip(logs, bg, strict=True)]
    return rig, ScannerReturns.from_framed(frame_points(scs, [g.stamps_s for g in logs], [g.ranges_m for g in logs],
                                                        masks))


def _drive(t: float) -> np.ndarray:
    """The hull's pose of :func:`_logged_recording` at ``t`` (s): x, y (m), yaw (rad), world frame."""
    return np.array([-1 + 0.3 * t, 0.2 * t, 0.3 + 0.4 * t])


def test_recording_returns_read_a_window_at_a_time_are_the_whole_logs_returns(tmp_path) -> None:  # noqa: ANN001
    """The scanners' returns for the per-scanner offsets, read from the logs a few frames at a time, are
    the returns of the whole logs read at once, bit for bit (only the returns stay in memory)."""
    rig, whole = _logged_recording(tmp_path)
    assert whole.stamps_s.size > 500
    for w in (7, 10**6):
        got = recording_returns(tmp_path, rig, window_frames=w)
        assert got.names == whole.names
        for k in ("stamps_s", "xy_world", "scanner_index", "dir_world", "origin_xy", "sigma_m", "frame_index",
                  "frame_stamps_s"):
            np.testing.assert_array_equal(getattr(got, k), getattr(whole, k), err_msg=f"{k}, windows of {w}")


@pytest.mark.parametrize(("spool", "window"), [(True, 9), (False, 9), (True, 10**6)])
def test_scanner_fit_over_windows_of_the_logs_is_the_fit_over_all_returns(tmp_path, spool: bool, window: int,  # noqa: ANN001
                                                                          ) -> None:
    """The per-scanner fit summed window by window over returns spooled to a file (or re-read from the
    logs) gives the fit over all returns in memory, to the order of the sums (bit for bit in one window);
    the windows are the whole logs' returns; the per-frame uses (shares, frames of stamps) are the same;
    the spool file is gone after."""
    from gtrig.sync.returns import returns_of_recording

    rig, whole = _logged_recording(tmp_path / "rec")
    t = np.arange(-0.5, 1.5, 0.02)
    xyt = np.array([_drive(x) for x in t])
    ref = Reference(t, xyt, np.gradient(xyt, t, axis=0), np.zeros((t.size, 3, 3)))
    corners = rig.hull.corners_xy()
    one = scanner_offsets(whole, ref, corners, block_s=0.1, max_ci_s=1.0)
    spool_dir = tmp_path / "spool"
    spool_dir.mkdir()
    with returns_of_recording(tmp_path / "rec", rig, spool=spool, tmp_dir=spool_dir, window_frames=window) as ret:
        assert len(list(spool_dir.iterdir())) == (1 if spool else 0)
        parts = list(ret.windows())
        assert len(parts) > 5 if window < 75 else len(parts) == 1
        np.testing.assert_array_equal(np.concatenate([r.stamps_s for r in parts]), whole.stamps_s)
        np.testing.assert_array_equal(np.concatenate([r.frame_index for r in parts]), whole.frame_index)
        got = scanner_offsets(ret, ref, corners, block_s=0.1, max_ci_s=1.0)
    assert not list(spool_dir.iterdir())
    np.testing.assert_array_equal(ret.frame_shares(), whole.frame_shares())
    some = whole.frame_stamps_s[::3]
    np.testing.assert_array_equal(ret.frame_of(some)[0], whole.frame_of(some)[0])
    for a, b in zip(one, got, strict=True):
        assert a.verdict == b.verdict == "ok", (a.reason, b.reason)
        assert a.windows == b.windows and a.reason == b.reason
        if window > 75:
            assert (b.offset_s, b.ci95_s, b.corr.tolist()) == (a.offset_s, a.ci95_s, a.corr.tolist())
            continue
        # the cost curve is not smooth: a return beyond a hull corner is as far from both sides, and which
        # side it is given flips with the last bit of the trial offset, so the sums' order (window by
        # window, and the libraries' builds: a fresh install moved it 0.54 ms of 8.9) can move the minimum by a
        # few per cent of its interval: the same estimate, not the same bits
        half = 0.5 * (a.ci95_s[1] - a.ci95_s[0])
        assert abs(b.offset_s - a.offset_s) < 0.1 * half, (a.offset_s, b.offset_s, half)
        np.testing.assert_allclose(np.diff(b.ci95_s), np.diff(a.ci95_s), rtol=0.1)
        assert np.argmax(b.corr) == np.argmax(a.corr)
        np.testing.assert_allclose(b.corr, a.corr, atol=0.05)


def test_reference_in_windows_is_the_whole_batch_and_bounded(tmp_path) -> None:  # noqa: ANN001
    """A long reference smoothed in windows (each with 30 s of fixes beyond its ends) is the one-batch
    smoothing to a nanometre and a nanoradian, with a gap inside one window and one across a
    window's end; and its peak memory is that of a window, not of the whole span."""
    import tracemalloc

    rng = np.random.default_rng(11)
    t = np.arange(0.0, 1000.0, 0.1)
    t = t[~(((t > 130.0) & (t < 133.0)) | ((t > 398.0) & (t < 403.0)))]  # gaps: in a window, across an end
    xyt = np.column_stack([2.0 * np.cos(0.05 * t) + 0.3 * np.sin(0.31 * t), 1.5 * np.sin(0.05 * t),
                           0.05 * t + 0.2 * np.sin(0.17 * t)])  # yaw winds past +-pi many times
    cov = np.tile(np.diag([1e-6, 1e-6, 1e-5]), (t.size, 1, 1))
    z = xyt + rng.multivariate_normal(np.zeros(3), cov[0], t.size)
    fixes = [fixes_from_track(PoseTrack.from_xytheta(t, z, cov=cov, source="v"), "v")]
    # one short smoothing first: the first call's lazy imports and caches (some 40 MB, more than a
    # window's own working set) would otherwise be charged to whichever call is traced first
    reference_track([fixes[0].between(0.0, 20.0)], window_s=np.inf)
    tracemalloc.start()
    try:
        windowed = reference_track(fixes, window_s=200.0)
        _, peak_windowed = tracemalloc.get_traced_memory()
        tracemalloc.reset_peak()
        whole = reference_track(fixes, window_s=np.inf)
        _, peak_whole = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert windowed.stamps_s.size == whole.stamps_s.size
    assert np.abs(windowed.stamps_s - whole.stamps_s).max() < 1e-9  # the same grid (its phase from each start)
    d = np.abs(windowed.xytheta - whole.xytheta)
    assert d[:, :2].max() < 1e-9 and d[:, 2].max() < 1e-9  # metres, radians
    assert np.abs(windowed.velocity - whole.velocity).max() < 1e-7
    assert np.allclose(windowed.cov, whole.cov, rtol=1e-6, atol=1e-15)
    assert peak_windowed < 0.5 * peak_whole


def test_reference_is_cut_where_its_fixes_jump() -> None:
    """Two laps of a path joined with 0.36 s between them (a recording made of laps): the robot is back
    at the lap's start, 3 m back, after the seam. The reference has no pose across the seam and never
    moves faster than the path does (smoothed across, it went back at some 8 m/s, speeds that outweighed
    every other time of the offset fits)."""
    rng = np.random.default_rng(3)
    t = np.arange(0.0, 30.0, 1 / 75)
    xyt = np.column_stack([0.1 * t, 0.5 * np.sin(0.2 * t), 0.3 * np.sin(0.1 * t)])
    cov = np.tile(np.diag([1e-6, 1e-6, 1e-5]), (t.size, 1, 1))
    period = 30.36
    z = np.r_[xyt, xyt] + rng.multivariate_normal(np.zeros(3), cov[0], 2 * t.size)
    fixes = [fixes_from_track(PoseTrack.from_xytheta(np.r_[t, t + period], z, cov=np.r_[cov, cov], source="v"), "v")]
    cuts = jump_stamps(fixes)
    assert cuts.size == 1 and abs(cuts[0] - period) < 1e-9
    ref = reference_track(fixes)
    seam = (ref.stamps_s > t[-1] + 0.05) & (ref.stamps_s < period - 0.05)  # a grid step past the fixes at most
    assert not seam.any()
    assert not near_reference(ref, np.array([t[-1] + 0.18]), 0.05).any()
    speed = np.hypot(ref.velocity[:, 0], ref.velocity[:, 1])
    assert speed.max() < 0.3  # the path's own: 0.14 m/s at most
