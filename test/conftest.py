"""Shared by the test modules: the repository's folders (as constants, since parametrize
lists are built at import) and fixtures for them."""

import os
import shutil
import signal
import tempfile
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
CONFIG = REPO / "config"
PROBLEMS = CONFIG / "problems"
PACKAGE = REPO / "cdh_planner"


def aot_built(*kernels):
    """Whether each kernel module (manifold.kernels, scene.kernels, wrench.compiled,
    model.elastic_kernel, trajectory.motion_kernel, ...) has its ahead-of-time build of its
    current source (``make``)."""
    from cdh_planner import aot
    return all(aot.load(k) is not None for k in kernels)


def default_sigint():
    """``preexec_fn`` of a child a test interrupts with SIGINT: the signal's default action,
    as a shell in a terminal gives it. A suite started in the background (``&``, nohup) has
    SIGINT ignored, children inherit that, and Python then installs no KeyboardInterrupt."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def pytest_configure(config):
    """A short temporary root of the run's own (/tmp/cdh-test-XXXX; the workers of
    pytest-xdist take popen-gwN folders inside it), unless --basetemp is given: error lines
    show at most 80 characters of a value (errors.MAX_VALUE_CHARS), and the tests that
    read a file's whole path in them need it shorter than pytest-of-USER/pytest-N/popen-gwN/
    makes it. pytest empties a basetemp it is given, so each run has a new one."""
    if config.option.basetemp is None and not hasattr(config, "workerinput"):
        config.option.basetemp = config._cdh_basetemp = tempfile.mkdtemp(prefix="cdh-test-",
                                                                          dir="/tmp")


def pytest_sessionfinish(session, exitstatus):
    """The run's temporary root goes when every test passed (kept to look at otherwise)."""
    made = getattr(session.config, "_cdh_basetemp", None)
    if made is not None and exitstatus == 0:
        shutil.rmtree(made, ignore_errors=True)


@pytest.fixture(scope="session", autouse=True)
def ray_temp_dir():
    """Ray's session folders (and ``ray start``'s address file) in a folder of the run's own,
    removed at its end, instead of /tmp/ray: RAY_TMPDIR, read by ``ray.init``, ``ray start``
    and every process they start. Short (/tmp/cdh-ray-XXXX): Ray's socket paths inside it
    must stay under the 107 bytes of a Unix socket name."""
    folder = tempfile.mkdtemp(prefix="cdh-ray-", dir="/tmp")
    saved = os.environ.get("RAY_TMPDIR")
    os.environ["RAY_TMPDIR"] = folder
    yield Path(folder)
    if saved is None:
        os.environ.pop("RAY_TMPDIR", None)
    else:
        os.environ["RAY_TMPDIR"] = saved
    shutil.rmtree(folder, ignore_errors=True)


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
