"""The cable-driven hexapod: anchors, limits, load and wrench ellipsoid (SI units).

A robot file is a ROS 2 parameters file, so the same file configures the node:

    cdh_planner:
      ros__parameters:
        robot: {name, winch_names, base_anchors, platform_anchors, length_min, ...}

Arrays are flat because ROS 2 parameters cannot nest lists: ``base_anchors`` holds
A_1..A_m, x y z each (metres, base frame F1; m cables, one per winch name, 6 to 16),
``platform_anchors`` B_1..B_m (metres, platform frame F2); a 6x6 matrix is 36 numbers
row-major, or 6 numbers for a diagonal. Every field is declared once, on ``Robot``
(key, unit, size, bounds, description: a ``fields.Field``); the table of them
is docs/parameters.md (``robot.*``).
"""

from dataclasses import dataclass, field, fields, replace
from pathlib import Path

import numpy as np

from ..errors import MAX_FORCE_N, MAX_POSITION_M, InputError
from .. import files
from . import jacobian_probes
from .shapes import SHAPES, platform_types
from ..fields import CHOICE, MATRIX, NAME, NAMES, NUMBER, NUMBERS
from .robot_schema import N_CABLES, check_groups, read_fields, robot_field, schema_of

MAX_CABLE_RADIUS_M = 1.0  # m: a thicker "cable" is a unit mistake
MAX_STIFFNESS_N = 1e10  # N: EA of a 100 mm steel rope is about 1e9 N; more is a unit mistake
MAX_ELLIPSOID = 1e18  # largest |entry| of an ellipsoid matrix (1/N^2, 1/(N m)^2)
MIN_SPREAD_M = 1e-6  # anchors closer than this to one line are collinear
SINGULAR_RCOND = 1e-9  # J with smallest / largest singular value below this is singular
JACOBIAN_PROBES = jacobian_probes.PROBES  # poses at which a robot's J must be regular at least once
GRAVITY = 9.80665  # m/s^2: |force| of a load with a mass is its weight (within 2 %)
OPTIONAL_GROUPS = ("contact_ellipsoid",)
# robot.platform_shape.type: none, or a shape class that can be a platform (model.shapes)
PLATFORM_SHAPES = ("none", *sorted(platform_types()))
WINCH_NAMES = tuple(f"winch_{i + 1}" for i in range(N_CABLES))


