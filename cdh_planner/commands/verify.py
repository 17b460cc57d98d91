"""``cdh-planner verify``: wrench feasibility of poses and of the motion between them.

    cdh-planner verify ROBOT.yaml POSES.json [--json OUT] [--step S] [--angle-step A]
                       [--scene SCENE.yaml] [--all]

For every pose: feasible or not, normalised margin, binding constraint, cable lengths and
the tension envelope (min / nominal / max over the wrench ellipsoid). For every pair of
consecutive poses, the motion a controller executes (position linear, orientation slerp)
is checked by dense sampling (see cdh_planner.trajectory.path_check): worst point and first
unsafe point. With ``--scene`` (a scene file, cdh_planner/scene/schema.py), a pose or
sample is feasible only if it is also clear of the obstacles and of the other cables: its
margin is the least of the wrench margin and the collision margin (m / 0.1 m, binding
"collision winch_2 / ball"). Exit code 0 if everything is feasible, 1 if some pose or segment is not,
2 for bad input (including a segment that would need more than
``trajectory.path_check.MAX_SEGMENT_SAMPLES`` samples at the given steps). Time and memory
are linear in the number of poses.

``--json OUT`` writes (non-finite numbers as null)::

    {"robot": name, "robot_file": path, "max_step_m": .., "max_step_rad": ..,
     "poses": [{"position", "quaternion", "tau", "feasible", "margin", "binding",
                "lengths", "tension_min", "tension_nominal", "tension_max",
                "position_error_m", "orientation_error_rad"}],
     "segments": [{"from", "to", "feasible", "samples", "unresolved",
                   "worst": {"s", "margin", "binding", "position", "quaternion"},
                   "first_unsafe": null or {same keys}}],
     "all_feasible": bool}

``position_error_m`` (m) and ``orientation_error_rad`` (rad), present when the robot has
``length_error``: the largest platform error the winches' length errors can cause at the
pose (``accuracy.pose_accuracy``, exact over the box of errors).
"""

ORDER = 10  # its place in `cdh-planner --help`
SUMMARY = "check poses and the motion between them for wrench feasibility"
QUICK_EXIT = True  # run() closes what it writes and leaves no thread working (cli._quick_exit)

import dataclasses
import json
import math
from itertools import chain

import numpy as np

from ..accuracy import has_accuracy, pose_accuracy
from ..errors import InputError
from ..wrench import wrench_feasibility
from .. import compiled_json
from .outputs import check_output, write_text
from ..parsing.poses import load_poses, parse_angle, parse_length
from ..model.robot import load_robot
from ..parallel import beside, in_order
from ..scene.margin import combine
from ..scene.schema import default_scene, load_scene
from ..trajectory.path_check import DEFAULT_STEP_M, DEFAULT_STEP_RAD, check_motion

EXIT_OK, EXIT_INFEASIBLE = 0, 1
FULL_REPORT_POSES = 20  # more poses: the text report lists only those not feasible
LISTED_NOT_FEASIBLE = 10  # ... and at most this many poses and segments of them (without --all)


def add_parser(subparsers):
    """Register ``verify`` on the top-level subparsers."""
    p = subparsers.add_parser(
        "verify", help=SUMMARY,
        description="Check each pose and, by dense sampling, the motion between consecutive "
                    "poses (position linear, orientation slerp). Exit 0 if all feasible, 1 if not, "
                    "2 for bad input.")
    p.add_argument("robot", help="robot file (ROS 2 parameters YAML)")
    p.add_argument("poses", help='JSON list of {"position": [x,y,z], "quaternion": [x,y,z,w]} '
                                 'or {"position": [..], "tau": [phi,theta,sigma]} (m, rad)')
    p.add_argument("--json", metavar="OUT", help="also write the results as JSON")
    p.add_argument("--scene", metavar="FILE", help="scene file (YAML, scene: obstacles, cable "
                                                   "radius, platform shape): also check collisions")
    p.add_argument("--all", action="store_true", dest="all_poses",
                   help=f"print every pose and segment in full (default: all of them up to "
                        f"{FULL_REPORT_POSES} poses, beyond that only those not feasible)")
    p.add_argument("--step", default=str(DEFAULT_STEP_M), metavar="S",
                   help="largest position step between samples, m or with unit (default 0.001 = 1 mm)")
    angle_default = f"{np.rad2deg(DEFAULT_STEP_RAD):g}deg"
    p.add_argument("--angle-step", default=angle_default, metavar="A",
                   help=f"largest rotation between samples, rad or deg (default {angle_default})")
    p.set_defaults(func=run)


