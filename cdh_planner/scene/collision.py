"""Collision checks of a pose against a scene: least signed distance and what binds.

Each cable i is a capsule of radius r (``scene.cable_radius``) from its base anchor a_i
to its platform anchor p + R b_i. Checked at a pose: every cable against every obstacle,
the platform's shape against every obstacle, every cable against the platform's own shape
(beyond ``scene.shared_anchor_exemption`` of its platform anchor, where it is fixed to the
body), and every pair of cables (those sharing an anchor point compared only beyond
``scene.shared_anchor_exemption`` of it: see ``schema``). Distances are signed (m, negative: penetration depth) and computed by the
coal library (GJK / EPA and closed forms), except cable against cable: two capsules of
one radius are the distance of two segments less 2 r, computed for all pairs at once in
the compiled kernel below.

Cable against a sphere, box or cylinder platform: the kernel minimises the shape's signed
distance (convex) along the cable by golden-section search, exactly; in contact that is
the deepest point of the cable's axis less its radius, where coal (a mesh platform, the
obstacles) gives the penetration depth: the same sign, a smaller magnitude.

Speed: a compiled kernel computes all cable pairs and a lower bound for every
cable-obstacle and platform-obstacle pair (bounding spheres of the obstacles); coal is
then called in the order of those bounds only while a bound is below the least distance
found, so the result is the exact least distance with a few library calls.
benchmarks/collision.py measures it.
"""

import math
from dataclasses import dataclass

import coal
import numpy as np
from numba import njit

from .margin import COLLISION_UNIT_M, combine  # noqa: F401  (their home; re-exported)
from .schema import SHARED_ANCHOR_M

# A collision margin joins the normalised wrench margin as metres / COLLISION_UNIT_M: 1 cm
# of room counts as a wrench margin of 0.1 (Robot 2's poses have 0.03 to 0.15), and the
# planner's margin floor (1e-3) keeps planned waypoints 0.1 mm beyond the scene's clearance.
GJK_TOLERANCE = 1e-9  # m: coal's convergence tolerance (its default, 1e-6, is too coarse)
EPS = 1e-300
MESH_CODE = 3.0   # a platform the kernel leaves to coal (a mesh)
GOLDEN_STEPS = 40   # golden-section steps on a cable: 0.618^40 = 4e-9 of its length (~1 nm)


@dataclass(frozen=True)
class Clearance:
    """The least signed distance at a pose (m) and what binds: ``kind`` one of
    "cable-obstacle", "platform-obstacle", "cable-cable" (None with nothing to check and
    ``distance`` inf); ``obstacle`` its id (or None), ``cables`` the cable indices
    involved (0-based): "cable-platform" names the obstacle "platform". ``margin`` =
    distance - the scene's clearance; ``ok`` when >= 0."""

    distance: float
    margin: float
    kind: str = None
    obstacle: str = None
    cables: tuple = ()
    names: tuple = ()  # the cables' winch names

    @property
    def ok(self):
        return self.margin >= 0.0

    @property
    def binding(self):
        """What binds, in words: "winch_2 / ball", "platform / post", "winch_1 / winch_4"."""
        if self.kind is None:
            return ""
        parts = [self.names[i] for i in self.cables] if self.cables else ["platform"]
        return " / ".join(parts + ([self.obstacle] if self.obstacle is not None else []))