@dataclass(frozen=True, kw_only=True)
class Robot:
    """A cable-driven hexapod. Lengths in m, forces in N, moments in N m.

    The load wrench is ``force`` applied at ``load_point`` (platform frame) plus
    ``moment``; the wrench ellipsoid K = {w : (w - w0)^T E (w - w0) <= 1} has centre
    w0 = load wrench + ``ellipsoid_offset`` and shape ``ellipsoid_matrix`` (E), both given
    in ``ellipsoid_frame``: "load" (F3: parallel to the base, origin at the load point, the
    paper's App. A) or "base" (F1, moments about the base origin). A contact ellipsoid
    (``contact_matrix``, ``contact_center`` as given, or None) is already folded into
    ``ellipsoid_matrix`` and ``ellipsoid_offset`` (paper Eqs. 22-23).

    Each field read from the robot file carries its declaration (a ``fields.Field``, see
    ``robot_schema``): the file's key, unit, size, bounds and description. The node's
    ``robot.*`` parameters and docs/parameters.md are built from them; a new robot field is
    one field here. m, the number of cables, is the number of ``winch_names``.
    """

    name: str = robot_field(
        key="name", kind=NAME, unit="", default=None,
        description="robot name, for messages (absent: the file's name)")
    winch_names: tuple = robot_field(
        key="winch_names", kind=NAMES, unit="", default=WINCH_NAMES,
        description="joint names of the winches (JointState / JointTrajectory names)")
    base_anchors: np.ndarray = robot_field(  # (m, 3) A_i in F1
        key="base_anchors", kind=NUMBERS, unit="m", count=3, per_cable=True,
        limit=MAX_POSITION_M, description="cable anchors A_i on the base, x y z in the base frame")
    platform_anchors: np.ndarray = robot_field(  # (m, 3) B_i in F2
        key="platform_anchors", kind=NUMBERS, unit="m", count=3, per_cable=True,
        limit=MAX_POSITION_M, description="cable anchors B_i on the platform, x y z in the platform frame")
    length_min: np.ndarray = robot_field(  # (m,)
        key="length_min", kind=NUMBERS, unit="m", per_cable=True, broadcast=True,
        limit=MAX_POSITION_M, sign="positive", description="least cable length")
    length_max: np.ndarray = robot_field(
        key="length_max", kind=NUMBERS, unit="m", per_cable=True, broadcast=True,
        limit=MAX_POSITION_M, sign="positive", description="greatest cable length")
    tension_min: np.ndarray = robot_field(
        key="tension_min", kind=NUMBERS, unit="N", per_cable=True, broadcast=True,
        limit=MAX_FORCE_N, sign="non-negative", description="least cable tension")
    tension_max: np.ndarray = robot_field(
        key="tension_max", kind=NUMBERS, unit="N", per_cable=True, broadcast=True,
        limit=MAX_FORCE_N, sign="positive", description="greatest cable tension")
    cable_stiffness: np.ndarray = robot_field(  # (m,) EA_i, or None: rigid cables
        key="cable_stiffness", kind=NUMBERS, unit="N", per_cable=True, broadcast=True,
        limit=MAX_STIFFNESS_N, sign="positive", default=None,
        description="axial stiffness EA of each cable: of unstretched length L0 under tension t "
                    "it is L0 (1 + t / EA) long; above the cable's greatest tension (absent: "
                    "rigid cables; required to execute by lengths alone with more than 6 cables)")
    least_stiffness: float = robot_field(
        key="least_stiffness", kind=NUMBER, unit="N/m", sign="non-negative",
        limit=MAX_STIFFNESS_N, default=None,
        description="with cable_stiffness and more than 6 cables: the least eigenvalue of the "
                    "platform's stiffness (N/m, N m/rad) its nominal tensions keep, moved in "
                    "the null space where the rule's would leave it softer (absent: 0, a "
                    "stable equilibrium; docs/elastic-cables.md)")
    tension_rule: str = robot_field(
        key="tension_rule", kind=NAME, unit="", default="centred",
        description="how more than 6 cables share the wrench: a tension rule of "
                    "cdh_planner.wrench.RULES (centred: the range-weighted pseudo-inverse, its "
                    "nominal centred in the null space; docs/more-cables.md)")
    length_error: np.ndarray = robot_field(  # (m,) e_i, or None: exact winches
        key="length_error", kind=NUMBERS, unit="m", per_cable=True, broadcast=True,
        limit=MAX_POSITION_M, sign="non-negative", default=None,
        description="bound e_i on the error of the cable length each winch realises, below its "
                    "length range (absent: exact winches; gives the pose accuracy)")
    cable_radius: float = robot_field(
        key="cable_radius", kind=NUMBER, unit="m", sign="non-negative", limit=MAX_CABLE_RADIUS_M,
        default=0.0, description="cable radius: each cable is a capsule of it in the collision "
                                 "checks (a scene's cable_radius overrides it)")
    platform_shape: str = robot_field(
        key="platform_shape.type", kind=CHOICE, unit="", choices=PLATFORM_SHAPES, default="none",
        description="the platform's body in the collision checks (obstacles, its own cables), "
                    "the default of a scene's platform; none: not checked")
    platform_size: np.ndarray = robot_field(  # (3,)
        key="platform_shape.size", kind=NUMBERS, unit="m", count=3, limit=MAX_POSITION_M,
        sign="positive", default=None,
        description="the body's full extent along the platform frame's x, y, z: a box's edges; "
                    "a cylinder (axis z): diameter, diameter, height; a sphere: its diameter "
                    "three times (required with a type)")
    platform_center: np.ndarray = robot_field(  # (3,)
        key="platform_shape.position", kind=NUMBERS, unit="m", count=3, limit=MAX_POSITION_M,
        default=(0.0, 0.0, 0.0), description="the body's centre, platform frame")
    force: np.ndarray = robot_field(  # (3,)
        key="load.force", kind=NUMBERS, unit="N", count=3, limit=MAX_FORCE_N,
        description="load force, base frame")
    load_point: np.ndarray = robot_field(  # (3,) the paper's g / p_m
        key="load.point", kind=NUMBERS, unit="m", count=3, limit=MAX_POSITION_M,
        default=(0.0, 0.0, 0.0), description="where the load force acts, platform frame")
    moment: np.ndarray = robot_field(  # (3,)
        key="load.moment", kind=NUMBERS, unit="N m", count=3, limit=MAX_FORCE_N,
        default=(0.0, 0.0, 0.0), description="load moment, base frame")
    mass: float = robot_field(
        key="load.mass", kind=NUMBER, unit="kg", sign="positive", limit=MAX_FORCE_N,
        default=None, description="load mass (optional: enables the dynamic timing; "
                                  "load.force must then be its weight)")
    inertia: np.ndarray = robot_field(  # (3, 3) about the centre of mass (load_point)
        key="load.inertia", kind=MATRIX, unit="kg m^2", count=3, limit=MAX_FORCE_N,
        definite="semi", default=None,
        description="load inertia about its centre of mass, platform frame (needs load.mass; "
                    "empty: 0, a point mass)")
    ellipsoid_frame: str = robot_field(
        key="wrench_ellipsoid.frame", kind=CHOICE, unit="", choices=("load", "base"),
        default="load", description="frame of the wrench ellipsoid (load: F3, parallel to the "
                                    "base, origin at the load point; base: F1)")
    ellipsoid_matrix: np.ndarray = robot_field(  # (6, 6), combined with the contact one if any
        key="wrench_ellipsoid.matrix", kind=MATRIX, unit="1/N^2 (force rows), 1/(N m)^2 "
        "(moment rows)", count=6, limit=MAX_ELLIPSOID, definite="positive",
        description="wrench ellipsoid shape E, symmetric positive definite")
    ellipsoid_offset: np.ndarray = robot_field(  # (6,), plus the contact centre if any
        key="wrench_ellipsoid.offset", kind=NUMBERS, unit="N, N m", count=6, limit=MAX_FORCE_N,
        default=(0.0,) * 6, description="wrench ellipsoid centre offset from the load wrench")
    contact_matrix: np.ndarray = robot_field(  # (6, 6) or None; folded into ellipsoid_matrix
        key="contact_ellipsoid.matrix", kind=MATRIX, unit="1/N^2, 1/(N m)^2", count=6,
        limit=MAX_ELLIPSOID, definite="positive",
        description="contact wrench ellipsoid shape (paper Eqs. 22-23; optional: empty for none)")
    contact_center: np.ndarray = robot_field(  # (6,); folded into ellipsoid_offset
        key="contact_ellipsoid.center", kind=NUMBERS, unit="N, N m", count=6, limit=MAX_FORCE_N,
        default=(0.0,) * 6, description="contact wrench ellipsoid centre")
    source: str = field(default="", compare=False)

    @property
    def wrench_center_local(self):
        """w0 in the ellipsoid frame before moving to F1: [F; M] + offset (N, N m)."""
        return np.concatenate([self.force, self.moment]) + self.ellipsoid_offset


