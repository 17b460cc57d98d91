"""The physics plant (cdh_planner/sim, ``cdh-planner mjcf`` / ``simulate``): the MJCF of every
shipped robot and scene loads and carries the robot file's values; the load cells read what
the cables apply (against the platform's change of momentum); static holds at planned poses
give the plan's nominal tensions with compensated commands; planned trajectories run within
the limits, and a constant-velocity retiming of the same plan, or an 8-cable plan commanded
by its geometric lengths, does not; bad input is one line, exit 2."""

import json
import math
import subprocess
import sys

import numpy as np
import pytest

mujoco = pytest.importorskip("mujoco")

from conftest import CONFIG, PROBLEMS, REPO  # noqa: E402
from cdh_planner import cli  # noqa: E402
from cdh_planner.wrench import rule_tensions  # noqa: E402
from cdh_planner.model.elastic import unstretched_lengths  # noqa: E402
from cdh_planner.model.kinematics import cable_lengths  # noqa: E402
from cdh_planner.model.pose import rotation_from_quaternion  # noqa: E402
from cdh_planner.model.robot import load_robot  # noqa: E402
from cdh_planner.scene.schema import load_scene  # noqa: E402
from cdh_planner.sim import mjcf as MJ  # noqa: E402
from cdh_planner.sim.commands import Trajectory  # noqa: E402
from cdh_planner.sim.plant import SimulatedRobot  # noqa: E402
from cdh_planner.sim.run import judge, plan_from_waypoints, run_plan  # noqa: E402

ROBOTS = sorted(CONFIG.glob("*.yaml"))
SCENES = sorted((CONFIG / "scenes").glob("*.yaml"))
PLANS = {"robot2": "robot2_q2_q3", "robot2_8": "robot2_8_q2_q3_free_flight",
         "cogiro": None}
# CoGiRo: a free flight across the middle of its workspace, 1.9 m with a tilt and a turn
COGIRO_PROBLEM = """robot: {robot}
task: {{type: free}}
planner: {{radius: 0.5, max_cable_speed: 1.0, max_cable_accel: 2.0}}
start: {{position: [0.0, 0.0, 2.0], tau: [0.0, 0.0, 0.0]}}
goal: {{position: [1.5, 1.0, 2.5], tau: [0.0, 0.2, 0.5]}}
"""
ENVELOPE_TOL = 0.01      # of the tension range
START_S = 0.02           # s: the plans' first acceleration is a step from rest (below)


def _cli(capsys, *argv):
    """(exit code, stdout, stderr lines) of ``cdh-planner ARGV`` in this process."""
    rc = cli.main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return rc, out, [line for line in err.splitlines() if line]


@pytest.fixture(scope="module")
def plans(tmp_path_factory):
    """{robot name: the plan JSON dict of its problem}, planned here by ``cdh-planner plan``."""
    out = {}
    folder = tmp_path_factory.mktemp("plans")
    for name, problem in PLANS.items():
        if problem is None:
            problem_file = folder / f"{name}.yaml"
            problem_file.write_text(COGIRO_PROBLEM.format(robot=CONFIG / f"{name}.yaml"))
        else:
            problem_file = PROBLEMS / f"{problem}.yaml"
        path = folder / f"{name}.json"
        assert cli.main(["plan", str(problem_file), "--json", str(path), "--quiet"]) == 0
        out[name] = (path, json.loads(path.read_text()))
    return out


def compensated(robot, doc):
    """The plan's Plan with compensated commands: the JSON's ``commanded_lengths`` where it
    has them; else computed here from the plan's own numbers, independently of the
    planner's elastic code: the unstretched lengths that carry the tension rule's tensions
    at each planned pose, L0 = L / (1 + t / EA), their rates by central differences over the
    waypoints' times, their accelerations the planned ones scaled by L0 / L."""
    plan = plan_from_waypoints(doc["path"], len(robot.base_anchors))
    if plan.source == "commanded_lengths":
        return plan
    t = rule_tensions(robot, plan.p, rotation_from_quaternion(plan.quaternion))[0]
    L0 = unstretched_lengths(robot, plan.L, t)
    plan.V = np.gradient(L0, plan.t, axis=0, edge_order=2)
    plan.V[[0, -1]] = 0.0
    plan.A = plan.A * L0 / plan.L
    plan.L = L0
    plan.source = "compensated in the test"
    return plan


