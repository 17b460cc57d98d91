"""Bad robot and pose files: an InputError naming the field and value, and through the CLI
exit code 2 with a one-line message and no traceback."""
import copy
import json
import subprocess
import sys
from dataclasses import dataclass

import numpy as np
import pytest
import yaml

from cdh_planner import cli
from cdh_planner.errors import InputError
from cdh_planner.fields import MATRIX, NUMBER, NUMBERS, REQUIRED, read
from cdh_planner.parsing.poses import load_poses
from cdh_planner.model import robot_schema
from cdh_planner.model.robot import FIELDS, OPTIONAL_GROUPS, Robot, load_robot, read_yaml, \
    robot_from_dict, ros_parameters

from conftest import REPO as ROOT
ROBOT1 = ROOT / "config" / "robot1.yaml"
GOOD_POSES = [{"position": [0.0, 0.0, 0.35], "tau": [-2.3, 1.6, 0.5934]}]


def robot_doc():
    return yaml.safe_load(ROBOT1.read_text())


def set_robot(doc, key_path, value):
    """doc with robot.<key_path> (dotted) set to value; value None deletes the key."""
    d = doc["cdh_planner"]["ros__parameters"]["robot"]
    *parents, last = key_path.split(".")
    for k in parents:
        d = d[k]
    if value is None:
        del d[last]
    else:
        d[last] = value
    return doc


def asym_matrix():
    E = np.diag([1e4, 1e4, 1e4, 1e10, 1e10, 1e10])
    E[0, 1] = 5.0
    return E.ravel().tolist()


# (id, key path, new value, expected field, text expected in the message)
BAD_ROBOTS = [
    ("five_anchors", "base_anchors", [0.1, 0.2, 0.0] * 5, "robot.base_anchors", "expected 18 numbers, got 15"),
    ("five_platform_anchors", "platform_anchors", [0.1, 0.2, 0.0] * 5, "robot.platform_anchors", "got 15"),
    ("dmin_ge_dmax", "length_min", [0.1, 0.1, 0.6, 0.1, 0.1, 0.1], "robot.length_min[2]", "must be below robot.length_max[2]"),
    ("dmin_eq_dmax", "length_min", [0.55] * 6, "robot.length_min[0]", "must be below"),
    ("fmin_ge_fmax", "tension_min", [0.05, 0.05, 0.05, 0.05, 0.7, 0.05], "robot.tension_min[4]", "must be below robot.tension_max[4]"),
    ("negative_dmin", "length_min", [-0.1, 0.1, 0.1, 0.1, 0.1, 0.1], "robot.length_min[0]", "must be positive"),
    ("negative_fmin", "tension_min", [0.05, -0.05, 0.05, 0.05, 0.05, 0.05], "robot.tension_min[1]", "must be non-negative"),
    ("negative_fmax", "tension_max", [0.5, 0.5, -0.5, 0.5, 0.5, 0.5], "robot.tension_max[2]", "must be positive"),
    ("E_not_symmetric", "wrench_ellipsoid.matrix", asym_matrix(), "robot.wrench_ellipsoid.matrix", "symmetric"),
    ("E_not_positive_definite", "wrench_ellipsoid.matrix", [1e4, 1e4, -1e4, 1e10, 1e10, 1e10],
     "robot.wrench_ellipsoid.matrix", "positive definite"),
    ("E_singular", "wrench_ellipsoid.matrix", [1e4, 1e4, 0.0, 1e10, 1e10, 1e10],
     "robot.wrench_ellipsoid.matrix", "positive definite"),
    ("nan_length", "length_max", [0.55, 0.55, float("nan"), 0.55, 0.55, 0.55], "robot.length_max[2]", "finite"),
    ("inf_force", "load.force", [0.0, 0.0, float("inf")], "robot.load.force[2]", "finite"),
    ("minus_inf_anchor", "base_anchors", [float("-inf")] + [0.0] * 17, "robot.base_anchors[0]", "finite"),
    ("unknown_robot_key", "lenght_max", [0.55] * 6, "robot.lenght_max", "unknown key"),
    ("unknown_load_key", "load.density", 1.0, "robot.load.density", "unknown key"),
    ("mass_not_the_weight", "load.mass", 1.0, "robot.load.mass", "must be its weight"),
    ("negative_mass", "load.mass", -0.6, "robot.load.mass", "must be positive"),
    ("inertia_without_mass", "load.inertia", [0.001, 0.001, 0.001], "robot.load.inertia", "needs robot.load.mass"),
    ("unknown_ellipsoid_key", "wrench_ellipsoid.centre", [0.0] * 6, "robot.wrench_ellipsoid.centre", "unknown key"),
    ("missing_tension_max", "tension_max", None, "robot.tension_max", "missing"),
    ("stiffness_below_tension_max", "cable_stiffness", [1000.0, 1000.0, 0.4, 1000.0, 1000.0, 1000.0],
     "robot.cable_stiffness[2]", "must exceed robot.tension_max[2]"),
    ("zero_stiffness", "cable_stiffness", 0.0, "robot.cable_stiffness[0]", "must be positive"),
    ("nan_stiffness", "cable_stiffness", float("nan"), "robot.cable_stiffness[0]", "finite"),
    ("absurd_stiffness", "cable_stiffness", 1e12, "robot.cable_stiffness[0]", "1e+10"),
    ("seven_stiffnesses", "cable_stiffness", [1000.0] * 7, "robot.cable_stiffness", "expected 6 numbers"),
    ("negative_length_error", "length_error", -1e-4, "robot.length_error[0]", "must be non-negative"),
    ("negative_least_stiffness", "least_stiffness", -1.0, "robot.least_stiffness", "must be non-negative"),
    ("length_error_over_range", "length_error", [1e-4, 1e-4, 1e-4, 1e-4, 0.5, 1e-4], "robot.length_error[4]",
     "below the cable's length range"),
    ("text_instead_of_number", "length_max", [0.55, "long", 0.55, 0.55, 0.55, 0.55], "robot.length_max[1]",
     "expected a number"),
]

