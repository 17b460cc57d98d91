"""The project's ROS 2 interfaces (interfaces/), as `make venv` builds them into the venv:
the generated Python types import, their messages round-trip through rclpy's serialization,
and a PlanPath action works over real DDS between two processes (goal, feedback, result,
cancel) against a test double server (test/doubles/plan_path_server.py) in a ROS domain of
its own. A colcon build of the workspace is in test_colcon_build.py (slow)."""

import subprocess
import sys
import time

import pytest
from rclpy.serialization import deserialize_message, serialize_message

from conftest import REPO
from ros_harness import claimed_domain, isolated_env, stop_process

SERVER = REPO / "test" / "doubles" / "plan_path_server.py"
ACTION = "/plan_path_double/plan_path"
WINCHES = [f"winch_{i + 1}" for i in range(6)]


def test_generated_types_import_from_the_venv():
    from cdh_planner_interfaces.action import PlanPath
    from cdh_planner_interfaces.msg import TensionEnvelope, TensionEnvelopePoint
    from control_msgs.action import FollowJointTrajectory
    from control_msgs.msg import JointComponentTolerance, JointTolerance

    for t in (PlanPath.Goal, PlanPath.Result, PlanPath.Feedback, TensionEnvelope,
              TensionEnvelopePoint, FollowJointTrajectory.Goal, JointTolerance,
              JointComponentTolerance):
        assert t.__module__.split(".")[0] in ("cdh_planner_interfaces", "control_msgs")
        t()   # the C type support loads (it is imported on first construction)
    assert set(PlanPath.Goal.get_fields_and_field_types()) == {
        "start", "goal", "use_current_start", "strategy", "timeout_s"}
    assert set(PlanPath.Feedback.get_fields_and_field_types()) == {"charts", "time_s", "best_h"}
    assert PlanPath.Result.get_fields_and_field_types() == {
        "error_code": "int32", "error_msg": "string", "path": "nav_msgs/Path",
        "cable_trajectory": "trajectory_msgs/JointTrajectory",
        "tension_envelope": "cdh_planner_interfaces/TensionEnvelope",
        "planning_time_s": "double", "charts": "int32", "min_margin": "double",
        "scene_version": "uint64"}


def test_error_codes_are_nav2s_where_they_fit_and_the_planners_own_beyond():
    from cdh_planner_interfaces.action import PlanPath
    R = PlanPath.Result
    # nav2_msgs/action/ComputePathToPose (Jazzy)
    nav2 = {"NONE": 0, "UNKNOWN": 200, "INVALID_PLANNER": 201, "TF_ERROR": 202,
            "START_OUTSIDE_MAP": 203, "GOAL_OUTSIDE_MAP": 204, "START_OCCUPIED": 205,
            "GOAL_OCCUPIED": 206, "TIMEOUT": 207, "NO_VALID_PATH": 208}
    assert {k: getattr(R, k) for k in nav2} == nav2
    own = {k: getattr(R, k) for k in ("CANCELED", "BUSY", "INVALID_REQUEST", "NO_CURRENT_STATE",
                                      "OUTPUT_LIMIT")}
    assert all(v >= 290 for v in own.values()) and len(set(own.values())) == len(own)
    from cdh_planner.ros.msgs import messages as M
    assert (M.NONE, M.UNKNOWN, M.TF_ERROR, M.TIMEOUT, M.NO_VALID_PATH) == (
        R.NONE, R.UNKNOWN, R.TF_ERROR, R.TIMEOUT, R.NO_VALID_PATH)


def _envelope(n_points=3):
    from builtin_interfaces.msg import Duration
    from cdh_planner_interfaces.msg import TensionEnvelope, TensionEnvelopePoint
    env = TensionEnvelope(winch_names=WINCHES)
    env.header.frame_id = "cdh_base"
    env.header.stamp.sec, env.header.stamp.nanosec = 12, 345
    for k in range(n_points):
        env.points.append(TensionEnvelopePoint(
            time_from_start=Duration(sec=k, nanosec=250_000_000),
            tension_min=[k + 0.1 * i for i in range(6)],
            tension_nominal=[k + 0.1 * i + 1.0 / 3.0 for i in range(6)],
            tension_max=[k + 0.1 * i + 2.0 for i in range(6)]))
    return env


def test_tension_envelope_indexes_waypoint_then_cable_and_round_trips():
    from cdh_planner_interfaces.msg import TensionEnvelope
    env = _envelope()
    back = deserialize_message(serialize_message(env), TensionEnvelope)
    assert back == env
    assert back.points[2].tension_nominal[4] == 2 + 0.4 + 1.0 / 3.0   # waypoint 2, cable 4
    assert back.points[1].time_from_start.sec == 1
    assert list(back.winch_names) == WINCHES