def constant_velocity(plan):
    """The same waypoints retimed so the fastest cable moves at the plan's own top cable
    speed throughout, positions only: a controller interpolates them in straight lines,
    starting and stopping at that speed (what a kinematic check of speed limits passes)."""
    top = np.max(np.abs(plan.V))
    step = np.max(np.abs(np.diff(plan.L, axis=0)), axis=1)
    plan.t = np.concatenate([[0.0], np.cumsum(step)]) / top
    plan.V = plan.A = None
    return plan


# ----------------------------------------------------------------------------- mjcf

@pytest.mark.parametrize("robot_file", ROBOTS, ids=lambda p: p.stem)
def test_mjcf_of_every_shipped_robot_loads_with_the_robot_files_values(robot_file, tmp_path,
                                                                        capsys):
    out = tmp_path / "robot.xml"
    rc, stdout, err = _cli(capsys, "mjcf", robot_file, "-o", out)
    assert rc == 0 and not err, err
    robot = load_robot(robot_file)
    model = mujoco.MjModel.from_xml_path(str(out))
    data = mujoco.MjData(model)
    m = len(robot.base_anchors)
    assert model.ntendon == model.nu == m
    for name, a, b in zip(robot.winch_names, robot.base_anchors, robot.platform_anchors):
        assert np.array_equal(model.site(f"{name}_base").pos, a)
        assert np.allclose(model.site(f"{name}_platform").pos, b, rtol=0, atol=1e-12)
    body = model.body("platform")
    mass = MJ.load_mass(robot)
    assert body.mass[0] == pytest.approx(mass, rel=1e-12)
    assert np.allclose(body.ipos, robot.load_point, atol=1e-12)
    assert np.allclose(model.opt.gravity * mass, robot.force, rtol=1e-12, atol=1e-12)
    # at the keyframe the tendons are the anchors' distances and k = EA / L there
    mujoco.mj_resetDataKeyframe(model, data, model.key("home").id)
    mujoco.mj_forward(model, data)
    p, q = MJ.home_pose(robot)
    L = cable_lengths(robot, p, rotation_from_quaternion(q))
    assert np.allclose(data.ten_length, L, rtol=0, atol=1e-12)
    k = MJ.cable_stiffness(robot) / L
    assert np.allclose(-model.actuator_gainprm[:, 0], k, rtol=1e-10)
    assert np.allclose(-model.actuator_biasprm[:, 2], MJ.DAMPING_TIME_S * k, rtol=1e-10)
    assert np.all(model.actuator_forcerange[:, 0] == 0) and np.all(model.actuator_gear[:, 0] == -1)
    # the camera: upright (its image's up against gravity) and every base anchor in view
    cam = model.camera("workspace")
    mujoco.mj_forward(model, data)
    Rc = data.cam_xmat[cam.id].reshape(3, 3)
    assert np.dot(Rc[:, 1], -model.opt.gravity) > 0.5 * np.linalg.norm(model.opt.gravity)
    rel = (robot.base_anchors - data.cam_xpos[cam.id]) @ Rc    # camera frame
    half = math.radians(model.cam_fovy[cam.id] / 2)
    assert np.all(rel[:, 2] < 0) and np.all(np.abs(rel[:, 1] / rel[:, 2]) < math.tan(half))


@pytest.mark.parametrize("scene_file", SCENES, ids=lambda p: p.stem)
@pytest.mark.parametrize("robot_name", ["robot2", "robot2_8"])
def test_mjcf_with_every_shipped_scene_has_its_obstacles(scene_file, robot_name, tmp_path,
                                                         capsys):
    out = tmp_path / "scene.xml"
    robot_file = CONFIG / f"{robot_name}.yaml"
    rc, _, err = _cli(capsys, "mjcf", robot_file, "--scene", scene_file, "-o", out)
    assert rc == 0 and not err, err
    model = mujoco.MjModel.from_xml_path(str(out))
    scene = load_scene(scene_file, load_robot(robot_file))
    for o in scene.obstacles:
        geom = model.geom(f"obstacle_{o.id}")
        assert np.allclose(geom.pos, o.position, atol=1e-12)
        assert geom.bodyid[0] == 0                      # static: on the world body
        if o.kind == "sphere":
            assert geom.size[0] == pytest.approx(o.radius)


