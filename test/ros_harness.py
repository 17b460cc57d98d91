"""Running the node for tests: its own process, its own ROS domain, discovery on localhost.

    with claimed_domain() as domain, NodeProcess(domain, tmp_path) as node, \
            PlannerClient(domain_id=domain) as client:
        client.wait_for_node()
        ...

``claimed_domain`` (cdh_planner.ros.isolation) holds a localhost TCP port per domain id while
the test runs, so test processes running at the same time (other sessions, other test
modules, the demo) never share a domain (two nodes with the same service name in one domain
answer each other's calls).
"""

import contextlib
import importlib.util
import math
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

from cdh_planner.ros.isolation import claimed_domain, isolated_env, stop_process  # noqa: F401 (re-exported)

from conftest import REPO


def _rigid_copy(path):
    """A copy of the robot parameters file ``path`` without ``cable_stiffness`` (rigid
    cables), in a folder of this process: the FollowJointTrajectory controller double
    reports positions only, no measured tensions, and the unstretched lengths of elastic
    cables taken as rigid put the measured pose off the plan by the stretch (elastic
    cables end to end: test_elastic_execution.py)."""
    import atexit
    import shutil
    import tempfile
    folder = Path(tempfile.mkdtemp(prefix="cdh_rigid_"))
    atexit.register(shutil.rmtree, folder, True)
    lines = path.read_text().splitlines(keepends=True)
    out = folder / path.name
    out.write_text("".join(x for x in lines if not x.lstrip().startswith("cable_stiffness:")))
    return out


ROBOT2 = _rigid_copy(REPO / "config" / "robot2.yaml")  # rigid cables (``_rigid_copy``)
FAKE_NODE = REPO / "test" / "doubles" / "fake_planner.py"
FRAME = "cdh_base"
# No winches in most node tests: ~/execute would be refused without a measured start (the
# node's default). Their fixtures allow it; tests of the refusal set it back to false.
UNCHECKED = "execution.allow_unchecked_start:=true"

# Robot 2's sphere task (config/robot2.yaml, paper Eq. 17): (alpha1, alpha2) in rad
Q1, Q2, Q3 = (0.55, math.pi / 2), (0.55, 0.75), (2.63, 0.75)
EQUATOR = (0.55, 0.0)         # on the sphere, not wrench-feasible (margin -0.15)
EQUATOR_Q3 = (2.63, 0.0)      # on the sphere, not wrench-feasible


def fake_planner_class():
    """The TEST DOUBLE planner class (test/doubles/fake_planner.py)."""
    spec = importlib.util.spec_from_file_location("fake_planner", FAKE_NODE)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module.FakePlanner


@contextlib.contextmanager
def in_process_nodes(log_dir):
    """Yield make(factory=FakePlanner, params=()) -> a PlannerNode in this process, in a ROS
    domain of its own (Robot 2's file, recording to ``log_dir``); each is closed and
    destroyed at the end. Nothing spins it: tests call its callbacks or spin it."""
    import rclpy
    from cdh_planner.ros.node.planner_node import PlannerNode
    made = []
    with claimed_domain() as domain:
        def make(factory=None, params=()):
            context = rclpy.Context()
            rclpy.init(context=context, domain_id=domain)
            args = ["--ros-args", "--params-file", str(ROBOT2), "-p", f"log_dir:={log_dir}",
                    "-p", UNCHECKED]
            for p in params:
                args += ["-p", p]
            node = PlannerNode(factory or fake_planner_class(), context=context,
                               cli_args=args)
            made.append((node, context))
            return node
        try:
            yield make
        finally:
            for node, context in made:
                node.close()
                node.destroy_node()
                rclpy.try_shutdown(context=context)


@contextlib.contextmanager
def spun_node(name, executor_class, **executor_kwargs):
    """(node, executor, ticked): a node in a fresh rclpy context on a domain of its own,
    added to an ``executor_class`` of that context (not spinning: the caller spins it), and
    an Event a 100 Hz timer of the node sets (the executor still runs callbacks); all shut
    down after."""
    import threading
    import rclpy
    with claimed_domain() as domain:
        context = rclpy.Context()
        rclpy.init(context=context, domain_id=domain)
        node = rclpy.create_node(name, context=context)
        ticked = threading.Event()
        node.create_timer(0.01, ticked.set)
        executor = executor_class(context=context, **executor_kwargs)
        executor.add_node(node)
        try:
            yield node, executor, ticked
        finally:
            executor.shutdown()
            node.destroy_node()
            context.try_shutdown()


def until(condition, timeout_s=10.0):
    """Whether ``condition()`` held within ``timeout_s`` (s), polled every 10 ms. The
    timeout only bounds a hang: tests wait for events with it, they do not time them."""
    end = time.monotonic() + timeout_s
    while not condition():
        if time.monotonic() > end:
            return False
        time.sleep(0.01)
    return True


def ros_env(domain):
    return isolated_env(domain)


def cli(*args):
    """The ``cdh-planner`` command of this interpreter's environment."""
    exe = Path(sys.executable).with_name("cdh-planner")
    return [str(exe), *args] if exe.exists() else [sys.executable, "-m", "cdh_planner.cli", *args]


def run_cli(domain, *args, timeout=120):
    """Run ``cdh-planner ARGS`` in ``domain``; CompletedProcess with text output."""
    return subprocess.run(cli(*args), env=ros_env(domain), capture_output=True, text=True,
                          timeout=timeout)


