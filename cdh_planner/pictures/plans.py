"""Pictures of a planning query (``cdh-planner plan --plot OUT.png``).

``plot_plan(planner, problem, result, out)`` writes

- ``out``: for tasks with two free coordinates, the atlas and the path over the C-space
  slice of the task (like the paper's Figs. 10 and 13). The background is the slice of
  ``pictures.slices`` (green feasible, orange a length out of range, blue a tension out of range,
  red det J = 0). Every chart is drawn as its domain mapped to task coordinates (its ball
  cut by its neighbours' half-spaces, s -> x = centre + basis s -> pose -> task coordinates; the
  tangent-space polygon, not projected on M, which is what the atlas covers to first
  order): closed charts light shaded with thin outlines (the explored part of the slice),
  open charts in gold, frontier charts (touching the variable domain's boundary, or where
  Newton could not reach) in purple; chart centres as small dots. The path is a black line
  with a white halo, broken where it wraps across +-pi, and start and goal are the white
  markers of the slice pictures. For tasks with 3 or 6 free coordinates (free torsion,
  free flight) this picture is skipped: a slice through a 3-D atlas would show a thin,
  misleading cut of it.
- ``<out stem>_tensions.png``: the tension envelope along the path, for any task, when
  there is a path: per cable, the band [tension_min, tension_max] (every wrench of the
  ellipsoid K is balanced with tensions inside it), the nominal tension f0 and the
  cable's tension limits, against time (s) of the time-parameterised path (waypoint index
  if the path carries no timing).

Periodic task coordinates (phi, sigma, alpha1) are drawn in [-pi, pi): a polygon is
unwrapped around its chart centre and drawn a second time shifted by 2 pi when it
straddles the edge. Prints nothing; matplotlib with the Agg backend.

``plot_paths`` (paths over a slice) and ``plot_execution`` (streamed cable lengths and tension
envelopes over time) draw what a node answered and streamed, with the same pieces.
"""

import contextlib
import itertools
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..atlas.domain import outline_2d
from . import slices
from .slices import DPI, Marker, SliceView, compute_slice, plt
from ..model.pose import wrap_angle
from ..model.task import COORDINATES
from ..search.strategies import STRATEGIES

TWO_PI = 2.0 * np.pi
CLOSED_FACE, CLOSED_EDGE = "white", "#303030"
OPEN_COLOR = "#ffd21f"  # gold
FRONTIER_COLOR = "#b03cff"  # purple
CENTRE_COLOR = "#202020"
PATH_COLOR = "black"
ATLAS_SIZE = (1000, 800)
TENSION_SIZE = (1200, 800)
PATHS_SIZE = (1000, 600)
EXECUTION_SIZE = (1000, 700)
PATH_COLORS = (PATH_COLOR, "#7b2cbf")
BAND_COLOR = "#3778bf"
ZOOM_SHARE = 0.4
CLASS_LABELS = ("wrench-feasible (C)", "a cable length out of range", "a tension out of range")


# ----- small geometric helpers (tested on their own) -----------------------------------
def wrap(values, periodic):
    """Periodic columns of ``values`` (N, k) wrapped to [-pi, pi); others unchanged."""
    out = np.array(values, dtype=float, copy=True)
    per = np.asarray(periodic, dtype=bool)
    out[..., per] = wrap_angle(out[..., per])
    return out


def unwrap_about(points, centre, periodic):
    """``points`` (V, k) moved by multiples of 2 pi on periodic columns so that each lies
    within pi of ``centre`` (k,): a polygon around its chart centre, drawn in one piece."""
    points = np.asarray(points, dtype=float)
    centre = np.asarray(centre, dtype=float)
    return centre + wrap(points - centre, periodic)


def order_by_angle(points, centre=None):
    """``points`` (V, 2) in counter-clockwise order of their angle around ``centre``
    (default: their mean): the polygon of a convex set's vertices."""
    points = np.asarray(points, dtype=float)
    c = points.mean(axis=0) if centre is None else np.asarray(centre, dtype=float)
    d = points - c
    return points[np.argsort(np.arctan2(d[:, 1], d[:, 0]), kind="stable")]


