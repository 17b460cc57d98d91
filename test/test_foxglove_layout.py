"""config/cdh_planner.foxglove.json, the Foxglove layout for the node's outputs (imported with
Layouts > Import layout): it has the shape of an exported Foxglove layout, its panels and its
mosaic agree, every topic it names is one the node publishes (or /joint_states), the 3D panel
renders in the node's default base frame, and its message paths into the TensionEnvelope use
that message's real field names (read from the .msg files)."""

import json
import re
import runpy

import pytest
import setuptools

from conftest import CONFIG, REPO

pytest.importorskip("rclpy")   # cdh_planner.ros.interface imports it

from cdh_planner.ros import interface  # noqa: E402
from cdh_planner.ros.core.params import SPEC  # noqa: E402

LAYOUT_FILE = CONFIG / "cdh_planner.foxglove.json"
MSG_DIR = REPO / "interfaces" / "cdh_planner_interfaces" / "msg"
PACKAGE = "cdh_planner_interfaces"
TOP_LEVEL = {"configById", "globalVariables", "userNodes", "playbackConfig", "layout"}
NOTE_KEY = "_comment"   # the layout's one-paragraph note, not a Foxglove setting

# the node's published topics, by their constants in ros/interface.py
TOPIC_CONSTANTS = ("PATH", "MARKERS", "PLAN_RESULT", "PLAN_PROGRESS", "CABLE_COMMAND",
                   "TENSION_ENVELOPE", "PLANNED_TRAJECTORY", "EXECUTION_RESULT", "SCENE_MARKERS")
# fields of the two standard types the envelope messages embed (not in this repository)
STANDARD_FIELDS = {
    "std_msgs/Header": {"stamp": "builtin_interfaces/Time", "frame_id": "string"},
    "builtin_interfaces/Time": {"sec": "int32", "nanosec": "uint32"},
    "builtin_interfaces/Duration": {"sec": "int32", "nanosec": "uint32"},
}


@pytest.fixture(scope="module")
def layout():
    return json.loads(LAYOUT_FILE.read_text())


def mosaic_leaves(tree):
    """Panel ids in a Foxglove (react-mosaic) layout tree: a panel id, or a split."""
    if isinstance(tree, str):
        return [tree]
    assert set(tree) <= {"direction", "first", "second", "splitPercentage"}, tree
    assert tree["direction"] in ("row", "column")
    if "splitPercentage" in tree:
        assert 0 < tree["splitPercentage"] < 100
    return mosaic_leaves(tree["first"]) + mosaic_leaves(tree["second"])


def strings(value):
    """Every string in a JSON value, object keys included."""
    if isinstance(value, str):
        yield value
    elif isinstance(value, dict):
        for k, v in value.items():
            yield k
            yield from strings(v)
    elif isinstance(value, list):
        for v in value:
            yield from strings(v)


def topic_of(path):
    """The topic of a message path: from the leading "/" up to the first "." (or the end)."""
    return path.split(".", 1)[0]


def msg_fields():
    """{"cdh_planner_interfaces/Name": {field: type}} from the package's .msg files, types
    made absolute (a bare message name is one of this package's)."""
    out = {}
    for f in sorted(MSG_DIR.glob("*.msg")):
        fields = {}
        for line in f.read_text().splitlines():
            line = line.split("#", 1)[0].strip()
            if not line or "=" in line:   # blank, comment or constant
                continue
            kind, name = line.split()[:2]
            base = kind.split("[", 1)[0]
            if base[0].isupper():
                base = f"{PACKAGE}/{base}"
            fields[name] = base
        out[f"{PACKAGE}/{f.stem}"] = fields
    return out


def path_fields(path):
    """Field names along a message path, array indices / slices and filters dropped:
    "/t.points[:].tension_max[0]" -> ["points", "tension_max"]."""
    rest = path[len(topic_of(path)):]
    rest = re.sub(r"\[[^\]]*\]|\{[^}]*\}", "", rest)
    return [part for part in rest.split(".") if part]


