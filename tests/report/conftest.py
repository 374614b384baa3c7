"""The report's results folder (tests/report/report_folder.py), made once per test run."""

from __future__ import annotations

from pathlib import Path

import pytest
from report_folder import make_results_dir


@pytest.fixture(scope="session")
def results_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A results folder with every kind of file the report knows, and a recording truth beside it."""
    return make_results_dir(tmp_path_factory.mktemp("demo"))
