"""The time-block jackknife of a lens against views whose errors are shared over a second, and the check
that compares two calibrations of the same cameras."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import cv2
import numpy as np
from typer.testing import CliRunner

from gtrig import geometry as geo
from gtrig.calib import synth
from gtrig.calib.chessboard import Board
from gtrig.calib.intrinsics import calibrate_point_sets
from gtrig.calib.lens_compare import compare_lenses, differing
from gtrig.calib.view_jackknife import block_jackknife_std, time_blocks, view_jackknife_std
from gtrig.cli.main import app
from gtrig.io.camfile import CameraIntrinsics, write_cam_yaml

SIZE = (640, 480)
K = np.array([[500.0, 0, 322.0], [0, 501.0, 238.0], [0, 0, 1]])
DIST = np.array([-0.2, 0.1, 0.0, 0.0, 0.0])
BOARD = Board(4, 3, 0.05)  # 12 corners, as a 4 x 5 ChArUco board


def _sweep(seed: int, focus_wander: float) -> tuple[list, list, np.ndarray]:
    """Eight seconds of a board video at 4 views/s: each second the board sways about one pose and the
    focal length is off by ``focus_wander`` (relative, Gaussian) for the whole second; 0.05 px corner noise."""
    rng = np.random.default_rng(seed)
    obj, img, stamps = [], [], []
    for b, T0 in enumerate(synth.random_intrinsic_views(rng, K, DIST, SIZE, BOARD, 8, depth_m=(0.4, 0.8))):
        K_b = K.copy()
        K_b[:2, :2] *= 1 + focus_wander * rng.standard_normal()
        for j in range(4):
            sway = geo.make_T(cv2.Rodrigues(0.02 * rng.standard_normal(3))[0], 0.005 * rng.standard_normal(3))
            obj.append(BOARD.object_points())
            img.append(synth.project_board(K_b, DIST, T0 @ sway, BOARD) + 0.05 * rng.standard_normal((12, 2)))
            stamps.append(b + j / 4)
    return obj, img, np.array(stamps)


def test_time_blocks() -> None:
    assert time_blocks(np.array([0.0, 0.2, 1.1, 0.9, 3.5]), 1.0) == [[0, 1, 3], [2], [4]]
    assert time_blocks(np.array([]), 1.0) == []


def test_block_jackknife_covers_a_focus_shared_over_a_second() -> None:
    """Errors shared by a second's views: the focal length's error over the block jackknife's sigma has an
    RMS near 1 over 6 sweeps, while the single-view jackknife's sigma is about half as large (each view's
    neighbours carry its error); with independent views both are near 1."""
    for wander, lo_view in ((0.01, 1.8), (0.0, 0.6)):
        z_block, z_view, ratio = [], [], []
        for seed in range(6):
            obj, img, stamps = _sweep(seed, wander)
            fit = calibrate_point_sets(obj, img, [str(i) for i in range(len(obj))], SIZE)
            err = np.array([fit.camera.camera_matrix[0, 0] - K[0, 0], fit.camera.camera_matrix[1, 1] - K[1, 1]])
            jb = block_jackknife_std(obj, img, fit.camera, stamps, 1.0)
            jv = view_jackknife_std(obj, img, fit.camera)
            z_block.append(err / [jb["fx"], jb["fy"]])
            z_view.append(err / [jv["fx"], jv["fy"]])
            ratio.append(jb["fx"] / jv["fx"])
        rms_block, rms_view = (float(np.sqrt(np.mean(np.square(z)))) for z in (z_block, z_view))
        # measured: wander 1 %: 1.25 / 2.87, blocks' sigma 2.1 x the views'; none: 0.85 / 0.82
        assert 0.6 < rms_block < 1.5, (wander, rms_block)
        assert lo_view < rms_view < (4.0 if wander else 1.5), (wander, rms_view)
        if wander:
            assert np.median(ratio) > 1.6, ratio
    obj, img, stamps = _sweep(0, 0.0)
    fit = calibrate_point_sets(obj[:12], img[:12], [str(i) for i in range(12)], SIZE)
    assert np.isnan(block_jackknife_std(obj[:12], img[:12], fit.camera, stamps[:12], 1.0)["fx"])  # 3 blocks


def _lens(fx: float, sigma_fx: float, cx: float = 320.0) -> CameraIntrinsics:
    Km = np.array([[fx, 0, cx], [0, fx, 240.0], [0, 0, 1]])
    std = {"fx": sigma_fx, "fy": sigma_fx, "cx": 2.0, "cy": 2.0}
    return CameraIntrinsics(SIZE, Km, np.zeros(5), 0.1, {"std": std, "std_honest": dict(std, fx=2 * sigma_fx)})


def test_compare_lenses_names_the_camera_and_parameter(tmp_path: Path) -> None:
    a = {"left": _lens(500.0, 1.0), "right": _lens(600.0, 1.0)}
    b = {"left": _lens(503.0, 1.0), "right": _lens(600.5, 1.0, cx=330.0), "extra": _lens(1.0, 1.0)}
    diffs = compare_lenses(a, b)
    assert [(d.camera, d.parameter) for d in diffs][:4] == [("left", "fx"), ("left", "fy"), ("left", "cx"),
                                                           ("left", "cy")] and len(diffs) == 8
    z = {(d.camera, d.parameter): d.z for d in diffs}
    assert z[("left", "fx")] == np.hypot(2, 2) ** -1 * 3  # std_honest preferred over std
    assert z[("left", "fy")] == 3 / np.hypot(1, 1)
    assert [(d.camera, d.parameter) for d in differing(diffs)] == [("right", "cx")]
    assert [(d.camera, d.parameter) for d in differing(diffs, 2.0)] == [("right", "cx"), ("left", "fy")]
    no_sigma = {"left": replace(a["left"], extra={})}
    assert np.isnan(compare_lenses(no_sigma, b)[0].z) and differing(compare_lenses(no_sigma, b)) == []

    for name, lenses in (("a", a), ("b", b)):
        (tmp_path / name).mkdir()
        for cam, lens in lenses.items():
            write_cam_yaml(tmp_path / name / f"{cam}.yaml", lens)
    r = CliRunner().invoke(app, ["calib", "compare-lenses", str(tmp_path / "a"), str(tmp_path / "b")])
    assert r.exit_code == 0, r.output
    assert "right cx differs by 3.5 combined sigma (-10.0 px)" in r.output
    assert "left fy: 500.0 ± 1.0 against 503.0 ± 1.0 px: 2.12 combined sigma" in r.output
    r = CliRunner().invoke(app, ["calib", "compare-lenses", str(tmp_path / "a"), str(tmp_path / "b"),
                                 "--limit", "4"])
    assert r.exit_code == 0 and "every lens parameter within 4 combined sigma (largest right cx, 3.54)" in r.output
    r = CliRunner().invoke(app, ["calib", "compare-lenses", str(tmp_path / "a"), str(tmp_path / "none")])
    assert r.exit_code == 2 and "no such folder or file" in r.output and "Traceback" not in r.output
