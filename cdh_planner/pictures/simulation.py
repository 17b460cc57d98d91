"""Pictures of a plan run on the simulated robot (``cdh-planner simulate --plot``, the demo's
execution picture): per cable the measured tension (line) over the plan's published envelope
(band: tension_min .. tension_max at the waypoints) and the robot's limits (dashed).
matplotlib with the Agg backend; prints nothing."""

import numpy as np

from .slices import DPI, plt

SIZE = (1400, 900)   # px


def plot_measured_tensions(robot, t_wp, low, high, t, tension, out, title="", size=SIZE):
    """Per cable (one panel each): the envelope band between ``low`` and ``high`` (N, m) N at
    waypoint times ``t_wp`` (N,) s, the measured ``tension`` (M, m) N at times ``t`` (M,) s,
    and the limits; written to ``out`` (PNG)."""
    m = tension.shape[1]
    cols = 2 if m <= 8 else 4
    rows = int(np.ceil(m / cols))
    fig = plt.figure(figsize=(size[0] / DPI, size[1] / DPI), dpi=DPI, layout="constrained")
    try:
        axes = np.atleast_1d(fig.subplots(rows, cols, sharex=True)).ravel()
        for i in range(m):
            ax = axes[i]
            ax.fill_between(t_wp, low[:, i], high[:, i], color="tab:green", alpha=0.35, lw=0,
                            label="published envelope" if i == 0 else None)
            ax.plot(t, tension[:, i], color="black", lw=0.9,
                    label="measured (load cell)" if i == 0 else None)
            for limit in (robot.tension_min[i], robot.tension_max[i]):
                ax.axhline(limit, color="red", ls="--", lw=0.8)
            lo = min(np.min(tension[:, i]), np.min(low[:, i]))
            hi = max(np.max(tension[:, i]), np.max(high[:, i]))
            pad = 0.1 * (hi - lo) + 1e-9
            ax.set_ylim(lo - pad, hi + pad)
            ax.set_title(robot.winch_names[i], fontsize="small")
            ax.set_ylabel("tension (N)")
        for ax in axes[m:]:
            ax.set_visible(False)
        for ax in axes[max(0, m - cols):m]:
            ax.set_xlabel("time (s)")
        axes[0].legend(fontsize="small", loc="best")
        fig.suptitle(title or "measured tensions over the planned envelope; dashed: limits "
                              "(shown where in view)")
        fig.savefig(out, dpi=DPI, format="png")
    finally:
        plt.close(fig)
