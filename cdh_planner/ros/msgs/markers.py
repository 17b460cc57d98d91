"""RViz / Foxglove markers of a planned path: the path, the platform and the cables
coloured by tension margin, and a scene's obstacles (no node, no graph).

    markers_msg(path, robot, frame_id, stamp, scene=None) -> visualization_msgs/MarkerArray
"""

import numpy as np
from geometry_msgs.msg import Point
from std_msgs.msg import ColorRGBA
from visualization_msgs.msg import Marker, MarkerArray

from ...model.pose import rotation_from_quaternion
from ...trajectory.sampling import check_timed_path


LINE_WIDTH_M = 0.002
MARGIN_FULL = 0.2  # normalised tension margin drawn fully green (0 or less: red)
PATH_COLOR = (0.2, 0.5, 1.0, 1.0)
PLATFORM_COLOR = (0.2, 0.2, 0.2, 1.0)
POSES_DRAWN = 5  # platform and cables drawn at this many poses along the path, ends included
OBSTACLE_COLOR = (0.6, 0.3, 0.1, 0.6)


def cable_margins(path, robot):
    """Per waypoint and cable, the normalised tension margin (N, 6): distance of the envelope
    to the robot's tension limits over the limit range, as in feasibility (positive inside)."""
    span = robot.tension_max - robot.tension_min
    low = (np.asarray(path.tension_min) - robot.tension_min) / span
    high = (robot.tension_max - np.asarray(path.tension_max)) / span
    return np.minimum(low, high)


def margin_color(margin, full=MARGIN_FULL):
    """RGBA of a normalised margin: red at <= 0, yellow at full/2, green at >= full
    (not finite: red)."""
    m = float(margin)
    x = float(np.clip(m / full, 0.0, 1.0)) if np.isfinite(m) else 0.0
    red = min(1.0, 2.0 * (1.0 - x))
    green = min(1.0, 2.0 * x) * 0.8
    return ColorRGBA(r=red, g=green, b=0.0, a=1.0)


def markers_msg(path, robot, frame_id, stamp, *, line_width=LINE_WIDTH_M, delete_all=True,
                scene=None):
    """visualization_msgs/MarkerArray for RViz / Foxglove, all in ``frame_id`` (m):

    - ns ``path`` id 0: LINE_STRIP through the platform positions p, each vertex coloured
      by the least tension margin of its waypoint (``margin_color``);
    - at ``drawn_waypoints`` (POSES_DRAWN evenly spaced, the ends included), ids 0, 1, ...:
      ns ``platform``, a closed LINE_STRIP through the anchor points p + R b_i (distinct
      points, by angle around their centre), and ns ``cables``, a LINE_LIST of the six
      cables from the base anchor a_i to p + R b_i, each coloured by its tension margin.

    - with a ``scene`` (scene.schema.Scene), ns ``obstacles`` id k: obstacle k as a SPHERE,
      CUBE, CYLINDER (RViz's: along z, as the scene's), for a capsule a CYLINDER with two
      SPHERE caps (ns ``obstacles/1`` and ``obstacles/2``) or, for a mesh, the
      TRIANGLE_LIST of its convex hull (what the checks use).

    With ``delete_all`` a DELETEALL marker comes first, so a new plan replaces the old one.
    """
    check_timed_path(path)
    out = MarkerArray()
    if delete_all:
        clear = Marker(action=Marker.DELETEALL)
        clear.header.frame_id, clear.header.stamp = frame_id, stamp
        out.markers.append(clear)
    if len(path) == 0:
        return out
    if scene is not None:
        out.markers.extend(obstacle_markers(scene, frame_id, stamp))
    margins = cable_margins(path, robot)
    line = _marker(frame_id, stamp, "path", 0, Marker.LINE_STRIP, line_width, PATH_COLOR)
    line.points = [_point(p) for p in path.p]
    line.colors = [margin_color(m) for m in margins.min(axis=1)]
    out.markers.append(line)
    for ident, k in enumerate(drawn_waypoints(len(path))):
        R = rotation_from_quaternion(path.quaternion[k])
        attach = path.p[k] + robot.platform_anchors @ R.T
        out.markers.append(_platform_marker(frame_id, stamp, ident, attach, robot, line_width))
        out.markers.append(_cables_marker(frame_id, stamp, ident, robot.base_anchors, attach,
                                          margins[k], line_width))
    return out