def test_plan_path_and_follow_joint_trajectory_messages_round_trip():
    from builtin_interfaces.msg import Duration
    from cdh_planner_interfaces.action import PlanPath
    from control_msgs.action import FollowJointTrajectory
    from control_msgs.msg import JointComponentTolerance, JointTolerance
    from geometry_msgs.msg import PoseStamped
    from trajectory_msgs.msg import JointTrajectoryPoint

    goal = PlanPath.Goal(use_current_start=True, strategy="astar", timeout_s=2.5)
    goal.goal.header.frame_id = "cdh_base"
    goal.goal.pose.position.z = 0.306
    goal.goal.pose.orientation.w = 1.0
    result = PlanPath.Result(error_code=PlanPath.Result.CANCELED, error_msg="canceled",
                             tension_envelope=_envelope(), planning_time_s=0.125, charts=17,
                             min_margin=0.03125)
    result.path.poses = [PoseStamped(), goal.goal]
    result.cable_trajectory.joint_names = WINCHES
    result.cable_trajectory.points = [JointTrajectoryPoint(positions=[0.5] * 6,
                                                           time_from_start=Duration(sec=1))]
    feedback = PlanPath.Feedback(charts=3, time_s=0.5, best_h=0.75)
    fjt = FollowJointTrajectory.Goal(goal_time_tolerance=Duration(nanosec=500_000_000))
    fjt.trajectory.joint_names = WINCHES
    fjt.trajectory.points = result.cable_trajectory.points
    fjt.path_tolerance = [JointTolerance(name=w, position=0.01) for w in WINCHES]
    fjt.component_goal_tolerance = [JointComponentTolerance(
        joint_name="w", component=JointComponentTolerance.ROTATION, position=0.1)]
    fjt_result = FollowJointTrajectory.Result(
        error_code=FollowJointTrajectory.Result.INVALID_JOINTS, error_string="no effort")
    for msg in (goal, result, feedback, fjt, fjt_result):
        assert deserialize_message(serialize_message(msg), type(msg)) == msg


def test_obstacle_scene_messages_round_trip_and_use_the_standard_shapes():
    """Obstacle is moveit_msgs/CollisionObject's applicable subset: an id, ADD / REMOVE, a
    shape_msgs SolidPrimitive or Mesh, a geometry_msgs Pose; the scene service answers a
    Scene with its version."""
    from cdh_planner_interfaces.msg import Obstacle, ObstacleArray, Scene
    from cdh_planner_interfaces.srv import GetScene
    from geometry_msgs.msg import Point
    from shape_msgs.msg import MeshTriangle, SolidPrimitive

    assert (Obstacle.ADD, Obstacle.REMOVE) == (0, 1)
    assert Obstacle.get_fields_and_field_types() == {
        "id": "string", "operation": "uint8", "primitive": "shape_msgs/SolidPrimitive",
        "mesh": "shape_msgs/Mesh", "pose": "geometry_msgs/Pose"}
    ball = Obstacle(id="ball", operation=Obstacle.ADD,
                    primitive=SolidPrimitive(type=SolidPrimitive.SPHERE, dimensions=[0.02]))
    ball.pose.position.z, ball.pose.orientation.w = 0.2, 1.0
    tet = Obstacle(id="tet")
    tet.mesh.vertices = [Point(x=0.0), Point(x=0.1), Point(y=0.1), Point(z=0.1)]
    tet.mesh.triangles = [MeshTriangle(vertex_indices=[0, 1, 2])]
    array = ObstacleArray(obstacles=[ball, tet, Obstacle(id="old", operation=Obstacle.REMOVE)])
    array.header.frame_id = "cdh_base"
    scene = Scene(version=3, checked=True, cable_radius=0.001, obstacles=[ball, tet],
                  platform=[Obstacle(id="platform")])
    for msg in (array, scene, GetScene.Response(scene=scene)):
        assert deserialize_message(serialize_message(msg), type(msg)) == msg


@pytest.fixture
def plan_path_server(tmp_path):
    """The test double PlanPath server in its own process and ROS domain: (domain, process)."""
    with claimed_domain() as domain:
        out = open(tmp_path / "server.log", "w+")
        proc = subprocess.Popen([sys.executable, str(SERVER)], env=isolated_env(domain),
                                stdout=out, stderr=subprocess.STDOUT, cwd=REPO)
        try:
            yield domain, proc
        finally:
            rc = stop_process(proc)
            out.seek(0)
            log = out.read()
            out.close()
            assert rc in (0, -2), f"server exit code {rc}:\n{log}"
            assert "Traceback" not in log, log