def run(args):
    """Verify, print the tables, optionally write JSON; exit code 0 / 1."""
    reading = beside(load_poses, args.poses)  # its compiled read beside the robot file's
    robot = load_robot(args.robot)
    poses = reading.result()
    step_m = _positive(parse_length(args.step, "--step"), "--step", args.step)
    step_rad = _positive(parse_angle(args.angle_step, "--angle-step"), "--angle-step", args.angle_step)
    json_out = None if args.json is None else check_output(
        "--json", args.json, inputs=[("the robot file ROBOT", args.robot),
                                     ("the poses file POSES", args.poses)])

    collision = _collision(robot, args.scene)

    feas = wrench_feasibility(robot, poses.positions, R=poses.rotations)
    if collision is not None:  # margins and bindings of wrench feasibility and collision
        margin, binding = combine(feas.margin, feas.binding, collision, poses.positions,
                                  poses.rotations, motion=True)
        feas = dataclasses.replace(feas, margin=margin, binding=binding)
    # the accuracy's kernel beside the dense check (numpy, mostly under the GIL)
    acc = beside(lambda: pose_accuracy(robot, poses.positions, R=poses.rotations,  # the tensions: once
                                       tensions=feas.tension_nominal) if has_accuracy(robot) else None)
    # The segments' ends are the poses (poses.rotations is Rotation.from_quat's): their
    # margins are those above, not evaluated again (wrench_margin's are the same numbers).
    segments = check_motion(robot, poses.positions, poses.quaternions, step_m, step_rad,
                            collision, waypoints=feas)
    ok = bool(np.all(feas.feasible)) and bool(np.all(segments.feasible))
    acc = acc.result()
    print_report(robot, poses, feas, segments, ok, acc,
                 every=args.all_poses or len(poses) <= FULL_REPORT_POSES)
    if json_out:
        write_text("--json", json_out,
                   result_json(robot, poses, feas, segments, ok, step_m, step_rad, acc))
        print(f"wrote {json_out}")
    return EXIT_OK if ok else EXIT_INFEASIBLE


def _positive(value, option, text):
    if value <= 0:
        raise InputError(option, text, "must be positive")
    return value


def result_json(robot, poses, feas, segments, ok, step_m, step_rad, accuracy=None):
    """The JSON document as ``dump_rows`` lays it out (a pose or a segment a line), as an
    iterator of its pieces in order (ASCII bytes, and blocks of rows as uint8 arrays),
    made as they are written: ROWS_PER_BLOCK rows at a time, the next blocks on threads
    meanwhile (``_rows_text``), so memory stays bounded and no 30 MB document is built;
    ``b"".join`` makes the document. Built column by column, each block of rows in one
    pass by compiled C (``compiled_json``: the json module's numbers, the GIL released);
    ``accuracy``: the poses' ``accuracy.Accuracy`` (robots with length_error), or None."""
    return (piece.encode("ascii") if isinstance(piece, str) else piece
            for piece in _layout_pieces({
        "robot": _encode(robot.name), "robot_file": _encode(robot.source),
        "max_step_m": _encode(step_m), "max_step_rad": _encode(step_rad),
        "poses": _rows_text(pose_columns(poses, feas, accuracy)),
        "segments": _rows_text(segment_columns(segments)) if segments else [],
        "all_feasible": _encode(bool(ok))}))


def pose_columns(poses, feas, accuracy=None):
    """The poses' JSON fields, name -> array (first axis the poses), in the file's order."""
    columns = {"position": poses.positions, "quaternion": poses.quaternions, "tau": poses.tau,
               "feasible": feas.feasible, "margin": feas.margin, "binding": feas.binding,
               "lengths": feas.lengths, "tension_min": feas.tension_min,
               "tension_nominal": feas.tension_nominal, "tension_max": feas.tension_max}
    if hasattr(feas, "tension_status"):  # m > 6: whether the band is controller-usable
        columns["tension_status"] = feas.tension_status
    if accuracy is not None:
        columns["position_error_m"] = accuracy.position_m
        columns["orientation_error_rad"] = accuracy.orientation_rad
    return columns