class CollisionModel:
    """The robot's cables and platform against the scene's obstacles, ready to check poses.

    ``clearance(p, R)``: the least signed distance and what binds (exact, pruned);
    ``distances(p, R)``: every checked pair's distance (no pruning: tests, markers).
    Holds its work buffers: one model per thread."""

    def __init__(self, robot, scene):
        self.scene = scene
        self.names = tuple(robot.winch_names)
        A = np.asarray(robot.base_anchors, dtype=float)
        B = np.asarray(robot.platform_anchors, dtype=float)
        m, K = len(A), len(scene.obstacles)
        self.obstacles = scene.obstacles
        self.platform = scene.platform
        self.pairs, trims = _cable_pairs(A, B)
        centres = np.array([o.position for o in self.obstacles], dtype=float).reshape(-1, 3)
        radii = np.array([o.bounding_radius() for o in self.obstacles], dtype=float)
        plat = self.platform
        self.static = np.concatenate([  # the kernel's constants, one array (offsets: _kernel)
            A.ravel(), B.ravel(), centres.ravel(), radii, trims.ravel(),
            [scene.cable_radius, scene.shared_anchor_exemption],
            plat.position if plat else np.zeros(3),
            [plat.bounding_radius() if plat else -1.0],  # < 0: no platform
            _platform_form(plat)])  # its kind code, 3 dimensions, rotation (platform frame)
        # work buffers: lower bounds (rows: cables, then the platform; columns: obstacles,
        # then the platform's own shape) and each cable's capsule frame (rotation 9, centre
        # 3, half length 1; its platform anchor 3) and that of its part kept clear of the
        # platform (13), cable pair distances
        self.lb = np.empty((m + 1, K + 1))
        self.frames = np.empty((m, 16))
        self.frames_p = np.empty((m, 13))
        self.cc = np.empty(len(self.pairs))
        self.cp = np.empty(m)   # cable-platform distances of a primitive platform (kernel)
        self.least = np.empty(3)   # the least of cc and cp: value, 0 (cc) / 1 (cp) / -1, index
        self._coal(m)

    def _coal(self, m):
        """coal's shapes, placements and distance functors (cables, platform, obstacles)."""
        scene, plat = self.scene, self.platform
        self.capsules = [coal.Capsule(float(scene.cable_radius), 1.0) for _ in range(m)]
        self.cable_T = [coal.Transform3s() for _ in range(m)]
        self.capsules_p = [coal.Capsule(float(scene.cable_radius), 1.0) for _ in range(m)]
        self.platform_T = coal.Transform3s()
        # ComputeDistance keeps pointers to its shapes: the model holds them
        self.geometry = geometry = [_geometry(o) for o in self.obstacles]
        self.platform_geometry = _geometry(plat) if plat else None
        self.placement = [coal.Transform3s(o.rotation, o.position) for o in self.obstacles]
        self.cable_fn = [[coal.ComputeDistance(c, g) for g in geometry] for c in self.capsules]
        self.platform_fn = [coal.ComputeDistance(self.platform_geometry, g) for g in geometry] \
            if plat else []
        self.own_fn = [coal.ComputeDistance(c, self.platform_geometry) for c in self.capsules_p] \
            if plat else []
        self.request = coal.DistanceRequest()
        self.request.gjk_tolerance = GJK_TOLERANCE
        self.result = coal.DistanceResult()

    # ------------------------------------------------------------------ least distance

    def clearance(self, p, R):
        """The least signed distance (m) at pose (p (3,) m, R (3, 3)) and what binds."""
        p, R = self._pose(p, R)
        best, kind, n = self.least   # the kernel's least cable-cable / cable-platform distance
        what = None if kind < 0 else \
            ("cable-cable", None, tuple(map(int, self.pairs[int(n)]))) if kind == 0 else \
            ("cable-platform", len(self.obstacles), (int(n),))
        best = float(best)
        flat = self.lb.ravel()  # consumed: each pair tried is set to inf
        m, K = len(self.names), len(self.obstacles)
        while True:  # in increasing order of the bounds, while one is below the best
            idx = int(np.argmin(flat))
            if flat[idx] >= best:
                break
            flat[idx] = math.inf
            i, k = divmod(idx, K + 1)
            if k == K:
                d, w = self._cable_platform(i, p, R), ("cable-platform", k, (i,))
            elif i < m:
                d, w = self._cable_obstacle(i, k), ("cable-obstacle", k, (i,))
            else:
                d, w = self._platform_obstacle(k, p, R), ("platform-obstacle", k, ())
            if d < best:
                best, what = d, w
        return self._answer(best, what)

    def _pose(self, p, R):
        """Fill the work buffers for pose (p, R): lower bounds, pair distances, frames."""
        p = np.ascontiguousarray(p, dtype=float)
        R = np.ascontiguousarray(R, dtype=float)
        _kernel(p, R, self.static, self.pairs, self.lb, self.frames, self.frames_p, self.cc,
                self.cp)
        _least(self.cc, self.cp, self.least)
        return p, R

    def _answer(self, best, what):
        if what is None:
            return Clearance(distance=math.inf, margin=math.inf)
        kind, k, cables = what
        oid = None if k is None else "platform" if k == len(self.obstacles) \
            else self.obstacles[k].id
        return Clearance(distance=best, margin=best - self.scene.clearance, kind=kind,
                         obstacle=oid, cables=cables, names=self.names)

    # ------------------------------------------------------------------ one pair (coal)

    def _cable_obstacle(self, i, k):
        """Signed distance (m) of cable i's capsule (frame from the last ``_pose``) to
        obstacle k, by coal."""
        f = self.frames[i]
        self.capsules[i].halfLength = f[12]
        T = self.cable_T[i]
        T.setTransform(f[:9].reshape(3, 3), f[9:12])
        self.result.clear()
        return float(self.cable_fn[i][k](T, self.placement[k], self.request, self.result))

    def _platform_obstacle(self, k, p, R):
        """Signed distance (m) of the platform's shape at (p, R) to obstacle k, by coal."""
        self._place_platform(p, R)
        self.result.clear()
        return float(self.platform_fn[k](self.platform_T, self.placement[k], self.request,
                                         self.result))

    def _cable_platform(self, i, p, R):
        """Signed distance (m) of cable i's capsule, short of its platform anchor by the
        exemption (frame from the last ``_pose``), to the platform's own shape at (p, R)."""
        f = self.frames_p[i]
        self.capsules_p[i].halfLength = f[12]
        T = self.cable_T[i]
        T.setTransform(f[:9].reshape(3, 3), f[9:12])
        self._place_platform(p, R)
        self.result.clear()
        return float(self.own_fn[i](T, self.platform_T, self.request, self.result))

    def _place_platform(self, p, R):
        s = self.platform
        self.platform_T.setTransform(R @ s.rotation, p + R @ s.position)

    # ------------------------------------------------------------------ every pair

    def distances(self, p, R):
        """Every checked pair at pose (p, R): a list of (kind, obstacle id or None, cable
        indices, signed distance m), unpruned (for tests and markers)."""
        p, R = self._pose(p, R)
        out = [("cable-cable", None, tuple(map(int, pair)), float(d))
               for pair, d in zip(self.pairs, self.cc)]
        for k, o in enumerate(self.obstacles):
            out += [("cable-obstacle", o.id, (i,), self._cable_obstacle(i, k))
                    for i in range(len(self.names))]
            if self.platform is not None:
                out.append(("platform-obstacle", o.id, (), self._platform_obstacle(k, p, R)))
        K = len(self.obstacles)
        out += [("cable-platform", "platform", (i,),
                 self._cable_platform(i, p, R) if self.lb[i, K] < math.inf else float(self.cp[i]))
                for i in range(len(self.names)) if self.lb[i, K] < math.inf or self.cp[i] < math.inf]
        return out

    def margins(self, p, R):
        """Collision margins (m, distance - clearance) and bindings ("collision winch_2 /
        ball") of N poses: p (N, 3) m, R (N, 3, 3)."""
        p = np.asarray(p, dtype=float).reshape(-1, 3)
        R = np.asarray(R, dtype=float).reshape(-1, 3, 3)
        margin, binding = np.empty(len(p)), np.empty(len(p), dtype=object)
        for n in range(len(p)):
            c = self.clearance(p[n], R[n])
            margin[n], binding[n] = c.margin, f"collision {c.binding}"
        return margin, binding

    def lower_bounds(self, p, R):
        """Lower bounds (m + 1, K + 1), m, of the cable-obstacle (rows 0..m-1, columns
        0..K-1), platform-obstacle (row m) and cable-platform (column K) distances at pose
        (p, R), from bounding spheres (inf: not checked)."""
        self._pose(p, R)
        return self.lb.copy()


