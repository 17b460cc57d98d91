"""The scene: obstacles in the base frame, the platform's shape, the cables' radius.

One format everywhere (problem files' ``scene:`` key, ``verify --scene FILE``, the node):

    scene:
      cable_radius: 0.001            # m; absent: robot.cable_radius (else 0)
      clearance: 0.0                 # m: the least distance kept everywhere
      shared_anchor_exemption: 0.01  # m: see below
      platform: {type: box, size: [0.14, 0.14, 0.01],
                 position: [0, 0, 0], quaternion: [0, 0, 0, 1]}   # platform frame; absent: robot.platform_shape
      obstacles:                     # base frame
        - {id: ball, type: sphere, radius: 0.02, position: [x, y, z]}
        - {id: post, type: box, size: [sx, sy, sz], position: [...], quaternion: [x, y, z, w]}
        - {id: pipe, type: cylinder, radius: r, height: h, position: [...], quaternion: [...]}
        - {id: rod, type: capsule, radius: r, length: l, position: [...], quaternion: [...]}
        - {id: fixture, type: mesh, file: fixture.stl, scale: 1.0, position: [...], quaternion: [...]}

SI units. The types are model.shapes.SHAPES (one class each: keys, checks, geometry). A
box's ``size`` is its full edge lengths; a cylinder's axis is its own z, ``height`` its
full length, centred on ``position``; a capsule is a cylinder of ``length`` along its z
with hemispherical caps of ``radius`` (length + 2 radius overall), centred; a mesh file (STL, OBJ, PLY; read by
trimesh) is relative to the scene file's folder, scaled by ``scale`` then placed by
``position`` / ``quaternion``, and checked as its convex hull (conservative: a concave
fixture is best given as several meshes). ``position`` defaults to 0 and ``quaternion``
(x, y, z, w, unit) to the identity.

``shared_anchor_exemption`` (rho): two cables that share an anchor point (within
SHARED_ANCHOR_M) touch there by design; their capsules are compared only beyond rho of
that point (each cable is cut short by rho at the shared end). So two cables leaving a
shared anchor at an angle alpha are in contact iff r / sin(alpha / 2) > rho (r the cable
radius): with r = 1 mm and rho = 10 mm, iff alpha < 11.5 degrees.

Every field is checked here; an error names the field and value (errors.InputError).
"""

from dataclasses import dataclass, field, fields, replace
from pathlib import Path

import numpy as np

from .. import files
from ..errors import MAX_POSITION_M, InputError, check_keys
from ..fields import CHOICE, NAME, NUMBER, NUMBERS, Field, read
from ..model.pose import check_quaternion, rotation_from_quaternion
from ..model.robot import MAX_CABLE_RADIUS_M
from ..model.shapes import SHAPES

MAX_OBSTACLES = 1000  # per scene: every one is checked at every pose
# a scene file's lists hold obstacles or a few numbers: more than MAX_OBSTACLES entries is
# refused while parsing, before the file's values add up to the generic bound
SCENE_FILE_LIMITS = replace(files.YAML_LIMITS, max_items=MAX_OBSTACLES,
                            items_note=f" (a scene has at most {MAX_OBSTACLES} obstacles)")
DEFAULT_EXEMPTION_M = 0.01
SHARED_ANCHOR_M = 1e-6  # two anchors closer than this are one shared anchor point
IDENTITY = (0.0, 0.0, 0.0, 1.0)

# the scene's numbers (its platform and obstacles are Shapes), each read by its Field
CABLE_RADIUS = Field("cable_radius", NUMBER, None, "the cables' radius (absent: the robot's)",
                     unit="m", sign="non-negative", limit=MAX_CABLE_RADIUS_M)
CLEARANCE = Field("clearance", NUMBER, 0.0, "the least distance kept everywhere", unit="m",
                  sign="non-negative", limit=MAX_POSITION_M)
EXEMPTION = Field("shared_anchor_exemption", NUMBER, DEFAULT_EXEMPTION_M,
                  "rho: cables sharing an anchor are compared beyond it", unit="m",
                  sign="non-negative", limit=MAX_POSITION_M)