def wrap_copies(polygon, periodic, lo=-np.pi, hi=np.pi):
    """The polygon (V, k) and its copies shifted by -+2 pi on each periodic column where it
    crosses ``lo`` or ``hi``: what to draw so that a picture over [lo, hi) shows it whole."""
    polygon = np.asarray(polygon, dtype=float)
    shifts = []
    for j, per in enumerate(periodic):
        options = [0.0]
        if per and polygon[:, j].min() < lo:
            options.append(TWO_PI)
        if per and polygon[:, j].max() > hi:
            options.append(-TWO_PI)
        shifts.append(options)
    return [polygon + np.array(s) for s in itertools.product(*shifts)]


def split_at_wraps(y, periodic):
    """A path (N, k) in wrapped coordinates as pieces to draw as lines: a new piece starts
    where a periodic coordinate jumps across +-pi, and each piece is extended by the
    wrapped step across the edge (so the line reaches the edge on both sides)."""
    y = np.asarray(y, dtype=float)
    if len(y) < 2:
        return [y.copy()]
    step = np.diff(y, axis=0)
    wrapped_step = wrap(step, periodic)
    jumps = np.flatnonzero(np.any(np.abs(step - wrapped_step) > 1e-9, axis=1))
    pieces, begin, head = [], 0, None
    for k in jumps:
        piece = y[begin:k + 1]
        if head is not None:
            piece = np.vstack([head, piece])
        pieces.append(np.vstack([piece, y[k] + wrapped_step[k]]))
        head = y[k + 1] - wrapped_step[k]
        begin = k + 1
    last = y[begin:]
    pieces.append(last if head is None else np.vstack([head, last]))
    return pieces


# ----- the atlas in task coordinates ----------------------------------------------------
def chart_polygons(planner):
    """Per chart: (kind, centre (k,), polygon (V, k) or None) in task coordinates, kind one
    of "closed", "open", "frontier"; polygons unwrapped around their centres and ordered
    by angle in the chart's tangent space (exact for its convex polytope)."""
    task, pose = planner.task, planner.constraint.pose
    periodic = task.periodic
    out = []
    for chart in planner.atlas.charts:
        centre = wrap(task.coords(*pose(chart.x))[0], periodic)
        kind = "frontier" if chart.frontier else ("closed" if chart.closed else "open")
        if chart.basis.shape[1] != 2:
            out.append((kind, centre, None))
            continue
        s = outline_2d(chart.domain)
        poses = [pose(chart.x + chart.basis @ v) for v in s]
        y = task.coords(np.array([p for p, _ in poses]), np.array([t for _, t in poses]))
        out.append((kind, centre, unwrap_about(y, centre, periodic)))
    return out


def plot_plan(planner, problem, result, out, resolution=400):
    """Write the pictures of a query (module docstring); returns the PNG paths written."""
    out = Path(out)
    written = []
    task = planner.task
    if len(task.names) == 2:
        plot_atlas(planner, problem, result, out, resolution=resolution)
        written.append(str(out))
    if result.path is not None:
        tensions = out.with_name(out.stem + "_tensions.png")
        plot_tensions(problem, result, tensions)
        written.append(str(tensions))
    return written


def plot_atlas(planner, problem, result, out, resolution=400, size=ATLAS_SIZE):
    """The atlas, path, start and goal over the slice of a 2-D task (module docstring)."""
    task = planner.task
    names = tuple(task.names)
    periodic = task.periodic
    polygons = chart_polygons(planner)
    ends = wrap(task.coords(np.array([problem.start.p, problem.goal.p]),
                            np.array([problem.start.tau, problem.goal.tau])), periodic)
    path = None
    if result.path is not None:
        path = wrap(task.coords(result.path.p, result.path.tau), periodic)
    data = [ends] + [c[None] for _, c, _ in polygons] + [p for _, _, p in polygons if p is not None]
    if path is not None:
        data.append(path)
    data = np.vstack(data)
    ranges = zoom(tuple(axis_range(name, data[:, j]) for j, name in enumerate(names)), data)
    view = SliceView(task=task, axes=names, ranges=ranges)
    grid = compute_slice(problem.robot, view, resolution)

    with _slice_picture(grid, out, size, _title(planner, problem, result)) as (ax, handles):
        _draw_atlas(ax, polygons, periodic, ranges)
        if path is not None:
            _draw_path(ax, path, periodic)
        for label, (a, b) in zip(("start", "goal"), ends):
            slices._draw_marker(ax, Marker(label, a, b), view)
        handles += _chart_handles(polygons, path is not None)


