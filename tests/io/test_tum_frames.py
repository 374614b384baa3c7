"""Write-read round trips and one-line errors for TUM and frame-index files."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from gtrig.errors import FormatError
from gtrig.io.frames import read_frame_index, write_frame_index
from gtrig.io.tum import Trajectory, read_tum, write_tum


def test_tum_round_trip(tmp_path: Path) -> None:
    rng = np.random.default_rng(0)
    n = 50
    T = np.tile(np.eye(4), (n, 1, 1))
    T[:, :3, :3] = Rotation.random(n, random_state=1).as_matrix()
    T[:, :3, 3] = rng.normal(0, 5, (n, 3))
    traj = Trajectory.from_matrices(np.arange(n) * 0.1 + 1e9, T)
    write_tum(tmp_path / "a.tum", traj)
    back = read_tum(tmp_path / "a.tum")
    np.testing.assert_allclose(back.stamps_s, traj.stamps_s, atol=1e-6)
    np.testing.assert_allclose(back.matrices(), T, atol=1e-9)
    with pytest.raises(ValueError):
        back.xyz[0, 0] = 1.0  # trajectories are never changed in place


def test_tum_reads_the_real_file(shared_dir: Path) -> None:
    traj = read_tum(shared_dir / "data/trajectories/freiburg1_xyz-groundtruth.txt")
    assert len(traj) > 2000
    assert np.all(np.diff(traj.stamps_s) > 0)


@pytest.mark.parametrize(
    "text,fragment",
    [
        ("1 2 3 4 0 0 0 1\n2 2 3 4 0 0 0\n", ":2: expected 8 values"),
        ("1 2 3 4 0 0 0 1\n2 2 3 4 0 0 0 1\n3 2 3 4 0 0 0 1\n-500 2 3 4 0 0 0 1\n", "steps back 503 s"),
        ("1 2 x 4 0 0 0 1\n", ":1: not a number"),
        ("1 2 3 4 0 0 0 2\n", "not unit"),
        ("# only a comment\n", "no poses"),
    ],
)
def test_tum_errors(tmp_path: Path, text: str, fragment: str) -> None:
    p = tmp_path / "bad.tum"
    p.write_text(text)
    with pytest.raises(FormatError, match=fragment) as e:
        read_tum(p)
    assert "\n" not in str(e.value)


def test_frame_index_round_trip(tmp_path: Path) -> None:
    stamps = 100.0 + np.arange(5) * 0.1
    write_frame_index(tmp_path, stamps, [f"{i:06d}.png" for i in range(5)])
    idx = read_frame_index(tmp_path)
    np.testing.assert_allclose(idx.stamps_s, stamps, atol=1e-6)
    assert idx.files[3] == "000003.png"
    (tmp_path / "timestamps.csv").write_text("frame,stamp_s,file\n0,1.0,a.png\n1,0.5,b.png\n")
    with pytest.raises(FormatError, match="do not increase"):
        read_frame_index(tmp_path)


def test_video_with_timestamps(tmp_path: Path) -> None:
    import cv2

    w = cv2.VideoWriter(str(tmp_path / "video.avi"), cv2.VideoWriter_fourcc(*"MJPG"), 10, (64, 48), isColor=False)
    for i in range(6):
        w.write(np.full((48, 64), 40 * i, np.uint8))
    w.release()
    rows = "".join(f"{i},{10 + i * 0.1:.1f},\n" for i in range(6))
    (tmp_path / "timestamps.csv").write_text("frame,stamp_s,file\n" + rows)
    idx = read_frame_index(tmp_path)
    assert idx.video is not None and len(idx) == 6
    frames = list(idx.iter_images())
    assert [round(t, 1) for t, _ in frames] == [10.0, 10.1, 10.2, 10.3, 10.4, 10.5]
    assert abs(float(frames[3][1].mean()) - 120) < 3  # MJPG is lossy
    assert abs(float(idx.read(5).mean()) - 200) < 3
    (tmp_path / "video.avi").unlink()
    with pytest.raises(FormatError, match="no video"):
        read_frame_index(tmp_path)
