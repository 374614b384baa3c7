from __future__ import annotations

from pathlib import Path

import pytest
from bad_input_kit import make_inputs


@pytest.fixture(scope="session")
def d(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The inputs of the bad-input family (tests/cli/bad_input_kit.py): made once, never written."""
    return make_inputs(tmp_path_factory.mktemp("inputs"))
