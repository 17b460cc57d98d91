"""The ROS story (``STEPS``, after the paper's): 5. start ``cdh-planner node`` on Robot 2
in a ROS domain of its own, recording to ``<out>/runs``; 6. a task sequencer plans
q_1 -> q_2 through the ``~/plan_path`` action, checks the motion densely and streams it
(``PlannerClient.execute_and_follow``); 7. ros2_control takes over: the simulated cable
controller (``ros/execution/simulated_controller.py``, a FollowJointTrajectory server with the winches'
JointState) starts where the winches are and the node switches to
``execution.mode: follow_joint_trajectory``; 8. q_2 -> q_3 planned from the pose of the
measured cable lengths (``use_current_start``) and executed through the controller;
9. replay: the recorded commands are republished and compared, the recorded goals re-sent
to a fresh node (the planner keeps its atlas between requests, so only a node in its
starting state answers the same); 10. SIGINT, the run file read back; 11. pictures
(``pictures.plans``) and a summary. The steps share ``demo.ros`` (a ``NodeStory``); the
processes are stopped at exit whatever happens. rclpy is imported inside the steps only,
so the paper's story runs without ROS.
"""

import atexit
import contextlib
import math
import subprocess
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Optional

import numpy as np

from ...pictures.plans import ExecutedMotion, plot_execution, plot_paths
from ...pictures.slices import Marker, SegmentOverlay, SliceView
from ...ros.isolation import chosen_domain, claimed_domain, isolated_env, stop_process
from .paper import PICTURES, paper_pose
from .steps import Step, table

LEGS = (("q_1", "q_2"), ("q_2", "q_3"))
REPLAY_RATE = 4.0
NODE_TIMEOUT_S = 60.0
PLAN_TIMEOUT_S = 120.0
TOLERANCE = 1e-9   # m and rad: a re-sent request must get the same path
PARAMETERS = ("base_frame", "task.type", "planner.strategy", "trajectory.max_cable_speed",
              "trajectory.max_cable_accel", "stream_rate_hz", "execution.mode",
              "execution.controller_action", "execution.joint_states_topic")
CONTROLLER_READY_S = 30.0
# what this part writes in the demo's --out directory (checked against the inputs first)
RUN_DIR, NODE_LOG, FRESH_NODE_LOG, CONTROLLER_LOG = "runs", "node.log", "node_fresh.log", \
    "controller.log"
PLANS_PICTURE, EXECUTION_PICTURE = "robot2_plans.png", "robot2_execution.png"
OUTPUTS = (RUN_DIR, NODE_LOG, FRESH_NODE_LOG, CONTROLLER_LOG, PLANS_PICTURE, EXECUTION_PICTURE)


class NodeFailed(RuntimeError):
    """The node did not start or stopped answering: the remaining ROS steps are skipped."""


@dataclass
class Leg:
    start: str
    goal: str
    current_start: bool = False           # from the measured pose (use_current_start)
    answer: object = None                 # client.PlanAnswer
    run: object = None                    # client.Execution
    measured: list = field(default_factory=list)  # (s, lengths) from the winches' JointState
    coords: Optional[np.ndarray] = None   # task coordinates of the waypoints
    safe: Optional[bool] = None
    worst_margin: float = math.nan


@dataclass
class NodeStory:
    stack: contextlib.ExitStack           # stops the nodes, closes the client
    domain: int
    process: subprocess.Popen
    client: object                        # client.PlannerClient
    node_log: Path
    frame: str = ""                       # the node's base_frame
    parameters: dict = field(default_factory=dict)  # PARAMETERS as the node has them
    joint_states: list = field(default_factory=list)  # (time.monotonic(), JointState)
    legs: list = field(default_factory=list)
    run_file: str = ""
    failed: bool = False                  # a step failed: the others are skipped


def _cli(*args):
    return [sys.executable, "-m", "cdh_planner.cli", *args]


def _node_args(demo, parameter):
    # the first leg streams with no winches measured yet: allowed explicitly
    return ["node", "--ros-args", "--params-file", str(demo.config_dir / "robot2.yaml"), "-p",
            parameter, "-p", "execution.allow_unchecked_start:=true"]


