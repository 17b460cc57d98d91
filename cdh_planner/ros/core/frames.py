"""Frames (REP 103 / REP 105) and a small transform book for goals in other frames.

- The fixed frame (parameter ``fixed_frame``, default ``world``) is z-up, as REP 103 asks
  and as RViz, Foxglove and every other node expect.
- The paper's frame, the planner's ``base_frame`` (default ``cdh_base``), has z down
  (gravity +z): it is a child of the fixed frame, rotated by pi about x (a static
  transform), so x is shared and y, z are flipped. Every plan and output stays in it.
- The platform (``platform_frame``, default ``cdh_platform``) is a child of the base frame,
  its pose the forward kinematics of the measured cable lengths.

``TransformBook`` keeps the latest transform per child frame from /tf and /tf_static (no
tf2 on PyPI, so no tf2_ros buffer) and resolves a pose in any frame connected to the base
frame. Quaternions are (x, y, z, w); transforms are (q, t): x_parent = R(q) x_child + t (m).
Products are plain Hamilton products, not renormalised, so a pi rotation about an axis is
exact (a z-up goal plans bit for bit as the same goal in the paper frame).
"""

import threading

import numpy as np
from geometry_msgs.msg import PoseStamped, TransformStamped

from ...errors import InputError

# fixed (z-up) -> paper frame (z-down): pi about x
Z_DOWN = (np.array([1.0, 0.0, 0.0, 0.0]), np.zeros(3))
MAX_FRAMES = 1000       # a bound on the frames kept (a /tf flood is cut, not grown)


def quat_multiply(a, b):
    """Hamilton product a * b of quaternions (x, y, z, w)."""
    ax, ay, az, aw = a
    bx, by, bz, bw = b
    return np.array([aw * bx + ax * bw + ay * bz - az * by,
                     aw * by - ax * bz + ay * bw + az * bx,
                     aw * bz + ax * by - ay * bx + az * bw,
                     aw * bw - ax * bx - ay * by - az * bz])


def quat_rotate(q, v):
    """R(q) v for a unit quaternion q (x, y, z, w): v + 2 w (u x v) + 2 u x (u x v)."""
    u, w = np.asarray(q[:3], dtype=float), float(q[3])
    v = np.asarray(v, dtype=float)
    c = np.cross(u, v)
    return v + 2.0 * w * c + 2.0 * np.cross(u, c)


def compose(a, b):
    """(q, t) of a then b: x = a(b(x))."""
    return quat_multiply(a[0], b[0]), quat_rotate(a[0], b[1]) + a[1]


def inverse(a):
    q_inv = np.array([-a[0][0], -a[0][1], -a[0][2], a[0][3]])
    return q_inv, -quat_rotate(q_inv, a[1])


IDENTITY = (np.array([0.0, 0.0, 0.0, 1.0]), np.zeros(3))


def transform_msg(parent, child, transform, stamp=None):
    """geometry_msgs/TransformStamped parent -> child of (q, t) (stamp None: zero)."""
    msg = TransformStamped()
    msg.header.frame_id, msg.child_frame_id = parent, child
    if stamp is not None:
        msg.header.stamp = stamp
    q, t = transform
    tr = msg.transform
    tr.translation.x, tr.translation.y, tr.translation.z = (float(v) for v in t)
    tr.rotation.x, tr.rotation.y, tr.rotation.z, tr.rotation.w = (float(v) for v in q)
    return msg



class TransformBook:
    """The latest transform of each child frame (from TransformStamped messages);
    ``lookup(target, source)`` composes them through the tree. Thread-safe."""

    def __init__(self, max_frames=MAX_FRAMES):
        self._lock = threading.Lock()
        self._edges = {}            # child -> (parent, (q, t))
        self._max = max_frames

    def add(self, msg):
        """Keep TransformStamped ``msg`` (parent -> child); False when the book is full."""
        t, r = msg.transform.translation, msg.transform.rotation
        edge = (msg.header.frame_id.lstrip("/"), (np.array([r.x, r.y, r.z, r.w]),
                                                  np.array([t.x, t.y, t.z])))
        child = msg.child_frame_id.lstrip("/")
        with self._lock:
            if child not in self._edges and len(self._edges) >= self._max:
                return False
            self._edges[child] = edge
        return True

    def frames(self):
        with self._lock:
            return sorted(set(self._edges) | {p for p, _ in self._edges.values()})

    def _to_root(self, frame):
        """(root frame, transform root <- frame)."""
        with self._lock:
            edges = dict(self._edges)
        transform, seen = IDENTITY, set()
        while frame in edges and frame not in seen:    # a loop in /tf: stop at it
            seen.add(frame)
            parent, edge = edges[frame]
            transform, frame = compose(edge, transform), parent
        return frame, transform

    def lookup(self, target, source):
        """(q, t) mapping coordinates in ``source`` to ``target``; LookupError naming the
        frames when they are not connected."""
        if target == source:
            return IDENTITY
        root_s, from_source = self._to_root(source)
        root_t, from_target = self._to_root(target)
        if root_s != root_t:
            raise LookupError(f"no transform from '{source}' to '{target}' in TF "
                              f"(frames known: {', '.join(self.frames()) or 'none'})")
        return compose(inverse(from_target), from_source)


def pose_in_frame(book, msg, target, field):
    """PoseStamped ``msg`` expressed in ``target`` (the same message when already there);
    InputError naming ``<field>.header.frame_id`` when TF cannot resolve its frame."""
    frame = msg.header.frame_id
    if frame == target:
        return msg
    try:
        q_t, t_t = book.lookup(target, frame.lstrip("/")) if frame else (None, None)
    except LookupError as exc:
        raise InputError(f"{field}.header.frame_id", frame, str(exc)) from None
    if q_t is None:
        raise InputError(f"{field}.header.frame_id", frame, f"empty: give '{target}' or a "
                                                            f"frame TF connects to it")
    pos, o = msg.pose.position, msg.pose.orientation
    p = quat_rotate(q_t, [pos.x, pos.y, pos.z]) + t_t
    q = quat_multiply(q_t, [o.x, o.y, o.z, o.w])
    out = PoseStamped()
    out.header.stamp, out.header.frame_id = msg.header.stamp, target
    out.pose.position.x, out.pose.position.y, out.pose.position.z = (float(v) for v in p)
    o2 = out.pose.orientation
    o2.x, o2.y, o2.z, o2.w = (float(v) for v in q)
    return out