def segment_columns(segments):
    """The segments' JSON fields (``segments``: a path_check.SegmentChecks), name -> array or
    a nested mapping of them (``worst``), or a list of ready texts (``first_unsafe``: null
    for most segments)."""
    worst, n = segments.worst, len(segments)
    first_unsafe = _Texts(["null"] * n)
    for k, point in zip(segments.unsafe_index.tolist(), segments.unsafe):
        first_unsafe[k] = _encode(_point_dict(point))
    return {"from": np.arange(n), "to": np.arange(1, n + 1), "feasible": segments.feasible,
            "samples": segments.samples, "unresolved": segments.unresolved,
            "worst": {"s": worst.s, "margin": worst.margin, "binding": worst.binding,
                      "position": worst.position, "quaternion": worst.quaternion},
            "first_unsafe": first_unsafe}


class _Texts(list):
    """A column given as the JSON text of each entry."""


ROWS_PER_BLOCK = 2048  # rows a block of the JSON: ~3 MB of eight-cable poses


def _rows_text(columns):
    """The JSON object texts of the rows of ``columns`` (name -> array, list of strings,
    nested mapping of them, or a ``_Texts`` of ready texts), as ``layout_rows`` joins
    list entries: an iterator of the texts of blocks of ROWS_PER_BLOCK rows, the next
    blocks made on threads while one is written (``parallel.in_order``; the compiled
    writer releases the GIL)."""
    literals, cols = _row_literals(columns)
    n = len(cols[0])
    return in_order(lambda a, b: _block_text(literals, [_rows(col, a, b) for col in cols]),
                    [(a, min(n, a + ROWS_PER_BLOCK)) for a in range(0, n, ROWS_PER_BLOCK)])


def _rows(col, a, b):
    """Rows a <= r < b of a column."""
    return _Texts(col[a:b]) if isinstance(col, _Texts) else col[a:b]


def _block_text(literals, cols):
    """The rows of the flat columns ``cols`` around ``literals`` (``_row_literals``) joined
    by ROW_SEPARATOR: by the compiled writer (``compiled_json.rows_text``, a uint8 array of
    ASCII), or without its build by the json module (bytes, the same)."""
    cols = [col if isinstance(col, _Texts) else _numbers_or_texts(np.asarray(col))
            for col in cols]
    text = compiled_json.rows_text(literals, cols, ROW_SEPARATOR)
    return _python_rows(literals, cols) if text is None else text


def _numbers_or_texts(arr):
    """A numeric or boolean array as it is; one of strings (binding names: few distinct,
    each encoded once) as the list of its entries' JSON texts."""
    if arr.dtype.kind in "biuf":
        return arr
    values = arr.tolist()
    texts = {v: _encode(v) for v in set(values)}
    return list(map(texts.__getitem__, values))


def _python_rows(literals, cols):
    """``_block_text``'s rows by the json module, entry by entry (no compiled writer)."""
    texts = [col if isinstance(col, list) else list(map(_encode, finite_or_none(col.tolist())))
             for col in cols]
    rows = ("".join(chain.from_iterable(zip(literals, row))) + literals[-1] for row in zip(*texts))
    return ROW_SEPARATOR.join(rows).encode("ascii")


def _row_literals(columns):
    """(the fixed texts of a row's object around its fields, one more than them; the
    fields' columns in order): a row is literals[0] field 0 literals[1] ... literals[F]."""
    literals, cols = ["{"], []
    for i, (key, col) in enumerate(columns.items()):
        literals[-1] += ("" if i == 0 else ", ") + _encode(key) + ": "
        if isinstance(col, dict):
            inner, inner_cols = _row_literals(col)
            literals[-1] += inner[0]
            literals += inner[1:]
            cols += inner_cols
        else:
            literals.append("")
            cols.append(col)
    literals[-1] += "}"
    return literals, cols


def _point_dict(pt):
    return {"s": pt.s, "margin": pt.margin, "binding": pt.binding,
            "position": pt.position.tolist(), "quaternion": pt.quaternion.tolist()}


