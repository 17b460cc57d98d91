"""A simulated cable controller: a FollowJointTrajectory action server standing in for a
ros2_control JointTrajectoryController (ros2_controllers, jazzy branch), with the winches'
JointState, to try the node's execution without hardware (the demo) and to test it
(test/doubles). Two modes, one of them chosen:

- ``--robot ROBOT.yaml``: the simulated robot (``cdh_planner/sim``): the goals, the
  forwarded commands and the streamed setpoints drive MuJoCo's model of the robot file (a
  free platform on elastic, tension-only cables, 1 kHz of simulated time following the wall
  clock times ``--time-scale``); the JointState carries each winch's position (the
  unstretched length it reached) and, in ``effort``, each cable's measured tension (N, a
  load cell). The platform starts at rest at the pose of the ``--initial`` lengths.
- ``--kinematic``: the pure-kinematic double for tests of the goal checks and the command
  plumbing: the joints move exactly as commanded (no physics), ``effort`` empty.

    python -m cdh_planner.ros.execution.simulated_controller JOINT [JOINT ...] (--robot ROBOT.yaml |
        --kinematic) [--action NAME] [--joint-states TOPIC] [--initial X [X ...]]
        [--time-scale K] [--effort-interface] [--allow-nonzero-velocity-at-end]
        [--commands TOPIC] [--stream TOPIC]

With ``--commands TOPIC`` it is also a JointGroupPositionController (forward_command_controller,
jazzy branch): std_msgs/Float64MultiArray on TOPIC (the controller's ``~/commands``) sets the
JOINTs' positions, data[i] to JOINT i. As the real controller's ``update`` does, a command
whose data size is not the number of JOINTs is not applied and reported
({"event": "command_rejected", "reason": its log message}); beyond it, a non-finite value is
rejected too (mock hardware would pass it to the winches). An applied command prints
{"event": "command", "data": [...]}. With ``--stream TOPIC`` it is the custom driver of the
node's ``stream`` mode: sensor_msgs/JointState setpoints on TOPIC (by joint name) are
applied the same way. On the simulated robot a command is reached in a straight line over
the interval since the previous one (a winch does not jump).

Before accepting a goal it checks what the real controller's goal callback checks
(``validate_trajectory_msg``, with the controller's defaults: no partial joint goals, no
integration in goal trajectories) and rejects it (GoalResponse.REJECT) otherwise, printing
one JSON line {"event": "rejected", "reason": ...} with the controller's own log message:

- the joint names: as many as the configured JOINTs, non-empty, each one configured (and,
  beyond the real controller, no name twice: there a duplicate leaves a joint uncommanded);
- at least one point;
- the last point's velocities zero (|v| <= float epsilon) unless
  ``--allow-nonzero-velocity-at-end`` (the controller's allow_nonzero_velocity_at_trajectory_end,
  default false);
- a non-zero header stamp: the trajectory must not end in the past;
- time_from_start strictly increasing (the first point's is not checked);
- per point: positions one per joint name, velocities and accelerations empty or one per
  joint name, effort empty unless ``--effort-interface`` (a controller with an effort
  command interface).

An accepted goal prints {"event": "accepted", "joint_names", "points", "has_effort",
"duration_s"} and preempts a running one (aborted, INVALID_GOAL, as the controller does). It
runs in real time divided by ``--time-scale``: on the simulated robot as a
JointTrajectoryController interpolates (the quintic of positions, velocities and
accelerations; positions alone: straight lines), kinematically with positions interpolated
linearly in time; from where the joints are to the first point, then between points (a non-zero stamp in the future
delays the start), with FollowJointTrajectory feedback at ~17 Hz, and succeeds with
SUCCESSFUL exactly at the last point's positions ({"event": "succeeded"}). A cancel is
accepted: the joints hold where they are and the result is canceled ({"event": "canceled"}).
At SIGINT / SIGTERM a running goal is aborted (as when the controller is deactivated).

sensor_msgs/JointState of the JOINTs' current positions (and measured tensions) is published at 50 Hz on
``--joint-states`` (default /joint_states; reliable, volatile, depth 10 like
joint_state_broadcaster) all the time, from ``--initial`` (one number per joint, default 0),
and once more as a goal ends, just before its result.
Prints "ready" once the action server and the publisher exist; ends cleanly on SIGINT or
SIGTERM.
"""

import argparse
import json
import signal
import sys
import threading
import time

import numpy as np
import rclpy
import rclpy.signals
from control_msgs.action import FollowJointTrajectory
from rclpy.action import ActionServer, CancelResponse, GoalResponse
from rclpy.callback_groups import ReentrantCallbackGroup
from rclpy.executors import ExternalShutdownException, MultiThreadedExecutor
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray
from trajectory_msgs.msg import JointTrajectoryPoint

