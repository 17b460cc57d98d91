"""Pictures of 2-D slices of the wrench-feasible C-space (like the paper's Fig. 9 / 13).

A slice view picks two of a task's free coordinates as picture axes and holds the task's
other free coordinates at given values. Every grid cell is classified with the closed-form
feasibility test:

- green: wrench-feasible (in C);
- orange: some cable length out of range (this rule wins when a tension is also out of
  range: the geometry alone already excludes the pose);
- blue: lengths in range but some tension bound violated (including singular J, where
  the tension envelope is unbounded);
- purple, with accuracy limits (``accuracy.AccuracyLimits``): wrench-feasible but the
  winches' length errors can move the platform beyond a limit (outside what a plan with
  those settings may use).

Red curves are det J = 0 (the zero contour of det J over the grid, computed with no
constraint on lengths or tensions, as in the paper). Axes are in radians for angles and
metres for positions. matplotlib with the Agg backend (no display needed).
"""

import re
from dataclasses import dataclass, field
from typing import Optional

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402  (after selecting the backend)
import numpy as np  # noqa: E402
from matplotlib.colors import ListedColormap  # noqa: E402
from matplotlib.lines import Line2D  # noqa: E402
from matplotlib.patches import Patch  # noqa: E402
from matplotlib.ticker import FuncFormatter, MultipleLocator  # noqa: E402

from ..wrench import wrench_feasibility  # noqa: E402
from ..model.pose import rotation_tt  # noqa: E402
from ..model.task import COORDINATES  # noqa: E402

FEASIBLE, LENGTH_OUT, TENSION_OUT, COLLISION, INACCURATE = 0, 1, 2, 3, 4
# green, orange, blue, dark grey, purple
CLASS_COLORS = ("#4daf4a", "#ff8c1a", "#3778bf", "#4d4d4d", "#b05cc6")
CLASS_LABELS = ("wrench-feasible (C)", "a cable length out of range (whatever the tensions)",
                "a tension out of range (lengths in range)",
                "in collision (closer than the scene's clearance, whatever the wrench)",
                "wrench-feasible, outside the accuracy limit (winch length errors)")
SINGULAR_COLOR = "#e41a1c"
SEGMENT_COLOR = "black"
CHUNK = 20_000  # poses per feasibility call (bounds memory)
DPI = 100

@dataclass(frozen=True)
class SliceView:
    """Two picture axes among ``task.names``; the task's other coordinates held at
    ``held`` (name -> value, m or rad); ``ranges`` ((lo, hi), (lo, hi)) of the axes."""

    task: object
    axes: tuple
    ranges: tuple
    held: dict = field(default_factory=dict)

    def coords(self, a, b):
        """Task coordinates (M, k) of picture points (a, b) (arrays of M values)."""
        a, b = np.broadcast_arrays(np.asarray(a, dtype=float), np.asarray(b, dtype=float))
        cols = []
        for name in self.task.names:
            if name == self.axes[0]:
                cols.append(a.ravel())
            elif name == self.axes[1]:
                cols.append(b.ravel())
            else:
                cols.append(np.full(a.size, self.held[name]))
        return np.stack(cols, axis=1)


@dataclass(frozen=True)
class SliceGrid:
    """Cell centres ``xs`` (nx,), ``ys`` (ny,); per cell (ny, nx): ``classes``
    (FEASIBLE, LENGTH_OUT, TENSION_OUT, COLLISION), ``margin`` (normalised, -inf singular),
    ``det_j``; ``scene``: whether collisions were checked; ``accuracy``: the
    AccuracyLimits checked (INACCURATE cells), or None."""

    view: SliceView
    xs: np.ndarray
    ys: np.ndarray
    classes: np.ndarray
    margin: np.ndarray
    det_j: np.ndarray
    scene: bool = False
    accuracy: object = None


def classify(feas):
    """Class of each pose of a Feasibility: FEASIBLE, LENGTH_OUT (wins) or TENSION_OUT."""
    length_out = np.any(feas.margins[:, :2, :] <= 0, axis=(1, 2))
    return np.where(feas.feasible, FEASIBLE, np.where(length_out, LENGTH_OUT, TENSION_OUT))