def test_a_robot_without_stiffness_gets_the_documented_default(tmp_path, capsys):
    text = (CONFIG / "robot2.yaml").read_text()
    rigid = tmp_path / "rigid.yaml"
    rigid.write_text(text.replace("cable_stiffness: 1000.0", "# no stiffness"))
    robot = load_robot(rigid)
    assert robot.cable_stiffness is None
    assert np.allclose(MJ.cable_stiffness(robot), robot.tension_max / MJ.DEFAULT_STRETCH)
    rc, out, _ = _cli(capsys, "mjcf", rigid)
    assert rc == 0 and "robot.cable_stiffness absent" in out


# ----------------------------------------------------------------------------- the plant

def test_load_cells_read_what_the_cables_apply():
    """Against the platform's equations of motion step by step, M dv / dt + c = -J^T t (M the
    mass matrix, c gravity and the velocity terms, J the cables' length Jacobian, all
    MuJoCo's at the step's start): the tensions the load cells report are the forces that
    moved the platform, through taut and slack phases (a fast swing in straight lines)."""
    robot = load_robot(CONFIG / "robot2.yaml")
    plant = SimulatedRobot(robot)
    model, data = plant.model, plant.data
    p, R = np.array([0.0, 0.0, 0.306]), np.eye(3)
    L = cable_lengths(robot, p, R)
    L0 = unstretched_lengths(robot, L, rule_tensions(robot, p[None], R[None])[0][0])
    plant.reset(p, [0, 0, 0, 1], L0)
    times = np.array([0.0, 0.05, 0.1, 0.15, 0.4])
    swing = np.array([0.0, 0.004, -0.004, 0.0, 0.0])[:, None] * np.array([1, -1, 1, -1, 1, -1])
    source = Trajectory(times, L0 + swing)
    worst, slack = 0.0, 0
    M = np.zeros((model.nv, model.nv))
    for k in range(400):
        Lk, rate = source.sample([k * 1e-3])
        plant.command(Lk[0], rate[0])
        mujoco.mj_forward(model, data)
        mujoco.mj_fullM(model, data, M)
        J, bias, v_old = data.ten_J.reshape(6, -1).copy(), data.qfrc_bias.copy(), data.qvel.copy()
        plant.step()
        residual = M @ (data.qvel - v_old) / 1e-3 + bias + J.T @ plant.tensions
        worst = max(worst, float(np.max(np.abs(residual))))
        slack += int(np.any(plant.tensions == 0))
    assert slack > 10                      # the swing slackens cables: both branches read
    assert worst < 1e-6 * np.max(robot.tension_max), worst    # measured 1.7e-7 N (of 6.58)