def axis_range(name, values):
    """Picture range of a task coordinate: [-pi, pi) for periodic ones; for theta and
    alpha2 the default range, or its half holding all ``values`` (the sphere task's lower
    hemisphere, as in the paper's Fig. 13); positions: the values with a 10 % border."""
    values = np.asarray(values, dtype=float)
    values = values[np.isfinite(values)]
    c = COORDINATES.get(name)
    if c is not None and c.bounds is not None:
        lo, hi = c.bounds
        if c.periodic or values.size == 0:
            return lo, hi
        mid = 0.5 * (lo + hi)
        if values.min() >= mid - 1e-9:
            return mid, hi
        if values.max() <= mid + 1e-9:
            return lo, mid
        return lo, hi
    lo, hi = (values.min(), values.max()) if values.size else (-1.0, 1.0)
    pad = max(0.1 * (hi - lo), 1e-3)
    return lo - pad, hi + pad


def zoom(ranges, data, share=ZOOM_SHARE):
    """``ranges`` narrowed to the ``data`` (N, 2) with a border when the data cover less
    than ``share`` of both ranges (a small atlas, like the sphere task's, would be a thin
    strip otherwise); the border is a quarter of the data's extent, at least 0.15 (rad or m)
    but never beyond the original ranges."""
    data = np.asarray(data, dtype=float)
    data = data[np.all(np.isfinite(data), axis=1)]
    if data.size == 0:
        return ranges
    lo, hi = data.min(axis=0), data.max(axis=0)
    if not all(h - l < share * (r1 - r0) for l, h, (r0, r1) in zip(lo, hi, ranges)):
        return ranges
    pad = np.maximum(0.25 * (hi - lo), 0.15)
    return tuple((max(r0, l - p), min(r1, h + p)) for l, h, p, (r0, r1) in zip(lo, hi, pad, ranges))


def _draw_atlas(ax, polygons, periodic, ranges):
    from matplotlib.collections import PolyCollection

    style = {"closed": (CLOSED_FACE, 0.35, CLOSED_EDGE, 0.4),
             "open": (OPEN_COLOR, 0.45, "#8a6d00", 0.6),
             "frontier": (FRONTIER_COLOR, 0.55, "#5a1080", 0.6)}
    for kind in ("closed", "open", "frontier"):
        verts = []
        for k, _, poly in polygons:
            if k == kind and poly is not None:
                verts.extend(wrap_copies(poly, periodic, lo=-np.pi, hi=np.pi))
        if verts:
            face, alpha, edge, lw = style[kind]
            ax.add_collection(PolyCollection(verts, facecolors=face, edgecolors=edge,
                                             linewidths=lw, alpha=alpha, zorder=2))
            ax.add_collection(PolyCollection(verts, facecolors="none", edgecolors=edge,
                                             linewidths=lw, zorder=2.1))
    centres = np.array([c for _, c, _ in polygons])
    if centres.size:
        ax.plot(centres[:, 0], centres[:, 1], ls="none", marker="o", markersize=1.6,
                color=CENTRE_COLOR, zorder=2.2)


@contextlib.contextmanager
def _slice_picture(grid, out, size, title):
    """Yield (axes showing the classified slice of ``grid``, its legend entries); at the
    end label the axes, limit them to the view, and write ``out`` with the legend below."""
    fig = plt.figure(figsize=(size[0] / DPI, size[1] / DPI), dpi=DPI, layout="constrained")
    try:
        ax = fig.add_subplot()
        slices._draw_classes(ax, grid)
        handles = _class_handles(slices._draw_singular(ax, grid))
        yield ax, handles
        slices._label_axes(ax, grid.view)
        ax.set_xlim(*grid.view.ranges[0])  # markers outside must not widen the view
        ax.set_ylim(*grid.view.ranges[1])
        ax.set_title(title)
        fig.legend(handles=handles, loc="outside lower center", ncol=3, fontsize="small")
        fig.savefig(out, dpi=DPI, format="png")
    finally:
        plt.close(fig)


