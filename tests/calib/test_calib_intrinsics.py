"""Detection and intrinsic calibration on rendered images."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from gtrig.calib import synth
from gtrig.calib.chessboard import Board, detect_corners, detect_folder, parse_board, read_grey
from gtrig.calib.intrinsics import calibrate_intrinsics
from gtrig.errors import InputError

from .conftest import BOARD, DIST, SIZE, K


def test_subpixel_corners_match_the_projection() -> None:
    rng = np.random.default_rng(5)
    T = synth.random_intrinsic_views(rng, K, DIST, SIZE, BOARD, 1, depth_m=(0.5, 0.6))[0]
    img = synth.render_board_view(K, DIST, SIZE, T, BOARD, rng=rng, supersample=2)
    c = detect_corners(img, BOARD)
    truth = synth.project_board(K, DIST, T, BOARD)
    d = min(c - truth, c[::-1] - truth, key=lambda e: np.abs(e).max())  # up to the grid's half turn
    assert np.sqrt(np.mean(np.sum(d**2, axis=1))) < 0.15  # rendering with 2 x 2 supersamples aliases a little


def test_intrinsics_recover_the_camera(sweep_dir) -> None:
    res = calibrate_intrinsics(sweep_dir, BOARD)
    cam = res.camera
    assert cam.rms_px < 0.2
    assert cam.image_size == SIZE
    est = cam.camera_matrix[[0, 1, 0, 1], [0, 1, 2, 2]]
    err = est - K[[0, 1, 0, 1], [0, 1, 2, 2]]
    std = np.array([cam.extra["std"][k] for k in ("fx", "fy", "cx", "cy")])
    assert np.all(np.abs(err) < np.maximum(4 * std, 0.5)) and np.all(np.abs(err) < 2.5), (err, std)
    assert abs(cam.dist_coeffs[0] - DIST[0]) < 0.03
    assert res.rejected == {"blank.jpg": "no board found"}
    assert set(cam.extra["std"]) >= {"fx", "fy", "cx", "cy", "k1"}
    assert len(res.per_image_rms_px) == 12


def test_jpeg_set_gives_the_png_solution(sweep_dir, tmp_path) -> None:
    """Ordinary camera output: the same views saved as JPEG (quality 90, colour) calibrate alike."""
    for f in sorted(sweep_dir.glob("*.png")):
        grey = cv2.imread(str(f), cv2.IMREAD_GRAYSCALE)
        cv2.imwrite(str(tmp_path / (f.stem + ".jpg")), cv2.cvtColor(grey, cv2.COLOR_GRAY2BGR),
                    [cv2.IMWRITE_JPEG_QUALITY, 90])
    png = calibrate_intrinsics(sweep_dir, BOARD).camera
    jpg = calibrate_intrinsics(tmp_path, BOARD).camera
    assert jpg.rms_px < 0.3
    assert np.abs(jpg.camera_matrix - png.camera_matrix).max() < 1.0


def test_outlier_image_is_rejected_and_named(sweep_dir, tmp_path) -> None:
    det = detect_folder(sweep_dir, BOARD)
    views = list(det.found)
    bad = views[2]
    # a bad detection: corners off by 1 px at random
    bent = bad.corners_px + np.random.default_rng(0).normal(0, 1.0, bad.corners_px.shape)
    from dataclasses import replace

    from gtrig.calib.intrinsics import calibrate_views

    views[2] = replace(bad, corners_px=bent)
    res = calibrate_views(views, BOARD, det.image_size)
    assert bad.file in res.rejected and bad.file not in res.per_image_rms_px
    assert any(bad.file in w for w in res.warnings)


def test_one_line_errors(sweep_dir, tmp_path) -> None:
    with pytest.raises(InputError, match="wrong board size") as e:
        calibrate_intrinsics(sweep_dir, Board(10, 6, 0.03))  # squares given instead of inner corners
    assert "\n" not in str(e.value)
    few = tmp_path / "few"
    few.mkdir()
    for n in ("000.png", "001.png"):
        (few / n).write_bytes((sweep_dir / n).read_bytes())
    with pytest.raises(InputError, match="too few views"):
        calibrate_intrinsics(few, BOARD)
    mixed = tmp_path / "mixed"
    mixed.mkdir()
    (mixed / "a.png").write_bytes((sweep_dir / "000.png").read_bytes())
    cv2.imwrite(str(mixed / "b.png"), cv2.resize(read_grey(sweep_dir / "001.png"), (320, 240)))
    with pytest.raises(InputError, match="mixed resolutions"):
        calibrate_intrinsics(mixed, BOARD)
    with pytest.raises(InputError, match="COLSxROWSxSQUARE"):
        parse_board("9x5")
    assert parse_board("9x6x0.025") == Board(9, 6, 0.025)


def test_imprecise_principal_point_is_warned_about(sweep_dir) -> None:
    from gtrig.calib.intrinsics import PP_SIGMA_WARN_PX, calibrate_views

    det = detect_folder(sweep_dir, BOARD)
    for views in (det.found[:4], det.found):
        res = calibrate_views(views, BOARD, det.image_size)
        sd = max(res.std["cx"], res.std["cy"])
        warned = any("imprecise principal point" in w for w in res.warnings)
        assert warned == (sd > PP_SIGMA_WARN_PX), (len(views), sd, res.warnings)
    # four views leave the principal point to within pixels, not tenths
    assert any("imprecise principal point" in w for w in calibrate_views(det.found[:4], BOARD, det.image_size).warnings)


def test_every_warning_names_its_camera(sweep_dir, tmp_path) -> None:
    """A recording's cameras are calibrated one after another: each warning says which one it is about."""
    from gtrig.calib.recording import load_intrinsics

    cam = tmp_path / "intrinsics" / "cam7"
    cam.mkdir(parents=True)
    for n in ("000.png", "001.png", "002.png", "003.png", "blank.jpg"):  # few views, one without a board
        (cam / n).write_bytes((sweep_dir / n).read_bytes())
    res = load_intrinsics(tmp_path / "intrinsics", ["cam7"], BOARD)["cam7"]
    warnings = res.camera.extra["warnings"]
    assert any("imprecise principal point" in w for w in warnings) and any("no board in" in w for w in warnings)
    assert all(w.startswith("camera cam7: ") for w in warnings), warnings


def test_calib_intrinsics_warnings_name_the_images_folder(sweep_dir, tmp_path) -> None:
    from typer.testing import CliRunner

    from gtrig.cli.main import app

    few = tmp_path / "left_camera"
    few.mkdir()
    for n in ("000.png", "001.png", "002.png", "003.png"):
        (few / n).write_bytes((sweep_dir / n).read_bytes())
    r = CliRunner().invoke(app, ["calib", "intrinsics", "--images", str(few), "--board", "9x5x0.03",
                                 "--out", str(tmp_path / "cam.yaml")])
    assert r.exit_code == 0, r.output
    warned = [x for x in r.output.splitlines() if x.startswith("warning:")]
    assert warned and all(x.startswith(f"warning: {few}: ") for x in warned), r.output
