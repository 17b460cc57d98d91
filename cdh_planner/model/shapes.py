"""The solids of a scene and of the platform: one registered class per shape type.

A class gives everything the package knows of its type: the file keys and their checks,
the bounding radius, the coal geometry, the compiled kernel's description of it (a form
code and three numbers), the ROS SolidPrimitive mapping (or why there is none), the RViz
markers and the MuJoCo geom. ``scene.schema``, ``scene.collision``, ``sim.mjcf`` and the
ROS message conversions read ``SHAPES``; ``Robot.platform_shape`` offers the types whose
class says it can be a platform (``platform_extents``). A new type is one class here:

    @register
    class Capsule(ShapeType):
        type = "capsule"
        ...

Shapes themselves are ``scene.schema.Shape`` records (kind = the type name); the classes
hold no state. Units: m.
"""

import math
import os

import numpy as np

from ..errors import MAX_POSITION_M, InputError
from ..fields import NUMBER, NUMBERS, REQUIRED, TEXT, Field, read
from .shape_forms import BOX_FORM, CAPSULE_FORM, COAL_FORM, CYLINDER_FORM, SPHERE_FORM

MAX_MESH_BYTES = 16 << 20  # a mesh file's size
MAX_MESH_VERTICES = 100_000  # of a mesh, before its convex hull is taken

SHAPES = {}
RADIUS = Field("radius", NUMBER, unit="m", sign="positive", limit=MAX_POSITION_M,
               description="radius")


def length(key, description):
    """A shape's positive length key (m), up to MAX_POSITION_M."""
    return Field(key, NUMBER, unit="m", sign="positive", limit=MAX_POSITION_M,
                 description=description)


def register(cls):
    """Class decorator: make ``cls`` a shape type of scene files, the node's obstacles and
    (with ``platform_extents``) of ``robot.platform_shape``; a type is registered once."""
    if cls.type in SHAPES and SHAPES[cls.type] is not cls:
        raise ValueError(f"shape type {cls.type!r} is already registered "
                         f"({SHAPES[cls.type].__name__})")
    missing = [m for m in _methods_owed(cls) if not callable(getattr(cls, m, None))]
    if missing:
        raise TypeError(f"shape type {cls.type!r} ({cls.__name__}) lacks {', '.join(missing)}")
    SHAPES[cls.type] = cls
    return cls


def _methods_owed(cls):
    """What a shape class must define (ShapeType's docstring): every type its bounding
    radius, coal geometry, markers and MuJoCo geom; a platform type ``platform_fields``; a
    type with a ROS primitive its ``primitive_*`` pair."""
    owed = ["bounding_radius", "coal_geometry", "marker_parts", "mjcf"]
    if cls.platform_extents:
        owed.append("platform_fields")
    if cls.primitive is not None:
        owed += ["primitive_dimensions", "primitive_fields"]
    return owed


def platform_types():
    """The types a robot's platform_shape may name (besides none), in registry order."""
    return tuple(t for t, c in SHAPES.items() if c.platform_extents)


class ShapeType:
    """One shape type. ``keys``: its file keys besides type, position and quaternion, each a
    ``fields.Field`` (``required`` / ``optional``: their names, by default REQUIRED or not);
    ``platform_extents``: 0 if it cannot be robot.platform_shape, else how
    many leading extents of platform_shape.size are one diameter; ``primitive``: the name
    of its type constant in shape_msgs/SolidPrimitive or else cdh_planner_interfaces/
    Obstacle, with ``dimensions`` numbers; None with ``no_primitive`` saying why;
    ``markers``: RViz Marker type names of its parts (the first is the obstacle's marker).

    ``fields(d, where, base_dir)`` gives the Shape fields (dict) of the file mapping, each
    key read by its Field (a type that derives more overrides it). A class defines, as static
    methods (``register`` refuses one that lacks any it owes): ``bounding_radius(s)``, m about the position; ``coal_geometry(s)``, in the shape's own
    frame; ``marker_parts(s)``, [(offset (3,), scale (3,))] for each of ``markers``;
    ``mjcf(s)``, (MuJoCo geom type, its sizes); a platform type ``platform_fields(size)``,
    the fields of robot.platform_shape.size (3,) m; a type with a primitive
    ``primitive_dimensions(s)`` (SolidPrimitive.dimensions, m) and ``primitive_fields(dims)``
    (the file keys of such dimensions)."""

    type = ""
    keys = ()
    required = ()
    optional = ()
    platform_extents = 0
    primitive = None
    dimensions = 0
    no_primitive = ""
    markers = ()

    def __init_subclass__(cls, **kwargs):
        super().__init_subclass__(**kwargs)
        cls.required = tuple(f.key for f in cls.keys if f.default is REQUIRED)
        cls.optional = tuple(f.key for f in cls.keys if f.default is not REQUIRED)

    @classmethod
    def fields(cls, d, where, base_dir):
        """The Shape fields of the mapping ``d`` (its keys checked): each key read by its
        Field, an absent optional one taking its default."""
        return {f.key: read(f, d.get(f.key, f.default), f"{where}.{f.key}") for f in cls.keys}

    @classmethod
    def bounding_capsule(cls, s):
        """(half axis (3,) m in the shape's parent frame, radius m): the capsule about its
        position that holds it, for the kernel's lower bounds; a sphere (zero axis) but
        for a capsule."""
        return np.zeros(3), cls.bounding_radius(s)

    @staticmethod
    def kernel_form(s):
        """(form code, three numbers) for the compiled kernel; COAL_FORM: left to coal."""
        return (COAL_FORM, 0.0, 0.0, 0.0)


