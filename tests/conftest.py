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


@pytest.fixture(scope="session", autouse=True)
def _marker_kernels_compiled(tmp_path_factory: pytest.TempPathFactory) -> None:
    """The marker detector's compiled kernels built by one test process at a time: numba writes its cache
    files without a lock between processes, and two workers building the same kernels at once crashed one
    (numba/numba#4807). The first worker compiles and caches them; the others wait, then load them."""
    import fcntl

    import numpy as np

    from gtrig.markers.detect import MarkerDetector
    from gtrig.markers.synth import homography_from_pose, render
    from gtrig.rig.models import MarkerFamily

    lock = tmp_path_factory.getbasetemp().parent / "marker-kernels.lock"
    with open(lock, "w") as f:
        fcntl.flock(f, fcntl.LOCK_EX)
        try:
            fam = MarkerFamily.APRILTAG_36H11
            markers = [(fam, 3 + i, homography_from_pose(60, (90 + 150 * i, 120 + 60 * (i % 2)), 20, 25 * i, 0))
                       for i in range(4)]
            img, _ = render((300, 640), markers, blur_px=0.7, noise=2.0, rng=np.random.default_rng(0))
            K = np.array([[600.0, 0.0, 320.0], [0.0, 600.0, 150.0], [0.0, 0.0, 1.0]])
            for det in (MarkerDetector(fam), MarkerDetector(fam, K, np.array([-0.1, 0.02, 0.0, 0.0, 0.0]))):
                det.detect(img)
        finally:
            fcntl.flock(f, fcntl.LOCK_UN)