def compute_slice(robot, view, resolution=400, collision=None, accuracy=None):
    """Classify a resolution x resolution grid of cell centres over the view's ranges;
    with ``collision`` (a scene's CollisionModel) a pose closer than the scene's clearance
    is COLLISION, whatever its wrench feasibility; with ``accuracy``
    (``accuracy.AccuracyLimits``) a feasible pose beyond a limit is INACCURATE."""
    (x0, x1), (y0, y1) = view.ranges
    xs = _cell_centres(x0, x1, resolution)
    ys = _cell_centres(y0, y1, resolution)
    A, B = np.meshgrid(xs, ys)
    p, tau = view.task.pose(view.coords(A, B))
    n = p.shape[0]
    classes = np.empty(n, dtype=np.int8)
    margin, det = np.empty(n), np.empty(n)
    for a in range(0, n, CHUNK):
        f = wrench_feasibility(robot, p[a:a + CHUNK], R=rotation_tt(tau[a:a + CHUNK]))
        classes[a:a + CHUNK] = classify(f)
        margin[a:a + CHUNK], det[a:a + CHUNK] = f.margin, f.det_j
        if accuracy is not None:
            _mark_inaccurate(classes[a:a + CHUNK], accuracy, robot, p[a:a + CHUNK],
                             rotation_tt(tau[a:a + CHUNK]))
        if collision is not None:
            hit = collision.margins(p[a:a + CHUNK], rotation_tt(tau[a:a + CHUNK]))[0] < 0
            classes[a:a + CHUNK][hit] = COLLISION
    shape = A.shape
    return SliceGrid(view=view, xs=xs, ys=ys, classes=classes.reshape(shape),
                     margin=margin.reshape(shape), det_j=det.reshape(shape),
                     scene=collision is not None, accuracy=accuracy)


def _mark_inaccurate(classes, accuracy, robot, p, R):
    """Set the FEASIBLE entries of ``classes`` (in place) whose poses (p, R) are beyond the
    AccuracyLimits ``accuracy`` to INACCURATE."""
    ok = classes == FEASIBLE
    if ok.any():
        beyond = accuracy.margins(robot, p[ok], R[ok])[0] < 0
        classes[np.flatnonzero(ok)[beyond]] = INACCURATE


def _cell_centres(lo, hi, n):
    h = (hi - lo) / n
    return lo + h * (np.arange(n) + 0.5)


@dataclass(frozen=True)
class Marker:
    """A labelled point (a, b) in picture coordinates."""

    label: str
    a: float
    b: float


@dataclass(frozen=True)
class SegmentOverlay:
    """The straight segment start -> goal in picture coordinates; ``first_unsafe_s`` is
    the fraction where it first leaves C (None if it stays inside)."""

    start: tuple
    goal: tuple
    first_unsafe_s: Optional[float] = None


def plot_slice(grid, path, size=(1000, 800), title=None, markers=(), segment=None):
    """Draw the classified slice to a PNG of exactly ``size`` = (width, height) pixels."""
    fig = plt.figure(figsize=(size[0] / DPI, size[1] / DPI), dpi=DPI, layout="constrained")
    try:
        ax = fig.add_subplot()
        _draw_classes(ax, grid)
        has_singular = _draw_singular(ax, grid)
        if segment is not None:
            _draw_segment(ax, segment)
        for m in markers:
            _draw_marker(ax, m, grid.view)
        _label_axes(ax, grid.view)
        (x0, x1), (y0, y1) = grid.view.ranges
        ax.set_xlim(x0, x1)  # markers or a segment outside the ranges must not widen the view
        ax.set_ylim(y0, y1)
        if title:
            ax.set_title(title)
        shown = [FEASIBLE, LENGTH_OUT, TENSION_OUT] + [COLLISION] * grid.scene + (
            [INACCURATE] if grid.accuracy is not None else [])
        handles = [Patch(color=CLASS_COLORS[k], label=_class_label(k, grid)) for k in shown]
        if has_singular:
            handles.append(Line2D([], [], color=SINGULAR_COLOR, lw=1.5, label=r"$\det J = 0$"))
        if segment is not None:
            handles.append(Line2D([], [], color=SEGMENT_COLOR, lw=1.5, ls="--",
                                  label="straight segment"))
            if segment.first_unsafe_s is not None:
                handles.append(Line2D([], [], color=SEGMENT_COLOR, marker="X", ls="none",
                                      label=f"leaves C at {100 * segment.first_unsafe_s:.1f} %"))
        fig.legend(handles=handles, loc="outside lower center", ncol=3, fontsize="small")
        fig.savefig(path, dpi=DPI, format="png")
    finally:
        plt.close(fig)