FIELDS = schema_of(Robot)  # the robot file's fields, declared once (above)


def combine_contact_ellipsoid(E_w, E_c):
    """Outer ellipsoid shape of the Minkowski sum of two ellipsoids (paper Eqs. 22-23)."""
    return 0.5 * E_w @ np.linalg.solve(E_w + E_c, E_c)


def read_yaml(path, field):
    """The parsed YAML file at ``path``; InputError naming ``field`` if it is missing, not
    a readable regular file, not UTF-8 YAML or beyond the input limits (``files``)."""
    return files.read_yaml(path, field)


def load_robot(path):
    """Read a robot from a ROS 2 parameters YAML file; raise InputError on bad content."""
    doc = read_yaml(path, "robot")
    params = ros_parameters(doc, str(path))
    if "robot" not in params:
        raise InputError("robot", str(path), "no 'robot:' section under ros__parameters")
    return robot_from_dict(params["robot"], source=str(path))


def ros_parameters(doc, where):
    """The ``ros__parameters`` mapping of a parameters file (first node entry)."""
    if not isinstance(doc, dict) or not doc:
        raise InputError(where, doc, "expected a ROS 2 parameters file (node: ros__parameters: ...)")
    for node_name, entry in doc.items():
        if isinstance(entry, dict) and "ros__parameters" in entry:
            params = entry["ros__parameters"]
            if not isinstance(params, dict):
                raise InputError(f"{node_name}.ros__parameters", params, "expected a mapping")
            return params
    raise InputError(where, list(doc), "no '<node>: ros__parameters:' entry")


