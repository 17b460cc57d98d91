"""The cable-driven hexapod: anchors, limits, load and wrench ellipsoid (SI units).

A robot file is a ROS 2 parameters file, so the same file configures the node:

    cdh_planner:
      ros__parameters:
        robot: {name, winch_names, base_anchors, platform_anchors, length_min, ...}

Arrays are flat because ROS 2 parameters cannot nest lists: ``base_anchors`` holds
A_1..A_6 as 18 numbers (m, base frame F1), ``platform_anchors`` B_1..B_6 (m, platform
frame F2); a 6x6 matrix is 36 numbers row-major, or 6 numbers for a diagonal.
"""

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .. import files
from ..errors import MAX_FORCE_N, MAX_POSITION_M, InputError, check_finite, check_keys, check_numbers, \
    is_number

N_CABLES = 6
ELLIPSOID_FRAMES = ("load", "base")
MAX_NAME_CHARS = 64
MAX_ELLIPSOID = 1e18  # largest |entry| of an ellipsoid matrix (1/N^2, 1/(N m)^2)
MIN_SPREAD_M = 1e-6  # anchors closer than this to one line are collinear
SINGULAR_RCOND = 1e-9  # J with smallest / largest singular value below this is singular
JACOBIAN_PROBES = 16  # poses at which a robot's J must be regular at least once


@dataclass(frozen=True)
class Robot:
    """A cable-driven hexapod. Lengths in m, forces in N, moments in N m.

    The load wrench is ``force`` applied at ``load_point`` (platform frame) plus
    ``moment``; the wrench ellipsoid K = {w : (w - w0)^T E (w - w0) <= 1} has centre
    w0 = load wrench + ``ellipsoid_offset`` and shape ``ellipsoid_matrix`` (E), both given
    in ``ellipsoid_frame``: "load" (F3: parallel to the base, origin at the load point, the
    paper's App. A) or "base" (F1, moments about the base origin).
    """

    name: str
    winch_names: tuple
    base_anchors: np.ndarray  # (6, 3) A_i in F1
    platform_anchors: np.ndarray  # (6, 3) B_i in F2
    length_min: np.ndarray  # (6,)
    length_max: np.ndarray
    tension_min: np.ndarray
    tension_max: np.ndarray
    force: np.ndarray  # (3,) N, base frame
    load_point: np.ndarray  # (3,) m, platform frame (the paper's g / p_m)
    moment: np.ndarray  # (3,) N m, base frame
    ellipsoid_frame: str
    ellipsoid_offset: np.ndarray  # (6,)
    ellipsoid_matrix: np.ndarray  # (6, 6) SPD, combined with the contact ellipsoid if any
    source: str = field(default="", compare=False)
    mass: float = None  # kg, the load's (optional): enables the dynamic timing
    inertia: np.ndarray = None  # (3, 3) kg m^2 about the centre of mass (load_point), platform frame

    @property
    def wrench_center_local(self):
        """w0 in the ellipsoid frame before moving to F1: [F; M] + offset (N, N m)."""
        return np.concatenate([self.force, self.moment]) + self.ellipsoid_offset


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


ROBOT_KEYS = {
    "name", "winch_names", "base_anchors", "platform_anchors", "length_min", "length_max",
    "tension_min", "tension_max", "load", "wrench_ellipsoid", "contact_ellipsoid",
}
LOAD_KEYS = {"force", "point", "moment", "mass", "inertia"}
GRAVITY = 9.80665  # m/s^2: |force| of a load with a mass is its weight (within 2 %)
ELLIPSOID_KEYS = {"frame", "matrix", "offset"}
CONTACT_KEYS = {"matrix", "center"}


