"""Collision checks of a pose against a scene: least signed distance and what binds.

Each cable i is a capsule of radius r (``scene.cable_radius``) from its base anchor a_i
to its platform anchor p + R b_i. Checked at a pose: every cable against every obstacle,
the platform's shape against every obstacle, every cable against the platform's own shape
(beyond ``scene.shared_anchor_exemption`` of its platform anchor, where it is fixed to the
body), and every pair of cables (those sharing an anchor point compared only beyond
``scene.shared_anchor_exemption`` of it: see ``schema``). Distances are signed (m, negative: penetration depth) and computed by the
coal library (GJK / EPA and closed forms) for a mesh, and for the platform against an
obstacle; the rest in the compiled kernel below: cable against cable (two capsules of one
radius are the distance of two segments less 2 r, all pairs at once), and cable against a
primitive obstacle or platform.

Cable against a sphere, box, cylinder or capsule, platform or obstacle: the kernel
minimises the shape's signed distance (convex) along the cable by golden-section search (a
sphere: point against segment; a capsule: segment against segment, closed form), exactly;
in contact that is the deepest point of the cable's axis less its radius, where coal (a
mesh) gives the penetration depth: the same sign, a smaller magnitude.

Speed: a compiled kernel computes all cable pairs and a lower bound for every
cable-obstacle and platform-obstacle pair (bounding capsules of the obstacles: a sphere,
or for a capsule the capsule itself, whose bound is then its exact distance), and the
exact distance of a cable to a primitive obstacle only where that bound is below the least
distance found so far; coal is then called (meshes, the platform against obstacles) in
the order of the remaining bounds only while a bound is below the least distance found,
so the result is the exact least distance with few or no library calls. coal is imported
only when a pair needs it (a scene of primitive obstacles and no platform never loads
it). benchmarks/collision.py measures it.
"""

import math
from dataclasses import dataclass

import numpy as np

from ..parallel import map_blocks
from ..model.shape_forms import COAL_FORM
from .kernels import cable_obstacle_batch, collision_batch
from .margin import COLLISION_UNIT_M, combine  # noqa: F401  (their home; re-exported)
from .schema import SHARED_ANCHOR_M

