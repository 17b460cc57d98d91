"""The demo's ROS story, as steps appended to ``demo.STEPS``:

5. ``node``: start ``cdh-planner node`` with config/robot2.yaml in a ROS domain of its own
   (discovery on localhost), recording to ``<out>/runs``;
6. ``q1-q2``, 7. ``q2-q3``: a task sequencer's calls: plan over ROS (the paper's Robot 2
   sphere task), check the motion between the planned waypoints densely, execute it,
   following the streamed cable commands to the last waypoint;
8. ``replay``: republish the recorded cable commands (``cdh-planner replay``) and compare
   them with the originals; re-send the recorded requests to a fresh node (same parameters,
   its own domain) and compare the answers. Not to the node that recorded them: the planner
   keeps its atlas between requests, so a node that has already planned may find other
   (equally valid) paths;
9. ``shutdown``: SIGINT, then read the run file back (rosbags, independent of ROS);
10. ``ros-pictures``: the planned paths on the sphere task's C-space, and the cable lengths
   and tension envelopes over time.

Everything shared lives on ``demo.ros`` (a ``NodeStory``). The node is stopped at exit
whatever happens (atexit), so a failing step never leaves it running.
"""

import atexit
import contextlib
import math
import signal
import subprocess
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Optional

import numpy as np


LEGS = (("q_1", "q_2"), ("q_2", "q_3"))
REPLAY_RATE = 4.0
NODE_TIMEOUT_S = 60.0
PLAN_TIMEOUT_S = 120.0
TOLERANCE = 1e-9   # m and rad: a re-sent request must get the same path


class NodeFailed(RuntimeError):
    """The node did not start or stopped answering: the remaining ROS steps are skipped."""


@dataclass
class Leg:
    start: str
    goal: str
    answer: object = None            # client.PlanAnswer
    trajectory: object = None        # trajectory_msgs/JointTrajectory received
    envelope: object = None          # (N, 6, 3) N
    coords: Optional[np.ndarray] = None   # task coordinates of the waypoints
    safe: Optional[bool] = None
    worst_margin: float = math.nan
    commands: list = field(default_factory=list)   # (receive time, JointState)


@dataclass
class NodeStory:
    stack: contextlib.ExitStack
    domain: int
    process: subprocess.Popen
    client: object
    run_dir: Path
    node_log: Path
    legs: list = field(default_factory=list)
    run_file: str = ""
    replay_lines: list = field(default_factory=list)


def _cli(*args):
    return [sys.executable, "-m", "cdh_planner.cli", *args]


def node_command(args):
    """The node's command line (``args`` start with "node")."""
    return _cli(*args)


def _spawn_node(demo, stack, args, log_name):
    """Start ``cdh-planner node ARGS`` in a domain of its own (held by ``stack``, which also
    stops the process); (domain, process, log path)."""
    from ..ros.domains import claimed_domain, isolated_env
    domain = stack.enter_context(claimed_domain())
    node_log = demo.out_dir / log_name
    out = stack.enter_context(open(node_log, "w"))
    process = subprocess.Popen(node_command(args), env=isolated_env(domain), stdout=out,
                               stderr=subprocess.STDOUT)
    stack.callback(_stop_process, process)
    return domain, process, node_log


def start_node(demo):
    """Start the node on Robot 2 and wait for its services."""
    try:
        from ..ros.client import PlannerClient
    except ImportError as exc:
        raise NodeFailed(f"rclpy is not installed here ({exc}): make venv installs the ROS 2 "
                         f"wheels") from None
    stack = contextlib.ExitStack()
    atexit.register(stack.close)
    run_dir = demo.out_dir / "runs"
    run_dir.mkdir(parents=True, exist_ok=True)
    robot_file = demo.config_dir / "robot2.yaml"
    args = ["node", "--ros-args", "--params-file", str(robot_file), "-p", f"log_dir:={run_dir}"]
    t0 = time.perf_counter()
    domain, process, node_log = _spawn_node(demo, stack, args, "node.log")
    client = PlannerClient(domain_id=domain, name="cdh_planner_demo")
    stack.callback(client.close)
    demo.ros = NodeStory(stack=stack, domain=domain, process=process, client=client,
                         run_dir=run_dir, node_log=node_log)
    print(f"$ cdh-planner {' '.join(args)}")
    print(f"  (ROS_DOMAIN_ID={domain}, ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST; node log "
          f"{node_log})")
    end = time.monotonic() + NODE_TIMEOUT_S
    while process.poll() is None and not client.plan_client.service_is_ready() \
            and time.monotonic() < end:
        client.spin(0.1)
    if process.poll() is not None:
        tail = node_log.read_text().strip().splitlines()[-3:]
        raise NodeFailed(f"the node exited with {process.returncode}: " + " | ".join(tail))
    client.wait_for_node(max(1.0, end - time.monotonic()))
    params = client.get_parameters(["base_frame", "task.type", "planner.strategy",
                                    "trajectory.max_cable_speed", "trajectory.max_cable_accel",
                                    "stream_rate_hz"])
    print(f"node /cdh_planner ready in {time.perf_counter() - t0:.1f} s: "
          + ", ".join(f"{k} {v}" for k, v in params.items()))