def robot_from_dict(d, source=""):
    """Build and validate a Robot from the ``robot:`` mapping (field names as in YAML).

    Numbers must be numbers (not strings), finite and within the input bounds of
    ``errors`` (coordinates and lengths 1e3 m, forces and tensions 1e7 N). A degenerate
    robot is refused: the six base (or platform) anchors on one line, all coincident
    included, or a J singular at every pose tried (see ``check_not_degenerate``)."""
    check_keys("robot", d, ROBOT_KEYS, required={"base_anchors", "platform_anchors",
                                                  "length_min", "length_max", "tension_min",
                                                  "tension_max", "load", "wrench_ellipsoid"})
    name = d.get("name", Path(source).stem or "robot")
    if not isinstance(name, str) or not name or len(name) > MAX_NAME_CHARS:
        raise InputError("robot.name", name, f"expected a name of 1 to {MAX_NAME_CHARS} characters")
    winches = d.get("winch_names", [f"winch_{i + 1}" for i in range(N_CABLES)])
    if (not isinstance(winches, (list, tuple)) or len(winches) != N_CABLES
            or not all(isinstance(w, str) and 0 < len(w) <= MAX_NAME_CHARS for w in winches)
            or len(set(winches)) != N_CABLES):
        raise InputError("robot.winch_names", winches, "expected 6 distinct non-empty names")
    A = _vector("robot.base_anchors", d["base_anchors"], 3 * N_CABLES, MAX_POSITION_M).reshape(N_CABLES, 3)
    B = _vector("robot.platform_anchors", d["platform_anchors"], 3 * N_CABLES,
                MAX_POSITION_M).reshape(N_CABLES, 3)
    lmin = _per_cable("robot.length_min", d["length_min"], positive=True, limit=MAX_POSITION_M)
    lmax = _per_cable("robot.length_max", d["length_max"], positive=True, limit=MAX_POSITION_M)
    fmin = _per_cable("robot.tension_min", d["tension_min"], positive=False, limit=MAX_FORCE_N)
    fmax = _per_cable("robot.tension_max", d["tension_max"], positive=True, limit=MAX_FORCE_N)
    _check_below("robot.length_min", lmin, "robot.length_max", lmax)
    _check_below("robot.tension_min", fmin, "robot.tension_max", fmax)

    load = d["load"]
    check_keys("robot.load", load, LOAD_KEYS, required={"force"})
    force = _vector("robot.load.force", load["force"], 3, MAX_FORCE_N)
    point = _vector("robot.load.point", load.get("point", [0.0, 0.0, 0.0]), 3, MAX_POSITION_M)
    moment = _vector("robot.load.moment", load.get("moment", [0.0, 0.0, 0.0]), 3, MAX_FORCE_N)
    mass, inertia = _mass_properties(load, force)

    ell = d["wrench_ellipsoid"]
    check_keys("robot.wrench_ellipsoid", ell, ELLIPSOID_KEYS, required={"matrix"})
    frame = ell.get("frame", "load")
    if not isinstance(frame, str) or frame not in ELLIPSOID_FRAMES:
        raise InputError("robot.wrench_ellipsoid.frame", frame, f"expected one of {ELLIPSOID_FRAMES}")
    E = _spd_matrix("robot.wrench_ellipsoid.matrix", ell["matrix"])
    offset = _vector("robot.wrench_ellipsoid.offset", ell.get("offset", [0.0] * 6), 6, MAX_FORCE_N)
    if "contact_ellipsoid" in d:
        con = d["contact_ellipsoid"]
        check_keys("robot.contact_ellipsoid", con, CONTACT_KEYS, required={"matrix"})
        E_c = _spd_matrix("robot.contact_ellipsoid.matrix", con["matrix"])
        offset = offset + _vector("robot.contact_ellipsoid.center", con.get("center", [0.0] * 6),
                                  6, MAX_FORCE_N)
        E = combine_contact_ellipsoid(E, E_c)
        E = 0.5 * (E + E.T)
    check_not_degenerate(A, B, lmin, lmax)
    return Robot(name=name, winch_names=tuple(winches), base_anchors=A, platform_anchors=B,
                 length_min=lmin, length_max=lmax, tension_min=fmin, tension_max=fmax,
                 force=force, load_point=point, moment=moment, ellipsoid_frame=frame,
                 ellipsoid_offset=offset, ellipsoid_matrix=E, source=source, mass=mass,
                 inertia=inertia)


