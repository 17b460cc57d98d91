"""``verify`` in bulk: the poses parsed as whole arrays accept and refuse exactly what the
pose-by-pose check does (same messages), the JSON built column by column is byte-identical
to the per-row output of before (test/verify_reference, written by the previous code; the
segments' end points since rewritten: the poses' own margins there, test_verify_waypoints), and
the text report of many poses lists only what is not feasible unless ``--all``."""
import json

import numpy as np
import pytest

from cdh_planner import cli
from cdh_planner.commands import verify
from cdh_planner.errors import InputError
from cdh_planner.files import JSON_LIMITS, check_structure
from cdh_planner.parsing import poses as poses_mod
from cdh_planner.parsing.poses import poses_from_obj

from conftest import REPO

REFERENCE = REPO / "test" / "verify_reference"
# name -> (robot, extra arguments): 6 cables (Robot 1 with length_error, Robot 2 with and
# without a scene) and 8 cables (CoGiRo, with tension_status)
CASES = {"robot1": ("robot1", []), "robot2": ("robot2", []), "cogiro": ("cogiro", []),
         "robot2_ball": ("robot2", ["--scene", "config/scenes/robot2_ball.yaml"])}


@pytest.mark.parametrize("name", CASES)
def test_json_and_text_are_those_of_the_per_row_code(name, tmp_path, monkeypatch, capsys):
    robot, extra = CASES[name]
    monkeypatch.chdir(REPO)  # the JSON holds the robot file's path as given
    out = tmp_path / "out.json"
    cli.main(["verify", f"config/{robot}.yaml", f"test/verify_reference/{robot}_poses.json",
              "--json", str(out), *extra])
    assert out.read_text() == (REFERENCE / f"{name}_out.json").read_text()
    old = (REFERENCE / f"{name}_out.txt").read_text().splitlines()
    new = capsys.readouterr().out.splitlines()
    assert new[:-1] == old[:-1] and new[-1] == f"wrote {out}"  # 8 poses: every one in full


def _slow(doc):
    """The pose-by-pose parse (the bulk path switched off)."""
    saved, poses_mod._bulk_poses = poses_mod._bulk_poses, lambda doc: None
    try:
        return poses_from_obj(doc)
    finally:
        poses_mod._bulk_poses = saved


def _good(n=30, seed=3):
    rng = np.random.default_rng(seed)
    doc = []
    for i in range(n):
        p = rng.uniform(-0.1, 0.1, 3).tolist()
        if i % 2:
            q = rng.normal(size=4)
            q *= (1 + rng.uniform(-9e-4, 9e-4)) / np.linalg.norm(q)  # within the tolerance
            doc.append({"position": p, "quaternion": q.tolist()})
        else:
            doc.append({"position": [int(v * 100) for v in p],
                        "tau": [rng.uniform(-6, 6), rng.uniform(0, np.pi), rng.uniform(-6, 6)]})
    doc[2]["tau"][1] = -1e-10  # within THETA_TOL: clipped to 0
    return doc


def test_bulk_parse_gives_the_pose_by_pose_arrays_bit_for_bit():
    doc = _good()
    bulk, slow = poses_from_obj(doc), _slow(doc)
    assert poses_mod._bulk_poses(doc) is not None  # the bulk path did the work
    for field in ("positions", "quaternions", "rotations", "tau"):
        assert np.array_equal(getattr(bulk, field), getattr(slow, field)), field
    assert np.all(bulk.quaternions[:, 3] >= 0) and bulk.tau[2, 1] == 0.0