def _stop_process(process, sig=signal.SIGINT, timeout=15.0):
    if process.poll() is None:
        process.send_signal(sig)
        try:
            process.wait(timeout)
        except subprocess.TimeoutExpired:
            process.kill()
            process.wait()
    return process.returncode


def _leg(demo, start, goal):
    """Plan start -> goal over ROS, check the motion densely, execute it."""
    from sensor_msgs.msg import JointState
    from std_msgs.msg import Float64MultiArray
    from trajectory_msgs.msg import JointTrajectory

    from ..model.pose import tau_from_quaternion
    from ..ros import messages as M
    from ..ros.client import path_duration, path_length, pose_stamped
    from ..ros.node import LATCHED
    from ..trajectory.verify import check_motion

    story, robot = demo.ros, demo.robots["robot2"]
    client, task = story.client, demo.tasks["robot2"]
    leg = Leg(start, goal)
    story.legs.append(leg)
    latched = LATCHED
    if not hasattr(story, "subscribed"):
        story.trajectories, story.envelopes = [], []
        client.node.create_subscription(JointTrajectory, "/cdh_planner/cable_trajectory",
                                        story.trajectories.append, latched)
        client.node.create_subscription(Float64MultiArray, "/cdh_planner/tension_envelope",
                                        story.envelopes.append, latched)
        story.commands = []
        client.node.create_subscription(JointState, "/cdh_planner/cable_command",
                                        lambda m: story.commands.append((time.time(), m)), 1000)
        story.subscribed = True
    poses = {}
    for label in (start, goal):
        p, tau = demo.pose("robot2", label)
        from ..model.pose import quaternion_from_tau
        poses[label] = pose_stamped(list(p) + list(quaternion_from_tau(tau)), "cdh_base")
    print(f"call ~/plan: {start} -> {goal} (poses of the sphere task, m and quaternion in "
          f"cdh_base)")
    leg.answer = answer = client.plan(poses[start], poses[goal], PLAN_TIMEOUT_S)
    v = answer.values
    if not answer.success:
        print(f"  NO PLAN (error code {v.get('error_code')}): {v.get('error_msg')}")
        demo.differs.append(f"robot2 {start} -> {goal} over ROS: no plan "
                            f"({v.get('error_msg')}), expected a path (the paper's Sec. 5.2)")
        return
    n = len(answer.path.poses)
    client.spin_until(lambda: story.trajectories and len(story.trajectories[-1].points) == n
                      and story.envelopes, 5.0)
    leg.trajectory = story.trajectories[-1]
    leg.envelope = M.envelope_from_msg(story.envelopes[-1])
    p = np.array([[q.pose.position.x, q.pose.position.y, q.pose.position.z]
                  for q in answer.path.poses])
    quat = np.array([[q.pose.orientation.x, q.pose.orientation.y, q.pose.orientation.z,
                      q.pose.orientation.w] for q in answer.path.poses])
    leg.coords = task.coords(p, tau_from_quaternion(quat))
    checks = check_motion(robot, p, quat)
    leg.safe = all(c.feasible for c in checks)
    leg.worst_margin = min(c.worst.margin for c in checks)
    print(f"  planned in {answer.number('planning_time_s'):.2f} s ({v['charts']} charts, "
          f"{v['strategy']}): {n} waypoints, path {path_length(answer.path):.4f} m, "
          f"duration {path_duration(answer.path):.2f} s, lowest tension margin "
          f"{answer.number('min_tension_margin_n'):.3f} N")
    print(f"  motion between the waypoints as a controller executes it (position linear, "
          f"orientation slerp), checked densely: "
          + (f"safe, worst margin {leg.worst_margin:+.4f}" if leg.safe else "UNSAFE"))
    if not leg.safe:
        demo.differs.append(f"robot2 {start} -> {goal}: the planned motion leaves C between "
                            f"waypoints")
    # execute, following the stream to its end
    t0 = time.time()
    ok, message = client.execute()
    print(f"call ~/execute: {message}")
    if not ok:
        demo.differs.append(f"robot2 {start} -> {goal}: execute refused: {message}")
        return
    duration = path_duration(answer.path)

    def finished():
        mine = [m for t, m in story.commands if t >= t0]
        return (mine and time.time() - t0 > duration
                and not np.any(np.asarray(mine[-1].velocity)))

    client.spin_until(finished, duration + 5.0)
    leg.commands = [(t, m) for t, m in story.commands if t >= t0]
    _report_stream(demo, leg, duration)