BAD_POSES = [
    ("zero_quaternion", [{"position": [0, 0, 0.35], "quaternion": [0, 0, 0, 0]}], "poses[0].quaternion", "zero"),
    ("non_normalised_quaternion", [GOOD_POSES[0], {"position": [0, 0, 0.35], "quaternion": [0, 0, 0.5, 0.5]}],
     "poses[1].quaternion", "not normalised"),
    ("empty_list", [], "poses", "empty"),
    ("empty_mapping_list", {"poses": []}, "poses", "empty"),
    ("nan_position", [{"position": [0, float("nan"), 0.35], "tau": [0, 0, 0]}], "poses[0].position[1]", "finite"),
    ("inf_tau", [{"position": [0, 0, 0.35], "tau": [0, 0, float("inf")]}], "poses[0].tau[2]", "finite"),
    ("short_position", [{"position": [0, 0.35], "tau": [0, 0, 0]}], "poses[0].position", "expected 3 numbers"),
    ("long_quaternion", [{"position": [0, 0, 0.35], "quaternion": [0, 0, 0, 1, 0]}], "poses[0].quaternion", "expected 4"),
    ("missing_position", [{"tau": [0, 0, 0]}], "poses[0].position", "missing"),
    ("both_orientations", [{"position": [0, 0, 0.35], "tau": [0, 0, 0], "quaternion": [0, 0, 0, 1]}],
     "poses[0]", "exactly one"),
    ("no_orientation", [{"position": [0, 0, 0.35]}], "poses[0]", "exactly one"),
    ("unknown_pose_key", [{"position": [0, 0, 0.35], "tau": [0, 0, 0], "speed": 1}], "poses[0].speed", "unknown key"),
    ("theta_in_degrees", [{"position": [0, 0, 0.35], "tau": [0, 90, 0]}], "poses[0].tau[1]", "[0, pi]"),
    ("boolean_number", [{"position": [0, 0, True], "tau": [0, 0, 0]}], "poses[0].position[2]", "number"),
    ("not_a_list", {"poses": 3}, "poses", "list"),
    ("unknown_top_key", {"poses": GOOD_POSES, "robot": "x"}, "robot", "unknown key"),
]