def _class_label(k, grid):
    """The legend's label of class k (INACCURATE names the limits)."""
    if k != INACCURATE:
        return CLASS_LABELS[k]
    a = grid.accuracy
    limits = [f"{1e3 * a.position_m:g} mm"] * (a.position_m > 0) + [
        f"{1e3 * a.orientation_rad:g} mrad"] * (a.orientation_rad > 0)
    return f"wrench-feasible, error over {' / '.join(limits)} (winch length errors)"


def _draw_classes(ax, grid):
    (x0, x1), (y0, y1) = grid.view.ranges
    ax.imshow(grid.classes, origin="lower", extent=(x0, x1, y0, y1), aspect="auto",
              cmap=ListedColormap(CLASS_COLORS), vmin=-0.5, vmax=len(CLASS_COLORS) - 0.5,
              interpolation="nearest")


def _draw_singular(ax, grid):
    """det J = 0 curves; False when det J has no sign change on the grid."""
    det = grid.det_j
    if not (np.nanmin(det) < 0 < np.nanmax(det)):
        return False
    ax.contour(grid.xs, grid.ys, det, levels=[0.0], colors=SINGULAR_COLOR, linewidths=1.2)
    return True


def _draw_segment(ax, seg):
    (a0, b0), (a1, b1) = seg.start, seg.goal
    ax.plot([a0, a1], [b0, b1], color=SEGMENT_COLOR, lw=1.5, ls="--")
    if seg.first_unsafe_s is not None:
        s = seg.first_unsafe_s
        ax.plot(a0 + s * (a1 - a0), b0 + s * (b1 - b0), marker="X", color=SEGMENT_COLOR,
                markersize=10, markeredgecolor="white", ls="none")


def _draw_marker(ax, m, view):
    (x0, x1), (y0, y1) = view.ranges
    inside = x0 <= m.a <= x1 and y0 <= m.b <= y1
    # Unclipped inside the ranges so that a point on the edge (a pole) shows whole.
    ax.plot(m.a, m.b, marker="o", markersize=8, color="white", markeredgecolor="black",
            ls="none", clip_on=not inside)
    if not inside:
        return
    # Labels go above right, or below right near the top edge (where the title is).
    dy = -16 if m.b > y1 - 0.08 * (y1 - y0) else 7
    ax.annotate(_math_label(m.label), (m.a, m.b), textcoords="offset points", xytext=(7, dy),
                fontsize="large", fontweight="bold",
                bbox=dict(boxstyle="round,pad=0.15", fc="white", ec="none", alpha=0.8))


def _math_label(label):
    """'q_s' is drawn as q with subscript s; other labels as given."""
    match = re.fullmatch(r"([A-Za-z]+)_([A-Za-z0-9]+)", label)
    return f"${match[1]}_{{{match[2]}}}$" if match else label


def _label_axes(ax, view):
    for name, axis, (lo, hi) in zip(view.axes, (ax.xaxis, ax.yaxis), view.ranges):
        c = COORDINATES[name]
        axis.set_label_text(f"{c.label or name} ({c.unit})")
        if c.unit == "rad":
            base = _pi_tick_base(hi - lo)
            if base:
                axis.set_major_locator(MultipleLocator(base))
                axis.set_major_formatter(FuncFormatter(_pi_formatter(base)))


def _pi_tick_base(span):
    """Tick spacing (rad) as a fraction of pi giving 4 to 12 ticks, or None."""
    for k in (1, 2, 4, 8, 16):
        if 4 <= span / (np.pi / k) <= 12:
            return np.pi / k
    return None


def _pi_formatter(base):
    """Tick labels as multiples of pi: -pi, -3pi/4, 0, pi/8, ..."""
    den = int(round(np.pi / base))

    def fmt(value, _pos):
        num = int(round(value / base))
        if num == 0:
            return "0"
        g = np.gcd(num, den)
        n, d = num // g, den // g
        sign = "-" if n < 0 else ""
        mag = "" if abs(n) == 1 else str(abs(n))
        return f"${sign}{mag}\\pi$" if d == 1 else f"${sign}{mag}\\pi/{d}$"

    return fmt