def _report_stream(demo, leg, duration):
    if not leg.commands:
        print("  no ~/cable_command received")
        demo.differs.append(f"robot2 {leg.start} -> {leg.goal}: nothing streamed")
        return
    stamps = np.array([m.header.stamp.sec + 1e-9 * m.header.stamp.nanosec
                       for _, m in leg.commands])
    rate = (len(stamps) - 1) / (stamps[-1] - stamps[0]) if len(stamps) > 1 else 0.0
    last = np.asarray(leg.commands[-1][1].position)
    end = np.asarray(leg.trajectory.points[-1].positions)
    err = float(np.max(np.abs(last - end)))
    print(f"  streamed {len(stamps)} cable commands over {stamps[-1] - stamps[0]:.2f} s "
          f"({rate:.1f} Hz); last = the final waypoint's cable lengths within {err:.1e} m: "
          + " ".join(f"{x:.4f}" for x in last) + " m")
    if err > 1e-9:
        demo.differs.append(f"robot2 {leg.start} -> {leg.goal}: streaming ended {err:.3g} m "
                            f"from the last waypoint")


def leg_q1_q2(demo):
    """Plan q_1 -> q_2 over ROS and execute it."""
    _leg(demo, *LEGS[0])


def leg_q2_q3(demo):
    """Plan q_2 -> q_3 over ROS and execute it."""
    _leg(demo, *LEGS[1])


def replay(demo):
    """Republish the recorded cable commands; re-send the recorded requests to a fresh node."""
    from ..ros.domains import isolated_env
    from ..ros.replay import read_records
    story = demo.ros
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
    robot_file = demo.config_dir / "robot2.yaml"
    fresh_args = ["node", "--ros-args", "--params-file", str(robot_file), "-p",
                  "log_enabled:=false"]
    fresh_domain, fresh, _ = _spawn_node(demo, story.stack, fresh_args, "node_fresh.log")
    env = isolated_env(story.domain)
    # republish the recorded commands at REPLAY_RATE and compare with the originals
    recorded = [rec for rec in read_records(story.run_file)
                if rec.topic == "/cdh_planner/cable_command"]
    client = story.client
    t0 = time.time()
    args = ["replay", story.run_file, "--rate", f"{REPLAY_RATE:g}", "--topics",
            "/cdh_planner/cable_command", "--delay", "10"]
    print(f"$ cdh-planner {' '.join(args)}")
    proc = subprocess.Popen(_cli(*args), env=env, stdout=subprocess.PIPE,
                            stderr=subprocess.STDOUT, text=True)
    deadline = time.monotonic() + 300
    while proc.poll() is None and time.monotonic() < deadline:
        client.spin(0.05)
    client.spin(0.3)
    out = proc.stdout.read()
    for line in out.splitlines():
        if line.startswith("republished"):
            print(f"  {line}")
    got = [m for t, m in story.commands if t >= t0]
    span = (recorded[-1].log_time_ns - recorded[0].log_time_ns) * 1e-9 if recorded else 0.0
    original = [m for leg in story.legs for _, m in leg.commands]
    same = len(got) == len(original) and all(
        a.header.stamp == b.header.stamp and np.array_equal(a.position, b.position)
        for a, b in zip(got, original))
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
        if line.startswith("request") or "answers match" in line:
            print(f"  {line.strip()}")
    if r.returncode != 0:
        demo.differs.append(f"replay --requests: exit {r.returncode}: "
                            f"{(r.stderr or r.stdout).strip().splitlines()[-1:]}")
    rc = _stop_process(fresh)
    print(f"fresh node stopped by SIGINT, exit code {rc}")
    if rc != 0:
        demo.differs.append(f"the fresh node exited with {rc} after SIGINT")