class NodeProcess:
    """``cdh-planner node`` (or, with ``fake=True``, the node around the test double
    planner of test/doubles/fake_planner.py) in its own process."""

    def __init__(self, domain, log_dir, params=(), fake=False, env=None, params_file=None):
        self.log_dir = Path(log_dir)
        self.log_dir.mkdir(parents=True, exist_ok=True)
        ros_args = ["--ros-args", "--params-file", str(params_file or ROBOT2),
                    "-p", f"log_dir:={self.log_dir}", "-p", UNCHECKED]
        for p in params:
            ros_args += ["-p", p]
        cmd = ([sys.executable, str(FAKE_NODE), *ros_args] if fake
               else cli("node", *ros_args))
        self.output = self.log_dir / f"node-{time.time_ns()}.log"
        full_env = ros_env(domain)
        full_env.update(env or {})
        self._out = open(self.output, "w")
        self.proc = subprocess.Popen(cmd, env=full_env, stdout=self._out,
                                     stderr=subprocess.STDOUT, cwd=REPO)

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.stop()

    def stop(self, sig=signal.SIGTERM, timeout=15.0):
        """Send ``sig`` (if still running) and wait; the exit code."""
        rc = stop_process(self.proc, sig, timeout)
        self._out.close()
        return rc

    def log(self):
        if not self._out.closed:
            self._out.flush()
        return self.output.read_text()

    def run_files(self):
        return sorted(self.log_dir.glob("*.mcap"))


def sphere_pose_msg(coords, frame=FRAME):
    """geometry_msgs/PoseStamped of Robot 2's sphere task at (alpha1, alpha2)."""
    from cdh_planner.commands.slice import task_in_yaml
    from cdh_planner.model.pose import quaternion_from_tau
    from cdh_planner.ros.client import pose_stamped
    task = task_in_yaml(ROBOT2)
    p, tau = task.pose(np.array([coords]))
    return pose_stamped(list(p[0]) + list(quaternion_from_tau(tau)[0]), frame)


def pose_text(coords):
    """"x y z qx qy qz qw" of a sphere-task pose (for ``cdh-planner call``)."""
    m = sphere_pose_msg(coords)
    p, o = m.pose.position, m.pose.orientation
    return " ".join(repr(float(v)) for v in (p.x, p.y, p.z, o.x, o.y, o.z, o.w))


class Collector:
    """Keep every message of a subscription with its arrival time (time.time())."""

    def __init__(self, node, msg_type, topic, qos):
        self.items = []
        node.create_subscription(msg_type, topic, self._add, qos)

    def _add(self, msg):
        self.items.append((time.time(), msg))

    @property
    def messages(self):
        return [m for _, m in self.items]


def stamp_s(stamp):
    from cdh_planner.ros.msgs.messages import to_seconds
    return to_seconds(stamp)


def flat_parameters(d, prefix=""):
    """ROS's flattening of nested parameters: {'a': {'b': 1}} -> {'a.b': 1}. PyYAML reads
    '1.0e4' as a string (YAML 1.1), rcl's parser as a double: read it as rcl does."""
    out = {}
    for k, v in d.items():
        if isinstance(v, dict):
            out.update(flat_parameters(v, f"{prefix}{k}."))
        else:
            out[prefix + k] = [_number(x) for x in v] if isinstance(v, list) else _number(v)
    return out


def _number(v):
    if isinstance(v, str):
        try:
            return float(v)
        except ValueError:
            return v
    return v


def file_parameters(path):
    """The flat ROS parameters of a parameters file's ``cdh_planner`` node."""
    import yaml
    return flat_parameters(yaml.safe_load(Path(path).read_text())["cdh_planner"]["ros__parameters"])


CONTROLLER_DOUBLE = REPO / "test" / "doubles" / "follow_joint_trajectory_server.py"


class ControllerDouble:
    """The FollowJointTrajectory test double (test/doubles/follow_joint_trajectory_server.py)
    in its own process in ``domain``; its JSON events collected from stdout. ``args``: its
    command line after the script (joint names and options)."""

    def __init__(self, domain, *args):
        import json
        import threading
        self._json = json    # also a JointGroupPositionController with --commands TOPIC
        self.proc = subprocess.Popen([sys.executable, str(CONTROLLER_DOUBLE), *map(str, args)],
                                     env=ros_env(domain), stdout=subprocess.PIPE,
                                     stderr=subprocess.STDOUT, text=True, cwd=REPO)
        self.lines, self.ready = [], threading.Event()
        self._reader = threading.Thread(target=self._read, daemon=True)
        self._reader.start()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.stop()

    def _read(self):
        for line in self.proc.stdout:
            self.lines.append(line.rstrip("\n"))
            if line.strip() == "ready":
                self.ready.set()

    def events(self, kind=None):
        """The double's events ({"event": ..., ...}) so far, of ``kind`` if given."""
        out = []
        for line in list(self.lines):
            if line.startswith("{"):
                event = self._json.loads(line)
                if kind is None or event["event"] == kind:
                    out.append(event)
        return out

    def stop(self):
        """(exit code, everything it printed)."""
        rc = stop_process(self.proc)
        self._reader.join(5.0)   # it ends at the end of the output: every line is in
        return rc, "\n".join(self.lines)


def wait_node_measures(client, goal_msg, timeout_s=20.0):
    """Wait until the node has the winches' joint states: a ``use_current_start`` goal to
    ``goal_msg`` (a PoseStamped where the winches are) ends other than NO_CURRENT_STATE.
    Processes started together may take a DDS announcement period (about 3 s) to find each
    other, even when a third process already sees both. The last answer (PlanAnswer)."""
    from cdh_planner_interfaces.action import PlanPath
    from cdh_planner.ros.client import plan_path_goal
    end = time.monotonic() + timeout_s
    while True:
        answer = client.plan_path(plan_path_goal(None, goal_msg, use_current_start=True),
                                  timeout_s=60)
        code = answer.result.error_code
        if code != PlanPath.Result.NO_CURRENT_STATE or time.monotonic() > end:
            return answer
        client.spin(0.2)
