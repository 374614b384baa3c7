"""Property tests of every reader: any bytes give a result or a GtrigError, never another exception.

Each reader gets random bytes, and mutations of a valid file (truncated, a byte flipped, a line
duplicated, a field replaced by nan, inf or a huge number), which reach deeper than random bytes do.
The long fuzz run of bench/fuzz.py uses the same readers and mutations.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import pytest
from fuzz_cases import READERS, mutate  # tests/io is on sys.path (pytest prepends it)
from hypothesis import HealthCheck, Phase, given, settings
from hypothesis import strategies as st

from gtrig.errors import GtrigError

# no shrinking: a failure prints its input as found, and the suite stays fast
SETTINGS = settings(max_examples=40, deadline=None, suppress_health_check=list(HealthCheck), derandomize=True,
                    phases=[Phase.explicit, Phase.generate], database=None)


def _check(read: Callable[[Path], object], path: Path, data: bytes) -> None:
    path.write_bytes(data)
    try:
        read(path)
    except GtrigError:
        pass


@pytest.mark.parametrize("name", sorted(READERS))
def test_random_bytes(tmp_path_factory, name):
    read, valid, suffix = READERS[name]
    path = tmp_path_factory.mktemp(name) / f"in{suffix}"

    @SETTINGS
    @given(st.binary(max_size=2000))
    def run(data: bytes) -> None:
        _check(read, path, data)

    run()


@pytest.mark.parametrize("name", sorted(READERS))
def test_mutated_valid_files(tmp_path_factory, name):
    read, valid, suffix = READERS[name]
    path = tmp_path_factory.mktemp(name) / f"in{suffix}"
    base = valid()
    path.write_bytes(base)
    read(path)  # the unmutated file is valid

    @SETTINGS
    @given(st.randoms(use_true_random=False), st.integers(1, 4))
    def run(rnd, n) -> None:
        _check(read, path, mutate(base, rnd, n))

    run()


# inputs on which a reader crashed in bench/fuzz.py runs, each now a one-line refusal
FOUND = [
    ("frame_index", b"frame,stamp_s,file\n99999999999999999999,0.0,0.png\n", "frame number"),
    ("rtklib_pos", b"%  GPST  latitude(deg) longitude(deg)\n99999999999999999999/10/04 13:55:52.000 45.5 9.1 186.5 1 9"
                   b" 0.0068 0.0052 0.0155 -0.0021 0.0010 -0.0042 0.60 12.3\n", "date"),
    ("odometry", b"stamp_s,x,y,theta,v,omega\n0.100,0.100,0#,0.1,0.5,0.\n", "'#'"),
    ("scans", b"timestamp,r_0,r_1\n0.0,1.0#,2.0\n0.1,1.0,2.0\n", "not a number|'#'"),
]


@pytest.mark.parametrize(("name", "data", "why"), FOUND, ids=[f[0] for f in FOUND])
def test_crashes_found_by_the_fuzz_run(tmp_path, name, data, why):
    read, _, suffix = READERS[name]
    path = tmp_path / f"in{suffix}"
    path.write_bytes(data)
    with pytest.raises(GtrigError, match=why):
        read(path)


@pytest.mark.parametrize("bag", ["rosbag1", "rosbag2_mcap"])
@pytest.mark.parametrize(("field", "renamed"), [(b"string frame_id", b"string frame_xx"),
                                                (b"Point position", b"Point positixn"),
                                                (b"float64 w", b"float64 v")])
def test_bag_with_a_renamed_field_is_refused(tmp_path, bag, field, renamed):
    # a bag embeds its own message definitions: the fuzz run found one with the header's frame_id renamed
    # (an AttributeError where the frame is read, after the pose had been read under a guard)
    read, valid, suffix = READERS[bag]
    data = valid()
    assert field in data
    path = tmp_path / f"in{suffix}"
    path.write_bytes(data.replace(field, renamed))
    # (ROS 1 also carries each definition's MD5, which then no longer matches)
    with pytest.raises(GtrigError, match="not the standard one" if bag == "rosbag2_mcap" else "hash mismatch"):
        read(path)
