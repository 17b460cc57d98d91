"""Obstacles and scenes as ROS messages (no rclpy, no node): cdh_planner_interfaces/Obstacle
<-> scene.schema.Shape, and the node's scene as a cdh_planner_interfaces/Scene.

    shape = shape_of_obstacle(msg, "obstacles[2]")      # InputError naming the field
    msg = obstacle_msg(shape)                           # ADD, its pose and shape
    msg = scene_msg(version, scene, frame_id, stamp)    # ~/get_scene, ~/scene
    array = scene_change(current, target)               # the ObstacleArray from one to the other

A SolidPrimitive SPHERE (radius), BOX (x, y, z: full edges) or CYLINDER (height, radius) is
the scene file's sphere, box or cylinder, and type Obstacle.CAPSULE (length, radius) its
capsule (each shape class of model.shapes gives its type number and dimensions); a Mesh is checked as the convex hull of its
vertices (as a mesh file is). Poses are in the base frame (m), orientations unit quaternions
(within 1e-3, as the goals').
"""

import numpy as np
from geometry_msgs.msg import Point
from shape_msgs.msg import MeshTriangle, SolidPrimitive

from cdh_planner_interfaces.msg import Obstacle, ObstacleArray, Scene

from ...errors import MAX_POSITION_M, InputError, check_numbers
from ...model.pose import check_quaternion
from ...model.shapes import SHAPES, hull_of_points
from ...scene.schema import Shape, check_obstacle_id, shape_from_dict

# {type number: shape type} of the classes with a primitive: SolidPrimitive's constant of
# that name, else the Obstacle message's own (CAPSULE)
PRIMITIVES = {getattr(SolidPrimitive, c.primitive, None) or getattr(Obstacle, c.primitive): t
              for t, c in SHAPES.items() if c.primitive is not None}


def _listed(words):
    """"a, b or c"."""
    return f"{', '.join(words[:-1])} or {words[-1]}"


def shape_of_obstacle(msg, where):
    """The Shape (base frame) of an ADD Obstacle message; InputError naming the field
    (``<where>.primitive.dimensions``, ``<where>.pose.orientation``, ...)."""
    oid = check_obstacle_id(msg.id, f"{where}.id")
    pos = msg.pose.position
    position = check_numbers(f"{where}.pose.position", [pos.x, pos.y, pos.z], 3, MAX_POSITION_M)
    o = msg.pose.orientation
    q = check_quaternion([o.x, o.y, o.z, o.w], f"{where}.pose.orientation")
    has_mesh = len(msg.mesh.vertices) > 0
    if has_mesh == (msg.primitive.type != 0):
        names = _listed([SHAPES[t].primitive for t in PRIMITIVES.values()])
        raise InputError(where, oid, f"give exactly one shape: a primitive (type {names}) or "
                                     "a mesh (its vertices)")
    if has_mesh:
        v = np.array([[p.x, p.y, p.z] for p in msg.mesh.vertices], dtype=float)
        hull = hull_of_points(v, f"{where}.mesh.vertices")
        if float(np.max(np.abs(hull))) > MAX_POSITION_M:
            raise InputError(f"{where}.mesh.vertices", "", f"beyond +-{MAX_POSITION_M:g} m")
        return Shape(id=oid, kind="mesh", position=np.array(position), quaternion=q,
                     vertices=hull)
    kind = PRIMITIVES.get(msg.primitive.type)
    if kind is None:
        raise InputError(f"{where}.primitive.type", int(msg.primitive.type),
                         "expected " + _listed([f"{SHAPES[t].primitive} ({n})"
                                                for n, t in PRIMITIVES.items()]))
    dims = [float(d) for d in msg.primitive.dimensions]
    count = SHAPES[kind].dimensions
    if len(dims) != count:
        raise InputError(f"{where}.primitive.dimensions", dims, f"a {kind} has {count}")
    fields = SHAPES[kind].primitive_fields(dims)
    return shape_from_dict(dict(type=kind, position=position, quaternion=q.tolist(), **fields),
                           f"{where}.primitive", oid)


def sendable(shape):
    """Does ``shape`` have an Obstacle message: a primitive, or a mesh's vertices?"""
    return shape.type.primitive is not None or shape.vertices is not None