@pytest.fixture
def good_poses(tmp_path):
    path = tmp_path / "poses.json"
    path.write_text(json.dumps(GOOD_POSES))
    return path


def write_bad_robot(tmp_path, key_path, value):
    doc = set_robot(copy.deepcopy(robot_doc()), key_path, value)
    path = tmp_path / "bad_robot.yaml"
    path.write_text(yaml.safe_dump(doc))
    return path


def test_the_shipped_robot_files_load():
    for name in ("robot1.yaml", "robot2.yaml"):
        robot = load_robot(ROOT / "config" / name)
        assert robot.base_anchors.shape == (6, 3)


@pytest.mark.parametrize("case", BAD_ROBOTS, ids=[c[0] for c in BAD_ROBOTS])
def test_bad_robot_file_names_field_and_value(tmp_path, case):
    _, key_path, value, field, text = case
    path = write_bad_robot(tmp_path, key_path, value)
    with pytest.raises(InputError) as exc:
        load_robot(path)
    assert exc.value.field == field
    assert text in str(exc.value)
    assert str(exc.value).startswith(f"{field} = ")


@pytest.mark.parametrize("case", BAD_ROBOTS, ids=[c[0] for c in BAD_ROBOTS])
def test_bad_robot_file_through_cli(tmp_path, good_poses, capsys, case):
    _, key_path, value, field, text = case
    path = write_bad_robot(tmp_path, key_path, value)
    assert cli.main(["verify", str(path), str(good_poses)]) == 2
    out = capsys.readouterr()
    assert_one_line_error(out.err, field, text)
    assert "Traceback" not in out.out + out.err


@pytest.mark.parametrize("case", BAD_POSES, ids=[c[0] for c in BAD_POSES])
def test_bad_pose_file_names_field(tmp_path, case):
    _, doc, field, text = case
    path = tmp_path / "poses.json"
    path.write_text(json.dumps(doc))
    with pytest.raises(InputError) as exc:
        load_poses(path)
    assert exc.value.field == field
    assert text in str(exc.value)


@pytest.mark.parametrize("case", BAD_POSES, ids=[c[0] for c in BAD_POSES])
def test_bad_pose_file_through_cli(tmp_path, capsys, case):
    _, doc, field, text = case
    path = tmp_path / "poses.json"
    path.write_text(json.dumps(doc))
    assert cli.main(["verify", str(ROBOT1), str(path)]) == 2
    out = capsys.readouterr()
    assert_one_line_error(out.err, field, text)
    assert "Traceback" not in out.out + out.err


def test_not_json_and_missing_files(tmp_path, capsys):
    bad = tmp_path / "poses.json"
    bad.write_text("[{position: 1}")
    assert cli.main(["verify", str(ROBOT1), str(bad)]) == 2
    assert "not valid JSON" in capsys.readouterr().err
    assert cli.main(["verify", str(tmp_path / "none.yaml"), str(bad)]) == 2
    assert "file not found" in capsys.readouterr().err


def test_subprocess_exit_code_and_stderr(tmp_path, good_poses):
    path = write_bad_robot(tmp_path, "base_anchors", [0.1, 0.2, 0.0] * 5)
    proc = subprocess.run([sys.executable, "-m", "cdh_planner.cli", "verify", str(path), str(good_poses)],
                          capture_output=True, text=True, cwd=ROOT, timeout=60)
    assert proc.returncode == 2
    assert "Traceback" not in proc.stderr
    assert_one_line_error(proc.stderr, "robot.base_anchors", "expected 18 numbers, got 15")


def assert_one_line_error(err, field, text):
    lines = err.splitlines()
    assert len(lines) == 1, err
    assert lines[0].startswith(f"cdh-planner: error: {field} = "), err
    assert text in lines[0]


