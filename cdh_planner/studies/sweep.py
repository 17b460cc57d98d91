"""Design sweeps: the workspace (and optional queries) of every design of a cartesian product.

A SWEEP file (YAML)::

    robot: config/robot2.yaml            # relative to the SWEEP file's folder
    vary:                                # robot.<key of the robot file>: [values], crossed
      robot.tension_max: [[4, 4, 4, 4, 4, 4], [6.58, 6.58, 6.58, 6.58, 6.58, 6.58]]
      robot.load.mass: [0.4, 0.6]
    workspace: {samples: 2000, seed: 1, reach: true, timeout: 5}
    queries: [config/problems/robot2_q2_q3.yaml]   # optional: planned on every design

``workspace.scene`` (a scene file, relative to the SWEEP file's folder) makes every design's
poses feasible only if clear of it, and its plans keep clear (``cdh-planner workspace
--scene``); a query plans in its own problem file's scene. The robot may have any number
of cables (the vary lists then hold that many values per cable key).

Each design is the robot file with the varied values put in; it must be a robot the robot
file's own checks accept (else the file is refused naming ``vary.<key>``). Varying
``robot.load.mass`` without ``robot.load.force`` scales the force to the new weight (its
direction kept): the robot file requires |force| = mass g. Every design is checked before
any is run. The workspace box is the base robot's (``workspace.box``: one box for all, so
the fractions compare) and the orientations tilt about the base robot's default home: every
design is asked about the same poses. Each design plans from its own default home
(``workspace.default_home``).

Output in DIR: ``design_NNNN.json`` per design (its values, metrics, queries and every
pose), ``results.csv`` (one row per design done: the varied keys as columns, then the
metrics), ``sweep.png``. Each file is written whole (a temporary file renamed), one design
at a time, so an interruption loses at most the design in flight; with ``resume`` a design
whose JSON holds the same values and settings is not recomputed.
"""

import copy
import csv
import io
import itertools
import json
import math
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .. import files
from ..errors import InputError, check_finite, check_keys, short_repr
from ..parsing.problem import load_problem
from ..model.robot import FIELDS, GRAVITY, ros_parameters, robot_from_dict
from ..scene.schema import load_scene
from . import workspace as ws

TOP_KEYS = ("robot", "vary", "workspace", "queries")
WORKSPACE_KEYS = ("samples", "seed", "reach", "timeout", "tilt", "box", "scene")
WORKSPACE_DEFAULTS = {"samples": 2000, "seed": 0, "reach": False, "timeout": 10.0,
                      "tilt": math.pi / 6, "box": None, "scene": None}
MAX_DESIGNS = 1000
MAX_VALUES = 100        # per varied key
MAX_QUERIES = 20
MAX_SWEEP_SAMPLES = 100_000  # per design: each design's JSON holds its poses (~20 MB at most)
ROBOT_KEYS = tuple(f.key for f in FIELDS)


@dataclass(frozen=True)
class Design:
    """One point of the product: ``index``, ``values`` (varied key -> value), ``robot``."""

    index: int
    values: dict
    robot: object


@dataclass(frozen=True)
class Sweep:
    source: str
    robot_file: str
    keys: tuple             # the varied keys, in the file's order
    designs: tuple          # Design, in product order (the last key varies fastest)
    workspace: dict         # WORKSPACE_KEYS -> value (tilt rad, box None or (low, high))
    queries: tuple          # (path, Problem)
    base_robot: object      # the robot file's own robot

    def settings(self):
        """What, beside a design's values, its answers depend on (resume compares it)."""
        w = dict(self.workspace)
        w["box"] = None if w["box"] is None else [list(c) for c in w["box"]]
        return {"workspace": w, "queries": [p for p, _ in self.queries]}