SCENE_KEYS = ("cable_radius", "clearance", "shared_anchor_exemption", "platform", "obstacles")
# every shape's keys besides its type's own
OBSTACLE_ID = Field("id", NAME, description="an obstacle's unique name (not 'platform')")
POSITION = Field("position", NUMBERS, (0.0, 0.0, 0.0), "its centre", unit="m", count=3,
                 limit=MAX_POSITION_M)
QUATERNION = Field("quaternion", NUMBERS, IDENTITY, "its orientation (x, y, z, w), unit",
                   count=4)
_COMMON = ("type", POSITION.key, QUATERNION.key)


@dataclass(frozen=True, eq=False)
class Shape:
    """A solid in its frame (base frame for an obstacle, platform frame for the platform).

    ``kind``: a type of model.shapes.SHAPES; ``radius`` (m, sphere, cylinder, capsule),
    ``height`` (m, cylinder, along its z), ``length`` (m, capsule: its cylinder's, along
    its z), ``size`` (3,) m (box, full edges), ``vertices`` (n, 3) m (mesh: its convex
    hull's vertices, scaled, in the shape's own frame), ``file`` and ``scale`` as given.
    ``position`` (3,) m and ``quaternion`` (x, y, z, w) place it; ``rotation`` is the
    quaternion's matrix. ``id``: an obstacle's unique name ("platform" for the platform)."""

    id: str
    kind: str
    position: np.ndarray
    quaternion: np.ndarray
    radius: float = 0.0
    height: float = 0.0
    length: float = 0.0
    size: np.ndarray = None
    vertices: np.ndarray = None
    file: str = ""
    scale: float = 1.0
    rotation: np.ndarray = field(init=False, repr=False)

    def __post_init__(self):
        object.__setattr__(self, "rotation", rotation_from_quaternion(self.quaternion))

    def same_geometry(self, other):
        """True when ``other`` is the same shape in the same place (ids, kinds, sizes and
        poses exactly equal; the source file's name aside): every field, so a shape type's
        new field counts without a change here."""
        return other is not None and all(_same_value(getattr(self, f.name), getattr(other, f.name))
                                         for f in fields(self) if f.name not in ("file", "rotation"))

    def bounding_radius(self):
        """Radius (m) of a sphere about ``position`` that holds the whole shape."""
        return self.type.bounding_radius(self)

    @property
    def type(self):
        """Its class in model.shapes.SHAPES."""
        return SHAPES[self.kind]


@dataclass(frozen=True, eq=False)
class Scene:
    """Obstacles (base frame), the platform's shape (platform frame, or None) and the
    cables' radius, all in m; ``clearance``: the least distance to keep (m);
    ``shared_anchor_exemption``: rho of the module docstring (m)."""

    cable_radius: float = 0.0
    clearance: float = 0.0
    shared_anchor_exemption: float = DEFAULT_EXEMPTION_M
    platform: Shape = None
    obstacles: tuple = ()
    source: str = ""

    def same_geometry(self, other):
        """True when ``other`` keeps the same distances and obstacles: a plan made under one
        is the plan under the other (where it was read from aside)."""
        if other is None or (self.cable_radius, self.clearance, self.shared_anchor_exemption) != (
                other.cable_radius, other.clearance, other.shared_anchor_exemption):
            return False
        if (self.platform is None) != (other.platform is None) or (
                self.platform is not None and not self.platform.same_geometry(other.platform)):
            return False
        return len(self.obstacles) == len(other.obstacles) and all(
            a.same_geometry(b) for a, b in zip(self.obstacles, other.obstacles))

    def obstacle(self, obstacle_id):
        """The obstacle named ``obstacle_id`` (KeyError if none)."""
        for o in self.obstacles:
            if o.id == obstacle_id:
                return o
        raise KeyError(obstacle_id)


def _same_value(a, b):
    if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
        return a is not None and b is not None and np.shape(a) == np.shape(b) \
            and bool(np.array_equal(a, b))
    return a == b


def load_scene(path, robot=None):
    """The scene of the YAML file ``path`` (its top-level key ``scene:``); ``robot`` gives
    the default cable radius (robot.cable_radius). InputError naming the field."""
    doc = files.read_yaml_mapping(path, "scene", "'scene:'", SCENE_FILE_LIMITS)
    check_keys("", doc, ("scene",), required=("scene",))
    return scene_from_dict(doc["scene"], robot=robot, base_dir=Path(path).parent, source=str(path))