def _platform_form(shape):
    """The kernel's description of a platform shape (13 numbers): kind code (0 sphere, 1
    box, 2 cylinder, MESH_CODE a mesh or none: coal's), dimensions (radius; half edges;
    radius, half height), its rotation in the platform frame (row-major)."""
    if shape is None:
        return np.r_[MESH_CODE, 0.0, 0.0, 0.0, np.eye(3).ravel()]
    dims = {"sphere": lambda: (0.0, shape.radius, 0.0, 0.0),
            "box": lambda: (1.0, *(0.5 * np.asarray(shape.size, float))),
            "cylinder": lambda: (2.0, shape.radius, 0.5 * shape.height, 0.0),
            "mesh": lambda: (MESH_CODE, 0.0, 0.0, 0.0)}[shape.kind]()
    return np.r_[dims, np.asarray(shape.rotation, float).ravel()]


def _geometry(shape):
    """The coal geometry of a Shape, in its own frame."""
    if shape.kind == "sphere":
        return coal.Sphere(shape.radius)
    if shape.kind == "box":
        return coal.Box(*map(float, shape.size))
    if shape.kind == "cylinder":
        return coal.Cylinder(shape.radius, shape.height)
    points = coal.StdVec_Vec3s()
    for v in shape.vertices:
        points.append(np.asarray(v, dtype=float))
    return coal.Convex.convexHull(points, False, "")