def robot_from_dict(d, source=""):
    """Build and validate a Robot from the ``robot:`` mapping (keys as declared in ``Robot``).

    Each field is read by its declaration (``robot_schema.read_fields``): numbers must be
    numbers (not strings), finite and within the input bounds of ``errors`` (coordinates
    and lengths 1e3 m, forces and tensions 1e7 N). Then what involves several fields: each
    minimum below its maximum, a load mass matching the load force, the contact ellipsoid
    folded into the wrench ellipsoid, and a degenerate robot refused: the base (or
    platform) anchors on one line, all coincident included, or a J singular at every pose
    tried (see ``check_not_degenerate``)."""
    check_groups(d, FIELDS, OPTIONAL_GROUPS)
    v = read_fields(d, FIELDS, defaults={"name": Path(source).stem or "robot"})
    _check_below("robot.length_min", v["length_min"], "robot.length_max", v["length_max"])
    _check_below("robot.tension_min", v["tension_min"], "robot.tension_max", v["tension_max"])
    _check_elastic(v)
    _check_mass_properties(v, d)
    _check_platform_shape(v)
    if v["contact_ellipsoid.matrix"] is None:
        v["contact_ellipsoid.center"] = None
    check_not_degenerate(v["base_anchors"], v["platform_anchors"], v["length_min"], v["length_max"])
    declared = {f.name: v[f.metadata["robot"].key] for f in fields(Robot) if "robot" in f.metadata}
    return _with_contact(Robot(**declared, source=source))


def _with_contact(robot):
    """``robot`` with its contact ellipsoid (if any) folded into the wrench ellipsoid: the
    outer ellipsoid of their sum (``combine_contact_ellipsoid``), centres added."""
    if robot.contact_matrix is None:
        return robot
    E = combine_contact_ellipsoid(robot.ellipsoid_matrix, robot.contact_matrix)
    return replace(robot, ellipsoid_matrix=0.5 * (E + E.T),
                   ellipsoid_offset=robot.ellipsoid_offset + robot.contact_center)


def _check_elastic(v):
    """A cable's stiffness EA above its greatest tension (else it would stretch past twice its
    length within its limits: a unit mistake); a winch error below its cable's length range."""
    EA, t_max = v["cable_stiffness"], v["tension_max"]
    if EA is not None:
        bad = np.flatnonzero(EA <= t_max)
        if bad.size:
            i = bad[0]
            raise InputError(f"robot.cable_stiffness[{i}]", float(EA[i]),
                             f"must exceed robot.tension_max[{i}] = {float(t_max[i])!r} N (EA is "
                             f"the force that doubles the cable's length)")
    e = v["length_error"]
    if e is not None:
        span = v["length_max"] - v["length_min"]
        bad = np.flatnonzero(e >= span)
        if bad.size:
            i = bad[0]
            raise InputError(f"robot.length_error[{i}]", float(e[i]),
                             f"must be below the cable's length range, {float(span[i]):.6g} m")


def _check_platform_shape(v):
    """A platform shape's size is given with its type; a cylinder's x and y extents are one
    diameter, a sphere's three are."""
    kind, size = v["platform_shape.type"], v["platform_shape.size"]
    if kind == "none":
        return
    if size is None:
        raise InputError("robot.platform_shape.size", None, f"required with type {kind}")
    same = SHAPES[kind].platform_extents
    if not np.allclose(size[:same], size[0], rtol=1e-9, atol=0.0):
        raise InputError("robot.platform_shape.size", list(map(float, size)),
                         f"a {kind}'s first {same} extents are one diameter")


def _check_mass_properties(v, d):
    """With a load mass, the load force must be its weight (|force| = mass g within 2 %), so
    that gravity and the inertial terms of the dynamic timing agree; the inertia then
    defaults to 0 (a point mass). Without one, no inertia."""
    mass, force = v["load.mass"], v["load.force"]
    if mass is None:
        if v["load.inertia"] is not None:
            raise InputError("robot.load.inertia", d["load"]["inertia"], "needs robot.load.mass")
        return
    weight = mass * GRAVITY
    if abs(float(np.linalg.norm(force)) - weight) > 0.02 * weight:
        raise InputError("robot.load.mass", mass, f"the load force ({np.linalg.norm(force):.4g} N) "
                         f"must be its weight, {weight:.4g} N (mass x {GRAVITY} m/s^2, 2 %)")
    if v["load.inertia"] is None:
        v["load.inertia"] = np.zeros((3, 3))