BAD = {  # a bad pose at index 17 of a good file
    "not a mapping": [0.0, 0.0, 0.3],
    "unknown key": {"position": [0, 0, 0.3], "tau": [0, 0, 0], "speed": 1},
    "both": {"position": [0, 0, 0.3], "tau": [0, 0, 0], "quaternion": [0, 0, 0, 1]},
    "neither": {"position": [0, 0, 0.3]},
    "no position": {"tau": [0, 0, 0]},
    "short position": {"position": [0, 0], "tau": [0, 0, 0]},
    "position a string": {"position": "0 0 0.3", "tau": [0, 0, 0]},
    "string number": {"position": [0, "0", 0.3], "tau": [0, 0, 0]},
    "boolean": {"position": [0, True, 0.3], "tau": [0, 0, 0]},
    "null": {"position": [0, None, 0.3], "tau": [0, 0, 0]},
    "NaN": {"position": [0, float("nan"), 0.3], "tau": [0, 0, 0]},
    "infinite": {"position": [0, 0, float("inf")], "tau": [0, 0, 0]},
    "huge integer": {"position": [0, 10 ** 400, 0.3], "tau": [0, 0, 0]},
    "far": {"position": [0, 0, 1e4], "tau": [0, 0, 0]},
    "nested": {"position": [0, [0], 0.3], "tau": [0, 0, 0]},
    "quaternion not normalised": {"position": [0, 0, 0.3], "quaternion": [0, 0, 0, 1.01]},
    "quaternion zero": {"position": [0, 0, 0.3], "quaternion": [0, 0, 0, 0]},
    "quaternion too large": {"position": [0, 0, 0.3], "quaternion": [0, 0, 0, 3]},
    "quaternion 3 numbers": {"position": [0, 0, 0.3], "quaternion": [0, 0, 1]},
    "theta negative": {"position": [0, 0, 0.3], "tau": [0, -0.1, 0]},
    "theta beyond pi": {"position": [0, 0, 0.3], "tau": [0, 3.2, 0]},
    "phi in degrees": {"position": [0, 0, 0.3], "tau": [90, 0.1, 0]},
    "sigma in degrees": {"position": [0, 0, 0.3], "tau": [0, 0.1, -30]},
    "tau a tuple-like mapping": {"position": [0, 0, 0.3], "tau": {"phi": 0}},
}


@pytest.mark.parametrize("case", BAD)
def test_bulk_parse_refuses_what_the_pose_by_pose_check_refuses(case):
    doc = _good()
    doc[17] = BAD[case]
    doc[25] = dict(BAD[case]) if isinstance(BAD[case], dict) else BAD[case]  # a later one too
    with pytest.raises(InputError) as slow:
        _slow(doc)
    with pytest.raises(InputError) as bulk:
        poses_from_obj(doc)
    assert str(bulk.value) == str(slow.value)
    assert "poses[17]" in str(bulk.value) and "\n" not in str(bulk.value)


def _walk_file(tmp_path, n, infeasible=()):
    """n Robot 2 poses 0.1 mm apart; the indices in ``infeasible`` far below the frame."""
    doc = [{"position": [1e-4 * i, 0.0, 0.3], "tau": [0.0, 0.05, 0.0]} for i in range(n)]
    for i in infeasible:
        doc[i]["position"] = [0.0, 0.0, 0.9]
    path = tmp_path / "poses.json"
    path.write_text(json.dumps(doc))
    return path


def test_many_poses_list_only_what_is_not_feasible(tmp_path, capsys):
    poses = _walk_file(tmp_path, 40, infeasible=(30,))
    rc = cli.main(["verify", str(REPO / "config/robot2.yaml"), str(poses)])
    out = capsys.readouterr().out
    assert rc == 1
    assert "pose 30: NOT FEASIBLE" in out and "pose 0:" not in out and "pose 29:" not in out
    assert "segment 29 -> 30: NOT FEASIBLE" in out and "segment 30 -> 31: NOT FEASIBLE" in out
    assert "segment 0 -> 1" not in out.split("least margin")[0]
    assert out.count("\n  winch_1 ") == 1  # one pose block
    assert "least margin: pose 30" in out
    assert "summary: 39/40 poses and 37/39 segments feasible: NOT FEASIBLE" in out

    rc = cli.main(["verify", str(REPO / "config/robot2.yaml"), str(poses), "--all"])
    out = capsys.readouterr().out
    assert out.count("\n  winch_1 ") == 40 and out.count("\nsegment ") == 39
    assert "least margin" not in out


