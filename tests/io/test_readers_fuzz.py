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
