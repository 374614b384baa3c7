from __future__ import annotations

import os

# Small matrices dominate: BLAS threads on two cores only contend (about 10x slower products).
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")

from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
SHARED = REPO.parent / "shared"


@pytest.fixture(scope="session")
def shared_dir() -> Path:
    """``../shared`` beside the repository (never an absolute path). Missing: the test is skipped on a
    developer's machine and fails in CI (``CI`` set), where the golden values must be checked."""
    if not SHARED.is_dir():
        if os.environ.get("CI"):
            pytest.fail(f"{SHARED}: the shared test data is missing (CI must check the golden values)")
        pytest.skip("../shared is not beside the repository")
    return SHARED
