"""Clearance against length on the paper's Table 1 rows, at several clearance weights.

    python benchmarks/clearance.py [--weights 0 0.5 1 2 5] [--only NAME ...]
                                   [--strategy auto] [--picture docs/clearance.png]

Each row is planned at each weight w (planner.clearance_weight: a path costs its length
times 1 + w ln(0.5 / margin) along it; w = 0 is the shortest path, A* up to 3-D; w > 0
picks Greedy Best-First under ``auto``). Per row and weight it prints the path cost in the
task's metric (rad, or m for the sphere and free flight) and how much longer it is than at
w = 0, the least normalised margin and the least tension margin (N: min over cables of
f - v - fmin, fmax - f - v), both over the waypoints and the motion between them, the
mean normalised margin along the path (samples evenly spaced in the motion), charts and
seconds. ``--picture`` draws, per row, the extra length against the least tension margin
and against the mean margin, and Robot 2 q2 -> q3's paths over its margin in (alpha1,
alpha2). Exit code 0 always (a benchmark, not a test).
"""

import argparse
import time
from pathlib import Path

import numpy as np

from cdh_planner.wrench import wrench_feasibility
from cdh_planner.parsing.problem import load_problem
from cdh_planner.planner import Planner
from cdh_planner.settings import STRATEGY_CHOICES
from cdh_planner.trajectory.path_check import SlerpPath

PROBLEMS = Path(__file__).resolve().parents[1] / "config" / "problems"
ROWS = ("robot1_qs_qg", "robot1_qs1_qg", "robot1_qs2_qg", "robot2_q1_q2", "robot2_q2_q3",
        "robot2_q2_q3_sigma_free", "robot2_q2_q3_free_flight")
SHOWN = "robot2_q2_q3"  # the row whose paths the picture draws


def mean_margin(robot, path, step_m=1e-3, step_rad=np.deg2rad(0.2)):
    """Mean normalised margin over the motion between the waypoints, sampled evenly."""
    motion = SlerpPath(path.p, path.quaternion)
    dp, da = motion.speeds()
    n = np.maximum(1, np.ceil(np.maximum(dp / step_m, da / step_rad))).astype(int)
    seg = np.repeat(np.arange(motion.n_segments), n)
    s = np.concatenate([(np.arange(k) + 0.5) / k for k in n])
    p, R = motion(seg, s)
    return float(np.mean(wrench_feasibility(robot, p, R=R).margin))


def draw_paths(ax, problem, paths):
    """Paths (weight -> PlannedPath) over the normalised margin of a 2-D task's plane."""
    names = problem.task.names
    ys = [problem.task.coords(path.p, path.tau) for path in paths.values()]
    lo = np.min([y.min(axis=0) for y in ys], axis=0) - 0.25
    hi = np.max([y.max(axis=0) for y in ys], axis=0) + 0.25
    a, b = np.meshgrid(np.linspace(lo[0], hi[0], 300), np.linspace(lo[1], hi[1], 200))
    p, tau = problem.task.pose(np.stack([a.ravel(), b.ravel()], axis=1))
    m = wrench_feasibility(problem.robot, p, tau).margin.reshape(a.shape)
    levels = [0.0, 0.002, 0.005, 0.01, 0.02, 0.05, 0.1, 0.2, 0.5]
    filled = ax.contourf(a, b, np.clip(m, -1.0, 0.5), levels=[-1.0] + levels, cmap="Greys_r")
    ax.figure.colorbar(filled, ax=ax, label="normalised margin (below 0: outside C)")
    for (w, path), y in zip(paths.items(), ys):
        ax.plot(y[:, 0], y[:, 1], lw=1.6, label=f"w = {w:g}")
    ax.set_xlabel(names[0])
    ax.set_ylabel(names[1])
    ax.legend(fontsize=8, loc="lower center")
    ax.set_title("Robot 2 q2 -> q3: paths by weight", fontsize=10)


def picture(rows, paths, out):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig = plt.figure(figsize=(18, 5))
    axes = [fig.add_subplot(1, 3, 1)]
    axes.append(fig.add_subplot(1, 3, 2, sharey=axes[0]))
    for name, points in rows.items():
        w = [p["w"] for p in points]
        extra = [100 * (p["cost"] / points[0]["cost"] - 1) for p in points]
        for ax, key in zip(axes, ("least_n", "mean")):
            x = [p[key] for p in points]
            line, = ax.plot(x, extra, "o-", ms=4, label=name)
            for xi, yi, wi in zip(x, extra, w):
                ax.annotate(f"{wi:g}", (xi, yi), textcoords="offset points", xytext=(3, 3),
                            fontsize=7, color=line.get_color())
    axes[0].set_xscale("log")
    axes[0].set_xlabel("least tension margin along the path (N, log)")
    axes[1].set_xlabel("mean normalised margin along the path")
    axes[0].set_ylabel("path cost, % above the shortest (w = 0)")
    axes[0].legend(fontsize=8)
    for ax in axes:
        ax.grid(alpha=0.3)
    if paths:
        draw_paths(fig.add_subplot(1, 3, 3), *paths)
    fig.suptitle("Clearance weight w (labels): length traded for margin, Table 1 rows")
    fig.tight_layout()
    fig.savefig(out, dpi=110)
    return out


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--weights", nargs="+", type=float, default=[0.0, 0.5, 1.0, 2.0, 5.0])
    ap.add_argument("--only", nargs="+", help="problem names (default: the seven Table 1 rows)")
    ap.add_argument("--strategy", default="auto", choices=STRATEGY_CHOICES)
    ap.add_argument("--picture", default=None, metavar="OUT.png", help="write the trade-off picture")
    args = ap.parse_args()
    head = (f"{'query':26} {'w':>4} {'strategy':8} {'charts':>6} {'seconds':>7} {'cost':>8} "
            f"{'longer':>7} {'least margin':>12} {'least N':>8} {'mean margin':>11}")
    print(head)
    print("-" * len(head))
    rows, shown = {}, {}
    shown_problem = None
    for name in ROWS:
        if args.only and name not in args.only:
            continue
        for w in args.weights:
            pr = load_problem(PROBLEMS / f"{name}.yaml")
            pr.settings.clearance_weight = w
            pr.settings.strategy = args.strategy
            t = time.perf_counter()
            res = Planner(pr.robot, pr.task, pr.settings).plan(pr.start, pr.goal)
            wall = time.perf_counter() - t
            if not res.success:
                print(f"{name:26} {w:4g} {res.strategy:8} {res.charts:6d} {wall:7.2f}  {res.reason}: "
                      f"{res.message}", flush=True)
                continue
            point = {"w": w, "cost": res.cost, "least": res.least_margin,
                     "least_n": res.least_tension_margin, "mean": mean_margin(pr.robot, res.path)}
            rows.setdefault(name, []).append(point)
            if name == SHOWN:
                shown_problem, shown[w] = pr, res.path
            base = rows[name][0]["cost"]
            print(f"{name:26} {w:4g} {res.strategy:8} {res.charts:6d} {wall:7.2f} {res.cost:8.4f} "
                  f"{100 * (res.cost / base - 1):+6.1f}% {res.least_margin:12.4f} "
                  f"{res.least_tension_margin:8.4f} {point['mean']:11.4f}", flush=True)
    if args.picture:
        print(f"picture: {picture(rows, (shown_problem, shown) if shown else None, args.picture)}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
