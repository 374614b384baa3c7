from __future__ import annotations

from pathlib import Path

import pytest

BOVISA = ("Bovisa_2008-09-01", "Bovisa_2008-10-04", "Bovisa_2008-10-06")


@pytest.fixture(scope="session", params=BOVISA)
def bovisa_log(request: pytest.FixtureRequest, shared_dir: Path) -> Path:
    p = shared_dir / "data" / "rawseeds" / request.param / f"{request.param}-GPS.csv"
    if not p.is_file():
        pytest.skip(f"{p} not in ../shared")
    return p