def _chart_handles(polygons, has_path):
    from matplotlib.lines import Line2D
    from matplotlib.patches import Patch

    handles = []
    counts = {k: sum(1 for kind, _, _ in polygons if kind == k) for k in ("closed", "open", "frontier")}
    handles.append(Patch(facecolor="#e8e8e8", edgecolor=CLOSED_EDGE, lw=0.6,
                         label=f"closed charts ({counts['closed']}): explored"))
    handles.append(Patch(facecolor=OPEN_COLOR, edgecolor="#8a6d00", lw=0.6,
                         label=f"open charts ({counts['open']})"))
    handles.append(Patch(facecolor=FRONTIER_COLOR, alpha=0.6, edgecolor="#5a1080", lw=0.6,
                         label=f"frontier charts ({counts['frontier']})"))
    if has_path:
        handles.append(Line2D([], [], color=PATH_COLOR, lw=2.2, label="planned path"))
    return handles


def _class_handles(has_singular):
    from matplotlib.lines import Line2D
    from matplotlib.patches import Patch

    handles = [Patch(color=c, label=l) for c, l in zip(slices.CLASS_COLORS, CLASS_LABELS)]
    if has_singular:
        handles.append(Line2D([], [], color=slices.SINGULAR_COLOR, lw=1.5, label=r"$\det J = 0$"))
    return handles


def _draw_path(ax, path, periodic, color=PATH_COLOR):
    """A path (N, 2) in wrapped picture coordinates, with a white halo, broken at the wraps."""
    for piece in split_at_wraps(path, periodic):
        ax.plot(piece[:, 0], piece[:, 1], color="white", lw=4.5, solid_capstyle="round")
        ax.plot(piece[:, 0], piece[:, 1], color=color, lw=2.2, solid_capstyle="round")


def _title(planner, problem, result):
    head = problem.description or problem.robot.name
    strategy = STRATEGIES[result.strategy].label if result.strategy in STRATEGIES else result.strategy
    outcome = "path found" if result.success else f"no path ({result.reason})"
    tail = f"{strategy}: {outcome}, {result.charts} charts, {result.time_s:.2f} s"
    if result.path is not None:
        tail += f", {len(result.path)} waypoints"
    return f"{head}\n{tail}"


# ----- the tension envelope ---------------------------------------------------------------
def plot_tensions(problem, result, out, size=TENSION_SIZE):
    """Per cable: tension band [min, max], nominal and limits along the path."""
    path, robot = result.path, problem.robot
    t = np.asarray(path.t, dtype=float)
    timed = t.size > 1 and np.all(np.isfinite(t)) and t[-1] > 0
    x = t if timed else np.arange(len(path), dtype=float)
    fig = plt.figure(figsize=(size[0] / DPI, size[1] / DPI), dpi=DPI, layout="constrained")
    try:
        axes = fig.subplots(2, 3, sharex=True)
        for i, ax in enumerate(axes.ravel()):
            lo, hi = robot.tension_min[i], robot.tension_max[i]
            _draw_envelope(ax, x, path.tension_min[:, i], path.tension_nominal[:, i],
                           path.tension_max[:, i], labels=("envelope [min, max]", "nominal $f_0$"))
            ax.axhline(lo, color="#e41a1c", ls="--", lw=1.2, label="tension limits")
            ax.axhline(hi, color="#e41a1c", ls="--", lw=1.2)
            span = hi - lo
            top = max(hi, float(np.max(path.tension_max[:, i])))
            bottom = min(lo, float(np.min(path.tension_min[:, i])))
            ax.set_ylim(bottom - 0.06 * span, top + 0.06 * span)
            ax.set_xlim(x[0], x[-1])
            name = robot.winch_names[i] if i < len(robot.winch_names) else ""
            label = f"cable {i + 1}" + (f" ({name})" if name and name != f"winch_{i + 1}" else "")
            least = float(min(np.min(path.tension_min[:, i]) - lo, hi - np.max(path.tension_max[:, i])))
            width = float(np.max(path.tension_max[:, i] - path.tension_min[:, i]))
            ax.set_title(f"{label}: band width \u2264 {width:.3g} N, "
                         f"slack \u2265 {least:.3g} N", fontsize="small")
            if i % 3 == 0:
                ax.set_ylabel("tension (N)")
            if i >= 3:
                ax.set_xlabel("time (s)" if timed else "waypoint")
            ax.grid(alpha=0.3)
        handles, labels = axes[0, 0].get_legend_handles_labels()
        fig.legend(handles, labels, loc="outside lower center", ncol=3, fontsize="small")
        head = problem.description or robot.name
        fig.suptitle(f"{head}\ntension envelope along the planned path ({len(path)} waypoints"
                     + (f", {t[-1]:.2f} s)" if timed else ")")
                     + "; slack: least distance from the band to a limit")
        fig.savefig(out, dpi=DPI, format="png")
    finally:
        plt.close(fig)


