"""Time of a full collision check of a pose (target: under 20 us).

    python benchmarks/collision.py [--poses 2000] [--repeats 5] [--plans 5]

Robot 2 (6 cables, 15 cable pairs), a box platform and 10 primitive obstacles (spheres,
boxes, cylinders), in two scenes: "spread" (obstacles about the workspace, 2-10 cm from
the cables) and "close" (obstacles on the cables: many hits, the pruning works least).
Per scene it prints the median and mean microseconds per ``CollisionModel.clearance``
(the least signed distance, exact, and what binds) over random poses, the same for
``distances`` (every pair, unpruned: 91 pairs; 10 of them by coal: the platform against
the obstacles; the cables against them in the compiled kernel), the compiled kernel alone
(the 15 cable pairs and the 6 cables against the box platform exactly, the 70 bounds, and
the cables against the primitive obstacles where a bound does not rule them out), and
one coal capsule-box distance call from Python. Then the planning target: Robot 2
free flight q2 -> q3 (Table 1) with a 1 cm ball on the platform's straight path and a ball
platform of 3 cm: seconds per plan (a new Planner each time, in a process that has loaded
the compiled kernels), median of ``--plans``. Exit code 0 always (a benchmark).
"""

import argparse
import time

import numpy as np
from cdh_planner.ports.rotation import Rotation

from pathlib import Path

from cdh_planner.model.robot import load_robot
from cdh_planner.scene.collision import CollisionModel
from cdh_planner.scene.schema import scene_from_dict

CONFIG = Path(__file__).resolve().parents[1] / "config"


def poses(rng, n):
    p = np.array([0.0, 0.0, 0.40]) + rng.uniform(-0.06, 0.06, (n, 3))
    R = Rotation.from_rotvec(rng.uniform(-0.3, 0.3, (n, 3))).as_matrix()
    return p, R


def scene(robot, rng, offset):
    """10 obstacles near points of the cables at the mid pose, ``offset`` m away."""
    p0, R0 = np.array([0.0, 0.0, 0.4]), np.eye(3)
    Bw = p0 + robot.platform_anchors @ R0.T
    shapes = [{"type": "sphere", "radius": 0.01}, {"type": "box", "size": [0.02, 0.03, 0.01]},
              {"type": "cylinder", "radius": 0.005, "height": 0.04}]
    obstacles = []
    for k in range(10):
        i = k % 6
        a, b = robot.base_anchors[i], Bw[i]
        c = a + rng.uniform(0.2, 0.8) * (b - a)
        direction = rng.normal(size=3)
        c = c + offset * direction / np.linalg.norm(direction)
        obstacles.append({"id": f"o{k}", "position": c.tolist(),
                          "quaternion": Rotation.random(1, rng).as_quat()[0].tolist(),
                          **shapes[k % 3]})
    return scene_from_dict({"cable_radius": 0.001, "obstacles": obstacles,
                            "platform": {"type": "box", "size": [0.14, 0.14, 0.01]}})


def per_call_us(fn, args, repeats):
    """Median and mean microseconds of fn(*a) over args (the best of ``repeats`` passes)."""
    best = None
    for _ in range(repeats):
        times = np.empty(len(args))
        for k, a in enumerate(args):
            t = time.perf_counter()
            fn(*a)
            times[k] = time.perf_counter() - t
        best = times if best is None or np.median(times) < np.median(best) else best
    return 1e6 * float(np.median(best)), 1e6 * float(np.mean(best))


def coal_calls(cm, pairs):
    """Mean number of coal distance calls a ``clearance`` makes over ``pairs``."""
    count = [0]
    names = ("_cable_obstacle", "_platform_obstacle", "_cable_platform")
    for name in names:
        fn = getattr(cm, name)
        setattr(cm, name, lambda *a, fn=fn: (count.__setitem__(0, count[0] + 1), fn(*a))[1])
    for a in pairs:
        cm.clearance(*a)
    for name in names:
        delattr(cm, name)
    return count[0] / len(pairs)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--poses", type=int, default=2000)
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--plans", type=int, default=5)
    args = ap.parse_args()
    robot = load_robot(CONFIG / "robot2.yaml")
    rng = np.random.default_rng(0)
    p, R = poses(rng, args.poses)
    pairs = list(zip(p, R))
    for name, offset in (("spread", 0.06), ("close", 0.0)):
        cm = CollisionModel(robot, scene(robot, np.random.default_rng(1), offset))
        cm.clearance(*pairs[0])  # load the compiled kernel
        hits = sum(not cm.clearance(*a).ok for a in pairs)
        med, mean = per_call_us(cm.clearance, pairs, args.repeats)
        print(f"{name}: clearance (exact least distance + binding): median {med:.1f} us, "
              f"mean {mean:.1f} us; {hits}/{len(pairs)} poses in collision")
        print(f"{name}: coal calls per check: mean {coal_calls(cm, pairs):.2f} (of 70 pairs "
              f"with obstacles; the cables against the box platform: the kernel's)")
        med, mean = per_call_us(cm.distances, pairs[:200], 1)
        print(f"{name}: distances (all 91 pairs, unpruned): median {med:.1f} us, "
              f"mean {mean:.1f} us")
        med, mean = per_call_us(cm._pose, pairs, args.repeats)
        print(f"{name}: kernel (15 cable pairs, 6 cables against the platform, 70 lower "
              f"bounds): median {med:.1f} us")
    med, _ = per_call_us(lambda: cm._cable_obstacle(0, 1, cm.frames), [()] * 2000, args.repeats)
    print(f"one coal capsule-box distance from Python (with its transform): median {med:.1f} us")
    plan_times(args.plans)


def plan_times(n):
    """Median seconds of Robot 2's free flight q2 -> q3 around a ball on the straight path."""
    from cdh_planner.parsing.problem import load_problem
    from cdh_planner.planner import Planner

    pr = load_problem(CONFIG / "problems" / "robot2_q2_q3_free_flight.yaml")
    mid = (0.5 * (pr.start.p + pr.goal.p)).tolist()
    scene = scene_from_dict({"cable_radius": 0.001, "platform": {"type": "sphere", "radius": 0.03},
                             "obstacles": [{"id": "ball", "type": "sphere", "radius": 0.01,
                                            "position": mid}]})
    times, charts = [], []
    for _ in range(n):
        t = time.perf_counter()
        r = Planner(pr.robot, pr.task, pr.settings, scene=scene).plan(pr.start, pr.goal)
        times.append(time.perf_counter() - t)
        charts.append(r.charts if r.success else -1)
    print(f"Robot 2 free flight around a ball: median {np.median(times):.2f} s "
          f"(min {min(times):.2f}, max {max(times):.2f}) over {n} plans; charts {charts}")


if __name__ == "__main__":
    main()
