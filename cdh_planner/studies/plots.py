"""Pictures of the studies: the workspace's feasible and reachable sets, and a sweep's
metrics per design. matplotlib with the Agg backend; each picture is readable alone (the
counts and fractions are in its legend and title)."""

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

MAX_DRAWN = 20_000  # points per class drawn (a seeded subsample beyond): pictures stay small
CLASSES = (  # (key, label, colour, marker size)
    ("infeasible", "not feasible", "#bbbbbb", 1),
    ("feasible", "feasible (not planned)", "#2ca02c", 4),
    ("reachable", "reachable from home", "#1f77b4", 5),
    ("unreachable", "feasible, no path", "#d62728", 7),
    ("unknown", "feasible, a plan bound hit", "#ff7f0e", 7),
)


def workspace_classes(feasible, reachable, reach):
    """{class key: index array} of the samples (module CLASSES)."""
    feasible = np.asarray(feasible, bool)
    r = np.array([2 if v is None else int(v) for v in reachable])
    out = {"infeasible": np.flatnonzero(~feasible)}
    if not reach:
        out["feasible"] = np.flatnonzero(feasible)
    else:
        out["reachable"] = np.flatnonzero(feasible & (r == 1))
        out["unreachable"] = np.flatnonzero(feasible & (r == 0))
        out["unknown"] = np.flatnonzero(feasible & (r == 2))
    return out


def plot_workspace(path, position, feasible, reachable, reach, title, home=None):
    """A 3-D scatter and the top view (x, y) of the samples by class, to the PNG ``path``."""
    position = np.asarray(position, float)
    classes = workspace_classes(feasible, reachable, reach)
    rng = np.random.default_rng(0)
    fig = plt.figure(figsize=(13, 6), dpi=100, layout="constrained")
    try:
        ax3 = fig.add_subplot(1, 2, 1, projection="3d")
        ax2 = fig.add_subplot(1, 2, 2)
        n = len(position)
        for key, label, colour, size in CLASSES:
            if key not in classes:
                continue
            idx = classes[key]
            text = f"{label}: {len(idx)} ({100 * len(idx) / max(n, 1):.1f} %)"
            if len(idx) > MAX_DRAWN:
                idx = np.sort(rng.choice(idx, MAX_DRAWN, replace=False))
            p = position[idx]
            ax3.scatter(p[:, 0], p[:, 1], p[:, 2], s=size, c=colour, label=text, depthshade=False,
                        alpha=0.3 if key == "infeasible" else 0.9)
            ax2.scatter(p[:, 0], p[:, 1], s=size, c=colour, alpha=0.3 if key == "infeasible" else 0.9)
        if home is not None:
            ax3.scatter(*home, s=80, c="k", marker="*", label="home")
            ax2.scatter(home[0], home[1], s=80, c="k", marker="*")
        ax3.set_xlabel("x (m)"), ax3.set_ylabel("y (m)"), ax3.set_zlabel("z (m)")
        ax3.invert_zaxis()  # the base frame's z points down: the platform hangs below
        ax3.legend(loc="upper left", fontsize=8, markerscale=3)
        ax2.set_xlabel("x (m)"), ax2.set_ylabel("y (m)"), ax2.set_aspect("equal")
        ax2.set_title("top view (all heights)")
        fig.suptitle(title)
        fig.savefig(path)
    finally:
        plt.close(fig)


def plot_sweep(path, labels, metrics, title):
    """Bars of each metric (a name -> list of values per design, fractions in [0, 1]) per
    design (``labels``), to the PNG ``path``."""
    names = list(metrics)
    x = np.arange(len(labels))
    width = 0.8 / max(len(names), 1)
    fig, ax = plt.subplots(figsize=(max(8, 0.6 * len(labels) + 4), 6), dpi=100, layout="constrained")
    try:
        for k, name in enumerate(names):
            values = [np.nan if v is None else v for v in metrics[name]]
            ax.bar(x + (k - (len(names) - 1) / 2) * width, values, width, label=name)
        ax.set_xticks(x, labels, rotation=30, ha="right", fontsize=8)
        ax.set_ylim(0, 1)
        ax.set_ylabel("fraction of the samples")
        ax.legend()
        ax.set_title(title)
        fig.savefig(path)
    finally:
        plt.close(fig)