def test_shape_of_an_exported_layout(layout):
    assert set(layout) - {NOTE_KEY} == TOP_LEVEL
    assert isinstance(layout.get(NOTE_KEY, ""), str)
    assert layout["globalVariables"] == {} and layout["userNodes"] == {}
    assert layout["playbackConfig"] == {"speed": 1}
    for panel_id, config in layout["configById"].items():
        kind, _, suffix = panel_id.partition("!")
        assert kind and suffix, panel_id
        assert isinstance(config, dict)


def test_every_panel_in_the_layout_has_a_config_and_vice_versa(layout):
    leaves = mosaic_leaves(layout["layout"])
    assert len(leaves) == len(set(leaves))
    assert set(leaves) == set(layout["configById"])


def test_every_topic_is_one_the_node_publishes_or_joint_states(layout):
    published = {f"/{interface.NODE_NAME}/{getattr(interface, c)}" for c in TOPIC_CONSTANTS}
    from cdh_planner.ros.core.live_state import LIVE_MARKERS     # measured, beside the planned
    allowed = published | {"/joint_states", f"/{interface.NODE_NAME}/{LIVE_MARKERS}"}
    topics = {topic_of(s) for s in strings(layout) if s.startswith("/")}
    assert topics <= allowed, sorted(topics - allowed)
    # every output the brief lists is shown somewhere
    assert topics == allowed


def test_the_3d_panel_renders_markers_and_path_in_the_default_fixed_frame(layout):
    (scene,) = [c for i, c in layout["configById"].items() if i.startswith("3D!")]
    assert scene["followTf"] == SPEC["fixed_frame"].default
    for name in (interface.MARKERS, interface.PATH, interface.SCENE_MARKERS):   # obstacles
        assert scene["topics"][f"/{interface.NODE_NAME}/{name}"]["visible"] is True


def test_tension_envelope_paths_use_the_messages_field_names(layout):
    known = msg_fields() | STANDARD_FIELDS
    envelope = f"/{interface.NODE_NAME}/{interface.TENSION_ENVELOPE}"
    paths = [s for s in strings(layout) if topic_of(s) == envelope]
    assert any("tension_max" in p for p in paths)
    for path in paths:
        kind = f"{PACKAGE}/TensionEnvelope"
        for name in path_fields(path):
            assert kind in known, f"{path}: {kind} has no fields"
            assert name in known[kind], f"{path}: {kind} has no field {name!r}"
            kind = known[kind][name]


def test_the_envelope_plot_is_against_the_waypoint_index(layout):
    """Index mode: the points of the latest (latched) envelope, x = waypoint index."""
    envelope = f"/{interface.NODE_NAME}/{interface.TENSION_ENVELOPE}"
    plots = [c for i, c in layout["configById"].items() if i.startswith("Plot!")
             and any(topic_of(p["value"]) == envelope for p in c["paths"])]
    assert plots and all(c["xAxisVal"] == "index" for c in plots)
    for c in plots:
        assert all(".points[:]." in p["value"] for p in c["paths"])


def test_setup_py_installs_the_layout(monkeypatch):
    captured = {}
    monkeypatch.setattr(setuptools, "setup", lambda **kw: captured.update(kw))
    monkeypatch.chdir(REPO)
    runpy.run_path(str(REPO / "setup.py"), run_name="__main__")
    installed = dict(captured["data_files"])["share/cdh_planner/config"]
    assert "config/cdh_planner.foxglove.json" in installed


def test_rviz_and_foxglove_agree_z_up_seen_from_above(layout):
    """Both viewers render in the z-up fixed frame (REP 103), looking down at the platform
    hanging below the base (z = -0.25 m in world): RViz's orbit pitch > 0 is a camera above
    its focal point; Foxglove's phi < 90 degrees is a camera above its target."""
    import yaml
    rviz = yaml.safe_load((CONFIG / "cdh_planner.rviz").read_text())["Visualization Manager"]
    (scene,) = [c for i, c in layout["configById"].items() if i.startswith("3D!")]
    assert rviz["Global Options"]["Fixed Frame"] == scene["followTf"] == "world"
    view = rviz["Views"]["Current"]
    assert view["Pitch"] > 0 and scene["cameraState"]["phi"] < 90
    assert view["Focal Point"]["Z"] == scene["cameraState"]["targetOffset"][2] < 0