from ..interface import ACTION_QOS

NODE = "simulated_cable_controller"
PERIOD_S = 0.02          # 50 Hz: joint states and the interpolation step
FEEDBACK_EVERY = 3       # feedback every 3rd step, ~17 Hz (the controller's
                         # action_monitor_rate defaults to 20 Hz)
FLOAT_EPSILON = float(np.finfo(np.float32).eps)   # the controller's zero velocity
JOINT_STATE_QOS = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE,
                             durability=DurabilityPolicy.VOLATILE)
Result = FollowJointTrajectory.Result


_SAYING = threading.Lock()


def say(event, **fields):
    """One JSON event per stdout line: whole, under a lock (print writes the text and its
    newline apart, and executor threads interleaved two events on one line)."""
    line = json.dumps({"event": event, **fields}) + "\n"
    with _SAYING:
        sys.stdout.write(line)
        sys.stdout.flush()


def seconds(duration):
    return duration.sec + duration.nanosec * 1e-9


def rejection(trajectory, joints, now_s, effort_interface=False, nonzero_end_velocity=False):
    """None if the real controller would accept ``trajectory``, else its log message."""
    names = list(trajectory.joint_names)
    if len(names) != len(joints):
        return "Joints on incoming trajectory don't match the controller joints."
    if not names:
        return "Empty joint names on incoming trajectory."
    if not trajectory.points:
        return "Empty trajectory received."
    for name in names:
        if name not in joints:
            return f"Incoming joint {name} doesn't match the controller's joints."
    for name in names:
        if names.count(name) > 1:
            return f"Incoming joint {name} is named more than once."   # the double's own check
    if not nonzero_end_velocity:
        for name, v in zip(names, trajectory.points[-1].velocities):
            if abs(v) > FLOAT_EPSILON:
                return f"Velocity of last trajectory point of joint {name} is not zero: {v:.15f}"
    start_s = seconds(trajectory.header.stamp)
    if start_s != 0.0:
        end_s = start_s + seconds(trajectory.points[-1].time_from_start)
        if end_s < now_s:
            return (f"Received trajectory with non-zero start time ({start_s:f}) that ends in "
                    f"the past ({end_s:f})")
    previous = 0.0
    for i, point in enumerate(trajectory.points):
        t = seconds(point.time_from_start)
        if i > 0 and t <= previous:
            return (f"Time between points {i - 1} and {i} is not strictly increasing, it is "
                    f"{previous:f} and {t:f} respectively")
        previous = t
        for field, allow_empty in (("positions", False), ("velocities", True),
                                   ("accelerations", True)):
            values = getattr(point, field)
            if not (allow_empty and len(values) == 0) and len(values) != len(names):
                return (f"Mismatch between joint_names size ({len(names)}) and {field} "
                        f"({len(values)}) at point #{i}.")
        if not effort_interface and len(point.effort) > 0:
            return ("Trajectories with effort fields are only supported for controllers "
                    "using the 'effort' command interface.")
    return None