def load_sweep(path):
    """Read and check a SWEEP file and every design of it (InputError naming the field)."""
    path = Path(path)
    doc = files.read_yaml_mapping(path, "sweep", "'robot:' and 'vary:'")
    check_keys("", doc, TOP_KEYS, required=("robot", "vary"))
    base = path.parent
    robot_file = _file(base, doc["robot"], "robot")
    mapping = _robot_mapping(robot_file)
    keys, lists = _vary(doc["vary"])
    base_robot = robot_from_dict(copy.deepcopy(mapping), source=str(robot_file))
    workspace = _workspace(doc.get("workspace") or {}, base, base_robot)
    queries = tuple((q, load_problem(_file(base, q, f"queries[{k}]")))
                    for k, q in enumerate(_list("queries", doc["queries"], MAX_QUERIES) if "queries" in doc else ()))
    designs = tuple(_design(k, dict(zip(keys, combo)), mapping, robot_file)
                    for k, combo in enumerate(itertools.product(*lists)))
    sweep = Sweep(str(path), str(robot_file), keys, designs, workspace, queries, base_robot)
    _home(base_robot)  # the orientations tilt about it: refused here if it holds its load nowhere
    if workspace["reach"]:  # before any design runs: the planner accepts the settings
        ws.check_planner(base_robot, design_spec(sweep, designs[0]), design_scene(sweep, designs[0]))
    return sweep


def _file(base, text, field):
    if not isinstance(text, str) or not text or "\x00" in text:
        raise InputError(field, text, "expected the path of a file")
    p = Path(text) if Path(text).is_absolute() else base / text
    if not p.is_file():
        raise InputError(field, text, f"file not found ({p})")
    return p


def _robot_mapping(robot_file):
    params = ros_parameters(files.read_yaml(robot_file, "robot"), str(robot_file))
    if not isinstance(params.get("robot"), dict):
        raise InputError("robot", str(robot_file), "no 'robot:' section under ros__parameters")
    return params["robot"]


def _list(field, value, limit):
    if not isinstance(value, list) or not value:
        raise InputError(field, value, "expected a non-empty list")
    if len(value) > limit:
        raise InputError(field, f"{len(value)} entries", f"at most {limit}")
    return value


def _vary(vary):
    if not isinstance(vary, dict) or not vary:
        raise InputError("vary", vary, "expected a mapping of robot.<key>: [values]")
    keys, lists = [], []
    for key, values in vary.items():
        name = str(key).removeprefix("robot.")
        if not str(key).startswith("robot.") or name not in ROBOT_KEYS:
            raise InputError(f"vary.{key}", values, "unknown key (expected robot.<key> of the "
                                                    f"robot file: {', '.join(ROBOT_KEYS)})")
        keys.append(str(key))
        lists.append(_list(f"vary.{key}", values, MAX_VALUES))
    n = math.prod(len(v) for v in lists)
    if n > MAX_DESIGNS:
        raise InputError("vary", f"{n} designs", f"at most {MAX_DESIGNS} designs (the product of the lists)")
    return tuple(keys), lists


def _workspace(d, base, robot):
    """The ``workspace:`` mapping checked (``scene`` as a path, its file checked against
    ``robot``)."""
    check_keys("workspace", d, WORKSPACE_KEYS)
    w = {**WORKSPACE_DEFAULTS, **d}
    for key in ("samples", "seed"):
        if isinstance(w[key], bool) or not isinstance(w[key], int):
            raise InputError(f"workspace.{key}", w[key], "expected an integer")
    if not 1 <= w["samples"] <= MAX_SWEEP_SAMPLES:
        raise InputError("workspace.samples", w["samples"], f"must be from 1 to {MAX_SWEEP_SAMPLES}")
    if not isinstance(w["reach"], bool):
        raise InputError("workspace.reach", w["reach"], "expected true or false")
    w["timeout"] = check_finite("workspace.timeout", w["timeout"], positive=True)
    w["tilt"] = check_finite("workspace.tilt", w["tilt"])  # rad
    if w["box"] is not None:
        flat = np.asarray(w["box"], dtype=object).ravel().tolist() if isinstance(w["box"], list) else None
        if flat is None or len(flat) != 6 or not all(isinstance(v, (int, float)) and not isinstance(v, bool)
                                                       for v in flat):
            raise InputError("workspace.box", w["box"], "expected [X0, Y0, Z0, X1, Y1, Z1] (m)")
        w["box"] = (tuple(map(float, flat[:3])), tuple(map(float, flat[3:])))
    if w["scene"] is not None:
        w["scene"] = str(_file(base, w["scene"], "workspace.scene"))
        load_scene(w["scene"], robot)  # refused here, naming the scene's field
    return w