# ------------------------------------------------------------------ the declaration (schema)

def _robot_block():
    """Robot 1's robot: block, read as load_robot reads it (YAML 1.2: 1.0e4 is a number)."""
    return ros_parameters(read_yaml(ROBOT1, "robot"), str(ROBOT1))["robot"]


def test_winch_names_give_the_cable_count_from_six_to_sixteen():
    doc = _robot_block()
    for m in (5, 17):
        doc["winch_names"] = [f"w{i}" for i in range(m)]
        with pytest.raises(InputError) as exc:
            robot_from_dict(doc)
        assert exc.value.field == "robot.winch_names" and "expected 6 to 16 distinct" in str(exc.value)
    doc["winch_names"] = [f"w{i}" for i in range(7)]
    with pytest.raises(InputError, match=r"robot.base_anchors = .*expected 21 numbers, got 18"):
        robot_from_dict(doc)
    doc["winch_names"] = ["a", "b", "c", "d", "e", "a"]
    with pytest.raises(InputError, match="robot.winch_names = .*distinct"):
        robot_from_dict(doc)


def test_per_cable_sizes_follow_the_number_of_winches():
    """An 8-winch robot block is read with 24 anchor coordinates and 8 limits per
    side (a single number broadcast to 8), and 18 anchor coordinates are then refused naming
    the count."""
    doc = _robot_block()
    doc["winch_names"] = [f"w{i}" for i in range(8)]
    doc["base_anchors"] = doc["base_anchors"] + doc["base_anchors"][:6]
    doc["platform_anchors"] = doc["platform_anchors"] + doc["platform_anchors"][:6]
    doc["length_min"], doc["length_max"] = 0.1, [0.6] * 8
    doc["tension_min"], doc["tension_max"] = 0.05, 0.5
    robot_schema.check_groups(doc, FIELDS, OPTIONAL_GROUPS)
    v = robot_schema.read_fields(doc, FIELDS)
    assert v["base_anchors"].shape == v["platform_anchors"].shape == (8, 3)
    assert v["length_min"].tolist() == [0.1] * 8 and v["length_max"].shape == (8,)
    assert v["load.force"].shape == (3,) and v["wrench_ellipsoid.matrix"].shape == (6, 6)
    doc["base_anchors"] = doc["base_anchors"][:18]
    with pytest.raises(InputError, match=r"robot.base_anchors = .*expected 24 numbers, got 18"):
        robot_schema.read_fields(doc, FIELDS)


def test_contact_ellipsoid_is_folded_into_the_wrench_ellipsoid():
    """Paper Eqs. 22-23: E = E_w (E_w + E_c)^-1 E_c / 2 (symmetrised), centres added."""
    doc = _robot_block()
    Ew = load_robot(ROBOT1).ellipsoid_matrix
    Ec = np.diag([2e4, 2e4, 2e4, 3e10, 3e10, 3e10])
    doc["contact_ellipsoid"] = {"matrix": np.diag(Ec).tolist(), "center": [0.0, 0.0, 1.0, 0, 0, 0]}
    robot = robot_from_dict(doc)
    np.testing.assert_allclose(robot.ellipsoid_matrix, 0.5 * Ew @ np.linalg.solve(Ew + Ec, Ec),
                               rtol=1e-12)
    assert np.allclose(robot.ellipsoid_matrix, robot.ellipsoid_matrix.T, rtol=0, atol=0)
    assert robot.ellipsoid_offset.tolist() == [0.0, 0.0, 1.0, 0.0, 0.0, 0.0]
    del doc["contact_ellipsoid"]["matrix"]
    with pytest.raises(InputError, match="robot.contact_ellipsoid.matrix = None: required key"):
        robot_from_dict(doc)


@dataclass(frozen=True, kw_only=True)
class WinchRobot(Robot):
    """A new robot field is one declaration: the drum radius of the winches."""

    drum_radius: float = robot_schema.robot_field(
        key="drum_radius", kind=NUMBER, unit="m", sign="positive", limit=1.0,
        default=0.05, description="winch drum radius")