@pytest.mark.parametrize("name", sorted(PLANS))
def test_static_holds_give_the_plans_nominal_tensions(name, plans):
    """At planned poses (first, middle, last waypoint), with the unstretched lengths that
    carry the tension rule's nominal tensions, the platform holds still and the load cells
    read those tensions to 1e-6 relative (after 0.5 s)."""
    robot = load_robot(CONFIG / f"{name}.yaml")
    plant = SimulatedRobot(robot)
    path = plans[name][1]["path"]
    for w in (path[0], path[len(path) // 2], path[-1]):
        p, q = np.array(w["p"]), np.array(w["quaternion"])
        t = rule_tensions(robot, p[None], rotation_from_quaternion(q)[None])[0][0]
        plant.reset(p, q, unstretched_lengths(robot, w["lengths"], t))
        for _ in range(500):
            plant.step()
        assert np.max(np.abs(plant.tensions - t) / t) < 1e-6, (plant.tensions, t)
        assert np.linalg.norm(plant.pose()[0] - p) < 1e-9


def test_a_stiff_cable_substeps_and_still_holds(tmp_path):
    """EA 1e8 N on Robot 2's 0.6 kg platform: sqrt(k / m) dt ~ 13 at 1 ms, explicit stiffness
    would diverge; the plant substeps and holds the nominal tensions."""
    stiff = tmp_path / "stiff.yaml"
    stiff.write_text((CONFIG / "robot2.yaml").read_text().replace(
        "cable_stiffness: 1000.0", "cable_stiffness: 1.0e8"))
    robot = load_robot(stiff)
    plant = SimulatedRobot(robot)
    p, R = np.array([0.0, 0.0, 0.306]), np.eye(3)
    t = rule_tensions(robot, p[None], R[None])[0][0]
    plant.reset(p, [0, 0, 0, 1], unstretched_lengths(robot, cable_lengths(robot, p, R), t))
    assert plant.substeps > 1
    for _ in range(300):
        plant.step()
    assert np.max(np.abs(plant.tensions - t) / t) < 1e-6


# ----------------------------------------------------------------------------- plans

@pytest.mark.parametrize("name", sorted(PLANS))
def test_plans_run_in_the_plant_within_limits_and_envelope(name, plans):
    """Compensated commands, a JointTrajectoryController's quintic, 1 kHz: every measured
    tension within its limits at every sample (no slack, no overload), and at the waypoints,
    where the envelope is published, within it to 1 % of the tension range once the
    platform has started: the plans' first point has a non-zero acceleration, a step from
    rest that no body on elastic cables follows at once, so the first START_S are checked
    against the limits only. The last point publishes the tension held at rest (elastic
    robots): it is compared with the tensions once the platform has settled, at the end of
    the run."""
    robot = load_robot(CONFIG / f"{name}.yaml")
    plan = compensated(robot, plans[name][1])
    record = run_plan(robot, plan)
    report = judge(robot, plan, record)
    assert report.ok, report
    assert not report.slack_s.any() and not report.overload_s.any()
    k = np.clip(np.searchsorted(record.t, plan.t - 0.5e-3), 0, len(record.t) - 1)
    k[-1] = len(record.t) - 1  # the last point's envelope is the tension held at rest: settled
    f = record.tension[k]
    margin = np.minimum(f - plan.low, plan.high - f) / (robot.tension_max - robot.tension_min)
    worst = float(np.min(margin[plan.t >= START_S]))
    assert worst > -ENVELOPE_TOL, worst


def test_a_constant_velocity_retiming_of_the_same_plan_fails(plans):
    """Robot 2's sphere-task plan (q2 -> q3, which passes 0.006 N from the least tension) at
    the plan's top cable speed throughout: tensions go below their least."""
    robot = load_robot(CONFIG / "robot2.yaml")
    plan = constant_velocity(compensated(robot, plans["robot2"][1]))
    report = judge(robot, plan, run_plan(robot, plan))
    assert not report.ok
    assert report.slack_s.any() or report.overload_s.any() or report.below_min_s.any()


def test_an_eight_cable_plan_commanded_by_its_geometric_lengths_fails(plans):
    """Without compensation a redundant robot's tensions are the stiffness-weighted
    least-norm ones, not the published rule: cables go below their least tension."""
    robot = load_robot(CONFIG / "robot2_8.yaml")
    plan = plan_from_waypoints(plans["robot2_8"][1]["path"], 8)
    plan.L = np.array([w["lengths"] for w in plans["robot2_8"][1]["path"]])   # geometric
    plan.source = "lengths"
    report = judge(robot, plan, run_plan(robot, plan))
    assert not report.ok and report.below_min_s.any()


# ----------------------------------------------------------------------------- simulate

def test_simulate_end_to_end(plans, tmp_path):
    """The command in a process of its own: report, --json, --plot; --frames without an
    OpenGL backend (MUJOCO_GL=osmesa, absent here or not) says so in one line or renders;
    the rest of the work is done either way. The plan, made without the ball of
    config/scenes/robot2_ball.yaml, runs through it: a contact, exit 1."""
    path = plans["robot2"][0]
    outs = {k: tmp_path / f"out.{k}" for k in ("json", "png")}
    frames = tmp_path / "frames.png"
    env = {**__import__("os").environ, "MUJOCO_GL": "osmesa"}
    run = subprocess.run([sys.executable, "-m", "cdh_planner.cli", "simulate", str(path),
                          str(CONFIG / "robot2.yaml"), "--scene",
                          str(CONFIG / "scenes" / "robot2_ball.yaml"), "--json",
                          str(outs["json"]), "--plot", str(outs["png"]), "--frames", str(frames)],
                         capture_output=True, text=True, timeout=300, cwd=REPO, env=env)
    assert run.returncode == 1, run.stdout + run.stderr
    assert "winch_3 / ball" in run.stdout and "LIMIT LEFT" in run.stdout
    assert [line for line in run.stdout.splitlines() if line.startswith("frames:")]
    doc = json.loads(outs["json"].read_text())
    assert doc["ok"] is False and "winch_3 / ball" in doc["contacts"]
    assert len(doc["limit_margin"]) == 6 and doc["commands"] in ("lengths", "commanded_lengths")
    assert outs["png"].stat().st_size > 10_000


def _bad(tmp_path, plans):
    robot2 = CONFIG / "robot2.yaml"
    not_json = tmp_path / "plan.json"
    not_json.write_text("{")
    no_path = tmp_path / "empty.json"
    no_path.write_text('{"success": false}')
    return [
        (("mjcf", tmp_path / "missing.yaml"), "robot"),
        (("mjcf", robot2, "-o", tmp_path / "out.txt"), "--output"),
        (("mjcf", robot2, "--scene", tmp_path / "missing.yaml"), "scene"),
        (("simulate", not_json, robot2), "PLAN"),
        (("simulate", no_path, robot2), "PLAN"),
        (("simulate", plans["robot2"][0], CONFIG / "robot2_8.yaml"), "path[0]."),
        (("simulate", plans["robot2"][0], robot2, "--plot", tmp_path / "x.jpg"), "--plot"),
        (("simulate", plans["robot2"][0], robot2, "--json", plans["robot2"][0]), "--json"),
    ]


def test_bad_input_is_one_line_exit_2(plans, tmp_path, capsys):
    for argv, field in _bad(tmp_path, plans):
        rc, _, err = _cli(capsys, *argv)
        assert rc == 2 and len(err) == 1 and field in err[0], (argv, err)


def test_mjcf_has_every_obstacle_shape_and_the_platform_collides_with_them(tmp_path, capsys):
    (tmp_path / "tet.obj").write_text("v 0 0 0\nv 0.02 0 0\nv 0 0.02 0\nv 0 0 0.02\n"
                                      "f 1 3 2\nf 1 2 4\nf 1 4 3\nf 2 3 4\n")
    scene = tmp_path / "scene.yaml"
    scene.write_text("""scene:
  platform: {type: box, size: [0.1, 0.1, 0.01]}
  obstacles:
    - {id: post, type: box, size: [0.02, 0.04, 0.1], position: [0.2, 0.2, 0.3],
       quaternion: [0, 0, 0.3826834, 0.9238795]}
    - {id: pipe, type: cylinder, radius: 0.01, height: 0.1, position: [-0.2, 0.2, 0.3]}
    - {id: tet, type: mesh, file: tet.obj, position: [0, -0.2, 0.3]}
""")
    out = tmp_path / "scene.xml"
    assert _cli(capsys, "mjcf", CONFIG / "robot2.yaml", "--scene", scene, "-o", out)[0] == 0
    model = mujoco.MjModel.from_xml_path(str(out))
    post, pipe, tet = (model.geom(f"obstacle_{n}") for n in ("post", "pipe", "tet"))
    assert np.allclose(post.size, [0.01, 0.02, 0.05]) and np.allclose(pipe.size[:2], [0.01, 0.05])
    assert np.allclose(post.quat, [0.9238795, 0, 0, 0.3826834], atol=1e-6)   # w x y z
    assert tet.type[0] == mujoco.mjtGeom.mjGEOM_MESH and model.nmesh == 1
    platform = model.geom("platform")
    for g in (post, pipe, tet):     # MuJoCo's contact filter: platform x obstacle only
        assert (platform.contype & g.conaffinity) or (g.contype & platform.conaffinity)
    assert not (post.contype & pipe.conaffinity) and not (pipe.contype & post.conaffinity)


def test_the_live_plant_follows_goals_setpoints_and_holds():
    """sim.live, as the controller double drives it (20x real time): a trajectory's end is
    reached exactly by the winches, a setpoint in a straight line over the setpoint period,
    a hold keeps them; the platform rests on taut cables throughout."""
    import time
    from cdh_planner.sim.live import LivePlant
    robot = load_robot(CONFIG / "robot2.yaml")
    p, R = np.array([0.0, 0.0, 0.306]), np.eye(3)
    L = cable_lengths(robot, p, R)
    live = LivePlant(robot, L, time_scale=20.0)
    try:
        live.start()
        target = cable_lengths(robot, p + [0.01, 0.0, 0.01], R)
        _, end = live.follow([0.0, 0.5], [L, target], np.zeros((2, 6)), np.zeros((2, 6)))
        deadline = time.monotonic() + 10.0
        while live.state()[0] < end + 0.05 and time.monotonic() < deadline:
            time.sleep(0.01)
        now, winch, tensions, _, _ = live.state()
        assert now >= end and np.array_equal(winch, target)
        assert np.all(tensions > robot.tension_min)
        live.setpoint(L)
        while live.state()[0] < now + 0.1 and time.monotonic() < deadline:
            time.sleep(0.01)
        assert np.array_equal(live.state()[1], L)
        live.hold()
        held = live.state()[1]
        time.sleep(0.05)
        assert np.array_equal(live.state()[1], held)
    finally:
        live.stop()
