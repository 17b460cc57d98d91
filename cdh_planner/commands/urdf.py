"""``cdh-planner urdf``: the robot description (URDF) of a robot file.

    cdh-planner urdf ROBOT.yaml [-o OUT.urdf] [--fixed-frame world] [--base-frame cdh_base]
        [--platform-frame cdh_platform]

The same URDF the node publishes on ``robot_description`` (``ros/core/description.py``): the
z-up fixed frame, the paper's z-down base frame under it, the anchors as frames, the
platform on a floating joint. Printed on stdout, or written to OUT. Exit 0, or 2 for bad
input (the robot file, an output that cannot be written or is the robot file).
"""

ORDER = 100  # its place in `cdh-planner --help`
SUMMARY = "print the robot description (URDF) of a robot file"


def add_parser(subparsers):
    p = subparsers.add_parser(
        "urdf", help=SUMMARY,
        description="The URDF of a robot file: the frames, the anchors, the platform (as the "
                    "node publishes it on robot_description).")
    p.add_argument("robot", help="robot file (ROS 2 parameters YAML)")
    p.add_argument("-o", "--output", metavar="OUT.urdf", help="write it here instead of stdout")
    p.add_argument("--fixed-frame", default="world", help="the z-up fixed frame (default world)")
    p.add_argument("--base-frame", default="cdh_base",
                   help="the paper's z-down frame (default cdh_base)")
    p.add_argument("--platform-frame", default="cdh_platform",
                   help="the platform's frame (default cdh_platform)")
    p.set_defaults(func=run)


def run(args):
    from ..errors import InputError
    from .outputs import check_output, print_or_write
    from ..model.robot import load_robot
    from ..ros.core.description import urdf
    frames = {"--fixed-frame": args.fixed_frame, "--base-frame": args.base_frame,
              "--platform-frame": args.platform_frame}
    for option, name in frames.items():
        if not name or any(c.isspace() for c in name):
            raise InputError(option, name, "expected a frame name (no spaces)")
    if len(set(frames.values())) < 3:
        raise InputError("--platform-frame", args.platform_frame, "the three frames must differ")
    out = None if args.output is None else check_output(
        "--output", args.output, suffixes=(".urdf", ".xml"),
        inputs=[("the robot file ROBOT", args.robot)])
    text = urdf(load_robot(args.robot), args.fixed_frame, args.base_frame, args.platform_frame)
    print_or_write("--output", out, text)
    return 0