def _design(index, values, mapping, robot_file):
    d = copy.deepcopy(mapping)
    for key, value in values.items():
        _put(d, key.removeprefix("robot.").split("."), copy.deepcopy(value))
    if "robot.load.mass" in values and "robot.load.force" not in values:
        _scale_force(d)
    try:
        robot = robot_from_dict(d, source=str(robot_file))
    except InputError as exc:
        key = next((k for k in values if exc.field.startswith(k)), None)
        if key is not None:
            raise InputError(f"vary.{key}", values[key], exc.reason) from None
        key = next((k for k in values if k in str(exc)), None)  # a check of two fields
        raise InputError(f"vary.{key}" if key else "vary", values[key] if key else values,
                         f"design {index}: {exc}") from None
    return Design(index, values, robot)


def _put(d, path, value):
    for name in path[:-1]:
        if not isinstance(d.get(name), dict):
            d[name] = {}
        d = d[name]
    d[path[-1]] = value


def _scale_force(d):
    """The load force along its direction, of magnitude mass g (module docstring)."""
    load = d.get("load") or {}
    try:
        force = np.asarray(load["force"], dtype=float)
        mass = float(load["mass"])
    except (KeyError, TypeError, ValueError):
        return  # robot_from_dict names what is wrong
    norm = float(np.linalg.norm(force))
    if norm > 0 and math.isfinite(mass):
        load["force"] = (force / norm * mass * GRAVITY).tolist()


# ----- running ----------------------------------------------------------------------------
def design_scene(sweep, design):
    """The scene of ``workspace.scene`` for ``design`` (its cable radius the default), or None."""
    path = sweep.workspace["scene"]
    return None if path is None else load_scene(path, design.robot)


def design_spec(sweep, design):
    """The WorkspaceSpec of a design: every design samples the same poses (the sweep's box,
    else the base robot's default; tilts about the base robot's default home orientation),
    and plans from its own default home (clear of the scene)."""
    w = sweep.workspace
    low, high = w["box"] or ws.default_box(sweep.base_robot)
    try:
        home = _home(design.robot, w["scene"])
    except InputError:  # a design that holds its load nowhere: 0 % feasible, nothing planned
        home = _home(sweep.base_robot)
    return ws.WorkspaceSpec(samples=w["samples"], seed=w["seed"], box_low=low, box_high=high,
                            home_position=home[0], home_quaternion=home[1], tilt=w["tilt"],
                            reach=w["reach"], timeout_s=w["timeout"],
                            tilt_about=_home(sweep.base_robot)[1]).check("workspace.")


_HOMES = {}  # (id(robot), scene path) -> (robot, home): default_home takes seconds; asked twice


def _home(robot, scene_path=None):
    key = (id(robot), scene_path)
    if key not in _HOMES or _HOMES[key][0] is not robot:
        scene = None if scene_path is None else load_scene(scene_path, robot)
        _HOMES[key] = (robot, ws.default_home(robot, scene=scene))
    return _HOMES[key][1]


def design_path(out_dir, design):
    return Path(out_dir) / f"design_{design.index:04d}.json"


def done_design(sweep, design, out_dir):
    """The stored JSON of ``design`` if it holds the same values and settings, else None."""
    path = design_path(out_dir, design)
    try:
        doc = json.loads(path.read_text())
    except (OSError, ValueError):
        return None
    same = doc.get("values") == _plain(design.values) and doc.get("settings") == _plain(sweep.settings())
    return doc if same else None


