"""Shared by the test modules: the repository's folders (as constants, since parametrize
lists are built at import) and fixtures for them."""

from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
CONFIG = REPO / "config"
PROBLEMS = CONFIG / "problems"
PACKAGE = REPO / "cdh_planner"


@pytest.fixture
def repo():
    """The repository's root folder."""
    return REPO


@pytest.fixture
def config_dir():
    """config/: the paper's robots and the Table 1 problems."""
    return CONFIG