def _draw_envelope(ax, x, low, nominal, high, color=BAND_COLOR, nominal_color="black",
                   labels=(None, None)):
    """A tension band [low, high] with its edges, and the nominal tension as a line."""
    ax.fill_between(x, low, high, color=color, alpha=0.3, lw=0, label=labels[0])
    ax.plot(x, low, color=color, lw=0.8)
    ax.plot(x, high, color=color, lw=0.8)
    ax.plot(x, nominal, color=nominal_color, lw=1.5, label=labels[1])


# ----- plans and executions received from the node (the demo) ------------------------------
def plot_paths(robot, view, paths, out, markers=(), segment=None, periodic=(False, False),
               title="", resolution=300, size=PATHS_SIZE):
    """Paths (label -> (N, 2) picture coordinates) over the classified slice of ``view``,
    broken where a ``periodic`` axis wraps, with ``markers`` (slices.Marker) and the straight
    ``segment`` (slices.SegmentOverlay)."""
    from matplotlib.lines import Line2D

    grid = compute_slice(robot, view, resolution)
    with _slice_picture(grid, out, size, title) as (ax, handles):
        if segment is not None:
            slices._draw_segment(ax, segment)
            leaves = ("" if segment.first_unsafe_s is None
                      else f", leaves C at {100 * segment.first_unsafe_s:.1f} %")
            handles.append(Line2D([], [], color=slices.SEGMENT_COLOR, lw=1.5, ls="--",
                                  label=f"straight segment{leaves}"))
        for (label, y), color in zip(paths.items(), itertools.cycle(PATH_COLORS)):
            _draw_path(ax, wrap(y, periodic), periodic, color)
            handles.append(Line2D([], [], color=color, lw=2.2, label=label))
        for m in markers:
            slices._draw_marker(ax, m, view)


@dataclass(frozen=True)
class ExecutedMotion:
    """A motion as executed: its waypoints' times ``t`` (N,) s, cable ``lengths`` (N, 6) m
    and tension ``envelope`` (N, 6, 3) N (min, nominal, max); the executed cable lengths
    ``executed`` (M, 6) m (the streamed commands, or the winches' measured joint states) at
    ``executed_t`` (M,) s from the first, and which of the two they are (``how``);
    ``tensions`` (M, 6) N: the tensions measured with them (a simulated or real robot's load
    cells, the joint states' effort), or None."""

    t: np.ndarray
    lengths: np.ndarray
    envelope: np.ndarray
    executed_t: np.ndarray
    executed: np.ndarray
    how: str = "streamed"
    tensions: np.ndarray = None


def plot_execution(robot, motions, out, size=EXECUTION_SIZE):
    """Motions (label -> ExecutedMotion) one after the other: above, per cable, the executed
    lengths (lines: streamed commands, or measured) through the waypoints' lengths (dots);
    below, the tension envelopes (bands, nominal as a line); dashed: the robot's limits."""
    fig = plt.figure(figsize=(size[0] / DPI, size[1] / DPI), dpi=DPI, layout="constrained")
    try:
        top, bottom = fig.subplots(2, 1, sharex=True)
        colors = plt.get_cmap("tab10")
        offset = 0.0
        for k, (label, m) in enumerate(motions.items()):
            for i in range(m.lengths.shape[1]):
                top.plot(offset + m.executed_t, m.executed[:, i], color=colors(i), lw=1.2,
                         label=robot.winch_names[i] if k == 0 else None)
                top.plot(offset + m.t, m.lengths[:, i], ".", color=colors(i), ms=3)
                _draw_envelope(bottom, offset + m.t, *m.envelope[:, i].T, color=colors(i),
                               nominal_color=colors(i))
                if m.tensions is not None:
                    bottom.plot(offset + m.executed_t, m.tensions[:, i], color="black", lw=0.7,
                                ls=(0, (2, 1)), label="measured" if (k, i) == (0, 0) else None)
            top.axvline(offset, color="grey", lw=0.8, ls=":")
            top.annotate(f"{label} ({m.how})", (offset, 1), xycoords=("data", "axes fraction"),
                         xytext=(4, -14), textcoords="offset points")
            offset += m.t[-1] + 0.5
        for ax, low, high in ((top, robot.length_min, robot.length_max),
                              (bottom, robot.tension_min, robot.tension_max)):
            ax.axhline(np.min(low), color="black", ls="--", lw=0.8)
            ax.axhline(np.max(high), color="black", ls="--", lw=0.8)
        top.set_ylabel("cable length (m)")
        top.set_title("executed cable lengths (lines) through the trajectory's waypoints "
                      "(dots); dashed: limits")
        top.legend(ncol=6, fontsize="small", loc="lower right")
        bottom.set_ylabel("tension (N)")
        bottom.set_xlabel("time (s)")
        measured = any(m.tensions is not None for m in motions.values())
        bottom.set_title("tension envelope over the wrench ellipsoid: nominal (line), "
                         "min..max (band); dashed: limits"
                         + ("\nblack dotted: measured tensions (load cells)" if measured else ""))
        fig.savefig(out, dpi=DPI, format="png")
    finally:
        plt.close(fig)


