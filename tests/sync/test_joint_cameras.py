"""The cameras' offsets refined in the joint fit of GTvision, GTlaser and odometry: against a GTlaser
whose errors are slow (correlated over seconds, as the real tracker's), the joint fit recovers each
camera's offset better than the pose fit against GTlaser alone, and its interval covers the truth."""

import numpy as np

from gtrig.fusion.measurements import fixes_from_track
from gtrig.sync.cameras import camera_offsets
from gtrig.sync.joint_cameras import joint_camera_offsets, restamped
from gtrig.sync.reference import reference_track
from gtrig.trajectory import PoseTrack

TAUS = {"a": 0.0015, "b": -0.0015}  # the cameras' stamps minus the true instants


def _slow_laser(run, rng: np.random.Generator) -> PoseTrack:  # noqa: ANN001
    """75 Hz poses with a first-order Gauss-Markov error: 0.7 mm and 1 mrad, correlated over 1.5 s."""
    t = run.laser.stamps_s
    a = np.exp(-np.diff(t, prepend=t[0]) / 1.5)
    e = np.zeros((t.size, 3))
    sd = np.array([0.0007, 0.0007, 0.001])
    e[0] = rng.normal(0, sd)
    for k in range(1, t.size):
        e[k] = a[k] * e[k - 1] + np.sqrt(1 - a[k] ** 2) * rng.normal(0, sd)
    cov = np.tile(np.diag([0.001**2, 0.001**2, 0.0015**2]), (t.size, 1, 1))
    return PoseTrack.from_xytheta(t, run.motion.planar(t) + e, cov=cov, source="laser")


def _vision(run, rng: np.random.Generator) -> tuple[PoseTrack, dict[str, np.ndarray]]:  # noqa: ANN001
    """Two 10 Hz cameras that see the robot in turn (5 s each), 1 mm / 0.5 mrad noise (GTvision's)."""
    t0, t1 = run.motion.stamps_s[0] + 0.5, run.motion.stamps_s[-1] - 0.5
    stamps = {c: np.arange(t0 + ph, t1, 0.1) + TAUS[c] for c, ph in (("a", 0.0), ("b", 0.05))}
    views = {c: s[(np.floor((s - t0) / 5.0) % 2 == k)] for k, (c, s) in enumerate(stamps.items())}
    t = np.concatenate(list(views.values()))
    z = np.concatenate([run.motion.planar(s - TAUS[c]) for c, s in views.items()])
    order = np.argsort(t)
    sig = np.array([0.001, 0.001, 0.0005])
    t, z = t[order], z[order] + rng.normal(0, 1, z.shape) * sig
    cov = np.tile(np.diag(sig**2), (t.size, 1, 1))
    return PoseTrack.from_xytheta(t, z, cov=cov, source="vision"), stamps


def test_joint_fit_beats_gtlaser_alone_and_covers(run) -> None:  # noqa: ANN001
    alone, joint = [], []
    for seed in range(4):
        rng = np.random.default_rng(40 + seed)
        laser = _slow_laser(run, rng)
        vision, stamps = _vision(run, rng)
        first = camera_offsets(vision, stamps, reference_track([fixes_from_track(laser, "laser")]), block_s=3.0)
        est = joint_camera_offsets(vision, stamps, laser, run.odometry, 0.0, first)
        share = np.array([0.5, 0.5])  # each camera makes half the poses: GTvision's clock is their mean
        truth = np.array(list(TAUS.values())) - share @ list(TAUS.values())
        for e0, e, tau in zip(first, est, truth, strict=True):
            assert e0.verdict == "ok" and e.verdict == "ok", (e0.reason, e.reason)
            assert "joint" in e.reason
            assert e.ci95_s[0] <= tau <= e.ci95_s[1], (seed, e.source, e.offset_s, e.ci95_s)
            alone.append(abs(e0.offset_s - tau))
            joint.append(abs(e.offset_s - tau))
    assert np.mean(joint) < 0.7 * np.mean(alone), (np.mean(joint), np.mean(alone))
    assert max(joint) < 0.001


def test_restamped_poses_may_pass_each_other() -> None:
    """Poses moved by their cameras' offsets can change order (two cameras' instants 10 ms apart, one
    camera 25 ms late): the restamped track keeps each pose with its own data, sorted by the new
    times, a repeated time once (an hour of the simulated room crashed here before)."""
    t = np.arange(8) * 0.01
    xyt = np.column_stack([t, 2 * t, 0.1 * np.arange(8)])
    cov = np.tile(np.diag([1e-6, 1e-6, 1e-5]), (8, 1, 1))
    track = PoseTrack.from_xytheta(t, xyt, cov=cov, source="v")
    late = np.arange(8) % 2 == 0  # the even poses' camera is 25 ms late
    times = t - np.where(late, 0.025, 0.0)
    times[7] = times[6] + 0.0  # two poses at one time: the first kept
    times[6] = times[7]
    out = restamped(track, times)
    assert np.all(np.diff(out.stamps_s) > 0)
    order = np.argsort(times, kind="stable")
    kept = order[np.r_[True, np.diff(times[order]) > 0]]
    assert len(out) == 7 and kept.size == 7
    np.testing.assert_array_equal(out.stamps_s, times[kept])
    np.testing.assert_array_equal(out.xytheta(), track.xytheta()[kept])  # each pose kept its own data
    np.testing.assert_array_equal(out.cov_xytheta(), track.cov_xytheta()[kept])
