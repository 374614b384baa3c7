"""Marker-to-robot calibration: accuracy against simulated truth, outliers, bridges, CLI errors."""

from __future__ import annotations

import math
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from gtrig import geometry as geo
from gtrig.cli.main import app
from gtrig.errors import InputError
from gtrig.io.camfile import read_cam_yaml
from gtrig.markers import robotcal as rc
from gtrig.markers.robotcal.calibrate import calibrate_from_views
from gtrig.markers.robotcal.observe import detect_views, image_files
from gtrig.rig import dump_rig, load_rig
from gtrig.sim.cameras import write_handheld_set
from gtrig.sim.config import SimConfig
from gtrig.sim.gtroom import make_scene

ANCHOR = 14
runner = CliRunner()


@pytest.fixture(scope="module")
def handheld(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A small simulated hand-held set (8 images, the quick default) with the nominal and true rigs."""
    out = tmp_path_factory.mktemp("handheld")
    scene = make_scene(3)
    dump_rig(scene.rig_nominal, out / "rig.yaml")
    (out / "truth").mkdir()
    dump_rig(scene.rig_true, out / "truth" / "rig.yaml")
    write_handheld_set(scene, out, SimConfig.quick_defaults(seed=3).model_copy(update={"workers": 2}))
    return out


@pytest.fixture(scope="module")
def views(handheld: Path) -> tuple[list, list, object]:
    cam = read_cam_yaml(handheld / "handheld" / "camera.yaml")
    specs = rc.specs_from_rig(load_rig(handheld / "rig.yaml"))
    v, _ = detect_views(image_files(handheld / "handheld" / "images"), cam, specs)
    return v, specs, cam


def _true(handheld: Path) -> tuple[object, np.ndarray]:
    truth = load_rig(handheld / "truth" / "rig.yaml")
    return truth, truth.marker(ANCHOR).T_robot_marker.matrix()


def _assert_accurate(cal: rc.RobotCalibration, truth: object, mm: float = 1.0, deg: float = 0.1) -> None:
    err = rc.marker_errors(cal, truth)
    assert set(err) == {3, 6, 14, 30, 89, 200}
    for m, (dt, dr) in err.items():
        assert dt < mm / 1000 and math.degrees(dr) < deg, (m, dt * 1000, math.degrees(dr))


def test_cli_accuracy_and_files(handheld: Path, tmp_path: Path) -> None:
    """The whole command on the simulated set: markers.yaml and the updated rig against the truth."""
    truth, T_a = _true(handheld)
    pose = ",".join(f"{x:.10f}" for x in [*T_a[:3, 3], *np.degrees(geo.rpy_from_T(T_a))])
    r = runner.invoke(app, ["markers", "calibrate-robot", "--images", str(handheld / "handheld" / "images"),
                            "--camera", str(handheld / "handheld" / "camera.yaml"), "--anchor", "14",
                            "--anchor-pose", pose, "--rig", str(handheld / "rig.yaml"),
                            "--out", str(tmp_path / "markers.yaml"), "--rig-out", str(tmp_path / "rig.yaml")])
    assert r.exit_code == 0, r.output
    assert "anchor 14" in r.output
    markers, cov = rc.read_markers_yaml(tmp_path / "markers.yaml")
    assert {m.id for m in markers} == {3, 6, 14, 30, 89, 200}
    true = {m.id: m.T_robot_marker.matrix() for m in truth.robot.markers}
    for m in markers:
        dt, dr = geo.pose_error(m.T_robot_marker.matrix(), true[m.id])
        # the acceptance is 1 mm / 0.1 deg; the simulated room gives a few hundredths of a millimetre
        assert dt < 0.2e-3 and math.degrees(dr) < 0.02, (m.id, dt * 1000, math.degrees(dr))
        if m.id != ANCHOR:
            s_m, s_r = math.sqrt(np.trace(cov[m.id][:3, :3])), math.sqrt(np.trace(cov[m.id][3:, 3:]))
            assert 0 < s_m < 0.5e-3 and 0 < s_r < math.radians(0.05)
    rig = load_rig(tmp_path / "rig.yaml")
    for m in rig.robot.markers:
        assert np.allclose(m.T_robot_marker.matrix(), next(x for x in markers if x.id == m.id)
                           .T_robot_marker.matrix(), atol=1e-8)


def test_library_accuracy(handheld: Path, views: tuple) -> None:
    v, specs, cam = views
    truth, T_a = _true(handheld)
    cal = calibrate_from_views(v, specs, ANCHOR, T_a, cam, 8)
    _assert_accurate(cal, truth)
    assert cal.images_used == 8 and not cal.rejected_images and not cal.uncalibrated
    new = rc.apply_to_rig(load_rig(handheld / "rig.yaml"), cal)
    assert np.allclose(new.marker(3).T_robot_marker.matrix(), cal.T_robot_marker[3], atol=1e-9)
    # the rig carries what the images measured, relative to the anchor: GTvision weighs markers by it
    assert np.allclose(np.asarray(new.marker(3).pose_cov), cal.cov_relative[3]) and cal.cov_relative[3][0, 0] > 0
    assert not np.any(np.asarray(new.marker(ANCHOR).pose_cov))


def test_wrong_view_is_rejected_and_named(handheld: Path, views: tuple) -> None:
    v, specs, cam = views
    truth, T_a = _true(handheld)
    k = next(i for i, x in enumerate(v) if x.marker_id == 30)
    bad = v[k]
    # a corner 3 px off (a misdetection): the view must be named and the rest unharmed
    px = bad.corners_px.copy()
    px[2] += 3.0
    xn, J = rc.observe.undistort_normalised(cam, px)
    v2 = list(v)
    v2[k] = replace(bad, corners_px=px, corners_n=xn, jac_px=J)
    cal = calibrate_from_views(v2, specs, ANCHOR, T_a, cam, 8)
    assert (bad.image, 30) in cal.rejected_views or bad.image in cal.rejected_images
    _assert_accurate(cal, truth)


def test_markers_never_seen_together_are_bridged(handheld: Path, views: tuple) -> None:
    v, specs, cam = views
    truth, T_a = _true(handheld)
    # marker 3 never in an image with the anchor: half the images lose one, half the other
    images = sorted({x.image for x in v})
    drop = {im: (3 if i % 2 else ANCHOR) for i, im in enumerate(images)}
    v2 = [x for x in v if x.marker_id != drop[x.image]]
    cal = calibrate_from_views(v2, specs, ANCHOR, T_a, cam, 8)
    assert (3, ANCHOR) in cal.bridged_pairs and len(cal.paths[3]) > 2
    _assert_accurate(cal, truth)


def test_anchor_uncertainty_is_propagated(handheld: Path, views: tuple) -> None:
    v, specs, cam = views
    _, T_a = _true(handheld)
    ca = np.diag([1e-6] * 3 + [math.radians(0.1) ** 2] * 3)
    cal0 = calibrate_from_views(v, specs, ANCHOR, T_a, cam, 8)
    cal1 = calibrate_from_views(v, specs, ANCHOR, T_a, cam, 8, anchor_cov=ca)
    assert np.allclose(cal1.cov[ANCHOR], ca)
    # marker 6 is ~0.4 m from the anchor: 0.1 deg adds ~0.7 mm in the plane
    assert cal1.sigma(6)[0] > cal0.sigma(6)[0] + 0.5e-3


def test_anchor_not_seen(views: tuple) -> None:
    v, specs, cam = views
    with pytest.raises(InputError, match="anchor marker 14 is not detected"):
        calibrate_from_views([x for x in v if x.marker_id != ANCHOR], specs, ANCHOR, np.eye(4), cam, 8)
    with pytest.raises(InputError, match="not among the markers"):
        calibrate_from_views(v, specs, 7, np.eye(4), cam, 8)


def test_anchor_pose_formats(tmp_path: Path) -> None:
    T = rc.parse_anchor_pose("-0.143,0.098,0.018,0,0,90")
    assert np.allclose(T[:3, 3], [-0.143, 0.098, 0.018]) and np.allclose(T[:3, 0], [0, 1, 0], atol=1e-12)
    p = tmp_path / "a.yaml"
    p.write_text("T_robot_marker: {xyz: [-0.143, 0.098, 0.018], rpy_deg: [0, 0, 90]}\n")
    assert np.allclose(rc.parse_anchor_pose(str(p)), T)
    with pytest.raises(InputError):
        rc.parse_anchor_pose("1,2,3")


def _one_line_error(args: list[str]) -> str:
    r = runner.invoke(app, args)
    assert r.exit_code == 2, r.output
    lines = [x for x in r.output.splitlines() if x.strip()]
    assert len(lines) == 1 and lines[0].startswith("error:") and "Traceback" not in r.output, r.output
    return lines[0]


def test_cli_errors(handheld: Path, tmp_path: Path) -> None:
    imgs, cam = str(handheld / "handheld" / "images"), str(handheld / "handheld" / "camera.yaml")
    base = ["markers", "calibrate-robot", "--images", imgs, "--camera", cam, "--out", str(tmp_path / "m.yaml")]
    assert "--rig" in _one_line_error(base)
    assert "--anchor-pose" in _one_line_error(base + ["--side-mm", "14=160,3=156"])
    assert "anchor-pose" in _one_line_error(base + ["--side-mm", "14=160", "--anchor-pose", "1,2"])
    assert "ID=MM" in _one_line_error(base + ["--side-mm", "14:160", "--anchor-pose", "0,0,0,0,0,0"])
    assert "no such folder" in _one_line_error(
        ["markers", "calibrate-robot", "--images", str(tmp_path / "none"), "--camera", cam, "--out",
         str(tmp_path / "m.yaml"), "--side-mm", "14=160,3=156", "--anchor-pose", "0,0,0,0,0,0"])
    assert "--rig-out needs --rig" in _one_line_error(base + ["--rig-out", str(tmp_path / "r.yaml")])