class SimulatedController:
    def __init__(self, node, args):
        self.node = node
        self.joints = list(args.joints)
        self.args = args
        self.lock = threading.Lock()
        self.positions = np.array(args.initial, dtype=float)
        self.live = None             # the simulated robot (sim.live.LivePlant), or kinematic
        if args.robot:
            from ...model.robot import load_robot
            from ...sim.live import LivePlant
            robot = load_robot(args.robot)
            if list(robot.winch_names) != self.joints:
                raise SystemExit(f"--robot: the robot's winch names {list(robot.winch_names)} "
                                 f"are not the JOINTs {self.joints}")
            self.live = LivePlant(robot, self.positions, args.time_scale)
            self.live.start()
        self.active = None           # the goal handle being executed
        self.stopping = threading.Event()   # set at SIGINT / SIGTERM: running goals abort
        group = ReentrantCallbackGroup()
        self.publisher = node.create_publisher(JointState, args.joint_states, JOINT_STATE_QOS)
        node.create_timer(PERIOD_S, self.publish_state, callback_group=group)
        self.server = ActionServer(
            node, FollowJointTrajectory, args.action, execute_callback=self.execute,
            goal_callback=self.goal_received, handle_accepted_callback=self.goal_accepted,
            cancel_callback=lambda handle: CancelResponse.ACCEPT, callback_group=group,
            **ACTION_QOS)
        if args.commands:   # the controller's subscription: rclcpp::SystemDefaultsQoS
            node.create_subscription(Float64MultiArray, args.commands, self.command, 10,
                                     callback_group=group)
        if args.stream:     # a custom driver of the node's stream mode
            node.create_subscription(JointState, args.stream, self.setpoint, 10,
                                     callback_group=group)

    def setpoint(self, msg):
        """A streamed JointState setpoint: the JOINTs' positions by name."""
        names = list(msg.name)
        if sorted(names) != sorted(self.joints) or len(msg.position) != len(names):
            say("command_rejected", reason=f"setpoint names {names} are not the joints")
            return
        self.apply([msg.position[names.index(j)] for j in self.joints])

    def command(self, msg):
        """A JointGroupPositionController's update with this command."""
        data = list(msg.data)
        if len(data) != len(self.joints):
            say("command_rejected", reason=f"command size ({len(data)}) does not match "
                                           f"number of interfaces ({len(self.joints)})")
            return
        if not np.all(np.isfinite(data)):
            say("command_rejected", reason=f"non-finite command {data}")
            return
        self.apply(data)
        say("command", data=data)

    def apply(self, data):
        """Move the joints to ``data`` (one position per JOINT)."""
        if self.live is not None:
            self.live.setpoint(np.array(data, dtype=float))
            return
        with self.lock:
            self.positions = np.array(data, dtype=float)

    def now_s(self):
        return self.node.get_clock().now().nanoseconds * 1e-9

    def publish_state(self):
        msg = JointState(name=self.joints)
        msg.header.stamp = self.node.get_clock().now().to_msg()
        if self.live is not None:
            _, positions, tensions, _, _ = self.live.state()
            msg.position, msg.effort = positions.tolist(), tensions.tolist()
        else:
            with self.lock:
                msg.position = self.positions.tolist()
        self.publisher.publish(msg)

    def goal_received(self, goal):
        reason = rejection(goal.trajectory, self.joints, self.now_s(),
                           self.args.effort_interface, self.args.allow_nonzero_velocity_at_end)
        if reason is not None:
            say("rejected", reason=reason)
            return GoalResponse.REJECT
        return GoalResponse.ACCEPT

    def goal_accepted(self, handle):
        trajectory = handle.request.trajectory
        say("accepted", joint_names=list(trajectory.joint_names), points=len(trajectory.points),
            has_effort=any(len(p.effort) > 0 for p in trajectory.points),
            duration_s=seconds(trajectory.points[-1].time_from_start))
        with self.lock:
            previous, self.active = self.active, handle
        if previous is not None:
            previous.preempted = True    # its execute loop aborts it (INVALID_GOAL)
        handle.execute()

    def execute(self, handle):
        if self.live is not None:
            return self.execute_simulated(handle)
        trajectory = handle.request.trajectory
        order = [list(trajectory.joint_names).index(j) for j in self.joints]
        times = np.array([seconds(p.time_from_start) for p in trajectory.points])
        points = np.array([[p.positions[k] for k in order] for p in trajectory.points])
        with self.lock:
            start = self.positions.copy()
        # from where the joints are to the first point (at its time), then point to point
        if times[0] > 0:
            times, points = np.concatenate([[0.0], times]), np.vstack([start, points])
        stamp_s = seconds(trajectory.header.stamp)
        t0 = time.monotonic() + (max(0.0, stamp_s - self.now_s()) if stamp_s else 0.0)
        scale = self.args.time_scale
        step = 0
        while True:
            ended = self._ended(handle)
            if ended is not None:
                return ended
            t = max(0.0, (time.monotonic() - t0) * scale)
            finished = t >= times[-1]
            desired = points[-1] if finished else np.array(
                [np.interp(t, times, points[:, j]) for j in range(len(self.joints))])
            with self.lock:
                if self.active is handle:
                    self.positions = desired.copy()
            if step % FEEDBACK_EVERY == 0:
                self.feedback(handle, desired)
            step += 1
            if finished:
                # the state where the goal ended goes out before the result, as a real
                # controller's state is at the goal when it reports success: a client
                # that reads the joint states on the result then sees where it ended
                return self._succeeded(handle, desired)
            time.sleep(PERIOD_S)

    def execute_simulated(self, handle):
        """A goal on the simulated robot: the trajectory handed to the plant, then watched
        (preemption, shutdown, cancel) until the plant's clock passes its end."""
        trajectory = handle.request.trajectory
        order = [list(trajectory.joint_names).index(j) for j in self.joints]
        times = np.array([seconds(p.time_from_start) for p in trajectory.points])
        L, V, A = (None if any(len(getattr(p, f)) == 0 for p in trajectory.points) else
                   np.array([[getattr(p, f)[k] for k in order] for p in trajectory.points])
                   for f in ("positions", "velocities", "accelerations"))
        stamp_s = seconds(trajectory.header.stamp)
        delay = max(0.0, stamp_s - self.now_s()) * self.args.time_scale if stamp_s else 0.0
        _, end = self.live.follow(times + delay, L, V, A if V is not None else None)
        step = 0
        while True:
            ended = self._ended(handle)
            if ended is not None:
                self.live.hold()
                return ended
            now, positions, _, _, _ = self.live.state()
            if step % FEEDBACK_EVERY == 0:
                self.feedback(handle, self.live.desired(), positions)
            step += 1
            if now >= end:
                return self._succeeded(handle, positions)
            time.sleep(PERIOD_S)

    def _succeeded(self, handle, positions):
        """The goal's success: the state where it ended goes out first, then the result."""
        self.publish_state()
        handle.succeed()
        self.release(handle)
        say("succeeded", positions=positions.tolist())
        return Result(error_code=Result.SUCCESSFUL, error_string="Goal successfully reached!")

    def _ended(self, handle):
        """The Result of a goal that ends otherwise than by reaching its end (preempted,
        shutting down, canceled), or None."""
        if getattr(handle, "preempted", False):
            self.publish_state()
            handle.abort()
            say("aborted", reason="preempted")
            return Result(error_code=Result.INVALID_GOAL,
                          error_string="Current goal preempted by new incoming action.")
        if self.stopping.is_set():
            self.publish_state()
            handle.abort()
            self.release(handle)
            say("aborted", reason="shutting down")
            return Result(error_code=Result.INVALID_GOAL,
                          error_string="Current goal cancelled during deactivate transition.")
        if handle.is_cancel_requested:
            self.publish_state()
            handle.canceled()
            self.release(handle)
            say("canceled")
            return Result()
        return None

    def feedback(self, handle, desired, actual=None):
        msg = FollowJointTrajectory.Feedback(joint_names=self.joints)
        msg.header.stamp = self.node.get_clock().now().to_msg()
        msg.desired = JointTrajectoryPoint(positions=desired.tolist())
        actual = desired if actual is None else actual
        msg.actual = JointTrajectoryPoint(positions=list(map(float, actual)))
        msg.error = JointTrajectoryPoint(positions=list(map(float, np.subtract(desired, actual))))
        handle.publish_feedback(msg)

    def release(self, handle):
        with self.lock:
            if self.active is handle:
                self.active = None


