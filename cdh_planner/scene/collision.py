"""Collision checks of a pose against a scene: least signed distance and what binds.

Each cable i is a capsule of radius r (``scene.cable_radius``) from its base anchor a_i
to its platform anchor p + R b_i. Checked at a pose: every cable against every obstacle,
the platform's shape against every obstacle, and every pair of cables (those sharing an
anchor point compared only beyond ``scene.shared_anchor_exemption`` of it: see
``schema``). Distances are signed (m, negative: penetration depth) and computed by the
coal library (GJK / EPA and closed forms), except cable against cable: two capsules of
one radius are the distance of two segments less 2 r, computed for all pairs at once in
the compiled kernel below.

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

from .schema import SHARED_ANCHOR_M

GJK_TOLERANCE = 1e-9  # m: coal's convergence tolerance (its default, 1e-6, is too coarse)
EPS = 1e-300


@dataclass(frozen=True)
class Clearance:
    """The least signed distance at a pose (m) and what binds: ``kind`` one of
    "cable-obstacle", "platform-obstacle", "cable-cable" (None with nothing to check and
    ``distance`` inf); ``obstacle`` its id (or None), ``cables`` the cable indices
    involved (0-based). ``margin`` = distance - the scene's clearance; ``ok`` when >= 0."""

    distance: float
    margin: float
    kind: str = None
    obstacle: str = None
    cables: tuple = ()
    binding: str = ""

    @property
    def ok(self):
        return self.margin >= 0.0


class CollisionModel:
    """The robot's cables and platform against the scene's obstacles, ready to check poses.

    ``clearance(p, R)``: the least signed distance and what binds (exact, pruned);
    ``distances(p, R)``: every checked pair's distance (no pruning: tests, markers)."""

    def __init__(self, robot, scene):
        self.scene = scene
        self.names = tuple(robot.winch_names)
        self.A = np.ascontiguousarray(robot.base_anchors, dtype=float)
        self.B = np.ascontiguousarray(robot.platform_anchors, dtype=float)
        self.r = float(scene.cable_radius)
        self.obstacles = scene.obstacles
        self.geometry = [_geometry(o) for o in self.obstacles]
        self.placement = [coal.Transform3s(o.rotation, o.position) for o in self.obstacles]
        self.centres = np.array([o.position for o in self.obstacles], dtype=float).reshape(-1, 3)
        self.radii = np.array([o.bounding_radius() for o in self.obstacles], dtype=float)
        self.platform = scene.platform
        self.platform_geometry = _geometry(scene.platform) if scene.platform else None
        self.pairs, self.trims = _cable_pairs(self.A, self.B)
        self.rho = float(scene.shared_anchor_exemption)
        self.capsules = [coal.Capsule(self.r, 1.0) for _ in self.names]
        self.request = coal.DistanceRequest()
        self.request.gjk_tolerance = GJK_TOLERANCE
        self.result = coal.DistanceResult()

    # ------------------------------------------------------------------ least distance

    def clearance(self, p, R):
        """The least signed distance (m) at pose (p (3,) m, R (3, 3)) and what binds."""
        p = np.asarray(p, dtype=float)
        R = np.asarray(R, dtype=float)
        Bw = p + self.B @ R.T
        lb, cc, plb = self._bounds(p, R, Bw)
        best, what = math.inf, None
        if cc.size:
            k = int(np.argmin(cc))
            best, what = float(cc[k]), ("cable-cable", None, tuple(map(int, self.pairs[k])))
        if self.obstacles:
            flat = np.concatenate([lb.ravel(), plb])
            m = len(self.names)
            for idx in np.argsort(flat):
                if flat[idx] >= best:
                    break
                i, k = divmod(int(idx), len(self.obstacles))
                if i < m:
                    d, w = self.cable_obstacle(i, k, Bw), ("cable-obstacle", k, (i,))
                else:
                    d, w = self.platform_obstacle(k, p, R), ("platform-obstacle", k, ())
                if d < best:
                    best, what = d, w
        return self._answer(best, what)

    def _bounds(self, p, R, Bw):
        """Cable-obstacle lower bounds (m, K), cable pair distances, platform lower bounds."""
        m, K = len(self.names), len(self.obstacles)
        lb = np.empty((m, K))
        cc = np.empty(len(self.pairs))
        _kernel(self.A, Bw, self.centres, self.radii, self.r, self.pairs, self.trims, self.rho,
                lb, cc)
        if self.platform is None or not K:
            return lb, cc, np.full(0, math.inf)
        centre = p + R @ self.platform.position
        plb = np.linalg.norm(self.centres - centre, axis=1) - self.radii \
            - self.platform.bounding_radius()
        return lb, cc, plb

    def _answer(self, best, what):
        if what is None:
            return Clearance(distance=math.inf, margin=math.inf)
        kind, k, cables = what
        oid = self.obstacles[k].id if k is not None else None
        parts = [self.names[i] for i in cables] if cables else ["platform"]
        binding = " / ".join(parts + ([oid] if oid is not None else []))
        return Clearance(distance=best, margin=best - self.scene.clearance, kind=kind,
                         obstacle=oid, cables=cables, binding=binding)

    # ------------------------------------------------------------------ one pair (coal)

    def cable_obstacle(self, i, k, Bw):
        """Signed distance (m) of cable i (capsule a_i .. Bw[i]) to obstacle k, by coal."""
        a, b = self.A[i], Bw[i]
        d = b - a
        length = float(np.linalg.norm(d))
        cap = self.capsules[i]
        cap.halfLength = 0.5 * length
        T = coal.Transform3s(_z_to(d / max(length, EPS)), 0.5 * (a + b))
        return self._distance(cap, T, self.geometry[k], self.placement[k])

    def platform_obstacle(self, k, p, R):
        """Signed distance (m) of the platform's shape at (p, R) to obstacle k, by coal."""
        s = self.platform
        T = coal.Transform3s(R @ s.rotation, p + R @ s.position)
        return self._distance(self.platform_geometry, T, self.geometry[k], self.placement[k])

    def _distance(self, g1, T1, g2, T2):
        self.result.clear()
        return float(coal.distance(g1, T1, g2, T2, self.request, self.result))

    # ------------------------------------------------------------------ every pair

    def distances(self, p, R):
        """Every checked pair at pose (p, R): a list of (kind, obstacle id or None, cable
        indices, signed distance m), unpruned (for tests and markers)."""
        p, R = np.asarray(p, dtype=float), np.asarray(R, dtype=float)
        Bw = p + self.B @ R.T
        _, cc, _ = self._bounds(p, R, Bw)
        out = [("cable-cable", None, tuple(map(int, pair)), float(d))
               for pair, d in zip(self.pairs, cc)]
        for k, o in enumerate(self.obstacles):
            out += [("cable-obstacle", o.id, (i,), self.cable_obstacle(i, k, Bw))
                    for i in range(len(self.names))]
            if self.platform is not None:
                out.append(("platform-obstacle", o.id, (), self.platform_obstacle(k, p, R)))
        return out


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