@register
class Sphere(ShapeType):
    """A ball of ``radius`` about its position."""

    type, keys, platform_extents, markers = "sphere", (RADIUS,), 3, ("SPHERE",)
    primitive, dimensions = "SPHERE", 1

    @staticmethod
    def platform_fields(size):
        return dict(radius=0.5 * size[0])

    @staticmethod
    def bounding_radius(s):
        return s.radius

    @staticmethod
    def coal_geometry(s):
        import coal
        return coal.Sphere(s.radius)

    @staticmethod
    def kernel_form(s):
        return (SPHERE_FORM, s.radius, 0.0, 0.0)

    @staticmethod
    def primitive_dimensions(s):
        return [s.radius]

    @staticmethod
    def primitive_fields(dims):
        return {"radius": dims[0]}

    @staticmethod
    def marker_parts(s):
        return [(np.zeros(3), np.full(3, 2.0 * s.radius))]

    @staticmethod
    def mjcf(s):
        return "sphere", [s.radius]


@register
class Box(ShapeType):
    """Full edge lengths ``size`` along its own x, y, z, centred on its position."""

    type, platform_extents, markers = "box", 1, ("CUBE",)
    keys = (Field("size", NUMBERS, count=3, unit="m", sign="positive", limit=MAX_POSITION_M,
                  description="full edge lengths along x, y, z"),)
    primitive, dimensions = "BOX", 3

    @staticmethod
    def platform_fields(size):
        return dict(size=size)

    @staticmethod
    def bounding_radius(s):
        return 0.5 * float(np.linalg.norm(s.size))

    @staticmethod
    def coal_geometry(s):
        import coal
        return coal.Box(*map(float, s.size))

    @staticmethod
    def kernel_form(s):
        return (BOX_FORM, *(0.5 * np.asarray(s.size, float)))

    @staticmethod
    def primitive_dimensions(s):
        return list(s.size)

    @staticmethod
    def primitive_fields(dims):
        return {"size": dims}

    @staticmethod
    def marker_parts(s):
        return [(np.zeros(3), np.asarray(s.size, float))]

    @staticmethod
    def mjcf(s):
        return "box", 0.5 * np.asarray(s.size)


class Axial(ShapeType):
    """A solid of revolution about its own z, centred: ``radius`` and the length named
    ``axis`` (its second key, a Shape field), sent over ROS as [that length, radius]."""

    axis, form, dimensions = "", COAL_FORM, 2

    @classmethod
    def kernel_form(cls, s):
        return (cls.form, s.radius, 0.5 * getattr(s, cls.axis), 0.0)

    @classmethod
    def primitive_dimensions(cls, s):
        return [getattr(s, cls.axis), s.radius]

    @classmethod
    def primitive_fields(cls, dims):
        return {cls.axis: dims[0], "radius": dims[1]}


@register
class Cylinder(Axial):
    """Axis z, ``height`` its full length, centred on its position."""

    type, platform_extents, markers = "cylinder", 2, ("CYLINDER",)
    keys = (RADIUS, length("height", "full length along z"))
    axis, form, primitive = "height", CYLINDER_FORM, "CYLINDER"

    @staticmethod
    def platform_fields(size):
        return dict(radius=0.5 * size[0], height=size[2])

    @staticmethod
    def bounding_radius(s):
        return math.hypot(s.radius, 0.5 * s.height)

    @staticmethod
    def coal_geometry(s):
        import coal
        return coal.Cylinder(s.radius, s.height)

    @staticmethod
    def marker_parts(s):
        return [(np.zeros(3), np.array([2.0 * s.radius, 2.0 * s.radius, float(s.height)]))]

    @staticmethod
    def mjcf(s):
        return "cylinder", [s.radius, 0.5 * s.height]


