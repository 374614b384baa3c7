"""Trajectory formats: every format written and read back to the precision it keeps, the published
RAWSEEDS files read and written back with the same numbers, and one-line errors."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from gtrig.errors import ConfigError, FormatError, InputError
from gtrig.io.formats import read_trajectory, sniff_format, write_trajectory
from gtrig.io.formats.rawseeds import rawseeds_text, read_rawseeds_rows
from gtrig.trajectory import PoseStatus, PoseTrack

RAWSEEDS = ("Bicocca_2009-02-25a", "Bicocca_2009-02-25b", "Bicocca_2009-02-26a")


def _track_3d(n: int = 40, cov: bool = True) -> PoseTrack:
    rng = np.random.default_rng(3)
    T = np.tile(np.eye(4), (n, 1, 1))
    T[:, :3, :3] = Rotation.random(n, random_state=4).as_matrix()
    T[:, :3, 3] = rng.normal(0, 7, (n, 3))
    A = rng.normal(0, 1e-3, (n, 6, 6))
    status = rng.integers(0, 4, n).astype(np.uint8)
    reasons = tuple("" if s == 0 else f"reason {i}, with a comma" for i, s in enumerate(status))
    return PoseTrack.from_matrices(1.2355e9 + np.cumsum(rng.uniform(0.01, 0.05, n)), T,
                                   cov=A @ np.swapaxes(A, 1, 2) if cov else None, status=status,
                                   reasons=reasons, source="GTvision", frame_id="map", child_frame_id="base_link")


def _track_planar(n: int = 40) -> PoseTrack:
    rng = np.random.default_rng(5)
    xyt = np.column_stack([rng.uniform(-5, 5, (n, 2)), rng.uniform(-np.pi, np.pi, n)])
    A = rng.normal(0, 3e-4, (n, 3, 3))
    return PoseTrack.from_xytheta(100.0 + 0.02 * np.arange(n), xyt, cov=A @ np.swapaxes(A, 1, 2), source="GTlaser")


def _same_poses(a: PoseTrack, b: PoseTrack, t_tol: float, x_tol: float, q_tol: float) -> None:
    assert len(a) == len(b)
    np.testing.assert_allclose(b.stamps_s, a.stamps_s, rtol=0, atol=t_tol)
    np.testing.assert_allclose(b.xyz, a.xyz, rtol=0, atol=x_tol)
    # q and -q are one rotation: compare the rotation angle between them
    dq = (Rotation.from_quat(a.quat_xyzw).inv() * Rotation.from_quat(b.quat_xyzw)).magnitude()
    assert dq.max() <= q_tol


@pytest.mark.parametrize("fmt,name,t_tol,x_tol,q_tol", [
    ("tum", "a.tum", 5e-7, 5e-10, 4e-12),
    ("kitti", "a.kitti", 1e-6, 1e-10, 1e-11),
    ("euroc", "state_groundtruth_estimate0/data.csv", 5e-7, 5e-10, 4e-12),
])
def test_pose_only_formats_round_trip(tmp_path: Path, fmt: str, name: str, t_tol: float, x_tol: float,
                                      q_tol: float) -> None:
    track = _track_3d(cov=False)
    written = write_trajectory(track, tmp_path / name, fmt)
    assert all(p.is_file() for p in written)
    back = read_trajectory(tmp_path / name)  # the format from the name
    _same_poses(track, back, t_tol, x_tol, q_tol)
    assert back.cov is None


def test_gtrig_pair_and_csv_keep_covariance_status_and_frames(tmp_path: Path) -> None:
    track = _track_3d()
    write_trajectory(track, tmp_path / "gt.tum", "gtrig")
    assert (tmp_path / "gt_cov.csv").is_file()
    for back in (read_trajectory(tmp_path / "gt.tum"), read_trajectory(tmp_path / "gt.tum", "gtrig")):
        _same_poses(track, back, 5e-7, 5e-10, 4e-12)
        np.testing.assert_array_equal(back.cov, track.cov)
        np.testing.assert_array_equal(back.status, track.status)
        assert back.reasons == track.reasons and back.frame_id == "map" and back.child_frame_id == "base_link"
    write_trajectory(track, tmp_path / "gt.csv", "csv")
    back = read_trajectory(tmp_path / "gt.csv")  # sniffed
    # the stamps every format writes (gtrig.stamps: a Unix-time float to the microsecond), read back exactly
    np.testing.assert_array_equal(back.integer_stamps_ns(), track.integer_stamps_ns())
    np.testing.assert_allclose(back.stamps_s, track.stamps_s, rtol=0, atol=5e-7)
    np.testing.assert_array_equal(back.xyz, track.xyz)
    np.testing.assert_array_equal(back.quat_xyzw, track.quat_xyzw)
    np.testing.assert_array_equal(back.cov, track.cov)
    assert back.cov_kind == "se3" and back.reasons == track.reasons
    assert [PoseStatus(s) for s in back.status] == [PoseStatus(s) for s in track.status]


def test_rawseeds_round_trip_planar_and_from_se3(tmp_path: Path) -> None:
    track = _track_planar()
    write_trajectory(track, tmp_path / "a-GROUNDTRUTH.csv")
    back = read_trajectory(tmp_path / "a-GROUNDTRUTH.csv")
    _same_poses(track, back, 5e-7, 5e-7, 1e-6)
    assert back.cov_kind == "xyyaw"
    np.testing.assert_array_equal(back.cov, track.cov)  # covariance written exactly
    # a 6-DoF track writes its planar marginal
    t3 = _track_3d()
    write_trajectory(t3, tmp_path / "b.csv", "rawseeds")
    b = read_trajectory(tmp_path / "b.csv", "rawseeds")
    np.testing.assert_array_equal(b.cov, t3.cov_xytheta())
    np.testing.assert_allclose(b.xytheta()[:, 2], t3.yaw_rad(), atol=5e-7)


@pytest.mark.parametrize("session", RAWSEEDS)
def test_published_rawseeds_ground_truth_written_back_with_the_same_numbers(
        shared_dir: Path, tmp_path: Path, session: str) -> None:
    src = shared_dir / "data/rawseeds" / session / f"{session}-GROUNDTRUTH.csv"
    printed = [line.split(",") for line in src.read_text().split()]
    rows = read_rawseeds_rows(src)
    track = read_trajectory(src)
    assert len(track) == len(printed) > 4000 and track.cov_kind == "xyyaw"
    # on the file's own heading branch: every number the same to its printed digits
    text = rawseeds_text(track, theta=rows[:, 3])
    again = [line.split(",") for line in text.split()]
    for a, b in zip(printed, again, strict=True):
        assert a[:4] == b[:4]  # t, x, y, theta: the same text
        assert [float(v) for v in a[4:]] == [float(v) for v in b[4:]]  # covariance: the same values
    # through the front door the heading comes back in (-pi, pi]: the same angle, same digits
    write_trajectory(track, tmp_path / "back.csv", "rawseeds")
    back = read_rawseeds_rows(tmp_path / "back.csv")
    np.testing.assert_array_equal(back[:, [0, 1, 2]], rows[:, [0, 1, 2]])
    np.testing.assert_array_equal(back[:, 4:], rows[:, 4:])
    wrapped = np.array([float(f"{v:.6f}") for v in np.angle(np.exp(1j * rows[:, 3]))])
    np.testing.assert_array_equal(back[:, 3], wrapped)


def test_published_solutions_read(shared_dir: Path) -> None:
    d = shared_dir / "data/rawseeds/Bicocca_2009-02-25b"
    for f in sorted(d.glob("SOLUTION_*.csv")):
        t = read_trajectory(f)
        assert len(t) > 1000 and t.cov is None and np.all(np.diff(t.stamps_s) > 0)


def test_sniffing_real_files(shared_dir: Path) -> None:
    assert sniff_format(shared_dir / "data/trajectories/freiburg1_xyz-groundtruth.txt") == "tum"
    assert sniff_format(shared_dir / "data/rawseeds/Bicocca_2009-02-25a/Bicocca_2009-02-25a-GT-extended.csv") \
        == "rawseeds"


def test_kitti_times_file_and_missing_times(tmp_path: Path, caplog: pytest.LogCaptureFixture) -> None:
    track = _track_3d(cov=False)
    write_trajectory(track, tmp_path / "00.txt", "kitti")
    assert (tmp_path / "00_times.txt").is_file()
    back = read_trajectory(tmp_path / "00.txt")  # sniffed: 12 numbers per line
    np.testing.assert_allclose(back.stamps_s, track.stamps_s, atol=1e-6)
    (tmp_path / "00_times.txt").unlink()
    bare = read_trajectory(tmp_path / "00.txt", "kitti")
    np.testing.assert_array_equal(bare.stamps_s, np.arange(len(track)))
    assert "no times file" in caplog.text


def test_refuses_to_overwrite_unless_forced(tmp_path: Path) -> None:
    track = _track_3d(cov=False)
    write_trajectory(track, tmp_path / "a.kitti")
    (tmp_path / "a.kitti").unlink()  # the times file alone is enough to refuse
    with pytest.raises(InputError, match="a_times.txt: exists"):
        write_trajectory(track, tmp_path / "a.kitti")
    assert not (tmp_path / "a.kitti").exists()
    write_trajectory(track, tmp_path / "a.kitti", force=True)
    assert (tmp_path / "a.kitti").is_file()


@pytest.mark.parametrize("name,text,fmt,exc,fragment", [
    ("a.tum", "1 0 0 0 0 0 0 1\n", "kitti", FormatError, "the name says tum, but kitti"),
    ("a.txt", "1 0 0 0 0 0 0 1\n", "kitti", FormatError, "the content is tum, but kitti"),
    ("a.txt", "1,0,0,0\n", "tum", FormatError, "the content is rawseeds, but tum"),
    ("a.txt", "hello world\n", None, FormatError, "not a trajectory in any known format"),
    ("a.txt", "1 0 0 0 0 0 0 1\n", "yaml", ConfigError, "is none of"),
    ("a.csv", "1,0,0,0\n0.5,0,0,0\n", "rawseeds", FormatError, ":2: the time stamp steps back 0.5 s"),
    ("a.csv", "1,0,0,0\n2,0,x,0\n", "rawseeds", FormatError, ":2: not a number"),
    ("a.csv", "1,0,0,0\n2,0,0\n", "rawseeds", FormatError, ":2: expected 4"),
    ("a.kitti", "1 0 0 0 0 1 0 0 0 0 2 0\n", None, FormatError, ":1: the 3x3 block is not a rotation"),
    ("a.csv", "#timestamp,x\n1,0,0,0,0.5,0,0,0\n", "euroc", FormatError, "quaternion is not unit"),
    ("a.tum", "", None, FormatError, "no poses"),
])
def test_bad_files_one_line(tmp_path: Path, name: str, text: str, fmt: str | None, exc: type,
                            fragment: str) -> None:
    p = tmp_path / name
    p.write_text(text)
    with pytest.raises(exc, match=fragment) as e:
        read_trajectory(p, fmt)
    assert "\n" not in str(e.value)


def test_writing_an_ambiguous_name_needs_a_format(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match="does not say which format"):
        write_trajectory(_track_3d(), tmp_path / "a.txt")
    assert not (tmp_path / "a.txt").exists()


def test_files_gtrig_writes_read_by_evo(tmp_path: Path, shared_dir: Path) -> None:
    fi = pytest.importorskip("evo.tools.file_interface")
    track = _track_3d(cov=False)
    write_trajectory(track, tmp_path / "a.tum")
    t = fi.read_tum_trajectory_file(str(tmp_path / "a.tum"))
    np.testing.assert_allclose(t.timestamps, track.stamps_s, atol=5e-7)
    np.testing.assert_allclose(t.positions_xyz, track.xyz, atol=5e-10)
    write_trajectory(track, tmp_path / "a.kitti")
    k = fi.read_kitti_poses_file(str(tmp_path / "a.kitti"))
    np.testing.assert_allclose(np.array(k.poses_se3), track.matrices(), atol=1e-11)
    write_trajectory(track, tmp_path / "state_groundtruth_estimate0/data.csv")
    e = fi.read_euroc_csv_trajectory(str(tmp_path / "state_groundtruth_estimate0/data.csv"))
    np.testing.assert_allclose(e.timestamps, track.stamps_s, atol=3e-7)
    np.testing.assert_allclose(e.positions_xyz, track.xyz, atol=5e-10)
    q = e.orientations_quat_wxyz[:, [1, 2, 3, 0]]
    np.testing.assert_allclose(q * np.sign(q[:, 3:]), track.quat_xyzw, atol=1e-12)
    # and the real TUM file reads as evo reads it
    real = shared_dir / "data/trajectories/freiburg1_xyz-groundtruth.txt"
    a, b = read_trajectory(real), fi.read_tum_trajectory_file(str(real))
    np.testing.assert_array_equal(a.stamps_s, b.timestamps)
    np.testing.assert_array_equal(a.xyz, b.positions_xyz)