def obstacle_markers(scene, frame_id, stamp):
    """One marker per obstacle of ``scene`` (ns ``obstacles``, ids in scene order), placed
    by its pose in ``frame_id`` (m); a shape of several parts (model.shapes: ``markers``,
    a capsule's two caps) adds part j in ns ``obstacles/<j>`` under the same id."""
    from scipy.spatial import ConvexHull

    out = []
    for k, o in enumerate(scene.obstacles):
        R = np.asarray(o.rotation, float)
        x, y, z, w = (float(v) for v in o.quaternion)
        for j, (kind, (offset, scale)) in enumerate(zip(o.type.markers, o.type.marker_parts(o))):
            ns = "obstacles" if j == 0 else f"obstacles/{j}"  # a capsule's caps: parts 1, 2
            m = _marker(frame_id, stamp, ns, k, getattr(Marker, kind), 1.0, OBSTACLE_COLOR)
            m.pose.position = _point(o.position + R @ offset)
            m.pose.orientation.x, m.pose.orientation.y, m.pose.orientation.z = x, y, z
            m.pose.orientation.w = w
            m.scale.x, m.scale.y, m.scale.z = (float(v) for v in scale)
            if kind == "TRIANGLE_LIST":  # a mesh: its convex hull, what the checks use
                m.points = [_point(o.vertices[i]) for tri in ConvexHull(o.vertices).simplices
                            for i in tri]
            out.append(m)
    return out


def pose_markers(robot, p, R, margins, frame_id, stamp, ns_suffix="", line_width=LINE_WIDTH_M):
    """The platform outline and the cables (each coloured by its margin, ``margins`` (6,))
    at one pose (p m, R): two markers, ns ``platform<suffix>`` and ``cables<suffix>``, id 0."""
    attach = np.asarray(p, dtype=float) + robot.platform_anchors @ np.asarray(R).T
    platform = _platform_marker(frame_id, stamp, 0, attach, robot, line_width)
    cables = _cables_marker(frame_id, stamp, 0, robot.base_anchors, attach, margins, line_width)
    platform.ns += ns_suffix
    cables.ns += ns_suffix
    return [platform, cables]


def drawn_waypoints(n, count=POSES_DRAWN):
    """Indexes of the waypoints (of n) where platform and cables are drawn: ``count``
    evenly spaced, the first and the last included, none twice."""
    return sorted(set(np.linspace(0, n - 1, min(count, n)).round().astype(int).tolist()))


def _marker(frame_id, stamp, ns, ident, kind, line_width, color=(1.0, 1.0, 1.0, 1.0)):
    """A line marker (LINE_STRIP / LINE_LIST) with identity pose: points are in frame_id."""
    m = Marker()
    m.header.frame_id = frame_id
    m.header.stamp = stamp
    m.ns, m.id, m.type, m.action = ns, ident, kind, Marker.ADD
    m.pose.orientation.w = 1.0
    m.scale.x = float(line_width)
    m.color = ColorRGBA(r=color[0], g=color[1], b=color[2], a=color[3])
    return m


def _point(p):
    return Point(x=float(p[0]), y=float(p[1]), z=float(p[2]))


def _platform_marker(frame_id, stamp, ident, attach, robot, line_width):
    """Closed outline through the distinct platform anchors, ordered by angle in the
    platform's own x-y plane."""
    local = robot.platform_anchors
    _, first = np.unique(np.round(local, 9), axis=0, return_index=True)
    idx = np.sort(first)
    centre = local[idx].mean(axis=0)
    angle = np.arctan2(local[idx, 1] - centre[1], local[idx, 0] - centre[0])
    ring = idx[np.argsort(angle)]
    m = _marker(frame_id, stamp, "platform", ident, Marker.LINE_STRIP, line_width,
                PLATFORM_COLOR)
    m.points = [_point(attach[i]) for i in list(ring) + [ring[0]]]
    return m


def _cables_marker(frame_id, stamp, ident, anchors, attach, margins, line_width):
    m = _marker(frame_id, stamp, "cables", ident, Marker.LINE_LIST, line_width)
    for a, b, margin in zip(anchors, attach, margins):
        color = margin_color(margin)
        m.points.extend([_point(a), _point(b)])
        m.colors.extend([color, color])
    return m
