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


# ------------------------------------------------- ROS: one domain and client per module

@pytest.fixture(scope="module")
def domain():
    """A ROS domain id of the module's own, held while its tests run
    (cdh_planner.ros.isolation.claimed_domain; see test/ros_harness.py)."""
    from cdh_planner.ros.isolation import claimed_domain
    with claimed_domain() as d:
        yield d


@pytest.fixture(scope="module")
def client(domain):
    """A PlannerClient in the module's ``domain`` (for the nodes its tests start there)."""
    from cdh_planner.ros.client import PlannerClient
    with PlannerClient(domain_id=domain) as c:
        yield c