def _spawn_node(demo, stack, args, log_name, domains=claimed_domain):
    """Start ``cdh-planner ARGS`` in a domain of its own (held by ``stack``, which also
    stops the process); (domain, process, log path). ``domains``: how it is chosen."""
    domain = stack.enter_context(domains())
    node_log = demo.out_dir / log_name
    out = stack.enter_context(open(node_log, "w"))
    process = subprocess.Popen(_cli(*args), env=isolated_env(domain), stdout=out,
                               stderr=subprocess.STDOUT)
    stack.callback(stop_process, process)
    return domain, process, node_log


def start_node(demo):
    """Start the node on Robot 2 and wait for its services."""
    try:
        from ...ros.client import PlannerClient
    except ImportError as exc:
        raise NodeFailed(f"rclpy is not installed here ({exc}): make venv installs the ROS 2 "
                         f"wheels") from None
    stack = contextlib.ExitStack()
    atexit.register(stack.close)
    run_dir = demo.out_dir / RUN_DIR
    run_dir.mkdir(parents=True, exist_ok=True)
    args = _node_args(demo, f"log_dir:={run_dir}")
    t0 = time.perf_counter()
    # ROS_DOMAIN_ID when set, so that it can be watched (ros2 topic echo, RViz, Foxglove)
    domain, process, node_log = _spawn_node(demo, stack, args, NODE_LOG, chosen_domain)
    client = PlannerClient(domain_id=domain, name="cdh_planner_demo")
    stack.callback(client.close)
    client.watch_execution()  # before the first plan, so that no streamed command is missed
    demo.ros = story = NodeStory(stack=stack, domain=domain, process=process, client=client,
                                 node_log=node_log)
    print(f"$ cdh-planner {' '.join(args)}")
    print(f"  (ROS_DOMAIN_ID={domain}, ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST; node log "
          f"{node_log})")
    end = time.monotonic() + NODE_TIMEOUT_S
    client.spin_until(lambda: process.poll() is not None or client.plan_client.service_is_ready(),
                      NODE_TIMEOUT_S)
    if process.poll() is not None:
        tail = node_log.read_text().strip().splitlines()[-3:]
        raise NodeFailed(f"the node exited with {process.returncode}: " + " | ".join(tail))
    client.wait_for_node(max(1.0, end - time.monotonic()))
    story.parameters = params = client.get_parameters(PARAMETERS)
    story.frame = params["base_frame"]
    print(f"node {client.target} ready in {time.perf_counter() - t0:.1f} s: "
          + ", ".join(f"{k} {v}" for k, v in params.items()))


