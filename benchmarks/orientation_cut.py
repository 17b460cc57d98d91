"""Is IPAnema 2's planning domain cut in two by the half turn of its platform?

    .venv/bin/python benchmarks/orientation_cut.py [--entry 0 0] [--within 0 0 -1]
        [--samples 2000000] [--local 15] [--seed 1]

IPAnema 2's platform (config/ipanema2.yaml) is symmetric under a half turn about its z axis,
and its feasible orientations gather in islands: the platform's long axis (body x) along +x
of the frame or along -x, upright or upside down. A continuous path between a pose with
R[i, j] > 0 and one with R[i, j] < 0 passes a pose with R[i, j] = 0 (body axis j
perpendicular to frame axis i; ``--entry i j``). This script draws ``--samples`` poses on
that set (position uniform in ``model.robot.workspace_box``, body axis j uniform on the
circle perpendicular to frame axis i, the next body axis uniform about it) and maximises the
planner's margin (``wrench.band_feasibility``) on it from the ``--local`` best (Nelder-Mead
over position and the two angles). All negative: no path crosses, so a query whose ends
have R[i, j] of opposite signs has none. ``--within k l sign``: only the poses with R[k, l]
of that sign count (a part already cut off by R[k, l] = 0). benchmarks/eight_cables.py
leaves out the pairs across R[0, 0] = 0 and, where R[0, 0] < 0, across R[2, 2] = 0
(measured: ``--entry 2 2`` crossed where R[0, 0] > 0, not within R[0, 0] < 0). For
reference the best margin of as many poses of random orientation. Prints the numbers.
"""

import argparse
import sys

import numpy as np

from cdh_planner.model.robot import load_robot, workspace_box
from cdh_planner.ports.rotation import Rotation
from cdh_planner.wrench import band_feasibility

ROBOT = "config/ipanema2.yaml"
BATCH = 50_000


def on_cut(z, i, j):
    """Poses (p (N, 3), R (N, 3, 3)) with R[i, j] = 0 of parameters z (N, 5): position,
    angle a of body axis j on the circle perpendicular to frame axis i, angle b of body
    axis j + 1 about it (axes cyclic: a right-handed frame)."""
    a, b = z[:, 3], z[:, 4]
    e = np.eye(3)
    u, w = e[(i + 1) % 3], e[(i + 2) % 3]
    x = np.cos(a)[:, None] * u + np.sin(a)[:, None] * w           # body axis j, R[i, j] = 0
    ei = np.broadcast_to(e[i], x.shape)
    y = np.cos(b)[:, None] * ei + np.sin(b)[:, None] * np.cross(x, ei)
    axes = {j: x, (j + 1) % 3: y, (j + 2) % 3: np.cross(x, y)}
    return z[:, :3], np.stack([axes[0], axes[1], axes[2]], axis=2)  # columns: body axes


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--entry", type=int, nargs=2, default=[0, 0], choices=range(3),
                    metavar=("I", "J"), help="the cut R[I, J] = 0")
    ap.add_argument("--within", type=int, nargs=3, metavar=("K", "L", "SIGN"),
                    help="only poses with R[K, L] of this sign (+1 or -1)")
    ap.add_argument("--samples", type=int, default=2_000_000)
    ap.add_argument("--local", type=int, default=15, help="local maximisations from the best samples")
    ap.add_argument("--seed", type=int, default=1)
    args = ap.parse_args()
    from scipy.optimize import minimize  # a benchmark: its import time does not matter

    robot = load_robot(ROBOT)
    lo, hi = workspace_box(robot)
    rng = np.random.default_rng(args.seed)

    def inside(R):  # the part of the cut that counts (--within)
        if args.within is None:
            return np.ones(len(R), dtype=bool)
        k, l, sign = args.within
        return np.sign(R[:, k, l]) == np.sign(sign)
    best_z, best_m, free_best = [], [], -np.inf
    for _ in range(max(1, args.samples // BATCH)):
        z = np.column_stack([rng.uniform(lo, hi, (BATCH, 3)), rng.uniform(0, 2 * np.pi, (BATCH, 2))])
        p, R = on_cut(z, *args.entry)
        m = np.where(inside(R), band_feasibility(robot, p, R=R).margin, -np.inf)
        top = np.argsort(m)[::-1][:args.local]
        best_z.append(z[top])
        best_m.append(m[top])
        p = rng.uniform(lo, hi, (BATCH, 3))
        free_best = max(free_best, float(band_feasibility(robot, p, R=Rotation.random(BATCH, rng).as_matrix()).margin.max()))
    z0 = np.concatenate(best_z)[np.argsort(np.concatenate(best_m))[::-1][:args.local]]
    sampled = float(max(np.concatenate(best_m)))

    def negative_margin(z):
        p, R = on_cut(z[None], *args.entry)
        return -float(band_feasibility(robot, p, R=R).margin[0]) if inside(R)[0] else np.inf

    local = sorted((-minimize(negative_margin, z, method="Nelder-Mead",
                              options=dict(maxiter=1500, xatol=1e-6, fatol=1e-8)).fun for z in z0),
                   reverse=True)
    n = max(1, args.samples // BATCH) * BATCH
    where = "" if args.within is None else " and R[{}, {}] of sign {:+d}".format(*args.within)
    print(f"{n} poses with R[{args.entry[0]}, {args.entry[1]}] = 0{where}: best margin {sampled:.4f}; local maxima from the "
          f"{len(z0)} best: {', '.join(f'{m:.4f}' for m in local)}")
    print(f"{n} poses of random orientation: best margin {free_best:.4f}")
    print("the cut " + ("holds no feasible pose found" if max(local) < 0 else "is CROSSED: a feasible pose on it"))
    return 0


if __name__ == "__main__":
    sys.exit(main())