def dump_rows(doc):
    """``doc`` as JSON text: its top-level keys on their own lines, and each entry of its
    lists (a pose, a segment) on one line; non-finite numbers as null. Written by the C
    encoder: linear and fast for 10^5 poses, unlike ``indent``."""
    return layout_rows({key: list(map(_encode, value)) if isinstance(value, list) else _encode(value)
                        for key, value in doc.items()})


ROW_SEPARATOR = ",\n    "  # between the entries of a list, each on a line of its own


def layout_rows(texts):
    """The JSON text of a mapping ``texts`` (key -> the JSON text of its value, or a list of
    the JSON texts of its entries): a key a line, a list entry a line. One join of all the
    pieces: the text is copied once (30 MB for 20,000 eight-cable poses)."""
    return "".join(_layout_pieces(texts))


def _layout_pieces(texts):
    """The pieces of ``layout_rows``'s text in order (the texts given, and the keys, brackets
    and separators around them), as they come: a list's entries may be an iterator."""
    for i, (key, text) in enumerate(texts.items()):
        yield (",\n  " if i else "{\n  ") + _encode(key) + ": "
        if isinstance(text, str):
            yield text
            continue
        opened = False
        for row in text:
            yield ROW_SEPARATOR if opened else "[\n    "
            opened = True
            yield row
        yield "\n  ]" if opened else "[]"
    yield "\n}\n"


_ENCODER = json.JSONEncoder(allow_nan=False)
MARGIN_RESOLUTION = 12   # decimals: a bisected boundary point's margin is 0 to rounding
# (-1e-16 on one machine, -1e-15 on another); the JSON keeps the computed value


def _encode(value):
    try:
        return _ENCODER.encode(value)
    except ValueError:  # a NaN or an infinity: null
        return _ENCODER.encode(finite_or_none(value))