def _cable_pairs(A, B):
    """Every pair (i, j), i < j, of cables, and which ends they share: trims (n, 2) with
    1.0 where the base anchors (column 0) or platform anchors (column 1) coincide."""
    m = len(A)
    pairs = [(i, j) for i in range(m) for j in range(i + 1, m)]
    trims = [(float(np.linalg.norm(A[i] - A[j]) < SHARED_ANCHOR_M),
              float(np.linalg.norm(B[i] - B[j]) < SHARED_ANCHOR_M)) for i, j in pairs]
    return np.array(pairs, dtype=np.int64).reshape(-1, 2), np.array(trims).reshape(-1, 2)


# ----------------------------------------------------------------------------- kernel

@njit(cache=True)
def _kernel(p, R, static, pairs, lb, frames, frames_p, cc, cp):
    """For pose (p, R): lb[i, k] = dist(segment a_i b_i, c_k) - rho_k - r, a lower bound
    of cable i's distance to obstacle k (c_k, rho_k its bounding sphere), and lb[m, k]
    the platform's (|centre - c_k| - rho_k - rho_platform; inf without a platform);
    lb[i, K] cable i's (cut by rho at its platform anchor) to the platform's own shape
    (inf without one, or if nothing is left; lb[m, K] inf); frames[i]: cable i's capsule
    frame (rotation taking z to the cable, row-major; centre; half length), frames_p[i]
    that of its cut part; cc[n]: the distance of the capsules of cable pair n (shared ends
    cut by rho; inf if nothing is left); cp[i]: cable i's (cut) distance to a sphere, box or
    cylinder platform, exact here (lb[i, K] is then inf: no coal call), inf otherwise.
    Scalar code on 3-tuples: no allocation in the loops."""
    m, K, P = lb.shape[0] - 1, lb.shape[1] - 1, pairs.shape[0]
    oB, oC = 3 * m, 6 * m
    oR = oC + 3 * K
    oT = oR + K
    o = oT + 2 * P
    r, rho = static[o], static[o + 1]
    pc = _add(_rot(R, _v(static, o + 2)), _v(p, 0))
    prad = static[o + 5]
    form = static[o + 6:o + 19]     # kind code, dimensions, rotation (platform frame)
    M = R @ form[4:13].reshape(3, 3)   # the platform shape's axes in the base frame
    for i in range(m):
        a = _v(static, 3 * i)
        b = _add(_rot(R, _v(static, oB + 3 * i)), _v(p, 0))
        frames[i, 13], frames[i, 14], frames[i, 15] = b  # the platform anchor, for the pairs
        _frame(a, b, frames[i])
        for k in range(K):
            lb[i, k] = _point_segment(_v(static, oC + 3 * k), a, b) - static[oR + k] - r
        lb[i, K], cp[i] = _own(a, b, pc, prad, M, form, r, rho, frames_p[i])
    lb[m, K] = np.inf
    for k in range(K):
        lb[m, k] = _norm(_sub(_v(static, oC + 3 * k), pc)) - static[oR + k] - prad \
            if prad >= 0.0 else np.inf
    for n in range(P):
        i, j = pairs[n, 0], pairs[n, 1]
        cut_a, cut_b = static[oT + 2 * n], static[oT + 2 * n + 1]
        ok1, p0, p1 = _cut(_v(static, 3 * i), _v(frames[i], 13), cut_a, cut_b, rho)
        ok2, q0, q1 = _cut(_v(static, 3 * j), _v(frames[j], 13), cut_a, cut_b, rho)
        cc[n] = _segment_segment(p0, p1, q0, q1) - 2.0 * r if ok1 and ok2 else np.inf


