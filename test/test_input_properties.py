"""Property-based tests of the input files (hypothesis): whatever a robot, pose or problem
file holds (random YAML-ish text, random bytes, random structures, mutations of the
shipped files), loading it either succeeds or raises InputError, and the CLI exits 0, 1
or 2 with at most one line on stderr and never a traceback.

Bounded for the default run: few examples each, a deadline per example, derandomized
(the same examples every run, no example database written). A deeper, random search:
``CDH_PROPERTY_SCALE=50 pytest test/test_input_properties.py`` (50x the examples).
"""
import contextlib
import copy
import io
import json
import math
import os
import tempfile
import warnings
from datetime import timedelta
from pathlib import Path

import pytest
import yaml
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from cdh_planner import cli
from cdh_planner.errors import MAX_MESSAGE_CHARS, InputError
from cdh_planner.files import parse_yaml
from cdh_planner.parsing.poses import load_poses
from cdh_planner.parsing.problem import load_problem
from cdh_planner.model.robot import load_robot

from conftest import CONFIG, PROBLEMS

ROBOT_FILES = sorted(CONFIG.glob("*.yaml"))
PROBLEM_FILES = sorted(PROBLEMS.glob("*.yaml"))
POSES = [{"position": [0.0, 0.0, 0.35], "tau": [0.0, 0.1, 0.0]},
         {"position": [0.01, 0.0, 0.34], "quaternion": [0.0, 0.0, 0.0, 1.0]}]


SCALE = int(os.environ.get("CDH_PROPERTY_SCALE", "1"))


def bounded(n, seconds=5):
    return settings(max_examples=n * SCALE, deadline=timedelta(seconds=seconds), derandomize=SCALE == 1,
                    database=None, suppress_health_check=[HealthCheck.too_slow,
                                                          HealthCheck.data_too_large])


WORKDIR = Path(tempfile.mkdtemp(prefix="cdh_properties_"))


def write(name, content):
    path = WORKDIR / name
    if isinstance(content, bytes):
        path.write_bytes(content)
    else:
        path.write_text(content)
    return path