def finite_or_none(obj):
    """Replace NaN and +-inf floats by None, recursively (JSON has no such numbers)."""
    if isinstance(obj, float):
        return obj if math.isfinite(obj) else None
    if isinstance(obj, list) and all(type(v) is float and math.isfinite(v) for v in obj):
        return obj
    if isinstance(obj, dict):
        return {k: finite_or_none(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [finite_or_none(v) for v in obj]
    return obj


def print_report(robot, poses, feas, segments, ok, accuracy=None, every=True):
    """Human-readable tables on stdout (linear in the number of poses: the arrays are
    turned into Python lists once). ``every``: every pose and segment in full; else only
    the first LISTED_NOT_FEASIBLE poses and segments that are not feasible, and a count of
    the rest."""
    print(f"robot {robot.name} ({robot.source}): {len(poses)} poses, {len(segments)} segments")
    if accuracy is None:
        print("accuracy: not given (the robot file has no robot.length_error)")
    else:
        print(f"accuracy: the largest platform error over winch length errors up to "
              f"{_vec(1e3 * robot.length_error, '.3g')} mm")
    print()
    n_pose_ok = int(np.sum(feas.feasible))
    n_seg_ok = int(np.sum(segments.feasible))
    listed = np.arange(len(poses)) if every else np.flatnonzero(~feas.feasible)[:LISTED_NOT_FEASIBLE]
    seg_listed = (segments if every else
                  [segments[k] for k in np.flatnonzero(~segments.feasible)[:LISTED_NOT_FEASIBLE]])
    if not every:
        print(f"listing only poses and segments that are not feasible, at most "
              f"{LISTED_NOT_FEASIBLE} of each (--all lists every one, --json OUT writes all)")
        print()
    rows = _PoseRows(robot, poses, feas, accuracy, listed)
    lines = []
    for k in range(len(listed)):
        lines.extend(rows.lines(k))
        if len(lines) > 10_000:
            print("\n".join(lines))
            lines = []
    if lines:
        print("\n".join(lines))
    for s in seg_listed:
        _print_segment(s)
    if not every:
        _print_least_margin(feas, segments)
    verdict = "ALL FEASIBLE" if ok else "NOT FEASIBLE"
    print(f"summary: {n_pose_ok}/{len(poses)} poses and {n_seg_ok}/{len(segments)} segments "
          f"feasible: {verdict}")


class _PoseRows:
    """The report lines of the poses ``listed`` (indices), from Python lists made once;
    ``lines(k)`` is the k-th listed pose's."""

    def __init__(self, robot, poses, feas, accuracy, listed):
        self.index, self.feasible = listed.tolist(), feas.feasible[listed].tolist()
        self.margin = feas.margin[listed].tolist()
        self.accuracy = None if accuracy is None else (accuracy.position_m[listed].tolist(),
                                                       accuracy.orientation_rad[listed].tolist())
        self.binding = [str(b) for b in feas.binding[listed]]
        self.p, self.q, self.tau = (a[listed].tolist() for a in (poses.positions, poses.quaternions, poses.tau))
        self.lengths, self.f_min = feas.lengths[listed].tolist(), feas.tension_min[listed].tolist()
        self.f_nom, self.f_max = feas.tension_nominal[listed].tolist(), feas.tension_max[listed].tolist()
        self.cables = [(name, f"d ({robot.length_min[c]:g}, {robot.length_max[c]:g}) "
                              f"f ({robot.tension_min[c]:g}, {robot.tension_max[c]:g})")
                       for c, name in enumerate(robot.winch_names)]

    def lines(self, i):
        state = "feasible" if self.feasible[i] else "NOT FEASIBLE"
        out = [f"pose {self.index[i]}: {state}, margin {_num(self.margin[i], '+.4f')}, binding {self.binding[i]}",
               f"  position {_vec(self.p[i], '.4f')} m, quaternion {_vec(self.q[i], '.4f')}, "
               f"tau {_vec(self.tau[i], '.4f')} rad",
               *self.accuracy_line(i),
               f"  {'cable':<10} {'length m':>9} {'f_min N':>9} {'f_nom N':>9} {'f_max N':>9}   limits"]
        for c, (name, lim) in enumerate(self.cables):
            out.append(f"  {name:<10} {self.lengths[i][c]:9.4f} {_num(self.f_min[i][c], '9.4f')} "
                       f"{_num(self.f_nom[i][c], '9.4f')} {_num(self.f_max[i][c], '9.4f')}   {lim}")
        out.append("")
        return out


    def accuracy_line(self, i):
        """The pose's accuracy line (none without length_error)."""
        if self.accuracy is None:
            return []
        e_p, e_w = self.accuracy[0][i], self.accuracy[1][i]
        return [f"  accuracy: position error {_num(1e3 * e_p, '.4g')} mm, orientation error "
                f"{_num(1e3 * e_w, '.4g')} mrad"]


def _print_least_margin(feas, segments):
    """The pose and the segment point of least margin (the report that lists few poses)."""
    i = int(np.argmin(feas.margin))
    print(f"least margin: pose {i} {_num(float(feas.margin[i]), '+.4f')} ({feas.binding[i]})")
    if segments:
        s = segments[int(np.argmin(segments.worst.margin))]
        print(f"  segment {s.index_from} -> {s.index_to} {_point_text(s.worst)}")
    print()


def _print_segment(s):
    state = "feasible" if s.feasible else "NOT FEASIBLE"
    note = f", {s.unresolved} intervals unresolved" if s.unresolved else ""
    print(f"segment {s.index_from} -> {s.index_to}: {state} ({s.samples} samples{note})")
    print(f"  worst        {_point_text(s.worst)}")
    if s.first_unsafe is not None:
        print(f"  first unsafe {_point_text(s.first_unsafe)}")
    print()


def _point_text(pt):
    margin = round(pt.margin, MARGIN_RESOLUTION) if math.isfinite(pt.margin) else pt.margin
    return (f"s = {pt.s:.4f}  margin {_num(margin, '+.4g')}  {pt.binding}  "
            f"p {_vec(pt.position, '.4f')}  q {_vec(pt.quaternion, '.4f')}")


def _num(x, fmt):
    width = fmt.split(".")[0].lstrip("+")
    return f"{x:{fmt}}" if math.isfinite(x) else f"{'-inf' if x < 0 else 'inf' if x > 0 else 'nan':>{width or 1}}"


def _vec(v, fmt):
    return "[" + ", ".join(f"{x:{fmt}}" for x in v) + "]"


def _collision(robot, scene_file):
    """The CollisionModel of ``--scene`` (without it: of the robot's platform shape, if it
    declares one, else None; the collision library loads only then)."""
    scene = load_scene(scene_file, robot) if scene_file else default_scene(robot)
    if scene is None:
        return None
    from ..scene.collision import CollisionModel
    return CollisionModel(robot, scene)