def plot_dynamics(robot, timing, tensions, out, title="", size=TENSION_SIZE):
    """Top: the tension envelope [f - v, f + v] over time of the cable nearest a limit,
    with the motion's own accelerations (dynamic) and without (static), and the limits.
    Bottom: the path speed s'(s) against its limit curve (the largest feasible s').
    ``tensions``: ``trajectory.dynamics.tensions_over_time`` of ``timing``."""
    t, f, f0, v = tensions
    slack = np.minimum(f - v - robot.tension_min, robot.tension_max - f - v)
    i = int(np.argmin(np.min(slack, axis=0)))
    fig = plt.figure(figsize=(size[0] / DPI, size[1] / DPI), dpi=DPI, layout="constrained")
    try:
        top, bottom = fig.subplots(2, 1)
        top.fill_between(t, f0[:, i] - v[:, i], f0[:, i] + v[:, i], color="#bbbbbb", alpha=0.6,
                         label="static (quasi-static model)")
        top.fill_between(t, f[:, i] - v[:, i], f[:, i] + v[:, i], color=BAND_COLOR, alpha=0.5,
                         label="dynamic (m c'' and rotational terms)")
        for limit in (robot.tension_min[i], robot.tension_max[i]):
            top.axhline(limit, color="#e41a1c", ls="--", lw=1.2)
        lower = np.min(f[:, i] - v[:, i] - robot.tension_min[i]) < np.min(robot.tension_max[i] - f[:, i] - v[:, i])
        near = robot.tension_min[i] if lower else robot.tension_max[i]  # zoom on the binding limit
        data = np.concatenate([f[:, i] - v[:, i], f[:, i] + v[:, i], f0[:, i] - v[:, i], f0[:, i] + v[:, i], [near]])
        pad = 0.05 * (np.max(data) - np.min(data))
        top.set_ylim(np.min(data) - pad, np.max(data) + pad)
        top.set_xlabel("time (s)")
        top.set_ylabel(f"cable {i + 1} tension (N)")
        top.set_title(f"cable {i + 1} (nearest a limit): least slack {np.min(slack[:, i]):.3g} N "
                      f"with dynamics; duration {timing.duration:.3f} s", fontsize="small")
        top.legend(loc="best", fontsize="small")
        top.grid(alpha=0.3)
        bottom.plot(timing.s, timing.limit, color="#e41a1c", lw=1.2, label="limit curve (largest feasible s')")
        bottom.plot(timing.s, timing.sd, color="black", lw=1.8, label="s'(s), time-optimal (TOPP-RA)")
        bottom.set_xlabel("path parameter s (m: |dp| + L |d angle|)")
        bottom.set_ylabel("s' (m/s)")
        bottom.set_ylim(0, 1.15 * float(np.max(timing.sd)) if np.max(timing.sd) > 0 else 1)
        bottom.legend(loc="best", fontsize="small")
        bottom.grid(alpha=0.3)
        fig.suptitle(title or "dynamic timing", fontsize="medium")
        fig.savefig(out, dpi=DPI, format="png")
    finally:
        plt.close(fig)