def _leg(demo, start, goal, current_start=False):
    """Plan start -> goal through ~/plan_path, check the motion densely, execute it."""
    from ...model.pose import quaternion_from_tau, tau_from_quaternion
    from ...ros import messages as M
    from ...ros.client import path_duration, path_length, plan_path_goal, pose_stamped
    from ...trajectory.path_check import check_motion

    story, robot, task = demo.ros, demo.robots["robot2"], demo.tasks["robot2"]
    leg = Leg(start, goal, current_start)
    story.legs.append(leg)
    poses = [pose_stamped([*p, *quaternion_from_tau(tau)], story.frame)
             for p, tau in (demo.pose("robot2", label) for label in (start, goal))]
    where = (f"the pose of the measured cable lengths (use_current_start; {start} expected)"
             if current_start else start)
    print(f"goal ~/plan_path: {where} -> {goal} (poses of the sphere task, m and quaternion "
          f"in {story.frame})")
    leg.answer = answer = story.client.plan_path(
        plan_path_goal(None if current_start else poses[0], poses[1],
                       use_current_start=current_start), PLAN_TIMEOUT_S)
    v = answer.values
    if not answer.success:
        print(f"  NO PLAN (error code {answer.result.error_code}): {answer.result.error_msg}")
        demo.differs.append(f"robot2 {start} -> {goal} over ROS: no plan "
                            f"({answer.result.error_msg}), expected a path (the paper's Sec. 5.2)")
        return
    p, quat = M.path_arrays(answer.path)
    if current_start:
        off = float(np.linalg.norm(p[0] - _position(poses[0])))
        print(f"  start from the forward kinematics of the measured lengths: {off:.1e} m from "
              f"{start}")
    leg.coords = task.coords(p, tau_from_quaternion(quat))
    checks = check_motion(robot, p, quat)
    leg.safe = all(c.feasible for c in checks)
    leg.worst_margin = min(c.worst.margin for c in checks)
    charts = [f.charts for f in answer.feedback]
    print(f"  {len(charts)} feedback messages while planning"
          + (f" (charts {charts[0]} .. {charts[-1]})" if charts else ""))
    print(f"  planned in {answer.result.planning_time_s:.2f} s ({answer.result.charts} charts, "
          f"{v['strategy']}): {len(p)} waypoints, path {path_length(answer.path):.4f} m, "
          f"duration {path_duration(answer.path):.2f} s, lowest tension margin "
          f"{answer.number('min_tension_margin_n'):.3f} N")
    print(f"  motion between the waypoints as a controller executes it (position linear, "
          f"orientation slerp), checked densely: "
          + (f"safe, worst margin {leg.worst_margin:+.4f}" if leg.safe else "UNSAFE"))
    if not leg.safe:
        demo.differs.append(f"robot2 {start} -> {goal}: the planned motion leaves C between "
                            f"waypoints")
    measured_from = len(story.joint_states)
    leg.run = run = story.client.execute_and_follow(answer)
    print(f"call ~/execute: {run.message}")
    print(f"  {run.end.message if run.end is not None else 'no ~/execution_result received'}")
    story.client.spin(0.1)   # the joint state at the end
    leg.measured = _from_first_motion(story.joint_states[measured_from:])
    if leg.measured:
        print(f"  the winches began to move {leg.measured[1][0] - run.called_at:.3f} s after "
              f"the ~/execute call (joint states at 50 Hz)")
    if not run.accepted:
        demo.differs.append(f"robot2 {start} -> {goal}: execute refused: {run.message}")
    elif run.commands:
        (span, rate), err = run.rate(), run.error_m()
        print(f"  streamed {len(run.commands)} cable commands over {span:.2f} s ({rate:.1f} "
              f"Hz); last = the final waypoint's cable lengths within {err:.1e} m: "
              + " ".join(f"{x:.4f}" for x in run.values()[1][-1]) + " m")
    elif leg.measured:
        last = _measured_lengths(leg.measured[-1][1], robot.winch_names)
        err = float(np.max(np.abs(last - run.goal))) if run.goal is not None else math.nan
        print(f"  the controller moved the winches: {len(leg.measured)} joint states; the last "
              f"= the final waypoint's cable lengths within {err:.1e} m")
        tensions = _measured_tensions(leg.measured, robot.winch_names)
        if tensions is not None:
            low = tensions.min(axis=0)
            within = bool(np.all(low >= robot.tension_min) and
                          np.all(tensions.max(axis=0) <= robot.tension_max))
            print(f"  measured tensions (the simulated robot's load cells, joint states' effort): "
                  f"{tensions.min():.3f} .. {tensions.max():.3f} N, least margin "
                  f"{float(np.min(low - robot.tension_min)):+.3f} N to the least tension: "
                  + ("within the limits" if within else "LIMIT LEFT"))
            if not within:
                demo.differs.append(f"robot2 {start} -> {goal}: a measured tension left its "
                                    f"limits on the simulated robot")
    if run.accepted and not run.arrived:
        demo.differs.append(f"robot2 {start} -> {goal}: the execution did not reach the last "
                            f"waypoint ({run.outcome or 'no result'})")


def _from_first_motion(states, tol_m=1e-9):
    """The (arrival time, JointState) list from the last state before the joints moved."""
    if not states:
        return []
    first = np.asarray(states[0][1].position)
    moved = [k for k, (_, m) in enumerate(states)
             if np.max(np.abs(np.asarray(m.position) - first)) > tol_m]
    return states[max(moved[0] - 1, 0):] if moved else []


def _position(pose_stamped):
    p = pose_stamped.pose.position
    return np.array([p.x, p.y, p.z])


def _measured_lengths(joint_state, names):
    return np.array([joint_state.position[list(joint_state.name).index(n)] for n in names])


def _measured_tensions(states, names):
    """The efforts (M, m) N of the (arrival time, JointState) list, or None when one lacks
    them (a controller without load cells)."""
    if any(len(m.effort) != len(m.name) for _, m in states):
        return None
    return np.array([[m.effort[list(m.name).index(n)] for n in names] for _, m in states])