def _z_to(u):
    """A rotation matrix taking the z axis to the unit vector u (a capsule's axis)."""
    c = float(u[2])
    if c < -1.0 + 1e-12:
        return np.diag([1.0, -1.0, -1.0])
    v = np.array([-u[1], u[0], 0.0])  # z x u
    K = np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])
    return np.eye(3) + K + K @ K / (1.0 + c)


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
def _kernel(A, Bw, C, rad, r, pairs, trims, rho, lb, cc):
    """lb[i, k] = dist(segment a_i b_i, C[k]) - rad[k] - r (a lower bound of cable i's
    distance to obstacle k); cc[n] = distance of the capsules of cable pair n (shared ends
    cut by rho; inf when a cut leaves nothing)."""
    m, K = A.shape[0], C.shape[0]
    for i in range(m):
        for k in range(K):
            lb[i, k] = _point_segment(C[k], A[i], Bw[i]) - rad[k] - r
    p0, p1, q0, q1 = np.empty(3), np.empty(3), np.empty(3), np.empty(3)
    for n in range(pairs.shape[0]):
        i, j = pairs[n, 0], pairs[n, 1]
        ok = _cut(A[i], Bw[i], trims[n, 0], trims[n, 1], rho, p0, p1) and \
            _cut(A[j], Bw[j], trims[n, 0], trims[n, 1], rho, q0, q1)
        cc[n] = _segment_segment(p0, p1, q0, q1) - 2.0 * r if ok else np.inf


@njit(cache=True)
def _cut(a, b, cut_a, cut_b, rho, out0, out1):
    """The segment a..b with rho removed at the ends flagged; False if nothing is left."""
    length = math.sqrt((b[0] - a[0]) ** 2 + (b[1] - a[1]) ** 2 + (b[2] - a[2]) ** 2)
    s0 = rho / length if cut_a > 0.0 and length > 0.0 else 0.0
    s1 = 1.0 - (rho / length if cut_b > 0.0 and length > 0.0 else 0.0)
    if (cut_a > 0.0 or cut_b > 0.0) and (length == 0.0 or s1 <= s0):
        return False
    for c in range(3):
        out0[c] = a[c] + s0 * (b[c] - a[c])
        out1[c] = a[c] + s1 * (b[c] - a[c])
    return True


@njit(cache=True)
def _point_segment(c, a, b):
    d0, d1, d2 = b[0] - a[0], b[1] - a[1], b[2] - a[2]
    w0, w1, w2 = c[0] - a[0], c[1] - a[1], c[2] - a[2]
    dd = d0 * d0 + d1 * d1 + d2 * d2
    t = 0.0 if dd <= 0.0 else min(1.0, max(0.0, (w0 * d0 + w1 * d1 + w2 * d2) / dd))
    return math.sqrt((w0 - t * d0) ** 2 + (w1 - t * d1) ** 2 + (w2 - t * d2) ** 2)


@njit(cache=True)
def _segment_segment(p0, p1, q0, q1):
    """Least distance between segments p0..p1 and q0..q1 (Ericson, Real-Time Collision
    Detection, 5.1.9)."""
    d1 = p1 - p0
    d2 = q1 - q0
    r = p0 - q0
    a, e, f = d1 @ d1, d2 @ d2, d2 @ r
    if a <= EPS and e <= EPS:
        return math.sqrt(r @ r)
    if a <= EPS:
        s, t = 0.0, min(1.0, max(0.0, f / e))
    else:
        c = d1 @ r
        if e <= EPS:
            s, t = min(1.0, max(0.0, -c / a)), 0.0
        else:
            b = d1 @ d2
            denom = a * e - b * b
            s = min(1.0, max(0.0, (b * f - c * e) / denom)) if denom > 1e-14 * a * e else 0.0
            t = (b * s + f) / e
            if t < 0.0:
                s, t = min(1.0, max(0.0, -c / a)), 0.0
            elif t > 1.0:
                s, t = min(1.0, max(0.0, (b - c) / a)), 1.0
    g = p0 + s * d1 - q0 - t * d2
    return math.sqrt(g @ g)
