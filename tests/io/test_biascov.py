"""``*_bias.yaml`` (gtrig.io.biascov): what the stages write is what fusion reads; bad files one clear line."""

import numpy as np
import pytest

from gtrig.errors import FormatError
from gtrig.fusion.bias import heading_averaged
from gtrig.io.biascov import read_bias_cov, write_bias_cov


def test_round_trip_sums_the_terms(tmp_path) -> None:
    a = np.array([[2e-6, 3e-7, 1e-8], [3e-7, 1e-6, 0.0], [1e-8, 0.0, 4e-8]])
    b = np.diag([1e-8, 1e-8, 2e-8])
    write_bias_cov(tmp_path / "b.yaml", "GTlaser", {"calibration": a, "frame": b})
    np.testing.assert_allclose(read_bias_cov(tmp_path / "b.yaml"), a + b, rtol=1e-15)


@pytest.mark.parametrize(("text", "what"), [
    ("format: gtrig run-constant error v1\naxes: [x, y, yaw]\ncov: [[1, 0], [0, 1]]\n", "3 x 3"),
    ("format: gtrig run-constant error v1\naxes: [x, y, yaw]\ncov: [[1, 2, 0], [2, 1, 0], [0, 0, 1]]\n",
     "positive semi-definite"),
    ("format: gtrig run-constant error v1\naxes: [x, z]\ncov: [[1, 0], [0, 1]]\n", "axes"),
    ("cov: [[1]]\n", "format"),
    ("format: gtrig run-constant error v1\naxes: [x, y]\ncov: [[1, 0], [0, .nan]]\n", "finite"),
])
def test_bad_files(tmp_path, text: str, what: str) -> None:
    (tmp_path / "b.yaml").write_text(text)
    with pytest.raises(FormatError, match=what):
        read_bias_cov(tmp_path / "b.yaml")


def test_heading_average_of_a_robot_frame_error() -> None:
    # an error fixed in the robot frame, turned by headings spread evenly: the mean of R C R^T
    c = np.array([[4e-6, 1e-6, 2e-7], [1e-6, 1e-6, -1e-7], [2e-7, -1e-7, 9e-8]])
    yaw = np.linspace(0, 2 * np.pi, 360, endpoint=False)
    R = np.zeros((yaw.size, 3, 3))
    R[:, 0, 0] = R[:, 1, 1] = np.cos(yaw)
    R[:, 0, 1], R[:, 1, 0], R[:, 2, 2] = -np.sin(yaw), np.sin(yaw), 1.0
    np.testing.assert_allclose(heading_averaged(c), (R @ c @ np.swapaxes(R, 1, 2)).mean(axis=0), atol=1e-20)
