"""A ROS domain of one's own for tests and demos (no rclpy here).

Two processes offering the same service name in one ROS_DOMAIN_ID answer each other's calls
(DDS matches them by name). ``claimed_domain()`` picks a domain id that no other cooperating process
(tests, demos) holds: holding one means holding a bound localhost TCP port, released when
the block ends or the process dies. Discovery should also stay on the machine:
``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST`` (``isolated_env``). ``stop_process`` ends a
node started there as a user would (a signal), killing it only if it does not stop.
"""

import contextlib
import os
import random
import signal
import socket
import subprocess
import tempfile
from pathlib import Path

PORT_BASE = 41_000
DOMAINS = range(1, 101)   # 0 is everybody's default; ids up to 101 keep DDS ports < 33000


# When each domain id was last released (a file's modification time per id): a node killed
# in a domain stays in the other participants' graphs until its lease ends, so a domain is
# handed out again only after every other one has been (least recently released first).
RELEASED = Path(tempfile.gettempdir()) / "cdh_planner_domains"


def _released_at(d):
    try:
        return (RELEASED / str(d)).stat().st_mtime
    except OSError:
        return 0.0


def _release(d):
    try:
        RELEASED.mkdir(exist_ok=True)
        (RELEASED / str(d)).touch()
    except OSError:
        pass   # only an ordering hint


@contextlib.contextmanager
def claimed_domain():
    """Yield a ROS domain id no other ``claimed_domain`` holds, the one released longest
    ago; RuntimeError if none."""
    ids = list(DOMAINS)
    random.shuffle(ids)
    ids.sort(key=_released_at)
    for d in ids:
        sock = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        try:
            sock.bind(("127.0.0.1", PORT_BASE + d))
        except OSError:
            sock.close()
            continue
        try:
            yield d
        finally:
            _release(d)
            sock.close()
        return
    raise RuntimeError(f"no free ROS domain id in {DOMAINS.start}..{DOMAINS.stop - 1}")


MAX_DOMAIN_ID = 232       # rcl's limit with the default DDS port mapping


@contextlib.contextmanager
def chosen_domain(environ=None):
    """The domain to watch a demo in: ``ROS_DOMAIN_ID`` when it is set (held like a claimed
    one when nobody else holds it; used anyway, as asked, when somebody does), else
    ``claimed_domain()``. InputError naming ROS_DOMAIN_ID when it is not 0..232."""
    from ..errors import InputError
    text = (os.environ if environ is None else environ).get("ROS_DOMAIN_ID", "").strip()
    if not text:
        with claimed_domain() as d:
            yield d
        return
    if not text.isdigit() or int(text) > MAX_DOMAIN_ID:
        raise InputError("ROS_DOMAIN_ID", text, f"expected an integer 0..{MAX_DOMAIN_ID}")
    sock = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    try:
        sock.bind(("127.0.0.1", PORT_BASE + int(text)))
    except OSError:
        pass
    try:
        yield int(text)
    finally:
        sock.close()


def isolated_env(domain, base=None):
    """A copy of ``base`` (default os.environ) for a process in ``domain``, discovery on
    localhost only, message definitions found in this interpreter's prefix."""
    import sys
    env = dict(os.environ if base is None else base)
    env.update(ROS_DOMAIN_ID=str(domain), ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST",
               AMENT_PREFIX_PATH=env.get("AMENT_PREFIX_PATH") or sys.prefix,
               PYTHONUNBUFFERED="1")
    env.pop("ROS_LOCALHOST_ONLY", None)
    return env


def stop_process(process, sig=signal.SIGINT, timeout_s=15.0):
    """Send ``sig`` to a child process (if still running) and wait; kill it if it has not
    ended within ``timeout_s``. Its exit code."""
    if process.poll() is None:
        process.send_signal(sig)
        try:
            process.wait(timeout_s)
        except subprocess.TimeoutExpired:
            process.kill()
            process.wait()
    return process.returncode
