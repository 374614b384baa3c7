"""The rig file: valid files round-trip; invalid ones give one line naming file, line and field."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml

from gtrig import geometry as geo
from gtrig.errors import ConfigError
from gtrig.rig import dump_rig, load_rig
from gtrig.rig.load import rig_to_dict
from gtrig.rig.models import pose_cov_rows
from gtrig.sim.gtroom import make_scene


@pytest.fixture(scope="module")
def rig_doc() -> dict[str, Any]:
    return rig_to_dict(make_scene(3).rig_true)


def _write(tmp_path: Path, doc: Any) -> Path:
    p = tmp_path / "rig.yaml"
    p.write_text(yaml.safe_dump(doc, sort_keys=False))
    return p


def test_round_trip(tmp_path: Path) -> None:
    rig = make_scene(3).rig_true
    dump_rig(rig, tmp_path / "rig.yaml")
    again = load_rig(tmp_path / "rig.yaml")
    assert again == rig
    for a, b in zip(rig.cameras, again.cameras, strict=True):
        np.testing.assert_allclose(a.T_world_cam.matrix(), b.T_world_cam.matrix(), atol=1e-12)


def test_pose_covariances_round_trip(tmp_path: Path) -> None:
    rig = make_scene(3).rig_true
    rng = np.random.default_rng(0)
    A = rng.normal(size=(6, 6)) * 1e-3
    cam = rig.cameras[0].model_copy(update={"pose_cov": pose_cov_rows(A @ A.T)})
    rig = rig.model_copy(update={"cameras": (cam,) + rig.cameras[1:]})
    dump_rig(rig, tmp_path / "rig.yaml")
    again = load_rig(tmp_path / "rig.yaml")
    assert again.cameras[0].pose_cov is not None and again.cameras[1].pose_cov is None
    np.testing.assert_allclose(np.asarray(again.cameras[0].pose_cov), A @ A.T, rtol=1e-12, atol=0)


def test_rpy_and_quaternion_poses_agree(tmp_path: Path, rig_doc: dict[str, Any]) -> None:
    doc = yaml.safe_load(yaml.safe_dump(rig_doc))
    T = geo.T_from_xyz_rpy([0.1, 0.2, 0.6], np.radians([1.0, -2.0, 90.0]))
    doc["robot"]["markers"][0]["T_robot_marker"] = {"xyz": [0.1, 0.2, 0.6], "rpy_deg": [1.0, -2.0, 90.0]}
    rig = load_rig(_write(tmp_path, doc))
    np.testing.assert_allclose(rig.robot.markers[0].T_robot_marker.matrix(), T, atol=1e-12)


def test_overrides_are_partial(tmp_path: Path, rig_doc: dict[str, Any]) -> None:
    rig = load_rig(_write(tmp_path, rig_doc), overrides={"world": {"name": "other"}})
    assert rig.world.name == "other"
    assert rig.world.description == rig_doc["world"]["description"]


def _set(doc: dict[str, Any], path: tuple[Any, ...], value: Any) -> None:
    for p in path[:-1]:
        doc = doc[p]
    if value is _DELETE:
        del doc[path[-1]]
    else:
        doc[path[-1]] = value


_DELETE = object()

INVALID = [
    # (description, path, value, expected fragments of the one-line message)
    ("missing field", ("robot", "hull", "width_m"), _DELETE, ["robot.hull.width_m", "missing field"]),
    ("unknown field", ("cameras", 0, "focal"), 1500.0, ["cameras[0].focal", "unknown field"]),
    ("marker side in mm", ("robot", "markers", 1, "side_m"), 156.0, ["robot.markers[1].side_m", "millimetres"]),
    ("camera position in mm", ("cameras", 2, "T_world_cam", "xyz"), [-2241.6, 1685.9, 2900.0],
     ["cameras[2].T_world_cam.xyz", "millimetres"]),
    ("camera matrix 3 x 2", ("cameras", 0, "camera_matrix"), [[1500, 0], [0, 1500], [0, 0]],
     ["cameras[0].camera_matrix"]),
    ("bad distortion count", ("cameras", 1, "dist_coeffs"), [0.1, 0.2, 0.0], ["cameras[1].dist_coeffs", "got 3"]),
    ("non-unit quaternion", ("laser_scanners", 0, "T_world_scanner", "quat_xyzw"), [0, 0, 0.5, 0.5],
     ["laser_scanners[0].T_world_scanner", "unit quaternion"]),
    ("two rotations", ("robot", "markers", 0, "T_robot_marker", "rpy_deg"), [0, 0, 0],
     ["robot.markers[0].T_robot_marker", "exactly one"]),
    ("increment in degrees", ("laser_scanners", 1, "angle_increment_rad"), 1.0,
     ["laser_scanners[1].angle_increment_rad", "degrees"]),
    ("negative beams", ("laser_scanners", 2, "beams"), -180, ["laser_scanners[2].beams"]),
    ("string for a number", ("cameras", 3, "rate_hz"), "ten", ["cameras[3].rate_hz"]),
    ("hull in mm", ("robot", "hull", "length_m"), 780.0, ["robot.hull.length_m", "millimetres"]),
    ("principal point outside", ("cameras", 0, "camera_matrix"), [[1500, 0, 5000], [0, 1500, 384], [0, 0, 1]],
     ["cameras[0]", "principal point"]),
    ("unknown marker family", ("robot", "markers", 0, "family"), "qr", ["robot.markers[0].family"]),
    ("duplicate camera name", ("cameras", 1, "name"), "cam0", ["cameras", "duplicate name 'cam0'"]),
    ("unknown tone curve", ("cameras", 2, "tone"), "gamma22", ["cameras[2].tone"]),
    ("negative focal length", ("cameras", 0, "camera_matrix"), [[-1500, 0, 512], [0, 1500, 384], [0, 0, 1]],
     ["cameras[0]", "focal lengths"]),
    ("pose covariance 5 x 5", ("cameras", 0, "pose_cov"), [[1e-6] * 5] * 5, ["cameras[0].pose_cov"]),
    ("pose covariance not symmetric", ("robot", "markers", 0, "pose_cov"),
     [[1e-6 if i == j else (1e-8 if i < j else 0.0) for j in range(6)] for i in range(6)],
     ["robot.markers[0].pose_cov", "symmetric"]),
    ("pose covariance negative", ("cameras", 1, "pose_cov"),
     [[(-1e-6 if i == 2 else 1e-6) if i == j else 0.0 for j in range(6)] for i in range(6)],
     ["cameras[1].pose_cov", "positive semi-definite"]),
]


@pytest.mark.parametrize("what,path,value,fragments", INVALID, ids=[x[0] for x in INVALID])
def test_invalid_rig_one_line(
    tmp_path: Path, rig_doc: dict[str, Any], what: str, path: tuple[Any, ...], value: Any, fragments: list[str]
) -> None:
    doc = yaml.safe_load(yaml.safe_dump(rig_doc))
    _set(doc, path, value)
    p = _write(tmp_path, doc)
    with pytest.raises(ConfigError) as e:
        load_rig(p)
    msg = str(e.value)
    assert "\n" not in msg
    assert msg.startswith(f"{p}:")
    for f in fragments:
        assert f in msg, msg


def test_error_names_the_line(tmp_path: Path, rig_doc: dict[str, Any]) -> None:
    doc = yaml.safe_load(yaml.safe_dump(rig_doc))
    doc["robot"]["markers"][1]["side_m"] = 156.0
    p = _write(tmp_path, doc)
    text = p.read_text().splitlines()
    with pytest.raises(ConfigError) as e:
        load_rig(p)
    line = int(str(e.value).split(":")[1])
    assert "side_m: 156" in text[line - 1]


@pytest.mark.parametrize(
    "content,fragment",
    [("cameras: [\n  - name: a\n  bad", "not valid YAML"), ("- 1\n- 2\n", "must be a mapping"), ("", "mapping")],
)
def test_not_a_rig(tmp_path: Path, content: str, fragment: str) -> None:
    p = tmp_path / "rig.yaml"
    p.write_text(content)
    with pytest.raises(ConfigError, match=fragment):
        load_rig(p)


def test_missing_file(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match="no such file"):
        load_rig(tmp_path / "nope.yaml")