class ActionCaller:
    """An rclpy ActionClient for PlanPath in this process, in its own rclpy context."""

    def __init__(self, domain):
        import rclpy
        from cdh_planner.ros.actions import RaceFreeActionClient
        from rclpy.executors import SingleThreadedExecutor
        from cdh_planner_interfaces.action import PlanPath
        self.context = rclpy.Context()
        rclpy.init(context=self.context, domain_id=domain)
        self.node = rclpy.create_node("plan_path_caller", context=self.context)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        self.client = RaceFreeActionClient(self.node, PlanPath, ACTION)
        self.feedback = []

    def close(self):
        self.client.destroy()
        self.executor.shutdown()
        self.node.destroy_node()
        self.context.try_shutdown()

    def spin_until(self, done, timeout_s):
        """spin_once until ``done()``; False on timeout."""
        end = time.monotonic() + timeout_s
        while not done():
            if time.monotonic() > end:
                return False
            self.executor.spin_once(timeout_sec=0.01)
        return True

    def wait_for_server(self, timeout_s=20.0):
        return self.spin_until(self.client.server_is_ready, timeout_s)

    def send(self, goal, timeout_s=60.0):
        """The goal handle of an accepted or rejected ``goal``."""
        future = self.client.send_goal_async(
            goal, feedback_callback=lambda m: self.feedback.append((time.monotonic(), m.feedback)))
        assert self.spin_until(future.done, timeout_s), "no answer to the goal"
        return future.result()

    def result(self, handle, timeout_s=60.0):
        future = handle.get_result_async()
        assert self.spin_until(future.done, timeout_s), "no result"
        return future.result()


def _goal(timeout_s, strategy=""):
    from cdh_planner_interfaces.action import PlanPath
    goal = PlanPath.Goal(strategy=strategy, timeout_s=timeout_s)
    for pose, x in ((goal.start, 0.1), (goal.goal, -0.1)):
        pose.header.frame_id = "cdh_base"
        pose.pose.position.x = x
        pose.pose.orientation.w = 1.0
    return goal


def test_plan_path_action_goal_feedback_result_and_cancel_over_dds(plan_path_server):
    from action_msgs.msg import GoalStatus
    from cdh_planner_interfaces.action import PlanPath
    domain, server = plan_path_server
    caller = ActionCaller(domain)
    try:
        assert caller.wait_for_server(), "the PlanPath server did not appear"

        # a goal: accepted, feedback while it runs, then a result that carries its types
        handle = caller.send(_goal(0.3))
        assert handle.accepted
        answer = caller.result(handle)
        assert answer.status == GoalStatus.STATUS_SUCCEEDED
        r = answer.result
        assert r.error_code == PlanPath.Result.NONE and r.error_msg == ""
        assert [p.pose.position.x for p in r.path.poses] == [0.1, 0.0, -0.1]
        assert list(r.tension_envelope.winch_names) == WINCHES
        assert len(r.tension_envelope.points) == len(r.cable_trajectory.points) == 3
        assert r.tension_envelope.points[2].tension_max[5] == 26.0   # waypoint 2, cable 5
        assert r.tension_envelope.points[1].time_from_start.nanosec == 500_000_000
        # feedback and result travel apart, and rclpy's client drops a goal's feedback that
        # arrives after its result: on a loaded machine the last ones may be missing, so
        # the feedback seen is 1, 2, ... k (none lost between) with k <= the result's count
        assert len(caller.feedback) >= 3
        charts = [f.charts for _, f in caller.feedback]
        assert charts == list(range(1, len(charts) + 1)) and charts[-1] <= r.charts

        # a long goal (300 s: long enough to be caught on a loaded machine), cancelled once
        # its feedback flows: CANCELED, and the last feedback is the one the double counted
        # when it saw the cancel. The waits' limits only bound a hang; the answer's content
        # says it was the cancel
        caller.feedback.clear()
        handle = caller.send(_goal(300.0))
        assert handle.accepted
        assert caller.spin_until(lambda: len(caller.feedback) >= 2, 60.0), "no feedback"
        cancel = handle.cancel_goal_async()
        assert caller.spin_until(cancel.done, 60.0)
        assert len(cancel.result().goals_canceling) == 1
        answer = caller.result(handle)
        assert answer.status == GoalStatus.STATUS_CANCELED
        assert answer.result.error_code == PlanPath.Result.CANCELED
        # the result's feedback count is the last feedback sent: none came after it (those
        # sent just before it may arrive after it, and rclpy's client drops them)
        charts = [f.charts for _, f in caller.feedback]
        assert charts == list(range(1, len(charts) + 1)) and charts[-1] <= answer.result.charts

        # after the cancel, the next goal runs to its result; a bad one is aborted with a code
        answer = caller.result(caller.send(_goal(0.05)))
        assert answer.status == GoalStatus.STATUS_SUCCEEDED
        assert answer.result.error_code == PlanPath.Result.NONE
        answer = caller.result(caller.send(_goal(0.05, strategy="dijkstra")))
        assert answer.status == GoalStatus.STATUS_ABORTED
        assert answer.result.error_code == PlanPath.Result.INVALID_PLANNER
    finally:
        caller.close()
    assert server.poll() is None, "the server died"