def shutdown(demo):
    """Stop the node with SIGINT; read the run file back with rosbags."""
    from collections import Counter

    from rosbags.highlevel import AnyReader
    story = demo.ros
    t0 = time.perf_counter()
    rc = _stop_process(story.process)
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
    story = demo.ros
    legs = [leg for leg in story.legs if leg.coords is not None]
    if not legs:
        print("no plans to draw")
        return
    path = demo.out_dir / "robot2_plans.png"
    _draw_plans(demo, legs, path)
    demo.files.append(path)
    print(f"wrote {path}")
    path = demo.out_dir / "robot2_execution.png"
    _draw_execution(demo, legs, path)
    demo.files.append(path)
    print(f"wrote {path}")
    rows = [[f"{leg.start} -> {leg.goal}", str(len(leg.answer.path.poses)),
             f"{leg.answer.number('planning_time_s'):.2f}", leg.answer.values["charts"],
             f"{leg.answer.number('path_length_m'):.4f}", f"{leg.answer.number('duration_s'):.2f}",
             f"{leg.answer.number('min_tension_margin_n'):.3f}",
             "safe" if leg.safe else "UNSAFE", str(len(leg.commands))] for leg in legs]
    from .demo_steps import table
    print()
    table(["motion", "waypoints", "planning (s)", "charts", "path (m)", "duration (s)",
            "least tension margin (N)", "between waypoints", "commands streamed"], rows)


def _draw_plans(demo, legs, out):
    import matplotlib.pyplot as plt
    from matplotlib.colors import ListedColormap
    from matplotlib.patches import Patch

    from ..io.plots import CLASS_COLORS, CLASS_LABELS, SliceView, compute_slice
    robot, task = demo.robots["robot2"], demo.tasks["robot2"]
    view = SliceView(task=task, axes=("alpha1", "alpha2"),
                     ranges=((-math.pi, math.pi), (0.0, math.pi / 2)))
    grid = compute_slice(robot, view, 300)
    fig, ax = plt.subplots(figsize=(10, 6), dpi=100, layout="constrained")
    try:
        ax.imshow(grid.classes, origin="lower", extent=(-math.pi, math.pi, 0, math.pi / 2),
                  aspect="auto", cmap=ListedColormap(CLASS_COLORS), vmin=-0.5, vmax=2.5,
                  interpolation="nearest")
        colors = ("black", "#7b2cbf")
        for leg, color in zip(legs, colors):
            a1, a2 = leg.coords[:, 0].copy(), leg.coords[:, 1]
            # alpha1 is undefined at the pole: draw pole points at their neighbour's alpha1
            pole = np.abs(a2 - math.pi / 2) < 1e-9
            if pole.any() and not pole.all():
                idx = np.flatnonzero(~pole)
                a1[pole] = a1[idx[np.clip(np.searchsorted(idx, np.flatnonzero(pole)), 0,
                                          idx.size - 1)]]
            jumps = np.flatnonzero(np.abs(np.diff(a1)) > math.pi)
            a1 = np.insert(a1, jumps + 1, np.nan)
            a2 = np.insert(a2, jumps + 1, np.nan)
            ax.plot(a1, a2, color=color, lw=2, label=f"planned {_plain(leg.start)} -> "
                                                     f"{_plain(leg.goal)} "
                                                     f"({len(leg.coords)} waypoints)")
        q2, q3 = (demo.pose("robot2", q) for q in ("q_2", "q_3"))
        c2, c3 = task.coords(q2[0][None], q2[1][None])[0], task.coords(q3[0][None], q3[1][None])[0]
        ax.plot([c2[0], c3[0]], [c2[1], c3[1]], color="white", lw=1.2, ls="--",
                label="straight q2 -> q3 (leaves C)")
        for label in ("q_1", "q_2", "q_3"):
            p, tau = demo.pose("robot2", label)
            c = task.coords(p[None], tau[None])[0]
            ax.plot(*c, "o", color="white", mec="black", ms=8, clip_on=False)
            ax.annotate(f"${label[0]}_{label[2]}$", c, textcoords="offset points",
                        xytext=(7, -14 if label == "q_1" else 6), fontsize="large")
        ax.set_xlim(-math.pi, math.pi)
        ax.set_ylim(0, math.pi / 2)
        ax.set_xlabel(r"$\alpha_1$ (rad)")
        ax.set_ylabel(r"$\alpha_2$ (rad)")
        ax.set_title("Robot 2, sphere task: paths planned by the ROS node (green: "
                     "wrench-feasible)")
        handles, _ = ax.get_legend_handles_labels()
        handles += [Patch(color=c, label=lbl) for c, lbl in zip(CLASS_COLORS, CLASS_LABELS)]
        ax.legend(handles=handles, loc="lower left", fontsize="small")
        fig.savefig(out)
    finally:
        plt.close(fig)