@njit(cache=True)
def _least(cc, cp, out):
    """out = (least of cc and cp, 0 if it is cc's / 1 if cp's / -1 if both are empty or
    inf, its index)."""
    out[0], out[1], out[2] = np.inf, -1.0, -1.0
    for n in range(cc.shape[0]):
        if cc[n] < out[0]:
            out[0], out[1], out[2] = cc[n], 0.0, n
    for i in range(cp.shape[0]):
        if cp[i] < out[0]:
            out[0], out[1], out[2] = cp[i], 1.0, i


@njit(cache=True)
def _own(a, b, pc, prad, M, form, r, rho, frame):
    """(lower bound, exact distance) of the cable a..b, cut by rho at its platform anchor
    b, to the platform's own shape: exact for a primitive (the bound inf), else the bound
    from its bounding sphere and the cut capsule's ``frame`` for coal; (inf, inf) without a
    platform or a cut cable."""
    if prad < 0.0:
        return np.inf, np.inf
    ok, q0, q1 = _cut(a, b, 0.0, 1.0, rho)
    if not ok:
        return np.inf, np.inf
    if form[0] < MESH_CODE:
        return np.inf, _segment_sdf(_local(M, pc, q0), _local(M, pc, q1), form) - r
    _frame(q0, q1, frame)
    return _point_segment(pc, q0, q1) - prad - r, np.inf


@njit(cache=True)
def _local(M, c, x):
    """x (base frame) in the frame of axes M (columns) and origin c."""
    d = _sub(x, c)
    return (M[0, 0] * d[0] + M[1, 0] * d[1] + M[2, 0] * d[2],
            M[0, 1] * d[0] + M[1, 1] * d[1] + M[2, 1] * d[2],
            M[0, 2] * d[0] + M[1, 2] * d[1] + M[2, 2] * d[2])


@njit(cache=True)
def _sdf(x, form):
    """Signed distance (m) of the point x (shape frame) to a sphere (code 0: radius), box
    (1: half edges) or cylinder (2: radius, half height; axis z)."""
    if form[0] == 0.0:
        return _norm(x) - form[1]
    if form[0] == 1.0:
        q = (abs(x[0]) - form[1], abs(x[1]) - form[2], abs(x[2]) - form[3])
    else:
        q = (math.hypot(x[0], x[1]) - form[1], abs(x[2]) - form[2], -np.inf)
    out = (max(q[0], 0.0), max(q[1], 0.0), max(q[2], 0.0))
    return _norm(out) + min(max(q[0], max(q[1], q[2])), 0.0)


@njit(cache=True)
def _segment_sdf(x0, x1, form):
    """Least signed distance of the segment x0..x1 (shape frame) to the shape: the signed
    distance to a convex set is convex, so golden-section search on the segment finds its
    minimum (GOLDEN_STEPS steps: within 4e-9 of the segment's length); a sphere's in
    closed form."""
    if form[0] == 0.0:
        return _point_segment((0.0, 0.0, 0.0), x0, x1) - form[1]
    d = _sub(x1, x0)
    lo, hi, g = 0.0, 1.0, 0.6180339887498949
    c, e = hi - g, g
    fc = _sdf(_add(x0, _scale(c, d)), form)
    fe = _sdf(_add(x0, _scale(e, d)), form)
    for _ in range(GOLDEN_STEPS):
        if fc < fe:
            hi, e, fe = e, c, fc
            c = hi - g * (hi - lo)
            fc = _sdf(_add(x0, _scale(c, d)), form)
        else:
            lo, c, fc = c, e, fe
            e = lo + g * (hi - lo)
            fe = _sdf(_add(x0, _scale(e, d)), form)
    return min(fc, fe, _sdf(x0, form), _sdf(x1, form))


@njit(cache=True, inline="always")
def _v(x, o):
    return (x[o], x[o + 1], x[o + 2])


