"""Odometry CSV files: round trip and one-line errors naming file and line."""

from __future__ import annotations

import numpy as np
import pytest

from gtrig.errors import FormatError
from gtrig.io.odometry import OdometryLog, read_odometry, write_odometry_csv

HEADER = "stamp_s,x,y,theta,v,omega\n"


def test_round_trip(tmp_path) -> None:  # type: ignore[no-untyped-def]
    rng = np.random.default_rng(1)
    n = 200
    stamps = 1.7e9 + 300 + np.arange(n) / 50
    vals = np.round(rng.normal(0, 3, (n, 5)) * 1e9) / 1e9
    log = OdometryLog(stamps, vals[:, :3], vals[:, 3], vals[:, 4])
    write_odometry_csv(tmp_path / "o.csv", log)
    back = read_odometry(tmp_path / "o.csv")
    np.testing.assert_array_equal(back.stamps_s, log.stamps_s)
    np.testing.assert_allclose(back.xytheta, log.xytheta, rtol=0, atol=1e-12)
    np.testing.assert_allclose(back.v_mps, log.v_mps, rtol=0, atol=1e-12)
    np.testing.assert_allclose(back.omega_radps, log.omega_radps, rtol=0, atol=1e-12)


@pytest.mark.parametrize(
    ("body", "line", "words"),
    [
        (HEADER + "1,0,0,0,0,0\n2,0,0,0,0\n", 3, "expected 6 values"),
        (HEADER + "1,0,0,0,0,0\n2,0,x,0,0,0\n", 3, "not a number: 'x'"),
        (HEADER + "1,0,0,0,0,0\n\n1,0,0,0,0,0\n", 4, "does not increase"),
        (HEADER + "1,0,0,nan,0,0\n", 2, "theta is not a finite number"),
    ],
)
def test_bad_lines_name_file_and_line(tmp_path, body, line, words) -> None:  # type: ignore[no-untyped-def]
    p = tmp_path / "bad.csv"
    p.write_text(body)
    with pytest.raises(FormatError) as e:
        read_odometry(p)
    msg = str(e.value)
    assert "\n" not in msg and f"{p}:{line}:" in msg and words in msg


def test_bad_header(tmp_path) -> None:  # type: ignore[no-untyped-def]
    p = tmp_path / "bad.csv"
    p.write_text("t,x,y,theta,v,omega\n1,0,0,0,0,0\n")
    with pytest.raises(FormatError, match="header must be"):
        read_odometry(p)
