"""``cdh-planner demo``: the paper's robots, poses and straight motions, checked, and
C-space pictures (``paper.py``); an obstacle the straight motion hits and the plan around it
(``obstacle.py``); then the ROS story (``ros_story.py``): the node plans Robot
2's sphere task q_1 -> q_2 -> q_3, streams it, records it, and the recording is replayed.

    cdh-planner demo [--out DIR] [--config-dir DIR]

The demo is a list of steps (``STEPS``, ``steps.Step``) run in order on one shared
``paper.Demo`` record: each prints its part and stores what it found there. Every verdict
with an expected value (the paper's results of Sec. 5) is compared with it. Exit code 0
when all agree, 1 when one differs (printed as DIFFERS FROM THE EXPECTED), 2 for bad input.
"""

ORDER = 130  # its place in `cdh-planner --help`
SUMMARY = ("the whole story: the paper's robots, poses and motions checked, then the ROS "
           "node planning, streaming, recording and replaying Robot 2's sphere task")

import argparse
import sys
import time
from pathlib import Path

from ...errors import InputError
from ..outputs import same_file
from . import more_cables, obstacle, paper, ros_story

PACKAGE = "cdh_planner"
DEFAULT_OUT = "demo_out"
EXIT_OK, EXIT_DIFFERS = 0, 1
STEPS = paper.STEPS + obstacle.STEPS + ros_story.STEPS + more_cables.STEPS


def add_parser(subparsers):
    """Register ``demo`` on the top-level subparsers."""
    p = subparsers.add_parser(
        "demo", help=SUMMARY,
        description="Load the paper's Robot 1 and Robot 2, check the paper's poses (closed-form "
                    "wrench feasibility) and the straight motions between them (dense "
                    "verification), compare each verdict with the paper's results, and write the "
                    "C-space pictures. Then start the ROS 2 node (its own ROS domain, discovery "
                    "on localhost), plan Robot 2's sphere task q1 -> q2 -> q3 over ROS, execute "
                    "it (streamed cable commands), record the run to MCAP, replay it, stop the "
                    "node and draw the plans and the execution. Exit 0 when every verdict "
                    "agrees, 1 if one differs.",
        epilog="example:\n  cdh-planner demo --out /tmp/demo", formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--out", default=DEFAULT_OUT, metavar="DIR",
                   help=f"directory for the pictures, created if missing (default: {DEFAULT_OUT}/ "
                        "in the current directory)")
    p.add_argument("--config-dir", metavar="DIR",
                   help="directory holding robot1.yaml and robot2.yaml (default: the package's "
                        "config/, found in the source tree or the installed share directory)")
    p.set_defaults(func=run)


def run(args):
    """Run every step; 0 when every verdict is the expected one, else 1."""
    demo = run_demo(args.out, config_dir=args.config_dir)
    return EXIT_OK if not demo.differs else EXIT_DIFFERS


def run_demo(out_dir=DEFAULT_OUT, config_dir=None, steps=None):
    """Run ``steps`` (default ``STEPS``) in order, printing as they go; return the Demo."""
    t0 = time.perf_counter()
    config = find_config_dir(config_dir)
    demo = paper.Demo(out_dir=prepare_out_dir(out_dir, config), config_dir=config)
    for i, step in enumerate(STEPS if steps is None else steps, 1):
        print(f"\n== {i}. {step.title}")
        step.run(demo)
    print(f"\n== Done in {time.perf_counter() - t0:.1f} s")
    if demo.files:
        print(f"files in {demo.out_dir.resolve()}/: {', '.join(f.name for f in demo.files)}")
    if demo.differs:
        print("DIFFERS FROM THE EXPECTED (the paper's Sec. 5 results):")
        for line in demo.differs:
            print(f"  {line}")
    else:
        print("every verdict is the expected one (the paper's Sec. 5 results)")
    return demo


def prepare_out_dir(path, config_dir=None):
    """The output directory, created if missing; none of the files the demo writes there
    may be one of the robot files it reads from ``config_dir``."""
    out = Path(path)
    if out.exists() and not out.is_dir():
        raise InputError("--out", str(path), "exists and is not a directory")
    if config_dir is not None:
        outputs = [spec.file for spec in paper.PICTURES] + [obstacle.PICTURE] \
            + list(ros_story.OUTPUTS)
        for name, robot_file in ((o, config_dir / f) for o in outputs
                                 for f in paper.ROBOT_FILES.values()):
            if same_file(out / name, robot_file):
                raise InputError("--out", str(path), f"its {name} would overwrite the robot "
                                                     f"file {robot_file.name} of --config-dir")
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise InputError("--out", str(path), f"cannot create the directory: {exc.strerror}") from None
    return out


def config_dir_candidates():
    """Where robot1.yaml / robot2.yaml may be, in order: the source tree (checkout or
    editable install), the ament index (colcon install), ``<sys.prefix>/share/cdh_planner/config``
    (pip install into a venv), and the share directory of the prefix the package sits in."""
    pkg = Path(__file__).resolve().parents[2]  # .../cdh_planner
    candidates = [pkg.parent / "config"]
    try:
        from ament_index_python.packages import get_package_share_directory
        candidates.append(Path(get_package_share_directory(PACKAGE)) / "config")
    except Exception:  # not installed, AMENT_PREFIX_PATH unset, or package not indexed
        pass
    candidates.append(Path(sys.prefix) / "share" / PACKAGE / "config")
    if len(pkg.parents) > 3:  # <prefix>/lib/pythonX.Y/site-packages/cdh_planner
        candidates.append(pkg.parents[3] / "share" / PACKAGE / "config")
    return list(dict.fromkeys(candidates))  # without repeats, in order


def find_config_dir(explicit=None):
    """The directory holding the paper's robot files (``explicit`` if given)."""
    files = paper.ROBOT_FILES.values()
    if explicit is not None:
        path = Path(explicit)
        missing = [f for f in files if not (path / f).is_file()]
        if missing:
            raise InputError("--config-dir", str(explicit), f"no {', '.join(missing)} there")
        return path
    candidates = config_dir_candidates()
    for path in candidates:
        if all((path / f).is_file() for f in files):
            return path
    raise InputError("config", [str(p) for p in candidates],
                     "robot1.yaml and robot2.yaml not found in any of these; give --config-dir")