def check_not_degenerate(A, B, length_min, length_max):
    """InputError if the anchors make J singular at every pose: the base anchors ``A``
    (6, 3) or the platform anchors ``B`` on one line (every cable line then meets that
    line, or passes through one point: rank J <= 5), or J singular at each of
    JACOBIAN_PROBES poses spread over the reachable region (the check of last resort for
    any other degenerate design). Pairs of coincident anchors are fine (robot1, robot2)."""
    for where, P in (("robot.base_anchors", A), ("robot.platform_anchors", B)):
        spread = _distance_from_best_line(P)
        if spread < MIN_SPREAD_M:
            kind = "coincident" if np.ptp(P, axis=0).max() < MIN_SPREAD_M else "collinear"
            raise InputError(where, P.ravel().tolist(), f"the {len(P)} anchors are {kind}: J is singular "
                             "at every pose (need 3 anchors not on one line)")
    centre = A.mean(axis=0)
    reach = 0.5 * (float(np.min(length_min)) + float(np.min(length_max)))
    p = centre + reach * np.reshape(jacobian_probes.OFFSETS, (JACOBIAN_PROBES, 3))
    R = _probe_rotations(np.reshape(jacobian_probes.AXES, (JACOBIAN_PROBES, 3)),
                         np.array(jacobian_probes.ANGLES))
    b = np.einsum("nij,kj->nki", R, B)  # R B_k, (n, 6, 3)
    d = A[None] - p[:, None] - b  # cable vectors
    u = d / np.maximum(np.linalg.norm(d, axis=-1, keepdims=True), 1e-300)
    J = np.concatenate([u, np.cross(b, u)], axis=-1)
    sv = np.linalg.svd(J, compute_uv=False)
    if np.all(sv[:, -1] <= SINGULAR_RCOND * sv[:, 0]):
        raise InputError("robot.base_anchors", A.ravel().tolist(),
                         f"with robot.platform_anchors J is singular at all {JACOBIAN_PROBES} "
                         "poses tried: a degenerate design")


def _distance_from_best_line(P):
    """Largest distance (m) of the points P (k, 3) from their least-squares line."""
    Q = P - P.mean(axis=0)
    if not np.any(Q):
        return 0.0
    _, _, vt = np.linalg.svd(Q)
    along = Q @ vt[0]
    return float(np.max(np.linalg.norm(Q - along[:, None] * vt[0], axis=1)))


def _probe_rotations(axis, angle):
    """Rotation matrices (n, 3, 3) about ``axis`` (n, 3), not normalised, by ``angle`` (n,)
    rad (Rodrigues)."""
    n = len(angle)
    axis = axis / np.linalg.norm(axis, axis=1, keepdims=True)
    K = np.zeros((n, 3, 3))
    K[:, 0, 1], K[:, 0, 2], K[:, 1, 2] = -axis[:, 2], axis[:, 1], -axis[:, 0]
    K -= K.transpose(0, 2, 1)
    s, c = np.sin(angle)[:, None, None], np.cos(angle)[:, None, None]
    return np.eye(3) + s * K + (1.0 - c) * K @ K


def _check_below(lo_name, lo, hi_name, hi):
    bad = np.flatnonzero(lo >= hi)
    if bad.size:
        i = bad[0]
        raise InputError(f"{lo_name}[{i}]", float(lo[i]),
                         f"must be below {hi_name}[{i}] = {float(hi[i])!r}")


def workspace_box(robot):
    """(low, high) corners (m) of the box under the base anchors that the cables reach."""
    a = robot.base_anchors
    down = 1.0 if robot.force[2] >= 0 else -1.0  # the platform hangs along the load
    z = sorted((float(a[:, 2].min()), float(a[:, 2].max() + down * robot.length_max.max())))
    return np.array([a[:, 0].min(), a[:, 1].min(), z[0]]), np.array([a[:, 0].max(), a[:, 1].max(), z[1]])
