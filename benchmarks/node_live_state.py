"""What a winch controller's joint states cost the node: its CPU at rest, and planning.

    .venv/bin/python benchmarks/node_live_state.py [--idle-s 10] [--runs 3]
        [--rates 0 50 500] [--plan-rates 0 50] [--python OTHER_CHECKOUT/.venv/bin/python]

(a) The idle node's CPU: ``cdh-planner node`` on Robot 2 (config/robot2.yaml) in a ROS
domain of its own, with no joint states and with a publisher of Robot 2's joint states at
each of ``--rates`` Hz (a process of its own: the lengths at q2, each wobbling by 10 um so
that forward kinematics has work); the node's process CPU time (utime + stime from
/proc/PID/stat) over ``--idle-s`` s of wall clock, in % of one core.

(b) Planning over ROS: Robot 2 q2 -> q3 (sphere task, A*) on ``~/plan``, round trip at the
client: on a fresh node per rate of ``--plan-rates`` (0: no publisher), its first plan
(cold); then on one more node, ``--runs`` rounds of one plan per rate, the publisher
started and stopped around each (warm: the node keeps its atlas; the rates in turn, so
that the machine's changing load falls on each alike); and the library's own time for
the same query (``Planner.plan`` in this process on the node's configuration, cold then
warm).

Targets (docs/performance.md, the node's live state): idle <= 10 % of a core at 50 Hz, <= 25 % at 500 Hz; planning with a
50 Hz publisher within 1.2x of without, within 1.3x of the library. ``--python`` runs the
node (not the publisher or the client) with another checkout's interpreter (e.g.
OTHER/.venv/bin/python: before and after). Timings depend on the machine's load:
report it with them.
"""

import argparse
import contextlib
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import yaml

ROOT = Path(__file__).resolve().parents[1]
ROBOT_FILE = ROOT / "config" / "robot2.yaml"
Q2, Q3 = (0.55, 0.75), (2.63, 0.75)
NODE_PARAMS = ("log_enabled:=false", "planner.strategy:=astar")
WOBBLE_M, WOBBLE_HZ = 1e-5, 0.5
SETTLE_S = 3.0     # s after the publisher starts before the CPU window (DDS discovery)


def _flat(d, prefix=""):
    """ROS's flattening of nested parameters: {'a': {'b': 1}} -> {'a.b': 1}."""
    out = {}
    for k, v in d.items():
        out.update(_flat(v, f"{prefix}{k}.") if isinstance(v, dict) else {prefix + k: v})
    return out


def node_configuration():
    """The node's NodeConfig for ROBOT_FILE and NODE_PARAMS."""
    from cdh_planner.model.robot import read_yaml, ros_parameters
    from cdh_planner.ros.core.params import node_config
    values = _flat(ros_parameters(read_yaml(ROBOT_FILE, "robot"), str(ROBOT_FILE)))
    values.update((name, yaml.safe_load(value))      # as rcl reads -p name:=value
                  for name, value in (p.split(":=") for p in NODE_PARAMS))
    return node_config(values)


def sphere_pose(task, coords):
    from cdh_planner.model.pose import quaternion_from_tau
    from cdh_planner.ros.client import pose_stamped
    p, tau = task.pose(np.array([coords]))
    return pose_stamped(list(p[0]) + list(quaternion_from_tau(tau)[0]), "cdh_base")


# ----------------------------------------------------------------------------- publisher

def publish(rate_hz, domain):
    """Robot 2's joint states at q2 at ``rate_hz`` Hz until killed (a child process)."""
    import rclpy
    from sensor_msgs.msg import JointState
    from cdh_planner.model.kinematics import cable_lengths
    from cdh_planner.model.pose import rotation_from_quaternion
    config = node_configuration()
    o = sphere_pose(config.task, Q2).pose
    lengths = cable_lengths(config.robot, np.array([o.position.x, o.position.y, o.position.z]),
                            rotation_from_quaternion(np.array([o.orientation.x, o.orientation.y,
                                                               o.orientation.z, o.orientation.w])))
    rclpy.init(domain_id=domain)
    node = rclpy.create_node("winch_controller_stand_in")
    pub = node.create_publisher(JointState, "/joint_states", 10)   # joint_state_broadcaster's
    names = list(config.robot.winch_names)
    t0, k = time.monotonic(), 0
    while True:
        k += 1
        wobble = WOBBLE_M * np.sin(2 * np.pi * WOBBLE_HZ * k / rate_hz)
        msg = JointState(name=names, position=(lengths + wobble).tolist())
        msg.header.stamp = node.get_clock().now().to_msg()
        pub.publish(msg)
        left = t0 + k / rate_hz - time.monotonic()
        if left > 0:
            time.sleep(left)