def test_at_most_ten_not_feasible_poses_are_listed(tmp_path, capsys):
    poses = _walk_file(tmp_path, 40, infeasible=range(5, 35, 2))  # 15 infeasible poses
    assert cli.main(["verify", str(REPO / "config/robot2.yaml"), str(poses)]) == 1
    out = capsys.readouterr().out
    listed = [int(line.split()[1][:-1]) for line in out.splitlines() if line.startswith("pose ")]
    assert listed == list(range(5, 25, 2))
    assert "summary: 25/40 poses" in out


def test_the_largest_document_the_bulk_parse_accepts_is_within_the_json_limits(tmp_path):
    """load_poses skips files.check_structure when _bulk_poses accepts a file: the largest
    such document (MAX_POSES quaternion poses in the {"poses": ...} wrapper) must pass it."""
    pose = {"position": [0.0, 0.0, 0.3], "quaternion": [0.0, 0.0, 0.0, 1.0]}
    doc = {"poses": [dict(pose) for _ in range(poses_mod.MAX_POSES)]}
    assert poses_mod._bulk_poses(doc["poses"]) is not None
    check_structure(doc, "poses", "x.json", JSON_LIMITS)  # no InputError
    path = tmp_path / "poses.json"
    path.write_text(json.dumps(doc))
    assert len(poses_mod.load_poses(path)) == poses_mod.MAX_POSES


@pytest.mark.parametrize("case", BAD)
def test_a_bad_pose_file_is_refused_as_the_pose_by_pose_check_refuses_it(case, tmp_path):
    """load_poses parses with orjson first (NaN and huge integers are not JSON to it: the
    json module's parse then reads them, as before)."""
    doc = _good()
    doc[17] = BAD[case]
    path = tmp_path / "poses.json"
    path.write_text(json.dumps(doc))
    with pytest.raises(InputError) as slow:
        _slow(json.loads(path.read_text()))
    with pytest.raises(InputError) as read:
        poses_mod.load_poses(path)
    assert str(read.value) == str(slow.value)


@pytest.mark.parametrize("text, key", [
    ('[{"position": [0, 0, 0.3], "tau": [0, 0.1, 0]}, '
     '{"position": [0, 0, 0.3], "tau": [0, 0.1, 0], "tau": [0, 0.2, 0]}]', "tau"),
    ('{"poses": [{"position": [0, 0, 0.3], "tau": [0, 0.1, 0]}], '
     '"poses": [{"position": [0, 0, 0.3], "tau": [0, 0.1, 0]}]}', "poses"),
])
def test_a_key_given_twice_is_refused_where_orjson_would_keep_the_last(tmp_path, text, key):
    """orjson keeps the last of two equal keys: the documents it reads into poses that the
    bulk check accepts are refused all the same (the quotes counted)."""
    path = tmp_path / "poses.json"
    path.write_text(text)
    with pytest.raises(InputError, match=f"duplicate key '{key}'"):
        poses_mod.load_poses(path)
    path.write_text(text.replace('"position"', '"\\u0070osition"', 1))  # an escaped key: read
    with pytest.raises(InputError, match=f"duplicate key '{key}'"):
        poses_mod.load_poses(path)


def test_the_orjson_and_json_module_reads_are_the_same_poses(tmp_path):
    doc = _good(200, seed=8)
    path = tmp_path / "poses.json"
    path.write_text(json.dumps({"poses": doc}).replace('"tau"', '"t\\u0061u"', 3))
    fast, slow = poses_mod.load_poses(path), _slow(doc)
    assert poses_mod._bulk_text(path.read_text()) is not None
    for field in ("positions", "quaternions", "rotations", "tau"):
        assert np.array_equal(getattr(fast, field), getattr(slow, field)), field