def parse(argv):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("joints", nargs="+", help="the controller's joints")
    parser.add_argument("--action", default="/cable_controller/follow_joint_trajectory")
    parser.add_argument("--joint-states", default="/joint_states")
    parser.add_argument("--initial", type=float, nargs="+", default=None,
                        help="initial positions, one per joint (default 0)")
    parser.add_argument("--time-scale", type=float, default=1.0,
                        help="run trajectories this many times faster than real time")
    parser.add_argument("--effort-interface", action="store_true")
    parser.add_argument("--allow-nonzero-velocity-at-end", action="store_true")
    parser.add_argument("--commands", default="",
                        help="also a JointGroupPositionController: its ~/commands topic")
    parser.add_argument("--stream", default="",
                        help="also the stream mode's driver: its JointState setpoint topic")
    mode = parser.add_mutually_exclusive_group(required=True)
    mode.add_argument("--robot", default="", metavar="ROBOT.yaml",
                      help="the simulated robot (MuJoCo) of this robot file")
    mode.add_argument("--kinematic", action="store_true",
                      help="pure-kinematic: the joints move exactly as commanded (tests)")
    args = parser.parse_args(argv)
    if args.initial is None:
        args.initial = [0.0] * len(args.joints)
    if len(args.initial) != len(args.joints):
        parser.error(f"--initial: {len(args.joints)} numbers expected")
    if not args.time_scale > 0:
        parser.error("--time-scale must be > 0")
    return args


def main(argv=None):
    args = parse(sys.argv[1:] if argv is None else argv)
    # our own handlers: rclpy's SIGTERM handler does not wake a waiting executor
    rclpy.init(signal_handler_options=rclpy.signals.SignalHandlerOptions.NO)
    node = rclpy.create_node(NODE)
    double = SimulatedController(node, args)
    executor = MultiThreadedExecutor(num_threads=4)
    executor.add_node(node)
    stop = threading.Event()
    for signum in (signal.SIGINT, signal.SIGTERM):
        signal.signal(signum, lambda *_: stop.set())
    spinner = threading.Thread(target=_spin, args=(executor, stop), daemon=True)
    spinner.start()
    print("ready", flush=True)
    while not stop.wait(0.5):
        pass
    double.stopping.set()
    time.sleep(2 * PERIOD_S)          # running goals see it and abort
    if double.live is not None:
        double.live.stop()
    executor.shutdown(timeout_sec=2.0)
    spinner.join(timeout=5.0)
    double.server.destroy()
    node.destroy_node()
    rclpy.try_shutdown()
    return 0


def _spin(executor, stop):
    try:
        executor.spin()
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        stop.set()


if __name__ == "__main__":
    sys.exit(main())