def loads_or_refuses(load, path):
    """``load(path)`` returns or raises InputError with a one-line message, nothing else,
    and no numeric warning (overflow, invalid value) on the way."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        try:
            load(path)
        except InputError as exc:
            text = str(exc)
            assert "\n" not in text and len(text) <= MAX_MESSAGE_CHARS, text
    numeric = [w for w in caught if issubclass(w.category, RuntimeWarning)]
    assert not numeric, [str(w.message) for w in numeric]


def cli_contract(argv, codes=(0, 1, 2)):
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err), \
            warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)  # a numeric warning is a failure
        rc = cli.main([str(a) for a in argv])
    lines = err.getvalue().splitlines()
    assert rc in codes, (rc, err.getvalue())
    assert "Traceback" not in err.getvalue() + out.getvalue()
    assert len(lines) <= 1, err.getvalue()
    if rc == 2:
        assert len(lines) == 1 and lines[0].startswith("cdh-planner: error: ")
    return rc


# ----------------------------------------------------------------------------- strategies

SCALARS = (st.none() | st.booleans() | st.integers(-10**30, 10**30)
           | st.floats(allow_nan=True, allow_infinity=True)
           | st.text(st.characters(blacklist_categories=("Cs",)), max_size=12)
           | st.sampled_from(["0.1", "1e308", "-1e-300", ".nan", "-.inf", "", "load", "sphere",
                              "~", "yes", "0x1F", "1_000", "2020-01-01"]))
KEYS = st.sampled_from(["robot", "task", "type", "center", "radius", "fixed", "start", "goal",
                        "lambda", "position", "tau", "quaternion", "planner", "base_anchors",
                        "platform_anchors", "load", "force", "matrix", "wrench_ellipsoid",
                        "ros__parameters", "cdh_planner", "poses", "x", "sigma"]) \
    | st.text(st.characters(blacklist_categories=("Cs",)), max_size=8)
VALUES = st.recursive(SCALARS, lambda inner: st.lists(inner, max_size=8)
                      | st.dictionaries(KEYS, inner, max_size=6), max_leaves=40)
YAML_TEXT = st.text(alphabet=st.sampled_from(list("[]{}:,-&*!|>'\"#%@`?\n\t abxyz019.e+_~")) |
                    st.characters(blacklist_categories=("Cs",)), max_size=300)


def _paths(doc, prefix=()):
    """Every (path, value) of a nested document."""
    yield prefix, doc
    if isinstance(doc, dict):
        for k, v in doc.items():
            yield from _paths(v, prefix + (k,))
    elif isinstance(doc, list):
        for i, v in enumerate(doc):
            yield from _paths(v, prefix + (i,))


def _set(doc, path, value, delete=False):
    node = doc
    for k in path[:-1]:
        node = node[k]
    if delete:
        del node[path[-1]]
    else:
        node[path[-1]] = value


@st.composite
def mutated(draw, doc):
    """``doc`` with 1 to 3 random mutations: a value replaced (by a random one, its string
    form, a huge or tiny multiple, another plausible number), a key deleted or added, a
    list shortened or grown (by a random value or a copy of an entry)."""
    doc = copy.deepcopy(doc)
    for _ in range(draw(st.integers(1, 3))):
        paths = [p for p, _ in _paths(doc) if p]
        if not paths:
            break
        path = draw(st.sampled_from(paths))
        node = doc
        for k in path:
            node = node[k]
        action = draw(st.sampled_from(["replace", "string", "scale", "delete", "add", "resize",
                                       "number", "number"]))
        if action == "number" and isinstance(node, (int, float)) and not isinstance(node, bool):
            _set(doc, path, draw(st.floats(-1.0, 1.0) | st.floats(-1e3, 1e3) | st.just(0.0)))
        elif action == "replace":
            _set(doc, path, draw(VALUES))
        elif action == "string":
            _set(doc, path, str(node))
        elif action == "scale" and isinstance(node, (int, float)) and not isinstance(node, bool):
            _set(doc, path, node * draw(st.sampled_from([1e300, -1e300, 1e-300, 0, -1, 1e6])))
        elif action == "delete" and isinstance(path[-1], str):
            _set(doc, path, None, delete=True)
        elif action == "add" and isinstance(node, dict):
            node[draw(KEYS)] = draw(VALUES)
        elif action == "resize" and isinstance(node, list):
            how = draw(st.sampled_from(["pop", "copy", "append"]))
            if node and how == "pop":
                node.pop(draw(st.integers(0, len(node) - 1)))
            elif node and how == "copy":
                node.append(copy.deepcopy(node[draw(st.integers(0, len(node) - 1))]))
            else:
                node.append(draw(VALUES))
    return doc


def _yaml(doc):
    return yaml.safe_dump(doc, allow_unicode=True)


def _robot_docs():
    return [yaml.safe_load(p.read_text()) for p in ROBOT_FILES]


def _problem_docs():
    docs = []
    for p in PROBLEM_FILES:
        doc = yaml.safe_load(p.read_text())
        doc["robot"] = str((p.parent / doc["robot"]).resolve())
        docs.append(doc)
    return docs


ROBOT_DOCS = _robot_docs()
PROBLEM_DOCS = _problem_docs()
LOADERS = [load_robot, load_problem, load_poses]


# ----------------------------------------------------------------------------- loaders

@bounded(60)
@given(text=YAML_TEXT)
def test_random_text_loads_or_is_refused(text):
    path = write("text.yaml", text)
    for load in LOADERS:
        loads_or_refuses(load, path)


@bounded(30)
@given(data=st.binary(max_size=300))
def test_random_bytes_load_or_are_refused(data):
    path = write("bytes.yaml", data)
    for load in LOADERS:
        loads_or_refuses(load, path)


@bounded(60)
@given(doc=VALUES)
def test_random_structures_load_or_are_refused(doc):
    for name, text in (("s.yaml", _yaml(doc)), ("s.json", json.dumps(doc))):
        path = write(name, text)
        for load in LOADERS:
            loads_or_refuses(load, path)


@bounded(80)
@given(data=st.data())
def test_mutated_robot_files_load_or_are_refused(data):
    doc = data.draw(mutated(data.draw(st.sampled_from(ROBOT_DOCS))))
    loads_or_refuses(load_robot, write("robot.yaml", _yaml(doc)))


@bounded(80)
@given(data=st.data())
def test_mutated_problem_files_load_or_are_refused(data):
    doc = data.draw(mutated(data.draw(st.sampled_from(PROBLEM_DOCS))))
    loads_or_refuses(load_problem, write("problem.yaml", _yaml(doc)))


@bounded(60)
@given(doc=mutated(POSES), as_mapping=st.booleans())
def test_mutated_pose_files_load_or_are_refused(doc, as_mapping):
    doc = {"poses": doc} if as_mapping else doc
    loads_or_refuses(load_poses, write("poses.json", json.dumps(doc)))


@bounded(40)
@given(text=YAML_TEXT)
def test_parse_yaml_returns_plain_data_or_refuses(text):
    try:
        doc = parse_yaml(text, "x")
    except InputError:
        return
    for _, value in _paths(doc):
        assert value is None or isinstance(value, (bool, int, float, str, bytes, list, dict)) \
            or type(value).__module__ == "datetime", type(value)


# ----------------------------------------------------------------------------- the CLI

@bounded(25, seconds=20)
@given(data=st.data())
def test_verify_cli_contract(data):
    robot = data.draw(st.sampled_from(ROBOT_DOCS))
    if data.draw(st.booleans()):
        robot = data.draw(mutated(robot))
    poses = data.draw(mutated(POSES)) if data.draw(st.booleans()) else POSES
    robot_file = write("cli_robot.yaml", _yaml(robot))
    poses_file = write("cli_poses.json", json.dumps(poses))
    cli_contract(["verify", robot_file, poses_file])


COORD = st.floats(-0.6, 0.6) | st.floats(-1e3, 1e3) | st.just(0.0)
ANGLE = st.floats(-6.28, 6.28)
POSE = st.one_of(
    st.builds(lambda p, t: {"position": p, "tau": t}, st.lists(COORD, min_size=3, max_size=3),
              st.tuples(ANGLE, st.floats(0.0, math.pi), ANGLE).map(list)),
    st.builds(lambda p, q: {"position": p, "quaternion": [x / math.sqrt(sum(y * y for y in q)) for x in q]},
              st.lists(COORD, min_size=3, max_size=3),
              st.lists(st.floats(-1.0, 1.0), min_size=4, max_size=4).filter(
                  lambda q: sum(x * x for x in q) > 1e-6)))


@bounded(25, seconds=20)
@given(poses=st.lists(POSE, min_size=1, max_size=6).flatmap(
           lambda ps: st.lists(st.sampled_from(ps), min_size=1, max_size=8)),
       robot=st.sampled_from(ROBOT_FILES), step=st.sampled_from(["1mm", "1cm", "0.1"]))
def test_verify_cli_contract_on_plausible_poses(poses, robot, step):
    """Valid numbers anywhere in the bounds, repeated poses included: 0, 1 or 2 (a segment
    over the sample cap), no numeric warning."""
    poses_file = write("plausible.json", json.dumps(poses))
    cli_contract(["verify", robot, poses_file, "--step", step])


@bounded(12, seconds=30)
@given(data=st.data())
def test_plan_cli_contract(data):
    doc = data.draw(mutated(data.draw(st.sampled_from(PROBLEM_DOCS))))
    problem = write("cli_problem.yaml", _yaml(doc))
    cli_contract(["plan", "--quiet", problem, "--max-charts", "40", "--timeout", "3"])


def test_the_shipped_files_pass_the_same_checks():
    for path in ROBOT_FILES:
        loads_or_refuses(load_robot, path)
        load_robot(path)
    for path in PROBLEM_FILES:
        load_problem(path)
    assert math.isfinite(load_problem(PROBLEM_FILES[0]).settings.timeout_s)


@pytest.fixture(scope="module", autouse=True)
def _cleanup():
    yield
    for path in WORKDIR.glob("*"):
        path.unlink()
    WORKDIR.rmdir()