def _plain(label):
    return label.replace("_", "")


def _draw_execution(demo, legs, out):
    import matplotlib.pyplot as plt
    from ..ros import messages as M
    robot = demo.robots["robot2"]
    fig, (top, bottom) = plt.subplots(2, 1, figsize=(10, 7), dpi=100, sharex=True,
                                      layout="constrained")
    try:
        cmap = plt.get_cmap("tab10")
        offset = 0.0
        for k, leg in enumerate(legs):
            t = np.array([M.duration_s(p.time_from_start) for p in leg.trajectory.points])
            L = np.array([p.positions for p in leg.trajectory.points])
            if leg.commands:
                s = np.array([m.header.stamp.sec + 1e-9 * m.header.stamp.nanosec
                              for _, m in leg.commands])
                C = np.array([m.position for _, m in leg.commands])
                for i in range(6):
                    top.plot(offset + s - s[0], C[:, i], color=cmap(i), lw=1.2,
                             label=robot.winch_names[i] if k == 0 else None)
            for i in range(6):
                top.plot(offset + t, L[:, i], ".", color=cmap(i), ms=3)
                env = leg.envelope
                bottom.fill_between(offset + t, env[:, i, 0], env[:, i, 2], color=cmap(i),
                                    alpha=0.2, lw=0)
                bottom.plot(offset + t, env[:, i, 1], color=cmap(i), lw=1)
            top.axvline(offset, color="grey", lw=0.8, ls=":")
            top.annotate(f"{_plain(leg.start)} -> {_plain(leg.goal)}", (offset, 1), xycoords=("data", "axes fraction"),
                         xytext=(4, -14), textcoords="offset points")
            offset += t[-1] + 0.5
        for y in (robot.length_min.min(), robot.length_max.max()):
            top.axhline(y, color="black", ls="--", lw=0.8)
        for y in (robot.tension_min.min(), robot.tension_max.max()):
            bottom.axhline(y, color="black", ls="--", lw=0.8)
        top.set_ylabel("cable length (m)")
        top.set_title("streamed ~/cable_command (lines) through the trajectory's waypoints "
                      "(dots); dashed: limits")
        top.legend(ncol=6, fontsize="small", loc="lower right")
        bottom.set_ylabel("tension (N)")
        bottom.set_xlabel("time (s)")
        bottom.set_title("tension envelope over the wrench ellipsoid: nominal (line), "
                         "min..max (band); dashed: limits")
        fig.savefig(out)
    finally:
        plt.close(fig)


def _guarded(step, needs_node=True):
    """Run ``step`` unless an earlier ROS step failed; a failure (node gone, no answer) is
    a line in demo.differs, and the node is stopped, never a traceback."""
    from ..ros.client import ClientError

    def run(demo):
        story = getattr(demo, "ros", None)
        if needs_node and (story is None or getattr(story, "failed", False)):
            print("skipped: the node is not running (see above)")
            return
        try:
            step(demo)
        except (ClientError, NodeFailed) as exc:
            print(f"FAILED: {exc}")
            demo.differs.append(f"ROS step {step.__name__}: {exc}")
            story = getattr(demo, "ros", None)
            if story is not None:
                story.failed = True
                story.stack.close()
    run.__name__ = step.__name__
    run.__doc__ = step.__doc__
    return run


def steps():
    """The steps to append to demo.STEPS."""
    from .demo_steps import Step
    return [
        Step("node", "The ROS 2 node (Robot 2, sphere task)", _guarded(start_node, False)),
        Step("q1-q2", "Task sequencer: plan q_1 -> q_2 over ROS, execute", _guarded(leg_q1_q2)),
        Step("q2-q3", "Task sequencer: plan q_2 -> q_3 over ROS, execute", _guarded(leg_q2_q3)),
        Step("replay", "Replay the recorded run", _guarded(replay)),
        Step("shutdown", "Shut the node down; the run file", _guarded(shutdown)),
        Step("ros-pictures", "Pictures of the plans and the execution; summary",
             _guarded(ros_pictures)),
    ]