def check_sendable(scene, where="scene"):
    """``scene`` (scene.schema.Scene or None) if every shape of it has an Obstacle message;
    else InputError naming the first shape's type with its class's reason (``no_primitive``):
    the node refuses such a scene when it loads it, rather than failing to publish ~/scene."""
    if scene is None:
        return scene
    shapes = [("platform", scene.platform)] * (scene.platform is not None) + [
        (f"obstacles[{i}]", o) for i, o in enumerate(scene.obstacles)]
    for name, shape in shapes:
        if not sendable(shape):
            raise InputError(f"{where}.{name}.type", shape.kind,
                             f"has no Obstacle message for the node: {shape.type.no_primitive}")
    return scene


def obstacle_msg(shape, operation=Obstacle.ADD):
    """The Obstacle message of a Shape (a mesh: its convex hull's vertices and triangles)."""
    msg = Obstacle(id=shape.id, operation=operation)
    msg.pose.position = _point(shape.position)
    x, y, z, w = (float(v) for v in shape.quaternion)
    msg.pose.orientation.x, msg.pose.orientation.y = x, y
    msg.pose.orientation.z, msg.pose.orientation.w = z, w
    if not sendable(shape):
        raise ValueError(f"a {shape.kind} has no Obstacle message: {shape.type.no_primitive}")
    if shape.type.primitive is None:
        from scipy.spatial import ConvexHull
        msg.mesh.vertices = [_point(v) for v in shape.vertices]
        msg.mesh.triangles = [MeshTriangle(vertex_indices=[int(i) for i in tri])
                              for tri in ConvexHull(shape.vertices).simplices]
        return msg
    dims = shape.type.primitive_dimensions(shape)
    number = {t: n for n, t in PRIMITIVES.items()}[shape.kind]
    msg.primitive = SolidPrimitive(type=number, dimensions=[float(d) for d in dims])
    return msg


def scene_msg(version, scene, frame_id, stamp=None):
    """cdh_planner_interfaces/Scene of ``scene`` (scene.schema.Scene, or None: nothing is
    checked) at ``version``."""
    msg = Scene(version=int(version), checked=scene is not None)
    msg.header.frame_id = frame_id
    if stamp is not None:
        msg.header.stamp = stamp
    if scene is not None:
        msg.cable_radius, msg.clearance = float(scene.cable_radius), float(scene.clearance)
        msg.platform = [obstacle_msg(scene.platform)] if scene.platform is not None else []
        msg.obstacles = [obstacle_msg(o) for o in scene.obstacles]
    return msg


def scene_change(current, target):
    """The ObstacleArray (frame of ``target``) that turns the obstacles of the Scene message
    ``current`` into those of ``target``: REMOVE those it lacks, ADD those that are new or
    differ (``same``). Empty when they hold the same obstacles."""
    now = {o.id: o for o in current.obstacles}
    want = {o.id: o for o in target.obstacles}
    out = ObstacleArray(header=target.header)
    out.obstacles = [Obstacle(id=i, operation=Obstacle.REMOVE) for i in now if i not in want]
    out.obstacles += [o for i, o in want.items() if i not in now or not same(now[i], o)]
    return out


def same(a, b, tol=1e-12):
    """Are two Obstacle messages the same obstacle (within ``tol``: a pose read back is
    normalised again, a mesh's hull may list its vertices in another order)?"""
    def pose(m):
        p, q = m.pose.position, m.pose.orientation
        return np.array([p.x, p.y, p.z, q.x, q.y, q.z, q.w])

    def vertices(m):
        v = np.array([[p.x, p.y, p.z] for p in m.mesh.vertices]).reshape(-1, 3)
        return v[np.lexsort(v.T[::-1])]

    va, vb = vertices(a), vertices(b)
    return (a.primitive.type == b.primitive.type and va.shape == vb.shape
            and np.allclose(a.primitive.dimensions, b.primitive.dimensions, rtol=0, atol=tol)
            and np.allclose(pose(a), pose(b), rtol=0, atol=tol)
            and np.allclose(va, vb, rtol=0, atol=tol))


def _point(p):
    return Point(x=float(p[0]), y=float(p[1]), z=float(p[2]))
