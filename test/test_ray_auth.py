"""``--ray-address`` as a user runs it: ``cdh-planner workspace`` in a fresh process against
a real ``ray start --head`` (each with a HOME of its own in the test's temporary folder, so
nothing is written to ~/.ray), with and without token authentication:

- a token cluster (its HOME holds ~/.ray/auth_token, so Ray 2.60's ``ray start`` turns token
  mode on) answers a command that finds the token where Ray's CLI looks: the default file,
  RAY_AUTH_TOKEN (RAY_AUTH_TOKEN_PATH and a wrong token: slow);
- without a token the command is refused in one line naming the address, the cause and
  the fix (exit 2), not "error: ConnectionError";
- a cluster without tokens answers a command whose HOME holds a token (a driver in token
  mode there would lose its workers);
- a port where nothing listens is refused at once, naming it.

Every answer is compared with the same samples run in the command's own process
(``--no-ray``): the feasible count is the same.
"""

import os
import secrets
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import time
from contextlib import contextmanager

import pytest

from conftest import CONFIG
from ros_harness import cli

pytest.importorskip("ray")
ROBOT2 = CONFIG / "robot2.yaml"
COMMON = ["workspace", str(ROBOT2), "--samples", "40", "--seed", "3", "--quiet"]
AUTH = ("RAY_AUTH_MODE", "RAY_AUTH_TOKEN", "RAY_AUTH_TOKEN_PATH", "RAY_ADDRESS")


def _env(home, **extra):
    env = {k: v for k, v in os.environ.items() if k not in AUTH}
    env.update(HOME=str(home), RAY_USAGE_STATS_ENABLED="0", **extra)
    return env


def _free_port():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _accepts(port):
    try:
        socket.create_connection(("127.0.0.1", port), timeout=1.0).close()
        return True
    except OSError:
        return False


@contextmanager
def ray_head(home, tmp_path):
    """``ray start --head --block`` with HOME ``home`` (its token, if any, turns token mode
    on), its files under ``tmp_path``; yields the port once it accepts; stopped after."""
    home.mkdir(parents=True, exist_ok=True)
    port = _free_port()
    # Ray's sockets live in its temp dir: a short path (a socket path has at most 107 bytes)
    short = tempfile.mkdtemp(prefix="ray", dir="/tmp")
    log = tmp_path / "head.log"
    with open(log, "w") as out:
        head = subprocess.Popen(
            [sys.executable, "-m", "ray.scripts.scripts", "start", "--head", "--block",
             f"--port={port}", "--num-cpus=1", "--include-dashboard=false",
             "--disable-usage-stats", f"--temp-dir={short}"],
            env=_env(home), stdout=out, stderr=subprocess.STDOUT, start_new_session=True)
    try:
        deadline = time.monotonic() + 180   # a limit for a hang, not a measure
        while not _accepts(port):
            assert head.poll() is None, f"ray start --head exited: {log.read_text()[-2000:]}"
            assert time.monotonic() < deadline, "the head never accepted"
            time.sleep(0.5)
        yield port
    finally:
        head.terminate()   # the head stops its daemons
        try:
            head.wait(timeout=60)
        except subprocess.TimeoutExpired:
            pass
        try:
            os.killpg(head.pid, signal.SIGKILL)   # whatever of its session is left
        except ProcessLookupError:
            pass
        head.wait(timeout=30)
        shutil.rmtree(short, ignore_errors=True)


def run(env, *extra):
    return subprocess.run(cli(*COMMON, *extra), env=env, capture_output=True, text=True,
                          timeout=300)


def feasible_line(out):
    return out.splitlines()[0]


@pytest.fixture(scope="module")
def reference(tmp_path_factory):
    """The first summary line of the same samples in the command's own process."""
    done = run(_env(tmp_path_factory.mktemp("home")), "--no-ray")
    assert done.returncode == 0, done.stderr
    return feasible_line(done.stdout)


def _token_home(path, token):
    (path / ".ray").mkdir(parents=True)
    (path / ".ray" / "auth_token").write_text(token)
    return path


def test_a_token_cluster_answers_with_the_token_and_refuses_without(tmp_path, reference):
    token = secrets.token_hex(16)
    home = _token_home(tmp_path / "head_home", token)
    other = tmp_path / "other_home"
    other.mkdir()
    with ray_head(home, tmp_path) as port:
        address = f"127.0.0.1:{port}"
        for env in (_env(home), _env(other, RAY_AUTH_TOKEN=token)):
            done = run(env, "--workers", "1", "--ray-address", address)
            assert done.returncode == 0, done.stderr
            assert feasible_line(done.stdout) == reference
        refused = run(_env(other), "--workers", "1", "--ray-address", address)
    assert refused.returncode == 2, refused.stderr
    line = refused.stderr.strip()
    assert "\n" not in line, line
    assert line.startswith(f"cdh-planner: error: --ray-address = '{address}': token required, "
                           f"none found (RAY_AUTH_TOKEN, RAY_AUTH_TOKEN_PATH, ~/.ray/auth_token)"
                           f": set RAY_AUTH_TOKEN to the head's `ray get-auth-token`"), line


def test_a_cluster_without_tokens_answers_a_command_that_holds_one(tmp_path, reference):
    user = _token_home(tmp_path / "user_home", secrets.token_hex(16))
    with ray_head(tmp_path / "head_home", tmp_path) as port:
        done = run(_env(user), "--workers", "1", "--ray-address", f"127.0.0.1:{port}")
    assert done.returncode == 0, done.stderr
    assert feasible_line(done.stdout) == reference
    assert not (tmp_path / "head_home" / ".ray").exists(), "the head made a token"


@pytest.mark.slow
def test_a_token_file_path_is_used_and_a_wrong_token_refused(tmp_path, reference):
    token = secrets.token_hex(16)
    home = _token_home(tmp_path / "head_home", token)
    other = tmp_path / "other_home"
    other.mkdir()
    (tmp_path / "token").write_text(token)
    with ray_head(home, tmp_path) as port:
        address = f"127.0.0.1:{port}"
        done = run(_env(other, RAY_AUTH_TOKEN_PATH=str(tmp_path / "token")), "--workers", "1",
                   "--ray-address", address)
        assert done.returncode == 0, done.stderr
        assert feasible_line(done.stdout) == reference
        wrong = run(_env(other, RAY_AUTH_TOKEN=secrets.token_hex(16)), "--workers", "1",
                    "--ray-address", address)
    assert wrong.returncode == 2
    assert "the cluster refused the token of RAY_AUTH_TOKEN" in wrong.stderr, wrong.stderr


def test_a_port_where_nothing_listens_is_refused_naming_it(tmp_path):
    port = _free_port()
    done = run(_env(tmp_path), "--workers", "1", "--ray-address", f"127.0.0.1:{port}")
    assert done.returncode == 2
    line = done.stderr.strip()
    assert "\n" not in line and line.startswith(
        f"cdh-planner: error: --ray-address = '127.0.0.1:{port}': nothing answers there "
        f"(Connection refused): start it with `ray start --head --port=PORT`"), line