def _mass_properties(load, force):
    """(mass kg, inertia (3, 3) kg m^2) of ``load`` (None, None without ``mass``). The force
    must then be the load's weight (|force| = mass g within 2 %), so that gravity and the
    inertial terms of the dynamic timing agree; inertia is 9 numbers (row-major) or 3
    (diagonal), symmetric positive semi-definite, default 0 (a point mass)."""
    if load.get("mass") is None:
        if load.get("inertia") is not None:
            raise InputError("robot.load.inertia", load["inertia"], "needs robot.load.mass")
        return None, None
    mass = check_finite("robot.load.mass", load["mass"], positive=True, limit=MAX_FORCE_N)
    weight = mass * GRAVITY
    if abs(float(np.linalg.norm(force)) - weight) > 0.02 * weight:
        raise InputError("robot.load.mass", mass, f"the load force ({np.linalg.norm(force):.4g} N) "
                         f"must be its weight, {weight:.4g} N (mass x {GRAVITY} m/s^2, 2 %)")
    value = load.get("inertia", [0.0, 0.0, 0.0])
    I = _square_matrix("robot.load.inertia", value, 3, MAX_FORCE_N)
    if not np.allclose(I, I.T, rtol=1e-9, atol=1e-15) or np.linalg.eigvalsh(I)[0] < -1e-12:
        raise InputError("robot.load.inertia", value, "must be symmetric positive semi-definite (kg m^2)")
    return mass, I


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
            raise InputError(where, P.ravel().tolist(), f"the 6 anchors are {kind}: J is singular "
                             "at every pose (need 3 anchors not on one line)")
    rng = np.random.default_rng(0)
    centre = A.mean(axis=0)
    reach = 0.5 * (float(np.min(length_min)) + float(np.min(length_max)))
    p = centre + reach * rng.uniform(-0.5, 0.5, size=(JACOBIAN_PROBES, 3))
    R = _random_rotations(rng, JACOBIAN_PROBES, max_angle=0.5)
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


def _random_rotations(rng, n, max_angle):
    """n rotation matrices about random axes by angles up to ``max_angle`` rad (Rodrigues)."""
    axis = rng.normal(size=(n, 3))
    axis /= np.linalg.norm(axis, axis=1, keepdims=True)
    angle = rng.uniform(0.0, max_angle, size=n)
    K = np.zeros((n, 3, 3))
    K[:, 0, 1], K[:, 0, 2], K[:, 1, 2] = -axis[:, 2], axis[:, 1], -axis[:, 0]
    K -= K.transpose(0, 2, 1)
    s, c = np.sin(angle)[:, None, None], np.cos(angle)[:, None, None]
    return np.eye(3) + s * K + (1.0 - c) * K @ K


def _vector(where, value, n, limit):
    """``n`` numbers (a single number when n is 1), each finite, a number (not a string)
    and within +-``limit``; InputError naming the list or its first bad entry."""
    if is_number(value):
        value = [value]
    if isinstance(value, np.ndarray):
        value = value.ravel().tolist()
    return np.array(check_numbers(where, value, n, limit), dtype=float)


def _per_cable(where, value, positive, limit):
    """6 per-cable values; a single number applies to every cable."""
    if is_number(value):
        value = [value] * N_CABLES
    arr = _vector(where, value, N_CABLES, limit)
    bad = np.flatnonzero(arr <= 0 if positive else arr < 0)
    if bad.size:
        need = "positive" if positive else "non-negative"
        raise InputError(f"{where}[{bad[0]}]", float(arr[bad[0]]), f"must be {need}")
    return arr


def _check_below(lo_name, lo, hi_name, hi):
    bad = np.flatnonzero(lo >= hi)
    if bad.size:
        i = bad[0]
        raise InputError(f"{lo_name}[{i}]", float(lo[i]),
                         f"must be below {hi_name}[{i}] = {float(hi[i])!r}")


def _square_matrix(where, value, n, limit):
    """An n x n matrix from n*n numbers (row-major) or n numbers (its diagonal)."""
    if isinstance(value, (list, tuple)) and len(value) == n:
        return np.diag(_vector(where, value, n, limit))
    return _vector(where, value, n * n, limit).reshape(n, n)


def _spd_matrix(where, value):
    """A 6x6 symmetric positive definite matrix from 36 numbers or a 6-number diagonal."""
    E = _square_matrix(where, value, 6, MAX_ELLIPSOID)
    if not np.allclose(E, E.T, rtol=1e-9, atol=0.0):
        raise InputError(where, value, "must be symmetric")
    eig = np.linalg.eigvalsh(E)
    if eig[0] <= 0:
        raise InputError(where, value, f"must be positive definite (smallest eigenvalue {eig[0]:.3g})")
    return E