def run_design(sweep, design, executor, progress=None):
    """The JSON document of one design: its workspace (every pose) and its queries."""
    spec = design_spec(sweep, design)
    queries = tuple((p.task, p.settings, p.start, p.goal, p.scene) for _, p in sweep.queries)
    res = ws.run_workspace(design.robot, spec, executor, progress=progress, queries=queries,
                           scene=design_scene(sweep, design))
    answers = dict(executor.map(res.job, [("query", k) for k in range(len(queries))]))
    doc = ws.result_dict(design.robot, res)
    return _plain({"index": design.index, "values": design.values, "settings": sweep.settings(),
                   "metrics": metrics(res, [answers[k] for k in range(len(queries))]),
                   "queries": [{"file": path, **answers[k]} for k, (path, _) in enumerate(sweep.queries)],
                   "workspace": doc})


def metrics(res, answers):
    f, c = res.fractions(), res.counts()
    out = {"feasible_fraction": f["feasible"], "reachable_fraction": f.get("reachable"),
           "reachable_of_feasible": f.get("reachable_of_feasible"), "unknown": c.get("unknown"),
           "seconds": res.seconds["total"]}
    for k, a in enumerate(answers, start=1):
        out[f"query{k}_success"], out[f"query{k}_cost"] = a["success"], a["cost"]
        out[f"query{k}_seconds"] = a["time_s"]
    out["seconds"] = res.seconds["total"] + sum(a["time_s"] for a in answers)
    return out


def run_sweep(sweep, out_dir, executor, resume=False, progress=None, on_design=None):
    """Run every design not done (``resume``), writing its JSON and the CSV after each;
    ``on_design(doc, skipped)`` after each design. Returns the documents in design order."""
    docs = []
    for design in sweep.designs:
        doc = done_design(sweep, design, out_dir) if resume else None
        skipped = doc is not None
        if doc is None:
            doc = run_design(sweep, design, executor, progress)
            write_atomic(design_path(out_dir, design), json.dumps(doc, allow_nan=False) + "\n")
        docs.append(doc)
        write_atomic(Path(out_dir) / "results.csv", results_csv(sweep, docs))
        if progress:
            progress("designs", len(docs), len(sweep.designs))
        if on_design:
            on_design(doc, skipped)
    return docs


def results_csv(sweep, docs):
    """One row per design: design, the varied keys, then the metrics (lists as JSON)."""
    metric_names = list(docs[0]["metrics"]) if docs else []
    out = io.StringIO()
    w = csv.writer(out, lineterminator="\n")
    w.writerow(["design", *sweep.keys, *metric_names])
    for doc in docs:
        w.writerow([doc["index"], *(_cell(doc["values"][k]) for k in sweep.keys),
                    *(_cell(doc["metrics"][m]) for m in metric_names)])
    return out.getvalue()


def _cell(v):
    return json.dumps(v) if isinstance(v, (list, dict)) else "" if v is None else v


def write_atomic(path, text):
    """Write ``text`` to ``path`` whole or not at all: a temporary file beside it, renamed."""
    path = Path(path)
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    try:
        with open(tmp, "w") as f:
            f.write(text)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:  # Ctrl-C or a full disk mid-write: no half file left behind
        tmp.unlink(missing_ok=True)
        raise


def design_label(design_values):
    return ", ".join(f"{k.removeprefix('robot.')}={short_repr(v, 24)}" for k, v in design_values.items())


def _plain(obj):
    """JSON's view of ``obj`` (tuples as lists, non-finite floats as None)."""
    if isinstance(obj, float):
        return obj if math.isfinite(obj) else None
    if isinstance(obj, dict):
        return {str(k): _plain(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_plain(v) for v in obj]
    if isinstance(obj, np.generic):
        return _plain(obj.item())
    return obj
