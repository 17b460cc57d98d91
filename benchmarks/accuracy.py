"""Cost per pose of the pose accuracy (``cdh_planner.accuracy``): the exact worst case over
the box of winch errors, for m = 6, 8 and 16 cables.

    python benchmarks/accuracy.py [--poses N]

For each robot, N random poses near the middle of its workspace in one call: microseconds
per pose of ``pose_accuracy`` (the error map with its nominal tensions, and the two exact
maxima), of ``box_max_norm`` alone (one 3 x m map per pose), of the same by brute force
over all 2^m vertices, and how many poses took the degenerate (brute-force) branch. The
16-cable robot is Robot 2-8 with a copy of its cables rotated 20 degrees about z (our own,
for timing only). CPU time of this process (the machine is shared).
"""

import argparse
import dataclasses
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))  # run from a checkout without installing

from cdh_planner import accuracy  # noqa: E402
from cdh_planner.model.robot import load_robot  # noqa: E402
from cdh_planner.model.pose import rotation_tt  # noqa: E402

# robot -> (box centre, half extents) m
BOXES = {"robot2": ((0.0, 0.0, 0.25), (0.05, 0.05, 0.05)),
         "robot2_8": ((0.0, 0.0, 0.25), (0.05, 0.05, 0.05)),
         "cogiro": ((0.0, 0.0, 1.5), (1.0, 0.5, 0.5)),
         "robot2_16": ((0.0, 0.0, 0.25), (0.05, 0.05, 0.05))}


def sixteen_cables():
    """Robot 2-8 and a copy of its cables rotated 20 degrees about z: 16 cables."""
    r = load_robot(ROOT / "config" / "robot2_8.yaml")
    c, s = np.cos(np.deg2rad(20)), np.sin(np.deg2rad(20))
    Rz = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])
    twice = {f: np.concatenate([getattr(r, f), getattr(r, f)])
             for f in ("length_min", "length_max", "tension_min", "tension_max",
                       "cable_stiffness", "length_error")}
    return dataclasses.replace(r, name="robot2_16", winch_names=tuple(f"w{i}" for i in range(16)),
                               base_anchors=np.concatenate([r.base_anchors, r.base_anchors @ Rz.T]),
                               platform_anchors=np.concatenate([r.platform_anchors,
                                                                r.platform_anchors @ Rz.T]),
                               **twice)


def cpu(f, *a, **k):
    t = time.process_time()
    out = f(*a, **k)
    return out, time.process_time() - t


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--poses", type=int, default=2000)
    args = ap.parse_args(argv)
    rng = np.random.default_rng(0)
    robots = [load_robot(ROOT / "config" / f"{n}.yaml") for n in ("robot2", "robot2_8", "cogiro")]
    for robot in robots + [sixteen_cables()]:
        centre, half = (np.array(v) for v in BOXES[robot.name])
        p = centre + (2 * rng.random((args.poses, 3)) - 1) * half
        R = rotation_tt(rng.normal(scale=[1.0, 0.1, 0.1], size=(args.poses, 3)))
        accuracy.pose_accuracy(robot, p[:2], R=R[:2])  # compile / warm up
        _, t_all = cpu(accuracy.pose_accuracy, robot, p, R=R)
        G = accuracy.error_map(robot, p, R)
        M = G[:, :3][np.all(np.isfinite(G), axis=(1, 2))]
        g = M * robot.length_error
        _, t_box = cpu(accuracy.box_max_norm, M, robot.length_error)
        k = min(len(g), 200 if len(robot.base_anchors) <= 8 else 20)
        _, t_brute = cpu(accuracy.brute_force_max, g[:k])
        m = len(robot.base_anchors)
        print(f"{robot.name} (m = {m}): pose_accuracy {1e6 * t_all / args.poses:.0f} us/pose "
              f"(both norms, with the map); box_max_norm {1e6 * t_box / len(M):.0f} us per "
              f"3 x {m} map; brute force over 2^{m} vertices {1e6 * t_brute / k:.0f} us")


if __name__ == "__main__":
    main()