def leg_q1_q2(demo):
    """Plan q_1 -> q_2 over ROS and execute it."""
    _leg(demo, *LEGS[0])


def start_controller(demo):
    """Start the simulated cable controller where the winches are; execution through it."""
    from sensor_msgs.msg import JointState
    story, client = demo.ros, demo.ros.client
    robot = demo.robots["robot2"]
    first = story.legs[0] if story.legs else None
    if first is None or first.run is None or first.run.goal is None:
        raise NodeFailed("no executed first leg: the winches' lengths are unknown")
    params = story.parameters
    args = ["-m", "cdh_planner.ros.execution.simulated_controller", *robot.winch_names,
            "--action", params["execution.controller_action"],
            "--joint-states", params["execution.joint_states_topic"],
            "--robot", robot.source,     # the simulated robot: MuJoCo, elastic cables
            "--initial", *(repr(float(x)) for x in first.run.goal)]
    log = demo.out_dir / CONTROLLER_LOG
    out = story.stack.enter_context(open(log, "w"))
    process = subprocess.Popen([sys.executable, *args], env=isolated_env(story.domain),
                               stdout=out, stderr=subprocess.STDOUT)
    story.stack.callback(stop_process, process)
    print(f"$ python {' '.join(args)}")
    print(f"  (a simulated ros2_control JointTrajectoryController driving the simulated robot "
          f"(MuJoCo: the platform on elastic cables, 1 kHz): it checks goals as the Jazzy "
          f"controller does and publishes the winches' JointState with the measured tensions "
          f"in effort; log {log})")
    client.node.create_subscription(JointState, params["execution.joint_states_topic"],
                                    lambda msg: story.joint_states.append(
                                        (time.monotonic(), msg)), 10)
    if not client.spin_until(lambda: story.joint_states or process.poll() is not None,
                             CONTROLLER_READY_S) or process.poll() is not None:
        raise NodeFailed(f"the simulated controller did not start (see {log})")
    client.spin(0.5)   # the node hears the joint states too
    print(f"  joint states on {params['execution.joint_states_topic']}: "
          + " ".join(f"{x:.4f}" for x in _measured_lengths(story.joint_states[-1][1],
                                                            robot.winch_names)) + " m")
    change = {"execution.mode": "follow_joint_trajectory"}
    results = client.set_parameters(change)
    print(f"set execution.mode follow_joint_trajectory: "
          + ("done" if results == [(True, "")] else f"REFUSED {results}"))
    if results != [(True, "")]:
        raise NodeFailed(f"the node refused {change}: {results}")


def leg_q2_q3(demo):
    """Plan q_2 -> q_3 from the measured pose; execute through the controller."""
    _leg(demo, *LEGS[1], current_start=True)


