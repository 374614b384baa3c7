"""The ``gtrig calib`` commands (CliRunner) and the steadiness check."""

from __future__ import annotations

import numpy as np
import yaml
from typer.testing import CliRunner

from gtrig import geometry as geo
from gtrig.calib import synth
from gtrig.calib.steady import check_steady
from gtrig.cli.main import app
from gtrig.io.camfile import read_cam_yaml
from gtrig.rig import dump_rig
from gtrig.sim.gtroom import make_scene

from .conftest import BOARD, DIST, SIZE, K

runner = CliRunner()


def _one_line_error(result, text: str) -> None:
    assert result.exit_code == 2, result.output
    out = result.output.strip()
    assert out.startswith("error:") and text in out and "\n" not in out, out


def test_intrinsics_command_writes_cam_yaml_and_figure(sweep_dir, tmp_path) -> None:
    out = tmp_path / "cam.yaml"
    r = runner.invoke(
        app, ["calib", "intrinsics", "--images", str(sweep_dir), "--board", "9x5x0.03", "--out", str(out)]
    )
    assert r.exit_code == 0, r.output
    cam = read_cam_yaml(out)
    assert cam.image_size == SIZE and cam.rms_px < 0.2
    assert "blank.jpg" in cam.extra["rejected"]
    assert (tmp_path / "cam_coverage.png").stat().st_size > 1000


def test_intrinsics_command_errors(tmp_path, sweep_dir) -> None:
    empty = tmp_path / "noboard"
    empty.mkdir()
    for i in range(3):
        (empty / f"{i}.jpg").write_bytes((sweep_dir / "blank.jpg").read_bytes())
    r = runner.invoke(
        app,
        [
            "calib",
            "intrinsics",
            "--images",
            str(empty),
            "--board",
            "9x5x0.03",
            "--out",
            str(tmp_path / "c.yaml"),
        ],
    )
    _one_line_error(r, "no 9x5 chessboard found")
    r = runner.invoke(
        app,
        ["calib", "intrinsics", "--images", str(empty), "--board", "9-5", "--out", str(tmp_path / "c.yaml")],
    )
    _one_line_error(r, "COLSxROWSxSQUARE")


def test_network_command_refuses_unmatched_pairs(tmp_path, sweep_dir) -> None:
    sc = make_scene(0)
    dump_rig(sc.rig_nominal, tmp_path / "rig.yaml")
    img = (sweep_dir / "000.png").read_bytes()
    for cam, name in (("cam0", "000000.png"), ("cam1", "000001.png")):
        d = tmp_path / "pairs" / "cam0-cam1" / cam
        d.mkdir(parents=True)
        (d / name).write_bytes(img)
    (tmp_path / "world" / "cam1").mkdir(parents=True)
    (tmp_path / "world" / "cam1" / "0.png").write_bytes(img)
    (tmp_path / "boards.yaml").write_text(
        yaml.safe_dump(
            {
                "inner_corners": [9, 5],
                "square_m": 0.1,
                "T_board1_board2": {"xyz": [1.5, 0, 0], "quat_xyzw": [0, 0, 0, 1]},
                "T_world_board": {"xyz": [0.55, 1.25, 0], "rpy_deg": [180, 0, 0]},
            }
        )
    )
    args = [
        "calib",
        "network",
        "--rig",
        str(tmp_path / "rig.yaml"),
        "--pairs",
        str(tmp_path / "pairs"),
        "--world-board",
        str(tmp_path / "world"),
        "--boards",
        str(tmp_path / "boards.yaml"),
        "--out",
        str(tmp_path / "out.yaml"),
    ]
    _one_line_error(runner.invoke(app, args), "pair names do not match: cam0/000000.png has no partner")
    (tmp_path / "pairs" / "cam0-cam1").rename(tmp_path / "pairs" / "cam0-camX")
    _one_line_error(runner.invoke(app, args), "must be <camA>-<camB>")


def test_steady_catches_a_small_rotation_only(tmp_path) -> None:
    rng = np.random.default_rng(2)
    T_world_cam = geo.look_at([0, 0, 1.2], [0.05, 0.1, 0])
    floor = synth.Plane(
        geo.make_T(np.eye(3), [0, 0, -0.001]), synth.noise_texture(rng, extent_m=3.0, cell_m=0.01)
    )
    board = synth.Plane(
        geo.make_T(np.diag([1.0, -1.0, -1.0]), [-0.12, 0.06, 0.0]), synth.checker_texture(BOARD)
    )
    moves = {"still": np.eye(4), "turned": geo.T_from_xyz_rpy([0, 0, 0], np.radians([0.0, 0.1, 0.0]))}
    for cam, dT in moves.items():
        for when, T in (("before", T_world_cam), ("after", T_world_cam @ dT)):
            img = synth.render(K, DIST, SIZE, T, [floor, board], rng=rng, supersample=2)
            (tmp_path / when / cam).mkdir(parents=True)
            import cv2

            cv2.imwrite(str(tmp_path / when / cam / "0.png"), img)
    res = {
        r.camera: r
        for r in check_steady(
            tmp_path / "before", tmp_path / "after", {c: (K, DIST) for c in moves}, BOARD, turn_deg=0.5
        )
    }  # a 75-px board: its tilt is noisy
    assert not res["still"].moved and res["still"].shift_px < 0.1
    assert res["still"].board is not None and res["still"].board.move_mm < 0.8
    assert res["turned"].moved and res["turned"].shift_px > 0.5