@contextlib.contextmanager
def publisher(rate_hz, domain):
    if not rate_hz:
        yield
        return
    from cdh_planner.ros.isolation import isolated_env, stop_process
    proc = subprocess.Popen([sys.executable, __file__, "--publish", str(rate_hz),
                             "--domain", str(domain)], env=isolated_env(domain),
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        yield
    finally:
        stop_process(proc)


# ----------------------------------------------------------------------------- node

@contextlib.contextmanager
def node_and_client(domain, python, params=()):
    from cdh_planner.ros.client import PlannerClient
    from cdh_planner.ros.isolation import isolated_env, stop_process
    ros_args = ["--ros-args", "--params-file", str(ROBOT_FILE)]
    for p in NODE_PARAMS + tuple(params):
        ros_args += ["-p", p]
    proc = subprocess.Popen([python, "-m", "cdh_planner.cli", "node", *ros_args],
                            env=isolated_env(domain), cwd=Path(python).parents[2],  # its checkout
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        with PlannerClient(domain_id=domain) as client:
            client.wait_for_node(120.0)
            yield proc, client
    finally:
        stop_process(proc)


def cpu_s(pid):
    """The process's CPU time so far (user + system, s), from /proc/PID/stat."""
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def idle_cpu(rate_hz, idle_s, python, params=()):
    """% of one core the idle node takes over ``idle_s`` s with joint states at ``rate_hz``."""
    from cdh_planner.ros.isolation import claimed_domain
    with claimed_domain() as domain, node_and_client(domain, python, params) as (proc, client), \
            publisher(rate_hz, domain):
        client.spin(SETTLE_S)
        c0, t0 = cpu_s(proc.pid), time.monotonic()
        time.sleep(idle_s)
        return 100.0 * (cpu_s(proc.pid) - c0) / (time.monotonic() - t0)


def node_plans(rates, runs, python):
    """({rate: cold s}, {rate: [warm s]}) of q2 -> q3 on ~/plan, round trips at the client,
    joint states at each of ``rates`` Hz (0: none). Cold: the first plan of a fresh node
    per rate. Warm: one more node, the rates taken in turn ``runs`` times (the publisher
    started and stopped around each plan), so that a change of the machine's load falls
    on every rate alike."""
    from cdh_planner.ros.isolation import claimed_domain
    config = node_configuration()
    start, goal = sphere_pose(config.task, Q2), sphere_pose(config.task, Q3)

    def plan(client):
        answer = client.plan(start, goal, timeout_s=300)
        if not answer.success:
            raise SystemExit(f"the node did not plan q2 -> q3: {answer.values}")
        return answer.seconds

    cold, warm = {}, {rate: [] for rate in rates}
    for rate in rates:
        with claimed_domain() as domain, node_and_client(domain, python) as (_, client), \
                publisher(rate, domain):
            client.spin(SETTLE_S)
            cold[rate] = plan(client)
    with claimed_domain() as domain, node_and_client(domain, python) as (_, client):
        plan(client)
        for _ in range(runs):
            for rate in rates:
                with publisher(rate, domain):
                    client.spin(SETTLE_S)
                    warm[rate].append(plan(client))
    return cold, warm


def library_plans(runs):
    """(cold s, [warm s]) of q2 -> q3 by Planner.plan in this process, as the node plans."""
    from nav_msgs.srv import GetPlan
    from cdh_planner.planner import Planner
    from cdh_planner.ros.core import plan_requests
    config = node_configuration()
    request = GetPlan.Request(start=sphere_pose(config.task, Q2), goal=sphere_pose(config.task, Q3))
    poses = plan_requests.request_poses(request, config.base_frame)
    planner = plan_requests.warm_up(Planner(config.robot, config.task, config.settings,
                                            scene=config.scene))
    times = []
    for _ in range(1 + runs):
        t0 = time.perf_counter()
        if not planner.plan(*poses).success:
            raise SystemExit("the library did not plan q2 -> q3")
        times.append(time.perf_counter() - t0)
    return times[0], times[1:]


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--idle-s", type=float, default=10.0)
    ap.add_argument("--runs", type=int, default=3, help="warm plans after the cold one")
    ap.add_argument("--rates", type=float, nargs="*", default=[0.0, 50.0, 500.0])
    ap.add_argument("--plan-rates", type=float, nargs="*", default=[0.0, 50.0])
    ap.add_argument("--python", default=sys.executable, help="the node's interpreter")
    ap.add_argument("--param", action="append", default=[],
                    help="name:=value, another node parameter for the idle runs (repeatable)")
    ap.add_argument("--publish", type=float, help=argparse.SUPPRESS)
    ap.add_argument("--domain", type=int, help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.publish:
        publish(args.publish, args.domain)
        return
    print(f"load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores; node: {args.python}")
    for rate in args.rates:
        print(f"idle node, joint states at {rate:g} Hz: "
              f"{idle_cpu(rate, args.idle_s, args.python, args.param):.1f} % of a core over "
              f"{args.idle_s:g} s",
              flush=True)
    if not args.plan_rates:
        return
    cold, warm = library_plans(args.runs)
    library = statistics.median(warm) if warm else cold
    print(f"library q2 -> q3: cold {cold:.2f} s, warm median {library:.2f} s", flush=True)
    cold, warm = node_plans(args.plan_rates, args.runs, args.python)
    base = None
    for rate in args.plan_rates:
        median = statistics.median(warm[rate]) if warm[rate] else cold[rate]
        base = median if base is None else base
        print(f"node q2 -> q3 over ~/plan, joint states at {rate:g} Hz: cold {cold[rate]:.2f} s, "
              f"warm median {median:.2f} s of {len(warm[rate])} ({median / base:.2f}x the first "
              f"rate, {median / library:.2f}x the library)", flush=True)


if __name__ == "__main__":
    main()
