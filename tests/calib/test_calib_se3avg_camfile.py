"""Rotation / pose averaging and the cam.yaml file."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from gtrig import geometry as geo
from gtrig.calib.se3avg import elementwise_mean_pose, mean_pose, mean_rotation
from gtrig.errors import FormatError
from gtrig.io.camfile import CameraIntrinsics, read_cam_yaml, write_cam_yaml


def test_mean_of_symmetric_perturbations_is_the_centre() -> None:
    rng = np.random.default_rng(1)
    R0 = Rotation.from_rotvec([0.3, -1.2, 2.0]).as_matrix()
    vs = rng.normal(0, 0.4, (20, 3))
    Rs = [R0 @ Rotation.from_rotvec(s * v).as_matrix() for v in vs for s in (1, -1)]
    Rm = mean_rotation(np.array(Rs))
    assert geo.rotation_angle(Rm.T @ R0) < 1e-9


def test_mean_pose_is_rigid_unlike_the_elementwise_mean() -> None:
    T0 = geo.T_from_xyz_rpy([1, 2, 3], [0.1, 0.2, 0.3])
    Ts = np.array([T0 @ geo.T_from_xyz_rpy([0, 0, 0], [0, 0, a]) for a in (-0.5, 0.5)])
    pm = mean_pose(Ts)
    assert geo.pose_error(pm.T, T0)[1] < 1e-9
    assert pm.rot_rms_rad == pytest.approx(0.5)
    E = elementwise_mean_pose(Ts)
    assert abs(np.linalg.det(E[:3, :3]) - 1) > 0.1  # the seeds' average is not a rotation


def test_cam_yaml_round_trip(tmp_path) -> None:
    K = np.array([[1500.5, 0, 511.2], [0, 1499.8, 383.9], [0, 0, 1]])
    cam = CameraIntrinsics(
        (1024, 768),
        K,
        np.array([-0.12, 0.1, 1e-4, -2e-4, 0]),
        0.05,
        {"std": {"fx": 0.3}, "per_image_rms_px": {"a.png": 0.04}, "rejected": {"b.png": "outlier"}},
    )
    write_cam_yaml(tmp_path / "cam.yaml", cam)
    back = read_cam_yaml(tmp_path / "cam.yaml")
    assert back.image_size == (1024, 768)
    np.testing.assert_allclose(back.camera_matrix, K)
    np.testing.assert_allclose(back.dist_coeffs, cam.dist_coeffs)
    assert back.rms_px == 0.05 and back.extra["rejected"] == {"b.png": "outlier"}


def test_cam_yaml_errors_are_one_line(tmp_path) -> None:
    p = tmp_path / "cam.yaml"
    p.write_text("image_size: [640, 480]\ncamera_matrix: [[1, 0], [0, 1]]\ndist_coeffs: [0, 0, 0, 0, 0]\n")
    with pytest.raises(FormatError, match=r"cam.yaml: camera_matrix") as e:
        read_cam_yaml(p)
    assert "\n" not in str(e.value)
