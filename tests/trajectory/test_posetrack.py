"""The pose-track contract: construction, views, and the TUM + covariance CSV round trip."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from gtrig.errors import FormatError
from gtrig.io.posetrack import read_pose_track, write_pose_track
from gtrig.trajectory import PoseStatus, PoseTrack


def _random_spd(rng: np.random.Generator, n: int, k: int) -> np.ndarray:
    A = rng.normal(size=(n, k, k)) * 1e-3
    return A @ np.swapaxes(A, 1, 2) + 1e-9 * np.eye(k)


@pytest.mark.parametrize("seed", range(5))
def test_round_trip_se3_and_planar(tmp_path, seed):
    rng = np.random.default_rng(seed)
    n = 50
    stamps = np.cumsum(rng.uniform(0.01, 0.1, n)) + 1e3
    T = np.tile(np.eye(4), (n, 1, 1))
    T[:, :3, :3] = Rotation.random(n, random_state=seed).as_matrix()
    T[:, :3, 3] = rng.normal(size=(n, 3))
    status = rng.integers(0, 4, n).astype(np.uint8)
    reasons = tuple("" if s == 0 else f"reason, {i}" for i, s in enumerate(status))
    tr = PoseTrack.from_matrices(stamps, T, cov=_random_spd(rng, n, 6), status=status, reasons=reasons,
                                 source="GTvision")
    write_pose_track(tr, tmp_path / "a.tum", tmp_path / "a_cov.csv")
    back = read_pose_track(tmp_path / "a.tum", tmp_path / "a_cov.csv")
    assert back.source == "GTvision" and back.cov_kind == "se3"
    np.testing.assert_allclose(back.stamps_s, stamps, atol=5e-7)
    np.testing.assert_allclose(back.matrices(), T, atol=1e-8)
    np.testing.assert_array_equal(back.cov, tr.cov)
    np.testing.assert_array_equal(back.status, status)
    assert back.reasons == reasons

    xyt = np.column_stack([rng.normal(size=(n, 2)), rng.uniform(-np.pi, np.pi, n)])
    pl = PoseTrack.from_xytheta(stamps, xyt, cov=_random_spd(rng, n, 3), source="GTlaser")
    write_pose_track(pl, tmp_path / "b.tum", tmp_path / "b_cov.csv")
    back = read_pose_track(tmp_path / "b.tum", tmp_path / "b_cov.csv")
    assert back.planar
    d = back.xytheta() - xyt
    d[:, 2] = np.angle(np.exp(1j * d[:, 2]))
    assert np.abs(d).max() < 1e-8
    np.testing.assert_array_equal(back.cov_xytheta(), pl.cov)


def test_planar_marginal_of_se3():
    cov = np.arange(36.0).reshape(1, 6, 6)
    cov = cov + cov.transpose(0, 2, 1)
    tr = PoseTrack.from_matrices([0.0], np.eye(4)[None], cov=cov)
    np.testing.assert_array_equal(tr.cov_xytheta()[0], cov[0][np.ix_([0, 1, 5], [0, 1, 5])])


def test_frozen_and_selection():
    tr = PoseTrack.from_xytheta(np.arange(4.0), np.zeros((4, 3)),
                                status=np.array([0, 1, 2, 3]), reasons=("", "f", "b", "r"))
    with pytest.raises(ValueError):
        tr.xyz[0, 0] = 1.0
    assert len(tr.usable()) == 2 and tr.counts() == {"ok": 1, "flagged": 1, "bridged": 1, "rejected": 1}
    assert tr.select(tr.status == PoseStatus.REJECTED).reasons == ("r",)
    with pytest.raises(ValueError):
        PoseTrack.from_xytheta(np.array([1.0, 1.0]), np.zeros((2, 3)))


def test_mismatched_rows_refused(tmp_path):
    tr = PoseTrack.from_xytheta(np.arange(3.0), np.zeros((3, 3)), cov=np.tile(np.eye(3), (3, 1, 1)))
    write_pose_track(tr, tmp_path / "a.tum", tmp_path / "a_cov.csv")
    write_pose_track(tr.select([0, 1]), tmp_path / "b.tum")
    with pytest.raises(FormatError, match="rows"):
        read_pose_track(tmp_path / "b.tum", tmp_path / "a_cov.csv")


def test_old_layouts_still_read(tmp_path):
    (tmp_path / "v.csv").write_text("stamp_s," + ",".join(f"c_{a}_{b}" for a in "x y yaw".split()
                                                           for b in "x y yaw".split()) + "\n"
                                    "1.000000," + ",".join(str(v) for v in np.eye(3).ravel()) + "\n")
    (tmp_path / "l.csv").write_text("timestamp,x,y,theta,cov_xx,cov_xy,cov_xtheta,cov_yy,cov_ytheta,"
                                    "cov_thetatheta,status,n_points,n_sides,rms_m\n"
                                    "1.000000,0,0,0,1,0.1,0.2,2,0.3,3,OK,10,2,0.001\n")
    write_pose_track(PoseTrack.from_xytheta([1.0], np.zeros((1, 3))), tmp_path / "a.tum")
    v = read_pose_track(tmp_path / "a.tum", tmp_path / "v.csv")
    np.testing.assert_array_equal(v.cov[0], np.eye(3))
    la = read_pose_track(tmp_path / "a.tum", tmp_path / "l.csv")
    np.testing.assert_array_equal(la.cov[0], [[1, 0.1, 0.2], [0.1, 2, 0.3], [0.2, 0.3, 3]])


@pytest.mark.parametrize("n", [0, 1, 2, 3, 7, 9])
def test_written_piece_by_piece_is_the_whole_text(tmp_path, n):
    """The files are written a few thousand rows at a time (an hour's track as one string took ~130 MB of
    the client's peak); whatever the cut, the bytes are those of the whole text, comments and reasons
    with commas and quotes included."""
    from gtrig.io.posetrack import covariance_pieces, covariance_text
    from gtrig.io.tum import tum_pieces, tum_text

    rng = np.random.default_rng(n)
    q = Rotation.random(n, random_state=n).as_quat() if n else np.zeros((0, 4))
    q[q[:, 3] < 0] *= -1
    status = np.where(np.arange(n) % 3 == 0, PoseStatus.REJECTED, PoseStatus.OK).astype(np.uint8)
    reasons = tuple('jump of 51 mm, "far"' if s == PoseStatus.REJECTED else "" for s in status)
    a = rng.normal(size=(n, 3, 3)) * 1e-3
    for cov, kind in ((None, "se3"), (a @ a.transpose(0, 2, 1), "xyyaw")):
        track = PoseTrack(np.arange(n) * 0.1 + 1e9, rng.normal(size=(n, 3)), q, cov, cov_kind=kind,  # type: ignore[arg-type]
                          status=status, reasons=reasons, source="GTlaser")
        tum, csv_text = tum_text(track), covariance_text(track)
        for rows in (1, 2, 4):
            assert "".join(tum_pieces(track, rows)) == tum
            assert "".join(covariance_pieces(track, rows)) == csv_text
        assert csv_text.count("\n") == n + 2 and tum.count("\n") == max(n, 1) + 1
        write_pose_track(track, tmp_path / "t.tum", tmp_path / "t_cov.csv")
        assert (tmp_path / "t.tum").read_bytes() == tum.encode()
        assert (tmp_path / "t_cov.csv").read_bytes() == csv_text.encode()
        if n:
            back = read_pose_track(tmp_path / "t.tum", tmp_path / "t_cov.csv")
            assert back.reasons == reasons and np.array_equal(back.stamps_s, track.stamps_s)


def test_extra_files_written_with_the_track_or_not_at_all(tmp_path, monkeypatch):
    """A report written with a track (``extra``) lands with it, and a failure part-way leaves no file."""
    track = PoseTrack.from_xytheta(np.arange(5.0), np.zeros((5, 3)))
    paths = tmp_path / "t.tum", tmp_path / "t_cov.csv", tmp_path / "report.json"
    write_pose_track(track, paths[0], paths[1], extra={paths[2]: '{"a": 1}\n'})
    assert paths[2].read_text(encoding="utf-8") == '{"a": 1}\n'
    assert len(read_pose_track(paths[0], paths[1])) == 5
    for p in paths:
        p.unlink()

    import gtrig.io.posetrack as pt

    real = pt.write_pieces

    def broken(path, pieces):
        # the report's temporary (named after it) is written last: the track's two are on disk by then
        if ".json" in str(path):
            raise OSError("disk full")
        real(path, pieces)

    monkeypatch.setattr(pt, "write_pieces", broken)
    with pytest.raises(OSError, match="disk full"):
        write_pose_track(track, paths[0], paths[1], extra={paths[2]: "{}\n"})
    assert not any(p.exists() for p in paths)
    assert not list(tmp_path.iterdir())