def replay(demo):
    """Republish the recorded cable commands; re-send the recorded requests to a fresh node."""
    from ...ros import messages as M
    from ...ros.interface import CABLE_COMMAND
    from ...ros.replay import read_records
    story, client = demo.ros, demo.ros.client
    planned = [leg for leg in story.legs if leg.answer is not None]
    if not planned:
        print("nothing recorded to replay")
        return
    story.run_file = planned[0].answer.values.get("log_file", "")
    if not story.run_file:
        demo.differs.append("the node recorded nothing (log_file empty)")
        return
    print(f"run file: {story.run_file}")
    # a fresh node for the recorded requests, starting while the commands are republished
    fresh_args = _node_args(demo, "log_enabled:=false")
    fresh_domain, fresh, _ = _spawn_node(demo, story.stack, fresh_args, FRESH_NODE_LOG)
    # republish the recorded commands at REPLAY_RATE and compare with the originals
    topic = client.topic(CABLE_COMMAND)
    recorded = [rec for rec in read_records(story.run_file) if rec.topic == topic]
    first = len(client.commands)
    args = ["replay", story.run_file, "--commands", "--rate", f"{REPLAY_RATE:g}", "--topics", topic,
            "--delay", "10"]
    print(f"$ cdh-planner {' '.join(args)}")
    proc = subprocess.Popen(_cli(*args), env=isolated_env(story.domain), stdout=subprocess.PIPE,
                            stderr=subprocess.STDOUT, text=True)
    deadline = time.monotonic() + 300
    while proc.poll() is None and time.monotonic() < deadline:
        client.spin(0.05)
    client.spin(0.3)
    for line in proc.stdout.read().splitlines():
        if line.startswith("republished"):
            print(f"  {line}")
    got = [M.winch_command_values(m) for m in client.commands[first:]]
    original = [M.winch_command_values(m) for leg in story.legs if leg.run for m in leg.run.commands]
    same = len(got) == len(original) and all(
        a[0] == b[0] and np.array_equal(a[1], b[1]) for a, b in zip(got, original))
    span = (recorded[-1].log_time_ns - recorded[0].log_time_ns) * 1e-9 if recorded else 0.0
    print(f"  received {len(got)} republished commands (recorded {len(recorded)} over "
          f"{span:.2f} s): {'identical to' if same else 'DIFFERENT FROM'} the ones streamed "
          f"live")
    if proc.returncode != 0 or not same:
        demo.differs.append("replay of the recorded cable commands differs from the original")
    # the recorded requests, re-sent to the fresh node
    print(f"$ cdh-planner {' '.join(fresh_args)}")
    print(f"  (a fresh node, ROS_DOMAIN_ID={fresh_domain}: the planner keeps its atlas between "
          f"requests, so the recording replays to the same answers on a node in the state it "
          f"started from)")
    args = ["replay", story.run_file, "--requests", "--tolerance", f"{TOLERANCE:g}",
            "--timeout", f"{NODE_TIMEOUT_S:g}"]
    print(f"$ cdh-planner {' '.join(args)}")
    r = subprocess.run(_cli(*args), env=isolated_env(fresh_domain), capture_output=True,
                       text=True, timeout=300)
    for line in r.stdout.splitlines():
        if line.startswith(("request", "goal")) or "answers match" in line:
            print(f"  {line.strip()}")
    if r.returncode != 0:
        demo.differs.append(f"replay --requests: exit {r.returncode}: "
                            f"{(r.stderr or r.stdout).strip().splitlines()[-1:]}")
    rc = stop_process(fresh)
    print(f"fresh node stopped by SIGINT, exit code {rc}")
    if rc != 0:
        demo.differs.append(f"the fresh node exited with {rc} after SIGINT")


def shutdown(demo):
    """Stop the node with SIGINT; read the run file back with rosbags."""
    from collections import Counter

    from rosbags.highlevel import AnyReader
    story = demo.ros
    t0 = time.perf_counter()
    rc = stop_process(story.process)
    print(f"node stopped by SIGINT in {time.perf_counter() - t0:.2f} s, exit code {rc}")
    story.stack.close()
    if rc != 0:
        demo.differs.append(f"the node exited with {rc} after SIGINT")
    if not story.run_file:
        return
    with AnyReader([Path(story.run_file)]) as reader:
        counts = Counter(c.topic for c, _, _ in reader.messages())
    print(f"{story.run_file}: complete MCAP (rosbags reads it), {sum(counts.values())} "
          f"messages:")
    for topic, n in sorted(counts.items()):
        print(f"  {topic}: {n}")
    demo.files.append(Path(story.run_file))


