"""``cdh-planner simulate``: a plan's published trajectory run on the simulated robot (MuJoCo).

    cdh-planner simulate PLAN.json ROBOT.yaml [--scene SCENE.yaml] [--plot OUT.png]
        [--frames OUT.png] [--json OUT]

The plan JSON (``cdh-planner plan --json``) is executed as a JointTrajectoryController
executes it (the quintic of its points) on the physics plant of ``cdh_planner/sim``: the
platform a free body on elastic, tension-only cables, stepped at 1 kHz. The commands are
the JSON's ``commanded_lengths`` where it has them (the unstretched lengths that carry the
nominal tensions), else its ``lengths``. Printed (and with --json written): per cable the
least tension margin against the robot's limits and against the published envelope, the
time slack, below the least tension and overloaded, the measured extremes; the tracking
error against the plan's poses; contacts with the scene's obstacles. Exit 0 when every
tension, length and clearance stayed within its limit, 1 when one was left, 2 for bad
input (one line naming the file or the field).

--plot: the measured tensions over the planned envelope, per cable. --frames: a strip of
rendered frames along the motion (MUJOCO_GL=egl unless MUJOCO_GL is set; without an OpenGL
library one line says so and the rest is done).
"""

ORDER = 120  # its place in `cdh-planner --help`
SUMMARY = "run a plan's trajectory on the simulated robot (MuJoCo physics)"

import os

SERIES_EVERY = 10   # samples between the rows of the --json time series (10 ms)


def add_parser(subparsers):
    p = subparsers.add_parser(
        "simulate", help=SUMMARY,
        description="Run a plan JSON's trajectory on the physics plant (elastic tension-only "
                    "cables, a free platform, 1 kHz) as a JointTrajectoryController executes "
                    "it; report the measured tensions against the limits and the published "
                    "envelope, slack, overload, tracking error and contacts.")
    p.add_argument("plan", help="plan JSON (cdh-planner plan --json)")
    p.add_argument("robot", help="robot file (ROS 2 parameters YAML)")
    p.add_argument("--scene", metavar="SCENE.yaml", help="scene file: obstacles")
    p.add_argument("--plot", metavar="OUT.png", help="measured tensions over the envelope")
    p.add_argument("--frames", metavar="OUT.png", help="a strip of rendered frames")
    p.add_argument("--json", metavar="OUT", help="write the report (and 10 ms time series)")
    p.set_defaults(func=run)


def run(args):
    from .outputs import check_output
    inputs = [("the plan file PLAN", args.plan), ("the robot file ROBOT", args.robot),
              ("the scene file", args.scene)]
    outs = {}
    for option, path, suffixes in (("--plot", args.plot, (".png",)),
                                   ("--frames", args.frames, (".png",)),
                                   ("--json", args.json, ())):
        if path is not None:
            others = [(f"the {o} output", p) for o, p in outs.items()]
            outs[option] = check_output(option, path, suffixes=suffixes, inputs=inputs + others)
    if args.frames:
        os.environ.setdefault("MUJOCO_GL", "egl")   # before mujoco is imported
    from ..model.robot import load_robot
    from ..scene.schema import load_scene
    from ..sim.plant import SimulatedRobot
    from ..sim.run import judge, read_plan, run_plan
    robot = load_robot(args.robot)
    scene = load_scene(args.scene, robot) if args.scene else None
    plan = read_plan(args.plan, robot)
    plant = SimulatedRobot(robot, scene)
    record = run_plan(robot, plan, scene, plant=plant)
    report = judge(robot, plan, record, scene)
    _print(robot, report, record)
    _outputs(args, outs, robot, plan, record, report, plant)
    return 0 if report.ok else 1


def _print(robot, r, record):
    print(f"simulated {r.duration_s:.3f} s at 1 kHz ({record.substeps} MuJoCo step(s) per ms) "
          f"on {robot.name}: commands = the plan's {r.commands}")
    print(f"{'cable':<10} {'least N':>9} {'limit margin N':>15} {'(of range)':>10} "
          f"{'envelope margin N':>18} {'(of range)':>10} {'slack s':>8} {'< min s':>8} "
          f"{'> max s':>8}")
    for i, name in enumerate(r.names):
        print(f"{name:<10} {r.tension_low[i]:>9.4g} {r.limit_margin[i]:>+15.4g} "
              f"{r.limit_margin_fraction[i]:>+10.2%} {r.envelope_margin[i]:>+18.4g} "
              f"{r.envelope_margin_fraction[i]:>+10.2%} {r.slack_s[i]:>8.3f} "
              f"{r.below_min_s[i]:>8.3f} {r.overload_s[i]:>8.3f}")
    print(f"tracking error at the waypoints: {r.tracking_position_m * 1e3:.3f} mm, "
          f"{r.tracking_orientation_rad * 1e3:.3f} mrad")
    if r.length_out_s.any():
        print("cable lengths out of their limits: " + ", ".join(
            f"{n} {s:.3f} s" for n, s in zip(r.names, r.length_out_s) if s))
    print("contacts with obstacles: " + (", ".join(f"{k} from {t:.3f} s" for k, t in
                                                   r.contacts.items()) or "none"))
    print("within every limit" if r.ok else "LIMIT LEFT")


def _outputs(args, outs, robot, plan, record, report, plant):
    from .outputs import write_text, writing
    if "--plot" in outs:
        from ..pictures.simulation import plot_measured_tensions
        with writing("--plot", outs["--plot"]):
            plot_measured_tensions(robot, plan.t, plan.low, plan.high, record.t, record.tension,
                                   outs["--plot"], title=f"{robot.name}: measured tensions "
                                   f"(black) over the published envelope (green); dashed: limits")
        print(f"picture: {outs['--plot']}")
    if "--frames" in outs:
        from ..sim.frames import NoRendering, render_strip
        try:
            with writing("--frames", outs["--frames"]):
                times = render_strip(plant, record, outs["--frames"])
            print(f"frames: {outs['--frames']} (t = {', '.join(f'{t:.2f}' for t in times)} s)")
        except NoRendering as exc:
            print(f"frames: not rendered: {exc}")
    if "--json" in outs:
        write_text("--json", outs["--json"], _json(report, record))
        print(f"JSON: {outs['--json']}")


def _json(r, record):
    import json
    per_cable = {k: getattr(r, k).tolist() for k in (
        "limit_margin", "limit_margin_fraction", "envelope_margin", "envelope_margin_fraction",
        "slack_s", "below_min_s", "overload_s", "length_out_s", "tension_low", "tension_high")}
    s = slice(None, None, SERIES_EVERY)
    doc = {"ok": r.ok, "duration_s": r.duration_s, "commands": r.commands,
           "winch_names": list(r.names), **per_cable,
           "tracking_position_m": r.tracking_position_m,
           "tracking_orientation_rad": r.tracking_orientation_rad, "contacts": r.contacts,
           "series": {"t": record.t[s].tolist(), "winch_positions": record.winch[s].tolist(),
                      "tensions": record.tension[s].tolist(), "p": record.p[s].tolist(),
                      "quaternion": record.quaternion[s].tolist()}}
    return json.dumps(doc) + "\n"