def scene_from_dict(d, robot=None, base_dir=".", where="scene", source=""):
    """A checked Scene from the ``scene:`` mapping ``d``; mesh files are relative to
    ``base_dir``. An absent cable_radius is the robot's (robot.cable_radius, else 0); an
    absent platform is the robot's (robot.platform_shape: none, not checked, by default)."""
    check_keys(where, d, SCENE_KEYS)
    radius = d.get("cable_radius")
    if radius is None:
        radius = getattr(robot, "cable_radius", None) or 0.0
    radius = read(CABLE_RADIUS, radius, f"{where}.cable_radius")
    clearance, rho = (read(f, d.get(f.key, f.default), f"{where}.{f.key}")
                      for f in (CLEARANCE, EXEMPTION))
    platform = d.get("platform")
    if platform is not None:
        platform = shape_from_dict(platform, f"{where}.platform", "platform", base_dir)
    else:
        platform = robot_platform(robot)
    return Scene(cable_radius=radius, clearance=clearance, shared_anchor_exemption=rho,
                 platform=platform, obstacles=_obstacles(d.get("obstacles", []), where, base_dir),
                 source=source)


def default_scene(robot):
    """The scene of a robot without a scene file: none (nothing checked), unless the robot
    declares its platform's shape (robot.platform_shape), whose cables are then kept clear
    of it and of each other."""
    return scene_from_dict({}, robot) if robot_platform(robot) is not None else None


def robot_platform(robot):
    """The platform Shape of ``robot.platform_shape`` (platform frame), or None (no robot,
    or type none)."""
    kind = getattr(robot, "platform_shape", "none")
    if kind == "none":
        return None
    fields = SHAPES[kind].platform_fields(np.asarray(robot.platform_size, dtype=float))
    return Shape(id="platform", kind=kind, position=np.asarray(robot.platform_center, float),
                 quaternion=np.array(IDENTITY), **fields)


def _obstacles(items, where, base_dir):
    where = f"{where}.obstacles"
    if items is None:
        return ()
    if not isinstance(items, list):
        raise InputError(where, items, "expected a list of obstacles")
    if len(items) > MAX_OBSTACLES:
        raise InputError(where, f"{len(items)} obstacles", f"at most {MAX_OBSTACLES}")
    out, seen = [], set()
    for i, item in enumerate(items):
        at = f"{where}[{i}]"
        if not isinstance(item, dict):
            raise InputError(at, item, "expected a mapping (id, type, ...)")
        if "id" not in item:
            raise InputError(f"{at}.id", None, "required key is missing")
        oid = check_obstacle_id(item["id"], f"{at}.id")
        if oid in seen:
            raise InputError(f"{at}.id", oid, "ids must be unique: given twice")
        seen.add(oid)
        rest = {k: v for k, v in item.items() if k != "id"}
        out.append(shape_from_dict(rest, at, oid, base_dir, extra=("id",)))
    return tuple(out)


def check_obstacle_id(oid, where):
    """An obstacle's id (OBSTACLE_ID), not "platform" (the platform's); InputError naming
    ``where``."""
    oid = read(OBSTACLE_ID, oid, where)
    if oid == "platform":
        raise InputError(where, oid, "the platform's id: an obstacle needs another")
    return oid


def shape_from_dict(d, where, shape_id, base_dir=".", extra=()):
    """A checked Shape from a mapping {type, <its fields>, position, quaternion}."""
    if not isinstance(d, dict):
        raise InputError(where, d, "expected a mapping (type, ...)")
    kind = read(Field("type", CHOICE, choices=tuple(SHAPES)), d.get("type"), f"{where}.type")
    cls = SHAPES[kind]
    check_keys(where, d, _COMMON + cls.required + cls.optional + tuple(extra),
               required=cls.required)
    position = read(POSITION, d.get(POSITION.key, POSITION.default), f"{where}.position")
    q = read(QUATERNION, d.get(QUATERNION.key, QUATERNION.default), f"{where}.quaternion")
    quaternion = check_quaternion(q, f"{where}.quaternion")
    return Shape(id=shape_id, kind=kind, position=position, quaternion=quaternion,
                 **cls.fields(d, where, base_dir))