def ros_pictures(demo):
    """The plans on the C-space; cable lengths and tension envelopes over time."""
    from ...ros import messages as M
    legs = [leg for leg in demo.ros.legs if leg.coords is not None]
    if not legs:
        print("no plans to draw")
        return
    robot, task, spec = demo.robots["robot2"], demo.tasks["robot2"], PICTURES[1]
    marks = {label: paper_pose("robot2", label).coords for label in spec.points}
    leaves = [m.leaves_at for m in demo.motions if m.motion.interpolation == "task"
              and (m.motion.robot, m.motion.start, m.motion.goal) == ("robot2", *spec.segment)]
    path = demo.out_dir / PLANS_PICTURE
    plot_paths(robot, SliceView(task=task, axes=spec.axes, ranges=spec.ranges),
               {f"planned {_plain(leg.start)} -> {_plain(leg.goal)} ({len(leg.coords)} "
                f"waypoints)": _off_pole(leg.coords) for leg in legs}, path,
               markers=[Marker(label, *c) for label, c in marks.items()],
               segment=SegmentOverlay(*(marks[label] for label in spec.segment), *leaves[:1]),
               periodic=task.periodic,
               title="Robot 2, sphere task: paths planned by the ROS node (green: wrench-feasible)")
    demo.files.append(path)
    print(f"wrote {path}")
    executed = {}
    for leg in legs:
        if leg.run is not None and leg.run.envelope is not None:
            t, lengths = M.trajectory_arrays(leg.run.trajectory)
            tensions = None
            if leg.run.commands:
                stamps, done = leg.run.values()
                how = "streamed commands"
            elif leg.measured:
                stamps = np.array([arrived for arrived, _ in leg.measured])
                done = np.array([_measured_lengths(m, robot.winch_names)
                                 for _, m in leg.measured])
                how = "measured joint states, from the first motion"
                tensions = _measured_tensions(leg.measured, robot.winch_names)
            else:
                continue
            executed[f"{_plain(leg.start)} -> {_plain(leg.goal)}"] = ExecutedMotion(
                t, lengths, M.envelope_from_msg(leg.run.envelope), stamps - stamps[:1], done,
                how, tensions)
    path = demo.out_dir / EXECUTION_PICTURE
    plot_execution(robot, executed, path)
    demo.files.append(path)
    print(f"wrote {path}")
    print()
    table(["motion", "waypoints", "planning (s)", "charts", "path (m)", "duration (s)",
           "least tension margin (N)", "between waypoints", "executed"],
          [[f"{leg.start} -> {leg.goal}", str(len(leg.coords)),
            f"{leg.answer.number('planning_time_s'):.2f}", leg.answer.values["charts"],
            f"{leg.answer.number('path_length_m'):.4f}", f"{leg.answer.number('duration_s'):.2f}",
            f"{leg.answer.number('min_tension_margin_n'):.3f}", "safe" if leg.safe else "UNSAFE",
            _executed(leg)] for leg in legs])


def _executed(leg):
    """How a leg was executed, for the summary: streamed, or by the controller."""
    if leg.run is None or not leg.run.accepted:
        return "no"
    how = f"{len(leg.run.commands)}_commands" if leg.run.commands else "controller"
    return f"{how}:{leg.run.outcome or 'no_result'}"


def _plain(label):
    return label.replace("_", "")


def _off_pole(coords):
    """Sphere-task coordinates with alpha1, undefined at the pole (alpha2 = pi/2), taken
    at a pole point from its next point off the pole."""
    a1, a2 = coords[:, 0].copy(), coords[:, 1]
    pole = np.abs(a2 - math.pi / 2) < 1e-9
    if pole.any() and not pole.all():
        off = np.flatnonzero(~pole)
        a1[pole] = a1[off[np.clip(np.searchsorted(off, np.flatnonzero(pole)), 0, off.size - 1)]]
    return np.column_stack([a1, a2])


def _guarded(step, needs_node=True):
    """Run ``step`` unless an earlier ROS step failed; a failure (node gone, no answer) is
    a line in demo.differs, and the node is stopped, never a traceback."""

    def run(demo):
        from ...ros.client import ClientError
        if needs_node and (demo.ros is None or demo.ros.failed):
            print("skipped: the node is not running (see above)")
            return
        try:
            step(demo)
        except (ClientError, NodeFailed) as exc:
            print(f"FAILED: {exc}")
            demo.differs.append(f"ROS step {step.__name__}: {exc}")
            if demo.ros is not None:
                demo.ros.failed = True
                demo.ros.stack.close()
    run.__name__, run.__doc__ = step.__name__, step.__doc__
    return run


STEPS = [
    Step("node", "The ROS 2 node (Robot 2, sphere task)", _guarded(start_node, False)),
    Step("q1-q2", "Task sequencer: plan q_1 -> q_2 through the action, stream it",
         _guarded(leg_q1_q2)),
    Step("controller", "ros2_control takes over: the simulated cable controller",
         _guarded(start_controller)),
    Step("q2-q3", "Plan q_2 -> q_3 from the measured pose, execute through the controller",
         _guarded(leg_q2_q3)),
    Step("replay", "Replay the recorded run", _guarded(replay)),
    Step("shutdown", "Shut the node down; the run file", _guarded(shutdown)),
    Step("ros-pictures", "Pictures of the plans and the execution; summary",
         _guarded(ros_pictures)),
]
