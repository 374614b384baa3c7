"""``gtrig calib video`` with an AprilGrid: rendered videos of three fixed cameras, lenses and poses checked."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest
import yaml
from scipy.spatial.transform import Rotation
from typer.testing import CliRunner

from gtrig import geometry as geo
from gtrig.calib import synth
from gtrig.calib.aprilgrid import AprilGrid
from gtrig.cli.main import app
from gtrig.io.camfile import read_cam_yaml

from .conftest import DIST, SIZE, K, aprilgrid_texture

GRID = AprilGrid(5, 4, 0.04, 0.3)
KALIBR_TARGET = "target_type: 'aprilgrid'\ntagCols: 5\ntagRows: 4\ntagSize: 0.04\ntagSpacing: 0.3\n"
FRAMES_PER_S = 6.0
N_FRAMES = 16

#: the cameras' poses in the world (cam0's frame): a 0.25 m wide row converging on a point 0.45 m ahead
T_WORLD_CAM = {
    "cam0": np.eye(4),
    "cam1": geo.T_from_xyz_rpy([0.13, 0.01, 0.01], np.radians([1.0, -15.0, 2.0])),
    "cam2": geo.T_from_xyz_rpy([-0.12, -0.02, 0.03], np.radians([-2.0, 13.0, -1.5])),
}


def _board_poses(rng: np.random.Generator, n: int) -> list[np.ndarray]:
    """``T_world_board`` held by hand 0.45 to 0.55 m ahead, tilted up to 35 deg, turned any way, whole in every
    camera's image."""
    P = GRID.object_points()
    out: list[np.ndarray] = []
    while len(out) < n:
        R = geo.T_from_xyz_rpy([0, 0, 0], np.radians([*rng.uniform(-35, 35, 2), rng.uniform(-180, 180)]))[:3, :3]
        centre = np.array([rng.uniform(-0.06, 0.06), rng.uniform(-0.04, 0.04), rng.uniform(0.45, 0.55)])
        T = geo.make_T(R, centre - R @ P.mean(axis=0))
        if all(synth.in_image(geo.project_points(geo.transform_points(geo.inv_T(Tc) @ T, P), K, DIST), SIZE, 12)
               for Tc in T_WORLD_CAM.values()):
            out.append(T)
    return out


@pytest.fixture(scope="module")
def aprilgrid_videos(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Per camera a lossless ``<cam>.avi`` of the grid moved through 16 poses, with ``<cam>.timestamps.csv``."""
    d = tmp_path_factory.mktemp("aprilgrid_videos")
    rng = np.random.default_rng(5)
    poses = _board_poses(rng, N_FRAMES)
    stamps = "frame,stamp_s\n" + "".join(f"{i},{i / FRAMES_PER_S:.6f}\n" for i in range(N_FRAMES))
    for cam, T_world_cam in T_WORLD_CAM.items():
        writer = cv2.VideoWriter(str(d / f"{cam}.avi"), cv2.VideoWriter_fourcc(*"FFV1"), FRAMES_PER_S, SIZE, True)
        assert writer.isOpened()
        for T in poses:
            grey = synth.render(K, DIST, SIZE, T_world_cam, [synth.Plane(T, aprilgrid_texture(GRID))],
                                supersample=2, rng=rng)
            writer.write(cv2.cvtColor(grey, cv2.COLOR_GRAY2BGR))
        writer.release()
        (d / f"{cam}.timestamps.csv").write_text(stamps)
    return d


def _angle_deg(R: np.ndarray) -> float:
    return float(np.degrees(np.arccos(np.clip((np.trace(R) - 1) / 2, -1, 1))))


def test_calib_video_with_a_kalibr_aprilgrid_recovers_lenses_and_poses(aprilgrid_videos: Path,
                                                                      tmp_path: Path) -> None:
    board = tmp_path / "aprilgrid.yaml"
    board.write_text(KALIBR_TARGET)
    out = tmp_path / "cal"
    res = CliRunner().invoke(app, ["calib", "video", "--board", str(board), "--videos", str(aprilgrid_videos),
                                   "--out", str(out)])
    assert res.exit_code == 0, res.output
    assert f"board in {N_FRAMES} of {N_FRAMES} frames" in res.output
    for cam in T_WORLD_CAM:
        lens = read_cam_yaml(out / f"{cam}.yaml")
        Kc = lens.camera_matrix
        got = np.array([Kc[0, 0], Kc[1, 1], Kc[0, 2], Kc[1, 2]])
        true = np.array([K[0, 0], K[1, 1], K[0, 2], K[1, 2]])
        sigma = np.array([lens.extra["std_honest"][k] for k in ("fx", "fy", "cx", "cy")])
        assert np.all(np.abs(got - true) < 3 * sigma) and np.all(np.abs(got - true) < 1.0), (cam, got - true, sigma)
        assert lens.rms_px < 0.15, (cam, lens.rms_px)
    net = yaml.safe_load((out / "network.yaml").read_text())
    assert net["reference"] == "cam0"
    for cam in ("cam1", "cam2"):
        T_true = geo.inv_T(T_WORLD_CAM["cam0"]) @ T_WORLD_CAM[cam]
        T_got = np.array(net["cameras"][cam]["T_ref_cam"])
        d_mm = 1000 * np.abs(T_got[:3, 3] - T_true[:3, 3])
        d_deg = _angle_deg(T_got[:3, :3].T @ T_true[:3, :3])
        assert np.all(d_mm < 1.0), (cam, d_mm)
        assert d_deg < 0.2, (cam, d_deg)
        # the stated sigmas (lenses' uncertainty included) are about T_cam_ref = [Exp(r) R0, t0 + t]
        T_cam_ref_got, T_cam_ref_true = geo.inv_T(T_got), geo.inv_T(T_true)
        err_rot_deg = np.degrees(Rotation.from_matrix(T_cam_ref_got[:3, :3] @ T_cam_ref_true[:3, :3].T).as_rotvec())
        err_pos_mm = 1000 * (T_cam_ref_got[:3, 3] - T_cam_ref_true[:3, 3])
        z = np.abs(np.concatenate([err_rot_deg / net["cameras"][cam]["sigma_rot_deg"],
                                   err_pos_mm / net["cameras"][cam]["sigma_pos_mm"]]))
        assert np.all(z < 3.0), (cam, z)


def test_calib_video_refuses_a_chessboard_in_one_line(aprilgrid_videos: Path, tmp_path: Path) -> None:
    board = tmp_path / "checker.yaml"
    board.write_text("target_type: 'checkerboard'\ntargetCols: 6\ntargetRows: 7\n"
                     "rowSpacingMeters: 0.06\ncolSpacingMeters: 0.06\n")
    res = CliRunner().invoke(app, ["calib", "video", "--board", str(board), "--videos", str(aprilgrid_videos),
                                   "--out", str(tmp_path / "cal")])
    assert res.exit_code != 0 and "Traceback" not in res.output, res.output
    (error,) = [line for line in res.output.splitlines() if line.startswith("error:")]
    assert "chessboard" in error and "ChArUco board or an AprilGrid" in error, res.output
    assert not (tmp_path / "cal").exists()