@register
class Mesh(ShapeType):
    """A mesh file (STL, OBJ, PLY; read by trimesh) relative to the scene file's folder,
    scaled by ``scale``, checked as its convex hull; over ROS a shape_msgs/Mesh."""

    type, markers = "mesh", ("TRIANGLE_LIST",)
    keys = (Field("file", TEXT, description="STL, OBJ or PLY file, relative to the scene file"),
            Field("scale", NUMBER, 1.0, unit="", sign="positive", limit=MAX_POSITION_M,
                  description="scale of the file's coordinates to m"))
    no_primitive = "a mesh is sent as shape_msgs/Mesh"

    @classmethod
    def fields(cls, d, where, base_dir):
        from pathlib import Path

        name, scale = super().fields(d, where, base_dir).values()
        if not name or "\x00" in name:
            raise InputError(f"{where}.file", name, "expected a file name (STL, OBJ or PLY)")
        path = Path(base_dir) / name
        vertices = mesh_hull(path, f"{where}.file") * scale
        if float(np.max(np.abs(vertices))) > MAX_POSITION_M:
            raise InputError(f"{where}.scale", scale, f"the scaled mesh reaches beyond "
                                                      f"+-{MAX_POSITION_M:g} m")
        return dict(vertices=vertices, file=str(path), scale=scale)

    @staticmethod
    def bounding_radius(s):
        return float(np.max(np.linalg.norm(s.vertices, axis=1)))

    @staticmethod
    def coal_geometry(s):
        import coal
        points = coal.StdVec_Vec3s()
        for v in s.vertices:
            points.append(np.asarray(v, dtype=float))
        return coal.Convex.convexHull(points, False, "")

    @staticmethod
    def marker_parts(s):
        return [(np.zeros(3), np.ones(3))]

    @staticmethod
    def mjcf(s):
        return "mesh", None


@register
class Capsule(Axial):
    """A cylinder of ``length`` along its own z with hemispherical caps of ``radius``,
    centred on its position: the points within ``radius`` of the segment z in
    [-length / 2, length / 2]. Over ROS: Obstacle.CAPSULE, dimensions [length, radius]."""

    type, markers = "capsule", ("CYLINDER", "SPHERE", "SPHERE")
    keys = (RADIUS, length("length", "length of its cylinder along z"))
    axis, form, primitive = "length", CAPSULE_FORM, "CAPSULE"

    @staticmethod
    def bounding_radius(s):
        return 0.5 * s.length + s.radius

    @staticmethod
    def bounding_capsule(s):
        return 0.5 * s.length * np.asarray(s.rotation)[:, 2], s.radius

    @staticmethod
    def coal_geometry(s):
        import coal
        return coal.Capsule(s.radius, s.length)

    @staticmethod
    def marker_parts(s):
        d, h = 2.0 * s.radius, 0.5 * s.length
        return [(np.zeros(3), np.array([d, d, float(s.length)])),
                (np.array([0.0, 0.0, h]), np.full(3, d)), (np.array([0.0, 0.0, -h]), np.full(3, d))]

    @staticmethod
    def mjcf(s):
        return "capsule", [s.radius, 0.5 * s.length]


def mesh_hull(path, where):
    """The vertices (n, 3) of the convex hull of the mesh file ``path`` (trimesh reads
    it); InputError naming ``where`` if it cannot be read or encloses no volume."""
    import trimesh  # only scenes with meshes need it

    try:
        st = os.stat(path)
    except (OSError, ValueError) as exc:
        raise InputError(where, str(path), f"cannot read: {getattr(exc, 'strerror', None) or exc}") \
            from None
    if not os.path.isfile(path):
        raise InputError(where, str(path), "not a regular file")
    if st.st_size > MAX_MESH_BYTES:
        raise InputError(where, str(path), f"file too large: {st.st_size} bytes "
                                           f"(at most {MAX_MESH_BYTES})")
    try:
        mesh = trimesh.load(str(path), force="mesh", process=False)
        return _hull(np.asarray(mesh.vertices, dtype=float))
    except Exception as exc:  # trimesh's many parsers raise many kinds: all are bad input
        raise InputError(where, str(path), f"not a mesh trimesh can read: "
                                           f"{type(exc).__name__}: {exc}") from None


def hull_of_points(points, where):
    """The vertices (n, 3) of the convex hull of ``points`` (m; a mesh given by its
    vertices, as shape_msgs/Mesh gives it); InputError naming ``where`` if there are not 4
    to MAX_MESH_VERTICES finite points enclosing a volume."""
    try:
        return _hull(np.asarray(points, dtype=float).reshape(-1, 3))
    except Exception as exc:  # noqa: BLE001 - qhull and trimesh raise many kinds
        raise InputError(where, f"{np.size(points) // 3} vertices", f"not a solid mesh: "
                                                                    f"{exc}") from None


def _hull(v):
    """Convex hull vertices of the points v (n, 3); ValueError saying why there are none."""
    import trimesh

    if not 4 <= len(v) <= MAX_MESH_VERTICES or not np.all(np.isfinite(v)):
        raise ValueError(f"{len(v)} vertices (need 4 to {MAX_MESH_VERTICES}, finite)")
    with np.errstate(all="ignore"):  # a flat set's volume is 0 / 0: refused below
        hull = trimesh.convex.convex_hull(v)
        volume = hull.volume
    if not volume > 0.0:
        raise ValueError("encloses no volume")
    return np.asarray(hull.vertices, dtype=float)