@njit(cache=True, inline="always")
def _add(a, b):
    return (a[0] + b[0], a[1] + b[1], a[2] + b[2])


@njit(cache=True, inline="always")
def _sub(a, b):
    return (a[0] - b[0], a[1] - b[1], a[2] - b[2])


@njit(cache=True, inline="always")
def _scale(s, a):
    return (s * a[0], s * a[1], s * a[2])


@njit(cache=True, inline="always")
def _dot(a, b):
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


@njit(cache=True, inline="always")
def _norm(a):
    return math.sqrt(_dot(a, a))


@njit(cache=True, inline="always")
def _rot(R, x):
    return (R[0, 0] * x[0] + R[0, 1] * x[1] + R[0, 2] * x[2],
            R[1, 0] * x[0] + R[1, 1] * x[1] + R[1, 2] * x[2],
            R[2, 0] * x[0] + R[2, 1] * x[1] + R[2, 2] * x[2])


@njit(cache=True)
def _frame(a, b, out):
    """out[:13] = rotation taking z to the unit vector u along a -> b (row-major:
    Rodrigues about z x u, R = I + K + K^2 / (1 + u_z)), the midpoint, half the length."""
    d = _sub(b, a)
    length = _norm(d)
    x, y, z = (d[0] / length, d[1] / length, d[2] / length) if length > 0.0 else (0.0, 0.0, 1.0)
    if z < -1.0 + 1e-12:
        rows = (1.0, 0.0, 0.0, 0.0, -1.0, 0.0, 0.0, 0.0, -1.0)
    else:
        h = 1.0 / (1.0 + z)
        rows = (1.0 - h * x * x, -h * x * y, x,
                -h * x * y, 1.0 - h * y * y, y,
                -x, -y, 1.0 - h * (x * x + y * y))
    for c in range(9):
        out[c] = rows[c]
    for c in range(3):
        out[9 + c] = 0.5 * (a[c] + b[c])
    out[12] = 0.5 * length


@njit(cache=True)
def _cut(a, b, cut_a, cut_b, rho):
    """(ok, a', b'): the segment a..b with rho removed at the ends flagged; ok False if
    nothing is left."""
    d = _sub(b, a)
    length = _norm(d)
    if (cut_a > 0.0 or cut_b > 0.0) and length == 0.0:
        return False, a, b
    s0 = rho / length if cut_a > 0.0 else 0.0
    s1 = 1.0 - (rho / length if cut_b > 0.0 else 0.0)
    if (cut_a > 0.0 or cut_b > 0.0) and s1 <= s0:
        return False, a, b
    return True, _add(a, _scale(s0, d)), _add(a, _scale(s1, d))


@njit(cache=True)
def _point_segment(c, a, b):
    d, w = _sub(b, a), _sub(c, a)
    dd = _dot(d, d)
    t = 0.0 if dd <= 0.0 else min(1.0, max(0.0, _dot(w, d) / dd))
    return _norm(_sub(w, _scale(t, d)))


@njit(cache=True)
def _segment_segment(p0, p1, q0, q1):
    """Least distance between segments p0..p1 and q0..q1 (Ericson, Real-Time Collision
    Detection, 5.1.9)."""
    d1, d2, r = _sub(p1, p0), _sub(q1, q0), _sub(p0, q0)
    a, e, f = _dot(d1, d1), _dot(d2, d2), _dot(d2, r)
    if a <= EPS and e <= EPS:
        return _norm(r)
    if a <= EPS:
        s, t = 0.0, min(1.0, max(0.0, f / e))
    else:
        c = _dot(d1, r)
        if e <= EPS:
            s, t = min(1.0, max(0.0, -c / a)), 0.0
        else:
            b = _dot(d1, d2)
            denom = a * e - b * b
            s = min(1.0, max(0.0, (b * f - c * e) / denom)) if denom > 1e-14 * a * e else 0.0
            t = (b * s + f) / e
            if t < 0.0:
                s, t = min(1.0, max(0.0, -c / a)), 0.0
            elif t > 1.0:
                s, t = min(1.0, max(0.0, (b - c) / a)), 1.0
    return _norm(_sub(_add(r, _scale(s, d1)), _scale(t, d2)))
