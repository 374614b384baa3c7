"""Board files (Kalibr's targets, gtrig's AprilGrid) and AprilGrid detection on rendered images."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest

from gtrig import geometry as geo
from gtrig.calib import synth
from gtrig.calib.aprilgrid import AprilGrid, AprilGridDetector
from gtrig.calib.charuco import CharucoBoard, charuco_board_document
from gtrig.calib.chessboard import Board, boards_spec_from_dict
from gtrig.calib.id_sweep import calibrate_id_folder
from gtrig.calib.idboards import id_board_from_dict
from gtrig.calib.targets import read_id_board_file, read_target_file
from gtrig.errors import FormatError, InputError

from .conftest import DIST, SIZE, K, aprilgrid_texture

KALIBR_APRILGRID = """target_type: 'aprilgrid' #gridtype
tagCols: 5               #number of apriltags
tagRows: 4               #number of apriltags
tagSize: 0.03            #size of apriltag, edge to edge [m]
tagSpacing: 0.3          #ratio of space between tags to tagSize
"""

KALIBR_CHECKERBOARD = """target_type: 'checkerboard' #gridtype
targetCols: 6               #number of internal chessboard corners
targetRows: 7               #number of internal chessboard corners
rowSpacingMeters: 0.06      #size of one chessboard square [m]
colSpacingMeters: 0.06      #size of one chessboard square [m]
"""


def test_kalibr_targets_are_read_as_they_are(tmp_path: Path) -> None:
    (tmp_path / "april.yaml").write_text(KALIBR_APRILGRID)
    (tmp_path / "checker.yaml").write_text(KALIBR_CHECKERBOARD)
    assert read_target_file(tmp_path / "april.yaml") == AprilGrid(5, 4, 0.03, 0.3)
    assert read_target_file(tmp_path / "checker.yaml") == Board(6, 7, 0.06)
    with pytest.raises(InputError, match="chessboard"):
        read_id_board_file(tmp_path / "checker.yaml")
    (tmp_path / "rect.yaml").write_text(KALIBR_CHECKERBOARD.replace("colSpacingMeters: 0.06", "colSpacingMeters: 0.05"))
    with pytest.raises(FormatError, match="differ"):
        read_target_file(tmp_path / "rect.yaml")
    (tmp_path / "bad.yaml").write_text(KALIBR_APRILGRID.replace("tagCols: 5", "tagCols: five"))
    with pytest.raises(FormatError, match="tagCols"):
        read_target_file(tmp_path / "bad.yaml")


def test_aprilgrid_points_are_kalibrs_turned_half_a_turn_about_x() -> None:
    g = AprilGrid(5, 4, 0.03, 0.3)
    P = g.object_points()
    assert P.shape == (80, 3)
    # Kalibr's point k: x from the column, y up from the row, of a 10 x 8 grid of tag corners
    C, R = np.arange(80) % 10, np.arange(80) // 10
    x = (C // 2) * 0.039 + (C % 2) * 0.03
    y = (R // 2) * 0.039 + (R % 2) * 0.03
    np.testing.assert_allclose(P, np.column_stack([x, -y, np.zeros(80)]), atol=1e-12)
    # tag 6 (second row, second column), its code turned half a turn: bottom-right, bottom-left, top-left,
    # top-right as printed (y up in Kalibr's frame, down in gtrig's)
    ids = g.tag_corner_ids(6)
    np.testing.assert_allclose(P[ids, :2], [[0.069, -0.039], [0.039, -0.039], [0.039, -0.069], [0.069, -0.069]],
                               atol=1e-12)
    assert id_board_from_dict({"type": "aprilgrid", "tags": [5, 4], "tag_m": 0.03, "spacing": 0.3}) == g


def test_sweep_board_of_boards_yaml_round_trips() -> None:
    b = CharucoBoard(10, 6, 0.1, 0.075, "DICT_4X4_50")
    doc = {"inner_corners": [9, 5], "square_m": 0.1, "T_board1_board2": np.eye(4).tolist(),
           "sweep_board": charuco_board_document(b)}
    assert boards_spec_from_dict(doc).sweep_board == b
    assert boards_spec_from_dict({**doc, "sweep_board": None}).sweep_board is None


GRID = AprilGrid(5, 4, 0.03, 0.3)


def _views(n: int, rng: np.random.Generator) -> list[np.ndarray]:
    """Poses ``T_cam_board`` with the whole grid in view, tilted up to 40 deg, turned any way."""
    P = GRID.object_points()
    out: list[np.ndarray] = []
    while len(out) < n:
        R = geo.T_from_xyz_rpy([0, 0, 0], np.radians([*rng.uniform(-40, 40, 2), rng.uniform(-180, 180)]))[:3, :3]
        c = np.linalg.inv(K) @ [rng.uniform(0.3, 0.7) * SIZE[0], rng.uniform(0.3, 0.7) * SIZE[1], 1.0]
        T = geo.make_T(R, c * rng.uniform(0.27, 0.36) - R @ P.mean(axis=0))
        if synth.in_image(geo.project_points(geo.transform_points(T, P), K, DIST), SIZE, 12):
            out.append(T)
    return out


@pytest.fixture(scope="module")
def aprilgrid_sweep(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, list[np.ndarray]]:
    """Eight rendered views of a 5 x 4 AprilGrid of 30 mm tags, with their true poses."""
    d = tmp_path_factory.mktemp("aprilgrid")
    rng = np.random.default_rng(3)
    poses = _views(8, rng)
    for i, T in enumerate(poses):
        img = synth.render(K, DIST, SIZE, np.eye(4), [synth.Plane(T, aprilgrid_texture(GRID))], supersample=2, rng=rng)
        cv2.imwrite(str(d / f"{i:03d}.png"), img)
    return d, poses


def test_aprilgrid_corners_are_found_where_the_renderer_put_them(aprilgrid_sweep) -> None:
    d, poses = aprilgrid_sweep
    det = AprilGridDetector(GRID)
    P = GRID.object_points()
    errs = []
    for i, T in enumerate(poses):
        v = det.detect(cv2.imread(str(d / f"{i:03d}.png"), cv2.IMREAD_GRAYSCALE))
        assert v is not None and len(v.ids) >= 0.6 * GRID.n_corners
        errs.append(np.linalg.norm(v.corners_px - geo.project_points(geo.transform_points(T, P[v.ids]), K, DIST),
                                   axis=1))
    e = np.concatenate(errs)
    assert np.mean(e) < 0.15 and np.max(e) < 0.5, (np.mean(e), np.max(e))


def test_aprilgrid_sweep_calibrates_the_lens(aprilgrid_sweep) -> None:
    d, poses = aprilgrid_sweep
    sweep = calibrate_id_folder(d, GRID, camera="cam0")
    Kc = sweep.camera.camera_matrix
    assert abs(Kc[0, 0] - K[0, 0]) < 2.0 and abs(Kc[1, 1] - K[1, 1]) < 2.0
    assert abs(Kc[0, 2] - K[0, 2]) < 2.0 and abs(Kc[1, 2] - K[1, 2]) < 2.0
    assert sweep.camera.rms_px < 0.15
    assert len(sweep.views) == len(poses) and sweep.views[0].object_points is not None
    # the views' poses are the rendered ones
    dt = [np.linalg.norm(sv.T_cam_board[:3, 3] - T[:3, 3]) for sv, T in zip(sweep.views, poses, strict=True)
          if sv.T_cam_board is not None]
    assert max(dt) < 0.003


def test_calib_intrinsics_reads_a_kalibr_aprilgrid_file(aprilgrid_sweep, tmp_path: Path) -> None:
    from typer.testing import CliRunner

    from gtrig.cli.main import app
    from gtrig.io.camfile import read_cam_yaml

    d, _poses = aprilgrid_sweep
    (tmp_path / "april.yaml").write_text(KALIBR_APRILGRID)
    r = CliRunner().invoke(app, ["calib", "intrinsics", "--images", str(d), "--board", str(tmp_path / "april.yaml"),
                                 "--out", str(tmp_path / "cam.yaml")])
    assert r.exit_code == 0, r.output
    cam = read_cam_yaml(tmp_path / "cam.yaml")
    assert abs(cam.camera_matrix[0, 0] - K[0, 0]) < 2.0 and (tmp_path / "cam_coverage.png").is_file()
    (tmp_path / "circles.yaml").write_text("target_type: 'circlegrid'\ntargetCols: 6\n")
    r = CliRunner().invoke(app, ["calib", "intrinsics", "--images", str(d), "--board", str(tmp_path / "circles.yaml"),
                                 "--out", str(tmp_path / "cam2.yaml")])
    assert r.exit_code != 0 and "circlegrid" in r.output and "Traceback" not in r.output
    assert not (tmp_path / "cam2.yaml").exists()


def test_aprilgrid_of_a_real_kalibr_target_is_read_whole_and_in_order() -> None:
    """A TUM VI calibration image (tests/data/aprilgrid/README.md): every tag corner found, and each 2 x 2
    block of tags mapped by one homography to within the fisheye's bending (a corner assigned to the
    wrong point of the grid is tens of pixels off)."""
    img = cv2.imread(str(Path(__file__).parents[1] / "data" / "aprilgrid" / "tum_vi.png"), cv2.IMREAD_GRAYSCALE)
    g = AprilGrid(6, 6, 0.088, 0.3)
    v = AprilGridDetector(g).detect(img)
    assert v is not None and len(v.ids) == g.n_corners
    P = g.object_points()[:, :2]
    rms = []
    for tr in range(5):
        for tc in range(5):
            ids = np.concatenate([g.tag_corner_ids(t) for t in (6 * tr + tc, 6 * tr + tc + 1, 6 * tr + tc + 6,
                                                                 6 * tr + tc + 7)])
            m = np.isin(v.ids, ids)
            H, _ = cv2.findHomography(P[v.ids[m]], v.corners_px[m], 0)
            r = cv2.perspectiveTransform(P[v.ids[m]].reshape(-1, 1, 2), H).reshape(-1, 2) - v.corners_px[m]
            rms.append(np.sqrt(np.mean(np.sum(r**2, axis=1))))
    assert np.max(rms) < 1.0, np.max(rms)


def test_calib_intrinsics_with_a_kalibr_checkerboard_file_matches_the_board_spec(sweep_dir, tmp_path: Path) -> None:
    from typer.testing import CliRunner

    from gtrig.cli.main import app

    (tmp_path / "checker.yaml").write_text(KALIBR_CHECKERBOARD.replace("targetCols: 6", "targetCols: 9")
                                           .replace("targetRows: 7", "targetRows: 5").replace("0.06", "0.03"))
    outs = []
    for k, board in enumerate((str(tmp_path / "checker.yaml"), "9x5x0.03")):
        out = tmp_path / f"cam{k}.yaml"
        r = CliRunner().invoke(app, ["calib", "intrinsics", "--images", str(sweep_dir), "--board", board,
                                     "--out", str(out)])
        assert r.exit_code == 0, r.output
        outs.append(out.read_text())
    assert outs[0] == outs[1]