def test_a_new_robot_field_is_one_declaration():
    fields = robot_schema.schema_of(WinchRobot)
    assert fields[:-1] == FIELDS and fields[-1].key == "drum_radius"
    doc = _robot_block()
    robot_schema.check_groups(doc, fields, OPTIONAL_GROUPS)  # absent: its default
    assert robot_schema.read_fields(doc, fields)["drum_radius"] == 0.05
    doc["drum_radius"] = 0.0
    with pytest.raises(InputError, match=r"robot.drum_radius = 0.0: must be positive"):
        robot_schema.read_fields(doc, fields)
    with pytest.raises(InputError, match="robot.drum_radius = .*unknown key"):
        robot_schema.check_groups(doc, FIELDS, OPTIONAL_GROUPS)  # Robot does not declare it


def test_every_declared_field_has_a_unit_or_kind_that_needs_none_and_a_description():
    keys = [f.key for f in FIELDS]
    assert len(set(keys)) == len(keys) and all(f.description for f in FIELDS)
    assert all(f.unit for f in FIELDS if f.kind in (NUMBER, NUMBERS, MATRIX))
    for f in FIELDS:  # a default is a valid value of its own field
        if f.default not in (None, REQUIRED):
            read(f, f.default, f.key, 6)


@pytest.mark.parametrize("f", FIELDS, ids=[f.key for f in FIELDS])
def test_a_null_value_is_refused_naming_the_field_unless_the_field_is_optional(f):
    """``key: null`` (YAML) is "not set" for an optional field (default None) and refused,
    naming the field, for every other one (a field with a default included)."""
    doc = _robot_block()
    doc.setdefault("contact_ellipsoid", {"matrix": [1e4] * 3 + [1e10] * 3})
    doc.setdefault("platform_shape", {"type": "none"})
    group = doc[f.group] if f.group else doc
    group[f.leaf] = None
    if f.key == "load.mass":
        doc["load"].pop("inertia", None)
    if f.default is None:
        robot_from_dict(doc)
        return
    with pytest.raises(InputError) as exc:
        robot_from_dict(doc)
    assert exc.value.field == f"robot.{f.key}" and exc.value.value is None


def test_elastic_fields_are_optional_per_cable_or_one_number(tmp_path):
    """cable_stiffness and length_error: absent is rigid cables and exact winches; one number
    stands for every cable."""
    rigid = load_robot(write_bad_robot(tmp_path, "cable_stiffness", None))
    assert rigid.cable_stiffness is None
    doc = set_robot(copy.deepcopy(robot_doc()), "cable_stiffness", 2500.0)
    doc = set_robot(doc, "length_error", [1e-4, 2e-4, 1e-4, 1e-4, 1e-4, 1e-4])
    path = tmp_path / "elastic.yaml"
    path.write_text(yaml.safe_dump(doc))
    r = load_robot(path)
    assert r.cable_stiffness.tolist() == [2500.0] * 6
    assert r.length_error[1] == 2e-4


def test_the_degeneracy_probes_are_the_generators_draws():
    """The probes written out in model/jacobian_probes.py are default_rng(0)'s first draws in
    the check's order (positions, axes, angles), so the check is the one it was with the
    generator; loading a robot then imports no numpy.random."""
    from cdh_planner.model import jacobian_probes as J
    rng = np.random.default_rng(0)
    n = J.PROBES
    np.testing.assert_array_equal(np.reshape(J.OFFSETS, (n, 3)), rng.uniform(-0.5, 0.5, (n, 3)))
    np.testing.assert_array_equal(np.reshape(J.AXES, (n, 3)), rng.normal(size=(n, 3)))
    np.testing.assert_array_equal(J.ANGLES, rng.uniform(0.0, 0.5, n))
    code = (f"import sys\nfrom cdh_planner.model.robot import load_robot\n"
            f"load_robot({str(ROOT / 'config' / 'cogiro.yaml')!r})\n"
            "print('numpy.random' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"
