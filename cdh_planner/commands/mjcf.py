"""``cdh-planner mjcf``: the robot (and a scene's obstacles) as MJCF, MuJoCo's model format.

    cdh-planner mjcf ROBOT.yaml [--scene SCENE.yaml] [-o OUT.xml]

The model the physics plant runs (``cdh_planner/sim/mjcf.py``): the base frame as the world,
the anchors as sites, each cable a spatial tendon driven by a tension-only actuator of the
robot's stiffness, the platform a free body with the load's mass, inertia and centre of
mass, the obstacles as static geoms, gravity from the load, a camera ``workspace``.
Printed on stdout, or written to OUT. Exit 0, or 2 for bad input (the robot or scene file,
an output that cannot be written or is an input).
"""

ORDER = 110  # its place in `cdh-planner --help`
SUMMARY = "print the MuJoCo model (MJCF) of a robot file"


def add_parser(subparsers):
    p = subparsers.add_parser(
        "mjcf", help=SUMMARY,
        description="The MJCF of a robot file (and a scene): anchors, cables as tendons with "
                    "tension-only actuators of the robot's stiffness, the platform body, "
                    "obstacles, gravity, a camera; it loads in mujoco.MjModel.from_xml_path.")
    p.add_argument("robot", help="robot file (ROS 2 parameters YAML)")
    p.add_argument("--scene", metavar="SCENE.yaml", help="scene file (obstacles, platform shape)")
    p.add_argument("-o", "--output", metavar="OUT.xml", help="write it here instead of stdout")
    p.set_defaults(func=run)


def run(args):
    from .outputs import check_output, print_or_write
    from ..model.robot import load_robot
    from ..scene.schema import load_scene
    from ..sim.mjcf import mjcf
    out = None if args.output is None else check_output(
        "--output", args.output, suffixes=(".xml", ".mjcf"),
        inputs=[("the robot file ROBOT", args.robot), ("the scene file", args.scene)])
    robot = load_robot(args.robot)
    scene = load_scene(args.scene, robot) if args.scene else None
    text = mjcf(robot, scene)
    print_or_write("--output", out, text)
    return 0