# A collision margin joins the normalised wrench margin as metres / COLLISION_UNIT_M: 1 cm
# of room counts as a wrench margin of 0.1 (Robot 2's poses have 0.03 to 0.15), and the
# planner's margin floor (1e-3) keeps planned waypoints 0.1 mm beyond the scene's clearance.
GJK_TOLERANCE = 1e-9  # m: coal's convergence tolerance (its default, 1e-6, is too coarse)
SWEEP_STRIDE = 16     # ``blocked_along``: poses checked exactly at least this often
SWEEP_SLACK_M = 1e-6  # m: a bound must clear a pose by this much (the golden-section search and
                      # GJK find distances to ~1e-9 m)


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
        self.static_anchors = (A, B)  # base and platform anchors (m, 3) m
        centres = np.array([o.position for o in self.obstacles], dtype=float).reshape(-1, 3)
        cores = [o.type.bounding_capsule(o) for o in self.obstacles]  # (half axis, radius)
        axes = np.array([h for h, _ in cores], dtype=float).reshape(-1, 3)
        radii = np.array([rad for _, rad in cores], dtype=float)
        forms = [_kernel_form(o) for o in self.obstacles]  # exact in the kernel unless COAL_FORM
        self.exact = [f[0] != COAL_FORM for f in forms]
        plat = self.platform
        self.static = np.concatenate([  # the kernel's constants (offsets: kernels._kernel)
            A.ravel(), B.ravel(), centres.ravel(), axes.ravel(), radii,
            np.reshape(forms, -1), trims.ravel(),
            [scene.cable_radius, scene.shared_anchor_exemption],
            plat.position if plat else np.zeros(3),
            [plat.bounding_radius() if plat else -1.0],  # < 0: no platform
            _kernel_form(plat)])  # its kind code, 3 dimensions, rotation (platform frame)
        self.m, self.K = m, K
        self.buffers = self._buffers(1)  # one pose's (clearance, distances, lower_bounds)
        self.lb, self.frames, self.frames_p, self.cc, self.cp, self.least = \
            (b[0] for b in self.buffers)
        # bindings of what the kernel resolves alone: cable pairs, cables on the platform
        self.pair_binding = np.array([f"collision {self.names[i]} / {self.names[j]}"
                                      for i, j in self.pairs] + ["collision "], dtype=object)
        self.own_binding = np.array([f"collision {n} / platform" for n in self.names],
                                    dtype=object)
        self.obstacle_binding = np.array([f"collision {n} / {o}" for n in self.names
                                          for o in [*(o.id for o in self.obstacles), "platform"]],
                                         dtype=object)  # index i (K + 1) + k (kernel: least)
        self.coal_ready = False  # coal's objects: made when a pair first needs them

    def _buffers(self, n):
        """The kernel's work buffers for n poses: lower bounds (rows: cables, then the
        platform; columns: obstacles, then the platform's own shape), each cable's capsule
        frame (rotation 9, centre 3, half length 1; its platform anchor 3) and that of its
        part kept clear of the platform (13), cable pair distances, cable-platform distances
        of a primitive platform, the least of those two (value, 0 pair / 1 platform / -1,
        index)."""
        m, K = self.m, self.K
        return (np.empty((n, m + 1, K + 1)), np.empty((n, m, 16)), np.empty((n, m, 13)),
                np.empty((n, len(self.pairs))), np.empty((n, m)), np.empty((n, 3)))

    def _run(self, p, R, buffers):
        """The compiled kernel on poses p (N, 3) m, R (N, 3, 3) into ``buffers`` (a large
        batch in blocks on threads: ``parallel.map_blocks``)."""
        p = np.ascontiguousarray(p, dtype=float)
        R = np.ascontiguousarray(R, dtype=float)
        map_blocks(lambda a, b: collision_batch(p[a:b], R[a:b], self.static, self.pairs,
                                                *(x[a:b] for x in buffers)), len(p))

    def _coal(self):
        """coal's shapes, placements and distance functors (cables, platform, obstacles),
        made on the first call that needs one (a scene of primitive obstacles and no
        platform never imports coal)."""
        if self.coal_ready:
            return
        import coal
        scene, plat, m = self.scene, self.platform, self.m
        self.capsules = [coal.Capsule(float(scene.cable_radius), 1.0) for _ in range(m)]
        self.cable_T = [coal.Transform3s() for _ in range(m)]
        self.capsules_p = [coal.Capsule(float(scene.cable_radius), 1.0) for _ in range(m)]
        self.platform_T = coal.Transform3s()
        # ComputeDistance keeps pointers to its shapes: the model holds them
        self.geometry = geometry = [o.type.coal_geometry(o) for o in self.obstacles]
        self.platform_geometry = plat.type.coal_geometry(plat) if plat else None
        self.placement = [coal.Transform3s(o.rotation, o.position) for o in self.obstacles]
        self.cable_fn = [[coal.ComputeDistance(c, g) for g in geometry] for c in self.capsules]
        self.platform_fn = [coal.ComputeDistance(self.platform_geometry, g) for g in geometry] \
            if plat else []
        self.own_fn = [coal.ComputeDistance(c, self.platform_geometry) for c in self.capsules_p] \
            if plat else []
        self.request = coal.DistanceRequest()
        self.request.gjk_tolerance = GJK_TOLERANCE
        self.result = coal.DistanceResult()
        self.coal_ready = True

    # ------------------------------------------------------------------ least distance

    def clearance(self, p, R):
        """The least signed distance (m) at pose (p (3,) m, R (3, 3)) and what binds."""
        p, R = self._pose(p, R)
        return self._answer(*self._resolve(p, R, self.lb, self.least, self.frames,
                                           self.frames_p))

    def _resolve(self, p, R, lb, least, frames, frames_p):
        """(least distance m, what binds: (kind, obstacle index, cables) or None) of pose
        (p, R) from its kernel buffers, calling coal in the order of the lower bounds ``lb``
        while one is below the least distance found (``lb`` is consumed)."""
        best, what = float(least[0]), self._kernel_least(least)
        flat = lb.ravel()  # consumed: each pair tried is set to inf
        m, K = self.m, self.K
        while True:  # in increasing order of the bounds, while one is below the best
            idx = int(np.argmin(flat))
            if flat[idx] >= best:
                break
            flat[idx] = math.inf
            i, k = divmod(idx, K + 1)
            if k == K:
                d, w = self._cable_platform(i, p, R, frames_p), ("cable-platform", k, (i,))
            elif i < m:
                d, w = self._cable_obstacle(i, k, frames), ("cable-obstacle", k, (i,))
            else:
                d, w = self._platform_obstacle(k, p, R), ("platform-obstacle", k, ())
            if d < best:
                best, what = d, w
        return best, what

    def _kernel_least(self, least):
        """What binds the kernel's least distance (value, kind, index): (kind, obstacle
        index (K: the platform), cables) or None."""
        kind, n = int(least[1]), int(least[2])
        if kind == 0:
            return "cable-cable", None, tuple(map(int, self.pairs[n]))
        if kind == 1:
            return "cable-platform", self.K, (n,)
        if kind == 2:
            i, k = divmod(n, self.K + 1)
            return "cable-obstacle", k, (i,)
        return None

    def _pose(self, p, R):
        """Fill the one-pose buffers for pose (p, R): lower bounds, pair distances, frames."""
        p = np.ascontiguousarray(p, dtype=float)
        R = np.ascontiguousarray(R, dtype=float)
        self._run(p[None], R[None], self.buffers)
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

    def _cable_obstacle(self, i, k, frames):
        """Signed distance (m) of cable i's capsule (its frame ``frames[i]``, from the
        kernel) to obstacle k, by coal (a mesh: the kernel has the primitives')."""
        f = frames[i]
        self._coal()
        self.capsules[i].halfLength = f[12]
        T = self.cable_T[i]
        T.setTransform(f[:9].reshape(3, 3), f[9:12])
        self.result.clear()
        return float(self.cable_fn[i][k](T, self.placement[k], self.request, self.result))

    def _platform_obstacle(self, k, p, R):
        """Signed distance (m) of the platform's shape at (p, R) to obstacle k, by coal."""
        self._coal()
        self._place_platform(p, R)
        self.result.clear()
        return float(self.platform_fn[k](self.platform_T, self.placement[k], self.request,
                                         self.result))

    def _cable_platform(self, i, p, R, frames_p):
        """Signed distance (m) of cable i's capsule, short of its platform anchor by the
        exemption (its frame ``frames_p[i]``, from the kernel), to the platform's own shape
        at (p, R)."""
        self._coal()
        f = frames_p[i]
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
        exact = self.cable_obstacle_distances(p[None], R[None])[0]
        out = [("cable-cable", None, tuple(map(int, pair)), float(d))
               for pair, d in zip(self.pairs, self.cc)]
        for k, o in enumerate(self.obstacles):
            out += [("cable-obstacle", o.id, (i,), float(exact[i, k]) if self.exact[k]
                     else self._cable_obstacle(i, k, self.frames)) for i in range(len(self.names))]
            if self.platform is not None:
                out.append(("platform-obstacle", o.id, (), self._platform_obstacle(k, p, R)))
        K = len(self.obstacles)
        out += [("cable-platform", "platform", (i,),
                 self._cable_platform(i, p, R, self.frames_p) if self.lb[i, K] < math.inf else float(self.cp[i]))
                for i in range(len(self.names)) if self.lb[i, K] < math.inf or self.cp[i] < math.inf]
        return out

    def margins(self, p, R):
        """Collision margins (m, distance - clearance) and bindings ("collision winch_2 /
        ball") of N poses: p (N, 3) m, R (N, 3, 3); equal to ``clearance`` pose by pose.
        One compiled call for the batch; coal only for the poses where a lower bound is
        below the kernel's least distance (near an obstacle or the platform's mesh)."""
        best, least, resolved = self._least_distances(p, R)
        kind, index = least[:, 1].astype(int), least[:, 2].astype(int)
        binding = np.where(kind == 1, self.own_binding[np.where(kind == 1, index, 0)],
                           np.where(kind == 2, self.obstacle_binding[np.where(kind == 2, index, 0)],
                                    self.pair_binding[np.where(kind == 0, index, -1)]))
        for n, what in resolved.items():
            binding[n] = f"collision {self._answer(best[n], what).binding}"
        return best - self.scene.clearance, binding

    def margins_only(self, p, R):
        """``margins(p, R)[0]`` (N,) m, the same numbers, without naming what binds (the
        search's and the sweep's yes / no questions)."""
        return self._least_distances(p, R)[0] - self.scene.clearance

    def _least_distances(self, p, R):
        """(least distance (N,) m, the kernel's least rows (N, 3), {pose index: what binds}
        where coal resolved it) of N poses p (N, 3) m, R (N, 3, 3): ``margins``' numbers."""
        p = np.ascontiguousarray(p, dtype=float).reshape(-1, 3)
        R = np.ascontiguousarray(R, dtype=float).reshape(-1, 3, 3)
        buffers = lb, frames, frames_p, _, _, least = self._buffers(len(p))
        self._run(p, R, buffers)
        best = least[:, 0].copy()
        near = np.flatnonzero(lb.reshape(len(p), -1).min(axis=1) < best) if len(p) else ()
        resolved = {}
        for n in near:
            best[n], resolved[n] = self._resolve(p[n], R[n], lb[n], least[n], frames[n],
                                                 frames_p[n])
        return best, least, resolved

    def blocked_along(self, p, R):
        """Which of N poses (p (N, 3) m, R (N, 3, 3)) of a motion, in order, are within the
        scene's clearance: ``margins(p, R)[0] < 0``, the same answers, from fewer exact
        checks (``margins_along`` with floor 0)."""
        return self.margins_along(p, R, named=False)[0] < 0

    def margins_along(self, p, R, floor=0.0, named=True):
        """Collision margins (m) and bindings of N poses (p (N, 3) m, R (N, 3, 3)) of a
        motion, in order: ``margins``'s numbers wherever they may lie below ``floor`` (m,
        scalar or (N,)); elsewhere a lower bound of the margin at least SWEEP_SLACK_M above
        the floor, binding None. Every SWEEP_STRIDE-th pose and the last are checked; a pose
        between is checked only where the checked poses before and after it do not clear it:
        margin there less ``reach`` x (how far any point of the robot can have moved since,
        ``sweep_steps``) below floor + SWEEP_SLACK_M. Sound because every distance checked is
        between two bodies of which each point moves at most that far (``sweep_steps``), and
        a least distance of sets moves no more than their points do. ``named=False``: no
        bindings (None everywhere; ``margins_only``, the yes / no questions)."""
        p = np.ascontiguousarray(p, dtype=float).reshape(-1, 3)
        R = np.ascontiguousarray(R, dtype=float).reshape(-1, 3, 3)
        n = len(p)
        measure = self.margins if named else (lambda p, R: (self.margins_only(p, R), None))
        if n <= 2:
            return measure(p, R)
        moved = np.concatenate([[0.0], np.cumsum(self.sweep_steps(p, R))])  # m, from pose 0
        exact = np.zeros(n, dtype=bool)
        exact[::SWEEP_STRIDE] = exact[-1] = True
        margin, binding = np.full(n, -np.inf), np.full(n, None, dtype=object)
        margin[exact], binding[exact] = measure(p[exact], R[exact])
        known = np.flatnonzero(exact)
        before = known[np.searchsorted(known, np.arange(n), side="right") - 1]
        after = known[np.searchsorted(known, np.arange(n), side="left")]
        with np.errstate(invalid="ignore"):  # nan (inf - inf: no bound) is checked
            bound = np.maximum(margin[before] - (moved - moved[before]),
                               margin[after] - (moved[after] - moved))
            check = ~exact & ~(bound - floor >= SWEEP_SLACK_M)
        margin[check], binding[check] = measure(p[check], R[check])
        cleared = ~(exact | check)
        margin[cleared] = bound[cleared]
        return margin, binding

    def sweep_steps(self, p, R):
        """(N - 1,) m: between consecutive poses (p (N, 3) m, R (N, 3, 3)), ``reach`` times the
        most any point of a cable or of the platform's shape moves, so that no distance this
        model checks changes by more. A point x of the platform frame moves |dp + dR x| <=
        |dp| + |dR|_F |x| (|x| up to the farthest platform anchor or the shape's bounding
        sphere); a point of a cable, a convex combination of its anchors (the base one fixed),
        no more than its platform anchor, and of a cable kept clear of a shared anchor by rho,
        whose end there is the anchor plus rho u, |du| <= 2 |dq| / L more: reach =
        2 (1 + 2 rho / L), L no longer than the shortest cable over the poses (|p - a_i| -
        |b_i|; inf steps where that is not positive); 2: both bodies of a pair move (cable
        against cable or against the platform)."""
        A, B = self.static_anchors
        b = np.linalg.norm(B, axis=1)
        plat = self.platform
        extent = max(b.max(), float(np.linalg.norm(plat.position)) + plat.bounding_radius()) \
            if plat else b.max()
        d = p[:, None, :] - A                      # |p + R b_i - a_i| >= |p - a_i| - |b_i|
        shortest = np.min(np.sqrt(np.einsum("nki,nki->nk", d, d)) - b)
        if not shortest > 0:  # no bound: every pose is checked
            return np.full(len(p) - 1, np.inf)
        reach = 2.0 * (1.0 + 2.0 * self.scene.shared_anchor_exemption / shortest)
        dp, dR = np.diff(p, axis=0), np.diff(R, axis=0).reshape(-1, 9)
        return reach * (np.sqrt(np.einsum("ni,ni->n", dp, dp))
                        + np.sqrt(np.einsum("ni,ni->n", dR, dR)) * extent)

    def cable_obstacle_distances(self, p, R):
        """Every cable's signed distance (m) to every primitive obstacle, unpruned: (N, m, K)
        at poses p (N, 3) m, R (N, 3, 3), the kernel's numbers (nan for a mesh: coal's)."""
        p = np.ascontiguousarray(p, dtype=float).reshape(-1, 3)
        R = np.ascontiguousarray(R, dtype=float).reshape(-1, 3, 3)
        out = np.empty((len(p), self.m, self.K))
        cable_obstacle_batch(p, R, self.static, self.pairs, out)
        return out

    def binding_cables(self, p, R):
        """(distance (N,) m, cable (N,) int) at poses p (N, 3) m, R (N, 3, 3): where a cable
        against a primitive obstacle is the kernel's least distance, that distance and the
        cable's index (the distance is the kernel's exact one, and moves no more than the
        cable's platform anchor does: each point of the cable moves less); elsewhere
        (inf, -1). One compiled call, no coal."""
        p = np.ascontiguousarray(p, dtype=float).reshape(-1, 3)
        R = np.ascontiguousarray(R, dtype=float).reshape(-1, 3, 3)
        buffers = self._buffers(len(p))
        self._run(p, R, buffers)
        least = buffers[-1]
        hit = least[:, 1] == 2.0
        cable = np.where(hit, least[:, 2].astype(int) // (self.K + 1), -1)
        return np.where(hit, least[:, 0], np.inf), cable


def _kernel_form(shape):
    """The kernel's description of a shape (13 numbers): its form code and three numbers
    (model.shapes: ``kernel_form``; COAL_FORM without a platform), its rotation (row-major;
    a platform's in the platform frame, an obstacle's in the base frame)."""
    if shape is None:
        return np.r_[COAL_FORM, 0.0, 0.0, 0.0, np.eye(3).ravel()]
    return np.r_[shape.type.kernel_form(shape), np.asarray(shape.rotation, float).ravel()]


def _cable_pairs(A, B):
    """Every pair (i, j), i < j, of cables, and which ends they share: trims (n, 2) with
    1.0 where the base anchors (column 0) or platform anchors (column 1) coincide."""
    m = len(A)
    pairs = [(i, j) for i in range(m) for j in range(i + 1, m)]
    trims = [(float(np.linalg.norm(A[i] - A[j]) < SHARED_ANCHOR_M),
              float(np.linalg.norm(B[i] - B[j]) < SHARED_ANCHOR_M)) for i, j in pairs]
    return np.array(pairs, dtype=np.int64).reshape(-1, 2), np.array(trims).reshape(-1, 2)


